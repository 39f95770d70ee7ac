"""``ebraille-sim identify``: the seed paper's FSR identification, on the virtual bench or on
recorded data.

Without ``--csv`` the virtual bench (:mod:`ebraille_sim.identification.bench`) records the paper's six
profiles, the 30-minute hold and the DMA test; with ``--csv FILE`` (repeatable) recorded
bench data are read instead (columns ``time_s``, ``voltage_v``, ``force_n``; the first file
is the estimation record).  Every model kind and order is identified on the estimation
record (:func:`ebraille_sim.identification.sysid.fit_report`) and scored on every record.

Outputs in ``--out DIR`` (written to a temporary folder first and moved into place only
when complete):

* ``fitness.json``: kind -> order -> profile -> fitness (eq. 7, %);
* ``fitness.md``: one table per kind (rows: profiles, columns: orders, best in bold), the
  paper's Tables 5-8 beside them for a bench run, and the winning model;
* ``summary.json``: settings, per-model delay, poles, stability and estimation fit; with
  ``--readings`` each model's fits with ``nk = 0`` and ``nk = 1`` (the paper prints no delay:
  its notation read literally and MATLAB's convention), estimation and mean over the records;
* ``models/KIND-ORDER.json``: the identified models, in the records' detrended units;
* ``models/KIND-ORDER-device.json``: the same models re-expressed for the device, which
  tares the voltage at no load and reads the absolute force
  (:func:`ebraille_sim.identification.sysid.shift_operating_point`); choose one as the in-loop estimator
  with ``[estimator] model = "path.json"`` (bench runs, or CSV runs with
  ``--no-load-voltage``);
* ``plots/KIND-ORDER.png``: measured and modelled force for every record;
* bench runs only: ``dma.md``/``dma.json`` (virtual DMA beside Table 3, eqs. 3-4 refitted,
  eq. 6 scored like Table 4), ``creep.json`` (30-minute hold) and ``data/*.csv`` (the raw
  records, readable back with ``--csv``).
"""
from __future__ import annotations

import dataclasses
import json
import math
import pathlib
import time

NAME = "identify"
HELP = "identify the FSR estimator models (virtual bench or recorded CSV); write fitness tables, plots and models"

MAX_STARTS = 64
"""Most starts per delay candidate (``--starts``)."""

IDENTIFY_OWNED = {"fitness.json": None, "fitness.md": None, "summary.json": None, "dma.md": None, "dma.json": None,
                  "creep.json": None, "models": "*.json", "plots": "*.png", "data": "*.csv"}
"""What ``identify`` writes into its folder (of ``models/``, ``plots/``, ``data/`` only those files)."""


def add_arguments(p):
    from ebraille_sim.commands import number, seed, whole
    p.add_argument("--out", default="runs/identify", metavar="DIR", help="output folder (default: runs/identify)")
    p.add_argument("--csv", action="append", default=None, metavar="FILE",
                   help="recorded bench data with columns time_s, voltage_v, force_n; repeat for more "
                        "records; the first is the estimation record")
    p.add_argument("--seed", type=seed, default=0,
                   help="master seed of the bench and the multi-start, in [0, 2**63) (default 0)")
    p.add_argument("--quick", action="store_true", help="one start and one delay candidate per model (about 4x faster)")
    p.add_argument("--starts", type=whole(1, MAX_STARTS), default=None, metavar="N",
                   help=f"starts per delay candidate, at most {MAX_STARTS} (default 4, --quick 1)")
    p.add_argument("--kinds", default="linear,hammerstein,wiener,hammerstein-wiener",
                   help="comma-separated model kinds (default: all four)")
    p.add_argument("--orders", default="2,3,4,5", help="comma-separated orders of the linear block (default 2,3,4,5)")
    p.add_argument("--baseline-s", type=number(0, 3600), default=2.0, metavar="S",
                   help="CSV: initial stretch at preload whose mean is removed, in [0, 3600] s "
                        "(0: keep offsets; default 2)")
    p.add_argument("--cutoff-hz", type=number(0, 1e6), default=40.0, metavar="HZ",
                   help="CSV: zero-phase low-pass cut-off, in [0, 1e6] Hz (0: none; default 40)")
    p.add_argument("--no-load-voltage", type=number(0, 100), default=None, metavar="V",
                   help="CSV: divider voltage with the FSR unloaded, for the device versions of the models")
    p.add_argument("--nk", type=whole(0, 10), default=None, metavar="K",
                   help="input delay of every model, samples (default: searched over 0-3); the paper prints none: "
                        "0 reads its notation literally, 1 is MATLAB's convention")
    p.add_argument("--readings", action="store_true",
                   help="also fit every model with nk = 0 and with nk = 1 (the paper's two readings of its delay) on "
                        "the same estimation record and report both fits (fitness.md, summary.json); not with --nk")
    p.add_argument("--nyquist-clearance", type=number(0, 0.99), default=0.0, metavar="D",
                   help="keep every pole at least D from z = -1, in [0, 0.99] (default 0: anywhere inside "
                        "the unit circle, as MATLAB placed most of the paper's)")
    p.add_argument("--chirp-dwell", type=number(0.05, 600), default=None, metavar="S",
                   help="virtual bench: seconds on each chirp frequency, rounded up to whole cycles, in "
                        "[0.05, 600] (default: two cycles or 1 s, whichever is longer)")
    p.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    p.add_argument("-j", "--jobs", type=whole(1, 256), default=1, metavar="N",
                   help="worker processes fitting the models side by side (default 1; same results for any N)")


