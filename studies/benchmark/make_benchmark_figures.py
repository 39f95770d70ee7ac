"""Leaderboards, results files and figures of docs/benchmark.md and studies/benchmark/NOTES.md.

Run from the repository root (about 2 minutes of wall time with ``-j 2`` on the shared
2-core development machine)::

    python studies/benchmark/make_benchmark_figures.py            # run the suites, then the figures
    python studies/benchmark/make_benchmark_figures.py --reuse    # redraw the figures from the results

The run is the command ``ebraille-sim benchmark pid pid_scheduled pid_feedforward
pid_friction pid_dob lqg policy:ppo policy:sac -j 2 --out studies/benchmark/standard``
(the two shipped learned policies run from their NumPy actors); it writes ``benchmark.json`` (the
results file ``--compare`` reads) and ``leaderboard.md`` there, and ``fast_estimator.json``
(the paper Wiener model's linear block re-discretised at 1 kHz against the 100 Hz one).  The
same controllers then run with the estimator's hysteresis compensation on (``--estimator
hysteresis_compensation=true --out studies/benchmark/hysteresis``), and
``hysteresis_free.json`` holds ``pid``, ``pid_dob`` and ``pid_dob`` with its first design's high
gains (``pid_dob_high_gain.json``) on ``pressing_90wpm`` with each reader's FSR as drawn and
with its hysteresis removed.  Last, ``pid_dob`` and four gains files of it
(``studies/benchmark/fast``: ``pid_dob_learn.json`` with the hold damping and the refresh
learning, ``pid_dob_hold.json`` with the hold damping, ``pid_dob_fast_8.json`` and
``pid_dob_fast_16.json``) run beside the bounds on the firmware variant with the 1 kHz
estimator path and the hysteresis compensation with its turn test at 1.75 counts (``--out
studies/benchmark/fast``), and
``pid_dob``'s first design (``pid_dob_high_gain.json``) runs without bounds on both estimators
(``studies/benchmark/first_design/default`` and ``.../hysteresis``).  The figures go to
``docs/figures/benchmark`` and ``docs/figures/benchmark_hysteresis``.  Every number quoted in
docs/benchmark.md and the notes comes from those files; the tables there that copy them (the leaderboards, the
learned policies', `ppo_hc`'s, `pid_dob`'s, the 1 kHz firmware's and the nominal reader's
calibration) are rewritten from them at the end of every run (:func:`write_tables`; the
`ppo_hc` results come from the two commands in the notes and the calibration study
from ``python studies/benchmark/make_dob_tuning.py --nominal-calibration``).  A table whose
header is in neither file is skipped.
"""
from __future__ import annotations

import json
import pathlib
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(ROOT))

from ebraille_sim.cli import main as cli  # noqa: E402

OUT = HERE / "standard"
OUT_HC = HERE / "hysteresis"
OUT_FAST = HERE / "fast"
FIG = ROOT / "docs" / "figures" / "benchmark"
FIG_HC = ROOT / "docs" / "figures" / "benchmark_hysteresis"
FAST_FIRMWARE = ["--estimator", "model=paper:wiener:5@1000", "--estimator", "antialias_cutoff_hz=50",
                 "--estimator", "hysteresis_compensation=true", "--estimator", "hysteresis_turn_lsb=1.75"]
FAST_CONTROLLERS = ["studies/benchmark/fast/pid_dob_learn.json", "studies/benchmark/fast/pid_dob_hold.json",
                    "studies/benchmark/fast/pid_dob_fast_8.json", "studies/benchmark/fast/pid_dob_fast_16.json",
                    "pid_dob"]
CONTROLLERS = ["pid", "pid_scheduled", "pid_feedforward", "pid_friction", "pid_dob", "lqg",
               "policy:ppo", "policy:sac"]


