"""``ebraille-sim tune SCENARIO``: robust PID tuning over a population, with report and figures.

Writes into ``--out`` (default ``runs/tune-SCENARIO``):

* ``gains.toml``: the tuned controller, accepted by ``ebraille-sim run --controller``;
* ``report.md`` and ``report.json``: gains, Ms, median and worst-case metrics of the tuned
  controller, the hand-tuned default PID and the SIMC rule, per device;
* ``bode.png``, ``nyquist.png`` (tuned loop on the nominal reader at each setpoint) and
  ``population.png`` (in-band fraction per device for the three controllers).
"""
from __future__ import annotations

import sys

NAME = "tune"
HELP = "tune PID gains over a population of readers and FSR units (Ms <= 1.6); write gains, report, figures"


def add_arguments(p):
    p.add_argument("scenario", help="scenario file or the name of a shipped scenario (see 'list')")
    p.add_argument("--population", type=int, default=8, metavar="N",
                   help="random devices drawn besides the 5 presets (default 8)")
    p.add_argument("--out", default=None, metavar="DIR", help="output folder (default runs/tune-SCENARIO)")
    p.add_argument("--seed", type=int, default=0, help="population seed (default 0)")
    p.add_argument("--family", default="pid_scheduled", choices=["pid", "pid_scheduled"],
                   help="fixed PID gains, or gains scheduled on force (default)")
    p.add_argument("--evaluations", type=int, default=30, metavar="N", help="cost evaluations (default 30)")
    p.add_argument("--duration", type=float, default=None, metavar="S", help="override the scenario duration, s")
    p.add_argument("--ms-max", type=float, default=1.6, help="bound on the sensitivity peak (default 1.6)")


class _Bar:
    """tqdm when installed, else a one-line bar on stderr."""

    def __init__(self, total: int, desc: str):
        self.total, self.n, self.desc = total, 0, desc
        try:
            from tqdm import tqdm
            self._tq = tqdm(total=total, desc=desc, unit="run", file=sys.stderr)
        except ImportError:
            self._tq = None

    def __call__(self, k: int) -> None:
        self.n += k
        if self._tq is not None:
            self._tq.update(k)
            return
        frac = min(self.n / max(self.total, 1), 1.0)
        width = 30
        fill = int(frac * width)
        sys.stderr.write(f"\r{self.desc} [{'#' * fill}{'.' * (width - fill)}] {self.n}/{self.total} runs")
        sys.stderr.flush()

    def close(self) -> None:
        if self._tq is not None:
            self._tq.close()
        else:
            sys.stderr.write("\n")


def _toml(doc: dict) -> str:
    lines = [f'controller = "{doc["controller"]}"', "", "[gains]"]
    lines += [f"{k} = {v!r}" for k, v in doc["gains"].items()]
    return "\n".join(lines) + "\n"


def _markdown(spec, rep: dict, n_dev: int) -> str:
    out = [f"# Robust tuning: {spec.name}", "",
           f"Population: {n_dev} devices (reader presets, FSR presets, random draws), "
           f"controller family `{rep['family']}`, {rep['evaluations']} cost evaluations.", "",
           "| controller | kp (V/N) | ki (V/Ns) | kd (Vs/N) | max Ms | in-band median | in-band worst | "
           "RMSE median (N) | RMSE worst (N) |", "|---|---|---|---|---|---|---|---|---|"]
    for key in ("tuned", "default", "simc"):
        b = rep[key]
        g, m = b["gains"], b["metrics"]
        out.append(f"| {key} | {g['kp_v_per_n']:.3g} | {g['ki_v_per_ns']:.3g} | {g['kd_vs_per_n']:.3g} | "
                   f"{b['ms_max']:.2f} | {m['in_band_fraction']['median']:.3f} | {m['in_band_fraction']['worst']:.3f} | "
                   f"{m['force_rmse_n']['median']:.3f} | {m['force_rmse_n']['worst']:.3f} |")
    out += ["", "The tuned gains of a scheduled family are its gains at 1 N; they scale with the pulp "
            "stiffness ratio K(1 N)/K(F) at other setpoints.", "",
            "## Per device (in-band fraction)", "", "| device | tuned | default | simc |", "|---|---|---|---|"]
    for a, b, c in zip(rep["tuned"]["per_device"], rep["default"]["per_device"], rep["simc"]["per_device"]):
        out.append(f"| {a['label']} | {a['in_band_fraction']:.3f} | {b['in_band_fraction']:.3f} | "
                   f"{c['in_band_fraction']:.3f} |")
    out += ["", "Figures: bode.png, nyquist.png (tuned loop, nominal reader), population.png."]
    return "\n".join(out) + "\n"