def _parse_list(text: str, name: str, allowed, convert=str):
    items = [t.strip() for t in str(text).split(",") if t.strip()]
    if not items:
        raise ValueError(f"--{name} is empty")
    out = []
    for t in items:
        try:
            v = convert(t)
        except ValueError:
            raise ValueError(f"--{name}: {t!r} is not valid") from None
        if v not in allowed:
            raise ValueError(f"--{name}: {t!r} is not one of {', '.join(str(a) for a in allowed)}")
        if v in out:
            raise ValueError(f"--{name}: {t!r} is given twice")
        out.append(v)
    return out


def _fit_one(job):
    """Fit and score one ``(kind, order)`` (a worker's unit; seeded by ``fit_options``, so the
    result does not depend on which process runs it or in which order)."""
    from ebraille_sim.identification.sysid import fit_readings, fit_report, fitness, simulate
    kind, order, records, estimation, fit_options, readings = job
    est = records[estimation]
    t0 = time.perf_counter()
    rep = fit_report(kind, est.voltage_v, est.force_n, order, dt_s=est.dt_s, **fit_options)
    seconds = time.perf_counter() - t0
    m = rep.model
    sims = {name: simulate(m, rec.voltage_v) for name, rec in records.items()}
    scores = {name: fitness(rec.force_n, sims[name]) for name, rec in records.items()}
    poles = m.linear.poles()
    info = {"nk": rep.nk, "estimation_fitness": rep.fitness_pct, "seconds": seconds,
            "poles": [[float(p.real), float(p.imag)] for p in poles],
            "max_abs_pole": float(max(abs(p) for p in poles)) if len(poles) else 0.0,
            "stable": bool(m.linear.is_stable()),
            "linear_fitness_by_nk": {str(k): v for k, v in rep.linear_fitness_by_nk.items()},
            "fitness_by_nk": {str(k): v for k, v in rep.fitness_by_nk.items()}}
    if readings:
        by_nk = fit_readings(kind, est.voltage_v, est.force_n, order, dt_s=est.dt_s, **fit_options)
        info["readings"] = {}
        for k, r in by_nk.items():
            rec_fit = {name: fitness(rec.force_n, simulate(r.model, rec.voltage_v)) for name, rec in records.items()}
            info["readings"][str(k)] = {"estimation_fitness": r.fitness_pct, "records": rec_fit,
                                        "mean_fitness": sum(rec_fit.values()) / len(rec_fit)}
    return m, scores, info, sims