def figure(doc: dict, path: pathlib.Path) -> None:
    """Worst-case (CVaR10) in_band and char_in_band per scenario, controllers between the bounds."""
    order = doc["ranking"]
    keys = [s["key"] for s in doc["scenarios"] if not s["fault"]]
    fig, axes = plt.subplots(2, 1, figsize=(11, 7), sharex=True)
    width = 0.8 / len(order)
    x = np.arange(len(keys))
    for ax, stat, title in ((axes[0], "in_band_fraction_cvar10", "CVaR10 in_band_fraction"),
                            (axes[1], "char_in_band_fraction_cvar10", "CVaR10 char_in_band_fraction")):
        for j, c in enumerate(order):
            vals = [doc["summary"][c]["scenarios"][k][stat] for k in keys]
            vals = [np.nan if v is None else v for v in vals]
            style = dict(hatch="//", edgecolor="k", linewidth=0.5) if doc["summary"][c]["bound"] else {}
            ax.bar(x + (j - (len(order) - 1) / 2) * width, vals, width, label=c, **style)
        ax.axhline(0.9, color="k", lw=0.6, ls="--")
        ax.set_ylabel(title)
        ax.set_ylim(0, 1.05)
    axes[1].set_xticks(x, keys, rotation=35, ha="right")
    axes[0].legend(ncol=4, fontsize=8, loc="lower left")
    axes[0].set_title(f"suite {doc['suite']} v{doc['suite_version']}, {doc['readers']} readers: worst 10 % "
                      "(hatched: bounds)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def fast_estimator(path: pathlib.Path) -> dict:
    """The paper Wiener model's linear block in continuous time, re-discretised at 1 kHz.

    Of the block's four poles only the one at z = 0.942 is positive real; the three negative
    real ones (-0.967, -0.590, -0.121) have no real continuous-time equivalent (``ln z`` is
    complex), so the continuous model keeps the positive pole with the positive real zero
    (0.948) and the block's DC gain, ``G(s) = g (s + a_z)/(s + a_p)``, ``a = -ln(z)/T``;
    ``G`` is then sampled with a zero-order hold at 1 kHz.  Written: both frequency
    responses and their relative difference at a few frequencies.
    """
    import control

    from ebraille_sim.estimation.registry import load_estimator
    m = load_estimator("paper:wiener:5")
    t = m.dt_s
    tf = m.to_control()
    pole = next(p.real for p in m.linear.poles() if abs(p.imag) < 1e-12 and p.real > 0)
    zero = next(z.real for z in m.linear.zeros() if abs(z.imag) < 1e-12 and z.real > 0)
    a_p, a_z = -np.log(pole) / t, -np.log(zero) / t
    dc = float(control.dcgain(tf))
    g = control.tf([1.0, a_z], [1.0, a_p])
    g = g * (dc / float(control.dcgain(g)))
    gd = control.sample_system(g, 1e-3, "zoh")
    rows = []
    for f in (0.1, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 40.0):
        w = 2 * np.pi * f
        h100, h1k = complex(tf(np.exp(1j * w * t))), complex(gd(np.exp(1j * w * 1e-3)))
        rows.append({"f_hz": f, "gain_100hz": abs(h100), "gain_1khz": abs(h1k),
                     "lag_100hz_deg": float(np.degrees(np.angle(-h100))) * -1,
                     "lag_1khz_deg": float(np.degrees(np.angle(-h1k))) * -1,
                     "relative_difference": abs(h100 - h1k) / abs(h100)})
    doc = {"pole_z": pole, "zero_z": zero, "a_p_per_s": a_p, "a_z_per_s": a_z, "dc_gain": dc,
           "dropped_poles_z": [p.real for p in m.linear.poles() if p.real < 0], "response": rows}
    path.write_text(json.dumps(doc, indent=1) + "\n")
    return doc


HIGH_GAIN_DOB = "studies/benchmark/standard/pid_dob_high_gain.json"
"""``pid_dob`` with the gains of its first design (kp 2 V/N, ki 8 V/(N s), f 0.9)."""


def hysteresis_free(path: pathlib.Path, controllers=("pid", "pid_dob", HIGH_GAIN_DOB),
                    key: str = "pressing_90wpm") -> dict:
    """in_band_fraction of each reader of one suite scenario, the FSR as drawn and without hysteresis."""
    import dataclasses

    from ebraille_sim.scenarios.runner import run_scenario
    from ebraille_sim.tools import benchmark as bm
    suite = bm.get_suite("standard")
    sc = next(s for s in suite.scenarios if s.key == key)
    spec = bm.scenario_spec(sc)
    devices = bm.scenario_devices(sc, suite.readers)
    doc = {"scenario": key, "readers": suite.readers,
           "hysteresis_fraction": [d.fsr.hysteresis_fraction for d in devices], "in_band_fraction": {}}
    for c in controllers:
        for label, scale in (("as_drawn", 1.0), ("no_hysteresis", 0.0)):
            vals = []
            for r, d in enumerate(devices):
                d = dataclasses.replace(d, fsr=dataclasses.replace(d.fsr, hysteresis_fraction=scale
                                                                   * d.fsr.hysteresis_fraction))
                res = run_scenario(spec, controller=c, seed=spec.seed + 101 * r, device=d)
                vals.append(round(float(res.metrics["in_band_fraction"]), 4))
            doc["in_band_fraction"][f"{c}/{label}"] = vals
    path.write_text(json.dumps(doc, indent=1) + "\n")
    return doc


DOCS = (ROOT / "docs" / "benchmark.md", HERE / "NOTES.md")
SUITE_ORDER = ("reading_60wpm", "reading_120wpm", "reading_200wpm", "setpoint_steps", "contact_onset",
               "tremor_90wpm", "pressing_90wpm", "strap_slip", "battery_sag", "everyday_session",
               "refresh_60wpm", "refresh_120wpm", "fault_fsr_open", "fault_motor_stall")
FAST_FILES = tuple(FAST_CONTROLLERS)


def _summary(folder: str) -> dict:
    return json.loads((HERE / folder / "benchmark.json").read_text())["summary"]


def _cell(summary: dict, controller: str, scenario: str) -> str:
    """Worst reader (CVaR10) in_band / char_in_band and the median in_band in brackets, or "-"."""
    e = summary.get(controller, {}).get("scenarios", {}).get(scenario)
    if e is None or e.get("in_band_fraction_cvar10") is None:
        return "-"
    return "%.2f/%.2f (%.2f)" % (e["in_band_fraction_cvar10"], e["char_in_band_fraction_cvar10"],
                                 e["in_band_fraction_median"])


def _worst_reading(summary: dict, controller: str) -> str:
    """:func:`_cell` of the reading speed with the lowest worst-reader in_band."""
    k = min(SUITE_ORDER[:3], key=lambda s: summary[controller]["scenarios"][s]["in_band_fraction_cvar10"])
    return _cell(summary, controller, k)


def _row(label: str, cells) -> str:
    return "| %s | %s |" % (label, " | ".join(cells))


def _replace_table(text: str, header: str, body: list) -> str:
    """``text`` with the rows of the table whose header line starts with ``header`` replaced
    (``text`` unchanged when it has no such table)."""
    lines = text.split("\n")
    i = next((k for k, line in enumerate(lines) if line.startswith(header)), None)
    if i is None:
        return text
    j = i + 2
    while j < len(lines) and lines[j].startswith("|"):
        j += 1
    lines[i + 2:j] = body
    return "\n".join(lines)


def write_tables(doc_path: pathlib.Path) -> None:
    """Rewrite the tables of ``doc_path`` that copy the results files (module docstring)."""
    t = doc_path.read_text()
    sd, sh, sf = _summary("standard"), _summary("hysteresis"), _summary("fast")
    ppo, sac = "policy:ppo", "policy:sac"
    lb = (OUT / "leaderboard.md").read_text().split("\n")
    i = next(k for k, line in enumerate(lb) if line.startswith("| controller | score"))
    rows = []
    for line in lb[i + 2:]:
        if not line.startswith("|"):
            break
        rows.append(line.replace(f"`{ppo}` |", f"`{ppo}` (PPO, learned) |").replace(f"`{sac}` |",
                                                                                  f"`{sac}` (SAC, learned) |"))
    t = _replace_table(t, "| controller | score | max peak force (N) | share of episodes > 3 N | latched faults", rows)
    cols = ("actuator_bound", "hysteresis_bound", "sensor_bound", "pid_dob", "pid_friction", "pid_feedforward",
            "pid_scheduled", "pid", "lqg")
    t = _replace_table(t, "| scenario | actuator_bound | hysteresis_bound | sensor_bound | `pid_dob` |",
                       [_row(s, [_cell(sd, c, s) for c in cols]) for s in SUITE_ORDER])
    t = _replace_table(t, "| scenario | PPO | SAC |",
                       [_row("reading_60/120/200wpm", [_worst_reading(sd, c) for c in (ppo, sac)])]
                       + [_row(s, [_cell(sd, c, s) for c in (ppo, sac)]) for s in SUITE_ORDER[3:12]])
    ph, pdf = _summary("ppo_hc/hysteresis"), _summary("ppo_hc/default")
    src = ((ph, "policy:ppo_hc"), (pdf, "policy:ppo_hc"), (sh, ppo), (sh, "pid_dob"))
    rows = [_row("score", ["%.2f" % s[c]["score"] for s, c in src])]
    rows += [_row(k, [_cell(s, c, k) for s, c in src]) for k in
             ("reading_60wpm", "setpoint_steps", "contact_onset", "pressing_90wpm", "battery_sag",
              "everyday_session", "refresh_120wpm")]
    rows.append(_row("max peak force, N", ["%.2f" % max(e["peak_force_n_max"] for e in s[c]["scenarios"].values()
                                                       if e.get("peak_force_n_max") is not None) for s, c in src]))
    t = _replace_table(t, "| | `ppo_hc`, compensated |", rows)
    src = ((sd, "pid"), (sd, "pid_friction"), (sd, "pid_dob"), (sh, "pid"), (sh, "pid_dob"))
    t = _replace_table(t, "| scenario | pid | pid_friction | pid_dob | pid, compensated |",
                       [_row("reading_60/120/200wpm", [_worst_reading(s, c) for s, c in src])]
                       + [_row(k, [_cell(s, c, k) for s, c in src]) for k in SUITE_ORDER[3:]])
    ctrls = sorted(("pid_dob", "pid", "lqg", "pid_friction", "pid_feedforward", "pid_scheduled"),
                   key=lambda c: -sh[c]["score"])
    names = [("*actuator_bound* (bound)", "actuator_bound"), ("*hysteresis_bound* (bound)", "hysteresis_bound"),
             ("*sensor_bound* (bound)", "sensor_bound")] + [(f"`{c}`", c) for c in ctrls] \
        + [("PPO (learned)", ppo), ("SAC (learned)", sac)]
    rows = [_row(lab, ["%.2f" % sd[c]["score"], ("**%.2f**" if c == ctrls[0] else "%.2f") % sh[c]["score"]])
            for lab, c in names]
    first = [_summary(f"first_design/{e}")[HIGH_GAIN_DOB]["score"] for e in ("default", "hysteresis")]
    rows.append(_row("`pid_dob`, first design (kp 2, ki 8, f 0.9)", ["%.2f" % v for v in first]))
    t = _replace_table(t, "| controller | score, default estimator | score, hysteresis compensated |", rows)
    t = _replace_table(t, "| worst reader in_band / char_in_band (median in_band) | `pid_dob_learn.json` |",
                       [_row("score", ["%.2f" % sf[c]["score"] for c in FAST_FILES])]
                       + [_row(k, [_cell(sf, c, k) for c in FAST_FILES]) for k in SUITE_ORDER[1:12]])
    nc = json.loads((OUT_FAST / "nominal_calibration.json").read_text())["rows"]
    rows = []
    for k in ("pressing_90wpm", "everyday_session", "battery_sag", "tremor_90wpm", "refresh_60wpm", "refresh_120wpm"):
        a, b = (next(r for r in nc if r["scenario"] == k and r["one_point_calibration"] is cal) for cal in (False, True))
        rows.append(_row(k, ["%.3f / %.3f" % (a["in_band"], a["char_in_band"]),
                             "%.3f / %.3f" % (b["in_band"], b["char_in_band"])]))
    t = _replace_table(t, "| reader 0, in_band / char_in_band |", rows)
    doc_path.write_text(t)


def main(argv=None) -> int:
    import argparse
    import os
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reuse", action="store_true", help="redraw the figures and tables from the results files")
    args = ap.parse_args(argv)
    os.chdir(ROOT)                      # the gains files are named by paths from the root
    OUT.mkdir(parents=True, exist_ok=True)
    if not args.reuse:
        code = cli(["benchmark", *CONTROLLERS, "-j", "2", "--out", str(OUT)])
        if code:
            return code
        OUT_HC.mkdir(parents=True, exist_ok=True)
        code = cli(["benchmark", *CONTROLLERS, "--estimator", "hysteresis_compensation=true", "-j", "2",
                    "--out", str(OUT_HC)])
        if code:
            return code
        hysteresis_free(OUT / "hysteresis_free.json")
        code = cli(["benchmark", *FAST_CONTROLLERS, *FAST_FIRMWARE, "-j", "2", "--out", str(OUT_FAST)])
        if code:
            return code
        for est, extra in (("default", []), ("hysteresis", ["--estimator", "hysteresis_compensation=true"])):
            code = cli(["benchmark", HIGH_GAIN_DOB, *extra, "--no-bounds", "-j", "2",
                        "--out", str(HERE / "first_design" / est)])
            if code:
                return code
    doc = json.loads((OUT / "benchmark.json").read_text())
    FIG.mkdir(parents=True, exist_ok=True)
    FIG_HC.mkdir(parents=True, exist_ok=True)
    figure(doc, FIG / "cvar_by_scenario.png")
    figure(json.loads((OUT_HC / "benchmark.json").read_text()), FIG_HC / "cvar_by_scenario.png")
    fast_estimator(OUT / "fast_estimator.json")
    for page in DOCS:
        write_tables(page)
    print(f"wrote {FIG / 'cvar_by_scenario.png'}, {FIG_HC / 'cvar_by_scenario.png'}, {OUT / 'fast_estimator.json'}, "
          f"the tables of {', '.join(str(d.relative_to(ROOT)) for d in DOCS)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