def _plot_population(rep: dict, path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    labels = [r["label"] for r in rep["tuned"]["per_device"]]
    x = np.arange(len(labels))
    fig, ax = plt.subplots(figsize=(max(6, 0.6 * len(labels) + 2), 4))
    for j, key in enumerate(("tuned", "default", "simc")):
        vals = [r["in_band_fraction"] for r in rep[key]["per_device"]]
        ax.bar(x + (j - 1) * 0.27, vals, width=0.27, label=key)
    ax.set_xticks(x)
    ax.set_xticklabels(labels, rotation=45, ha="right", fontsize=8)
    ax.set_ylabel("in-band fraction")
    ax.set_ylim(0, 1.05)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(args) -> int:
    import json
    import os
    import pathlib
    import shutil
    import tempfile

    from controllers.robust import robust_tune, scenario_setpoints, tuning_population
    from controllers.tuning import analyse_loop, plot_bode, plot_nyquist

    from ..scenario import load_scenario

    if args.population < 0:
        raise ValueError(f"--population must be >= 0, got {args.population}")
    if args.seed < 0:
        raise ValueError(f"--seed must be >= 0, got {args.seed}")
    if args.evaluations < 4:
        raise ValueError(f"--evaluations must be >= 4, got {args.evaluations}")
    if args.duration is not None and not args.duration > 0:
        raise ValueError(f"--duration must be > 0, got {args.duration}")
    spec = load_scenario(args.scenario)
    out = pathlib.Path(args.out) if args.out else pathlib.Path("runs") / f"tune-{spec.name}"
    pop = tuning_population(args.population, seed=args.seed, base=spec.device)
    total = len(pop) * (args.evaluations + 3)
    bar = _Bar(total, f"tune {spec.name}")
    try:
        res = robust_tune(spec, pop, family=args.family, ms_max=args.ms_max, duration_s=args.duration,
                          max_evaluations=args.evaluations, progress=bar)
    finally:
        bar.close()
    rep = res.report()
    rep["scenario"] = spec.name
    rep["population"] = [label for label, _ in pop]
    rep["population_seed"] = args.seed
    nominal = dict(pop).get("nominal", pop[0][1])
    if args.family == "pid":
        cfg_at = lambda f: res.config  # noqa: E731
    else:
        from controllers.schedule import ScheduledPID
        cfg_at = ScheduledPID(res.config).pid_config_at
    analyses = [analyse_loop(cfg_at(f), nominal, f) for f in scenario_setpoints(spec)]
    rep["nominal_loop"] = [a.summary() for a in analyses]
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = pathlib.Path(tempfile.mkdtemp(prefix=".ebraille-tune-", dir=out.parent))
    try:
        (tmp / "gains.toml").write_text(_toml(res.gains_file()))
        (tmp / "report.json").write_text(json.dumps(rep, indent=2, default=float) + "\n")
        (tmp / "report.md").write_text(_markdown(spec, rep, len(pop)))
        plot_bode(analyses, tmp / "bode.png", title=f"tuned loop, nominal reader ({spec.name})")
        plot_nyquist(analyses, tmp / "nyquist.png", title=f"tuned loop, nominal reader ({spec.name})",
                     ms_limit=args.ms_max)
        _plot_population(rep, tmp / "population.png")
        out.mkdir(parents=True, exist_ok=True)
        for f in tmp.iterdir():
            os.replace(f, out / f.name)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    t, d = rep["tuned"]["metrics"]["in_band_fraction"], rep["default"]["metrics"]["in_band_fraction"]
    print(f"tuned {args.family}: " + ", ".join(f"{k} {v:.4g}" for k, v in res.gains_file()["gains"].items()))
    print(f"max Ms {res.ms_max:.3f} (bound {args.ms_max:g}); in-band worst {t['worst']:.3f} "
          f"(default PID {d['worst']:.3f}), median {t['median']:.3f} (default {d['median']:.3f})")
    print(f"wrote {out / 'gains.toml'}, report.md, report.json, bode.png, nyquist.png, population.png")
    return 0