def identify_all(records: dict, estimation: str, kinds, orders, fit_options: dict, log=None, jobs: int = 1,
                 sims: dict | None = None, readings: bool = False):
    """Identify every kind and order on ``records[estimation]`` and score it on every record.

    Parameters
    ----------
    jobs : int
        Worker processes fitting models side by side (1: in this process).  The results do
        not depend on it: every fit is seeded by ``fit_options`` alone.
    sims : dict, optional
        Filled with ``(kind, order) -> record name -> simulated force`` (the scoring
        simulations, reused by :func:`plot_fit`).
    readings : bool
        Also fit each model with ``nk = 0`` and ``nk = 1`` (:func:`~ebraille_sim.identification.sysid.fit_readings`)
        and add their fits to ``info`` (``"readings"``).

    Returns
    -------
    models : dict
        ``(kind, order) -> BlockModel``.
    table : dict
        ``kind -> order -> record name -> fitness %``.
    info : dict
        ``"kind-order" -> {nk, estimation_fitness, poles, max_abs_pole, stable, seconds}``.
    """
    jobs_list = [(kind, order, records, estimation, fit_options, readings) for kind in kinds for order in orders]
    if jobs > 1 and len(jobs_list) > 1:
        from concurrent.futures import ProcessPoolExecutor

        from ebraille_sim.tools.parallel import process_context
        with ProcessPoolExecutor(max_workers=min(jobs, len(jobs_list)), mp_context=process_context()) as pool:
            done = list(pool.map(_fit_one, jobs_list))
    else:
        done = map(_fit_one, jobs_list)
    models, table, info = {}, {}, {}
    for (kind, order, *_), (m, scores, inf, sim) in zip(jobs_list, done):
        models[(kind, order)] = m
        table.setdefault(kind, {})[order] = scores
        info[f"{kind}-{order}"] = inf
        if sims is not None:
            sims[(kind, order)] = sim
        if log:
            log(f"  {kind:<19} order {order}: nk={inf['nk']}  estimation fit {inf['estimation_fitness']:6.2f} %  "
                f"({inf['seconds']:.1f} s)" + ("".join(
                    f"; nk = {k}: {r['estimation_fitness']:.2f} %" for k, r in inf["readings"].items())
                    if "readings" in inf else ""))
    return models, table, info


def best_model(table: dict) -> tuple[str, int, float]:
    """The kind and order with the highest mean fitness over the records."""
    best = None
    for kind, by_order in table.items():
        for order, by_rec in by_order.items():
            mean = sum(by_rec.values()) / len(by_rec)
            if best is None or mean > best[2]:
                best = (kind, order, mean)
    return best


def fitness_markdown(table: dict, labels: dict, paper: dict | None, estimation: str, source: str,
                     readings: dict | None = None) -> str:
    """``fitness.md``: one table per kind, best value of each row in bold; with ``readings``
    (``"kind-order" -> {"0": fits, "1": fits}``) the fits under both readings of the delay."""
    kind_title = {"linear": "Linear", "hammerstein": "Hammerstein", "wiener": "Wiener",
                  "hammerstein-wiener": "Hammerstein-Wiener"}
    lines = ["# Identification fitness (eq. 7, %)", "",
             f"Data: {source}. Estimation record: {labels.get(estimation, estimation)}. "
             "Every model is simulated from rest on each detrended record.", ""]

    def block(title, by_order):
        orders = list(by_order)
        names = list(next(iter(by_order.values())))
        out = [f"## {title}", "", "| Profile | " + " | ".join(f"Order {o}" for o in orders) + " |",
               "|---|" + "---:|" * len(orders)]
        for name in names:
            vals = [by_order[o][name] for o in orders]
            top = max(vals)
            cells = [f"**{v:.2f}**" if v == top else f"{v:.2f}" for v in vals]
            out.append(f"| {labels.get(name, name)} | " + " | ".join(cells) + " |")
        return out + [""]

    for kind, by_order in table.items():
        lines += block(kind_title.get(kind, kind), by_order)
    kind, order, mean = best_model(table)
    lines += [f"Best model by mean fitness over the records: **{kind_title.get(kind, kind)}, order {order}** "
              f"({mean:.2f} %).", ""]
    if readings:
        lines += ["## The paper's input delay: both readings", "",
                  "The paper prints no nk: nk = 0 reads its notation literally, nk = 1 is MATLAB's convention. "
                  "Each model fitted with the delay held, on the same estimation record.", "",
                  "| Model | estimation nk = 0 | estimation nk = 1 | mean over records nk = 0 | nk = 1 |",
                  "|---|---:|---:|---:|---:|"]
        for key, r in readings.items():
            lines.append(f"| {key} | {r['0']['estimation_fitness']:.2f} | {r['1']['estimation_fitness']:.2f} | "
                         f"{r['0']['mean_fitness']:.2f} | {r['1']['mean_fitness']:.2f} |")
        lines.append("")
    if paper:
        lines += ["# The paper's Tables 5-8, for comparison", ""]
        for kind in table:
            if kind in paper:
                sub = {o: paper[kind][o] for o in table[kind] if o in paper[kind]}
                if sub:
                    lines += block(f"{kind_title.get(kind, kind)} (paper)", sub)
    return "\n".join(lines)


PLOT_POINTS = 1200
"""Points per drawn line: a longer record is drawn as the minimum and maximum of each of
``PLOT_POINTS / 2`` time buckets (its visible envelope at the figure's resolution)."""


def _envelope(t: np.ndarray, y: np.ndarray, points: int = PLOT_POINTS) -> tuple[np.ndarray, np.ndarray]:
    """``(t, y)`` reduced to the minimum and maximum of ``points // 2`` equal buckets, in time order."""
    import numpy as np
    n = len(y)
    buckets = points // 2
    if n <= points or buckets < 1:
        return t, y
    edges = np.linspace(0, n, buckets + 1).astype(int)
    lo = np.minimum.reduceat(y, edges[:-1])
    hi = np.maximum.reduceat(y, edges[:-1])
    t_mid = 0.5 * (t[edges[:-1]] + t[np.maximum(edges[1:] - 1, edges[:-1])])
    return np.repeat(t_mid, 2), np.column_stack([lo, hi]).ravel()


class FitPlotter:
    """One figure of panels (one per record) redrawn for each model: the layout is computed once.

    Parameters
    ----------
    records : dict
        Record name -> record (``time_s``, ``force_n``, ``voltage_v``).
    labels : dict
        Record name -> panel title.
    """

    def __init__(self, records: dict, labels: dict):
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        self._plt = plt
        self.records = records
        self.labels = labels
        n = len(records)
        cols = 2 if n > 1 else 1
        rows = math.ceil(n / cols)
        self.fig, axes = plt.subplots(rows, cols, figsize=(6.0 * cols, 2.4 * rows), squeeze=False)
        self.panels = []
        for ax, (name, rec) in zip(axes.ravel(), records.items()):
            ax.plot(*_envelope(rec.time_s, rec.force_n), color="0.2", lw=0.8, label="measured")
            (line,) = ax.plot(*_envelope(rec.time_s, rec.force_n), color="tab:orange", lw=0.8, label="model")
            ax.set_title(f"{labels.get(name, name)}: 100.00 %", fontsize=9)
            ax.set_xlabel("time (s)", fontsize=8)
            ax.set_ylabel("force (N)", fontsize=8)
            ax.tick_params(labelsize=7)
            self.panels.append((ax, name, rec, line))
        for ax in axes.ravel()[n:]:
            ax.axis("off")
        axes[0, 0].legend(fontsize=7, loc="upper right")
        self.title = self.fig.suptitle("model", fontsize=10)
        self.fig.tight_layout()

    def draw(self, model, path, sims: dict | None = None) -> None:
        """Draw ``model`` (its simulated force on every record: ``sims`` when given) to ``path``."""
        from ebraille_sim.identification.sysid import fitness, simulate
        for ax, name, rec, line in self.panels:
            y = sims[name] if sims is not None else simulate(model, rec.voltage_v)
            line.set_data(*_envelope(rec.time_s, y))
            ax.set_title(f"{self.labels.get(name, name)}: {fitness(rec.force_n, y):.2f} %", fontsize=9)
            ax.relim()
            ax.autoscale_view()
        self.title.set_text(model.name)
        self.fig.savefig(path, dpi=90)

    def close(self) -> None:
        self._plt.close(self.fig)


def plot_fit(model, records: dict, labels: dict, path, sims: dict | None = None) -> None:
    """Measured and modelled force of one model on every record (one panel each)."""
    plotter = FitPlotter(records, labels)
    try:
        plotter.draw(model, path, sims)
    finally:
        plotter.close()


def dma_markdown(ideal_rows, real_rows, coeffs, eq6, eq6_paper_a, a_fit, labels) -> str:
    """``dma.md``: virtual DMA beside Table 3, eqs. 3-4 refitted, eq. 6 like Table 4."""
    from ebraille_sim.identification.dma import EQ3_DAMPING_COEFFS, EQ4_STIFFNESS_COEFFS, PAPER_A, TABLE4_FITNESS

    lines = ["# Virtual DMA and the second-order model", "",
             "## Stiffness and damping (eq. 5) beside Table 3", "",
             "Ideal instruments: no load-cell noise, no quantisation of the actuator, the displacement "
             "transducer or the force. Realistic: the bench's instruments "
             "(2.2 mN noise, 0.68 mN steps, 1.5 um actuator steps, 0.2 um transducer steps).", "",
             "| f (Hz) | k ideal (kN/m) | k realistic | k test 1 | k test 2 | c ideal (N s/m) | "
             "c realistic | c test 1 | c test 2 |", "|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r, q in zip(ideal_rows, real_rows):
        lines.append(f"| {r['frequency_hz']:.3f} | {r['k_virtual'] / 1e3:.2f} | {q['k_virtual'] / 1e3:.2f} "
                     f"+/- {q['k_se'] / 1e3:.2f} | {r['k_test1'] / 1e3:.2f} | {r['k_test2'] / 1e3:.2f} | "
                     f"{r['c_virtual']:.3f} | {q['c_virtual']:.1f} +/- {q['c_se']:.1f} | {r['c_test1']:.3f} | "
                     f"{r['c_test2']:.3f} |")
    c_co, k_co = coeffs
    if c_co:
        lines += ["", f"Eqs. 3-4 refitted to the ideal DMA: c = {c_co[0]:.2f} f^2 {c_co[1]:+.2f} f {c_co[2]:+.2f} "
                  f"N s/m (paper: {EQ3_DAMPING_COEFFS[0]:.2f} f^2 {EQ3_DAMPING_COEFFS[1]:+.2f} f "
                  f"{EQ3_DAMPING_COEFFS[2]:+.2f}); k = {k_co[0] / 1e3:.2f} f {k_co[1] / 1e3:+.2f} kN/m "
                  f"(paper: {EQ4_STIFFNESS_COEFFS[0] / 1e3:.2f} f {EQ4_STIFFNESS_COEFFS[1] / 1e3:+.2f})."]
    lines += ["", "## Eq. 6, F = A (m_ac V'' + c V' + k V), like Table 4", "",
              f"A fitted on the chirp: {a_fit:.4g} (paper: {PAPER_A:.4g}).", "",
              "| Profile | fitness, A fitted | fitness, paper's A | paper (Table 4) |", "|---|---:|---:|---:|"]
    for name, v in eq6.items():
        paper = TABLE4_FITNESS.get(name)
        lines.append(f"| {labels.get(name, name)} | {v:.2f} | {eq6_paper_a[name]:.2f} | "
                     f"{'' if paper is None else f'{paper:.2f}'} |")
    return "\n".join(lines) + "\n"


def _write_json(path, doc) -> None:
    path.write_text(json.dumps(doc, indent=2, allow_nan=False) + "\n", encoding="utf-8")


def main(args) -> int:
    import numpy as np

    from ebraille_sim.commands import check_out_dir, claim_out_dir, console
    from ebraille_sim.identification import bench as B
    from ebraille_sim.identification import dma as D
    from ebraille_sim.identification.sysid import PAPER_FITNESS, shift_operating_point

    con = console(args)
    if args.seed < 0:
        raise ValueError(f"--seed must be >= 0, got {args.seed}")
    if args.starts is not None and args.starts < 1:
        raise ValueError(f"--starts must be >= 1, got {args.starts}")
    kinds = _parse_list(args.kinds, "kinds", ("linear", "hammerstein", "wiener", "hammerstein-wiener"))
    orders = _parse_list(args.orders, "orders", tuple(range(1, 11)), int)
    if not (math.isfinite(args.baseline_s) and args.baseline_s >= 0):
        raise ValueError(f"--baseline-s must be a number >= 0, got {args.baseline_s}")
    if not (math.isfinite(args.cutoff_hz) and args.cutoff_hz >= 0):
        raise ValueError(f"--cutoff-hz must be a number >= 0, got {args.cutoff_hz}")
    if args.no_load_voltage is not None and not (args.csv and math.isfinite(args.no_load_voltage)):
        raise ValueError("--no-load-voltage needs --csv and a finite value (the bench knows its own)")
    for path in args.csv or ():
        if not pathlib.Path(path).exists():
            raise ValueError(f"--csv {str(path)!r}: CSV file not found")
        if not pathlib.Path(path).is_file():
            raise ValueError(f"--csv {str(path)!r} is not a file")
    if args.csv and args.chirp_dwell is not None:
        raise ValueError("--chirp-dwell sets the virtual bench's chirp; a recorded CSV has its own")
    fit_options = {"seed": args.seed, "n_starts": args.starts or (1 if args.quick else 4),
                   "n_delay_candidates": 1 if args.quick else 2, "max_nfev": 100 if args.quick else 200}
    if args.readings and args.nk is not None:
        raise ValueError("--readings fits nk = 0 and nk = 1 itself; give it without --nk")
    if args.nk is not None:
        fit_options["nk"] = args.nk
    if args.nyquist_clearance:
        fit_options["nyquist_clearance"] = args.nyquist_clearance

    out = check_out_dir(args.out, owned=IDENTIFY_OWNED)
    with claim_out_dir(out, IDENTIFY_OWNED) as target:
        log = con.say
        labels = dict(B.PROFILE_LABELS)
        extra = {}
        if args.csv:
            records = {}
            for path in args.csv:
                rec = B.load_csv(path, baseline_s=args.baseline_s, cutoff_hz=args.cutoff_hz or None)
                if rec.name in records:
                    raise ValueError(f"two CSV files share the name {rec.name!r}; rename one")
                first = next(iter(records.values()), rec)
                if abs(rec.dt_s - first.dt_s) > 1e-6 * first.dt_s:
                    raise ValueError(f"{path} is sampled every {rec.dt_s:g} s but {first.name} every {first.dt_s:g} s; "
                                     "all records must share one rate")
                records[rec.name] = rec
            estimation = next(iter(records))
            source = "recorded CSV (" + ", ".join(str(p) for p in args.csv) + ")"
            no_load_v = args.no_load_voltage
            log(f"read {len(records)} record(s); estimation record: {estimation}")
        else:
            ss_bench, ss_hold, ss_dma = np.random.SeedSequence(args.seed).spawn(3)
            bench = B.BenchParams()
            log("virtual bench: recording the paper's profiles ...")
            profiles = dict(B.PAPER_PROFILES)
            if args.chirp_dwell is not None:
                profiles["chirp"] = dataclasses.replace(profiles["chirp"], chirp_dwell_s=args.chirp_dwell)
            records = B.run_profiles(profiles.values(), bench, ss_bench)
            estimation = "chirp"
            source = f"virtual bench, seed {args.seed}"
            if args.chirp_dwell is not None:
                source += f", chirp dwell {args.chirp_dwell:g} s"
            from ebraille_sim.physics.fsr import static_voltage
            no_load_v = static_voltage(0.0, bench.device.fsr, bench.device.circuit)
            hold = B.run_profile(B.HOLD_PROFILE, bench, ss_hold)
            creep = B.hold_creep(hold, bench)
            extra["creep"] = {"hold_s": B.HOLD_PROFILE.hold_s, "resistance_start_ohm": creep["resistance_start_ohm"],
                              "resistance_end_ohm": creep["resistance_end_ohm"],
                              "creep_fraction": creep["creep_fraction"], "paper_creep_fraction": 0.06}
            log(f"  30-min hold: resistance creep {100 * creep['creep_fraction']:+.2f} % (paper: about +6 %)")
            log("virtual DMA at 0.125-0.5 Hz (ideal and realistic instruments) ...")
            cycles = 3 if args.quick else 10
            ss_ideal, ss_real = ss_dma.spawn(2)
            dma_ideal = D.dma_test(D.ideal_instruments(bench), cycles=cycles, seed=ss_ideal)
            dma_real = D.dma_test(bench, cycles=cycles, seed=ss_real)
            ideal_rows, real_rows = D.table3_comparison(dma_ideal), D.table3_comparison(dma_real)
            eq6_model = D.fit_second_order(records["chirp"], dma_ideal.damping_coeffs, dma_ideal.stiffness_coeffs)
            eq6 = D.second_order_table(records, eq6_model)
            eq6_paper_a = D.second_order_table(records, D.SecondOrderModel(D.PAPER_A))
            extra["dma"] = {"ideal": {"points": ideal_rows, "damping_coeffs": list(dma_ideal.damping_coeffs),
                                      "stiffness_coeffs": list(dma_ideal.stiffness_coeffs)},
                            "realistic": {"points": real_rows, "damping_coeffs": list(dma_real.damping_coeffs),
                                          "stiffness_coeffs": list(dma_real.stiffness_coeffs)},
                            "eq6_amplitude": eq6_model.amplitude, "eq6_fitness": eq6,
                            "eq6_fitness_paper_amplitude": eq6_paper_a}
            extra["dma_md"] = dma_markdown(ideal_rows, real_rows, (dma_ideal.damping_coeffs, dma_ideal.stiffness_coeffs),
                                           eq6, eq6_paper_a, eq6_model.amplitude, labels)
            worst = max(abs(r[k]) for r in ideal_rows for k in ("k_rel_test1", "k_rel_test2", "c_rel_test1", "c_rel_test2"))
            log(f"  ideal DMA vs Table 3: largest difference {100 * worst:.1f} %; eq. 6 A = {eq6_model.amplitude:.4g}")

        log(f"identifying {len(kinds)} kind(s) x {len(orders)} order(s) on {estimation} ...")
        t0 = time.perf_counter()
        sims: dict = {}
        models, table, info = identify_all(records, estimation, kinds, orders, fit_options, log, jobs=args.jobs,
                                           sims=sims, readings=args.readings)
        total = time.perf_counter() - t0

        with target.staged() as tmp:
            _write_json(tmp / "fitness.json", {k: {str(o): v for o, v in by.items()} for k, by in table.items()})
            paper = None if args.csv else PAPER_FITNESS
            readings = {key: inf["readings"] for key, inf in info.items() if "readings" in inf} or None
            (tmp / "fitness.md").write_text(fitness_markdown(table, labels, paper, estimation, source, readings),
                                            encoding="utf-8")
            kind, order, mean = best_model(table)
            summary = {"source": source, "seed": args.seed, "estimation_record": estimation, "records": list(records),
                       "fit_options": fit_options, "identification_seconds": total,
                       "best": {"kind": kind, "order": order, "mean_fitness": mean}, "models": info}
            if "creep" in extra:
                summary["creep"] = extra["creep"]
                _write_json(tmp / "creep.json", extra["creep"])
                _write_json(tmp / "dma.json", extra["dma"])
                (tmp / "dma.md").write_text(extra["dma_md"], encoding="utf-8")
                (tmp / "data").mkdir()
                for name, rec in records.items():
                    rec.to_csv(tmp / "data" / f"{name}.csv")
            _write_json(tmp / "summary.json", summary)
            (tmp / "models").mkdir()
            plotter = None
            if not args.no_plots:
                (tmp / "plots").mkdir()
                plotter = FitPlotter(records, labels)
            est = records[estimation]
            if no_load_v is not None:
                offsets = {"input_offset_v": est.voltage_offset_v - no_load_v, "output_offset_n": est.force_offset_n,
                           "no_load_voltage_v": no_load_v}
                summary["device_model_offsets"] = offsets
                _write_json(tmp / "summary.json", summary)
            for (k, o), m in models.items():
                m.save(tmp / "models" / f"{k}-{o}.json")
                if no_load_v is not None:
                    shift_operating_point(m, offsets["input_offset_v"], offsets["output_offset_n"],
                                          name=m.name + ", device (tared at no load)").save(
                        tmp / "models" / f"{k}-{o}-device.json")
                if plotter is not None:
                    plotter.draw(m, tmp / "plots" / f"{k}-{o}.png", sims[(k, o)])
            if plotter is not None:
                plotter.close()

        con.result({**summary, "fitness": {k: {str(o): v for o, v in by.items()} for k, by in table.items()},
                    "out": str(out)})
        con.say()
        con.say((out / "fitness.md").read_text(encoding="utf-8").split("# The paper's")[0].rstrip())
        con.say(f"\nidentification took {total:.1f} s; wrote {out}/fitness.json, fitness.md, summary.json, "
              f"models/*.json" + ("" if args.no_plots else ", plots/*.png")
              + ("" if args.csv else ", dma.md, dma.json, creep.json, data/*.csv"))
        return 0
