"""Run outputs: summary table, metrics.json, trace.csv and force.png.

Files are written into a temporary folder beside the target and moved into place only
when all of them are complete, so an interrupted or failed run leaves nothing half-way.
"""
from __future__ import annotations

import csv
import json
import os
import pathlib
import shutil
import tempfile

import numpy as np

from ebraille_sim.scenarios.metrics import evaluate_criteria
from ebraille_sim.scenarios.runner import TRACE_COLUMNS, RunResult

_FMT = {"force_rmse_n": "{:.4f}", "force_mae_n": "{:.4f}", "in_band_fraction": "{:.3f}",
        "char_in_band_fraction": "{:.3f}", "peak_force_n": "{:.3f}", "onset_overshoot_fraction": "{:.3f}",
        "settling_time_s": "{:.3f}", "estimate_rmse_n": "{:.4f}", "energy_j": "{:.3f}",
        "real_time_factor": "{:.0f}", "wpm": "{:.1f}",
        "legible_char_fraction": "{:.3f}", "legible_char_fraction_cv": "{:.3f}"}


def summary_table(result: RunResult) -> str:
    """A plain-text table of the run's metrics."""
    m = result.metrics
    lines = [f"scenario {result.spec.name}  controller {result.controller_name}  seed {result.seed}",
             f"{'metric':<26} value"]
    lines.append("-" * 40)
    for k, v in m.items():
        if v is None:
            s = "n/a"
        elif isinstance(v, float):
            s = _FMT.get(k, "{:.4g}").format(v)
        else:
            s = str(v)
        lines.append(f"{k:<26} {s}")
    for key, c in evaluate_criteria(result.spec.criteria, m).items():
        op = "<=" if key.endswith("max") or key.endswith("max_n") else ">="
        lines.append(f"criterion {c['metric']} {op} {c['limit']:g}: {'pass' if c['passed'] else 'FAIL'}")
    return "\n".join(lines)


def metrics_document(result: RunResult) -> dict:
    """The JSON document written as metrics.json."""
    return {"scenario": result.spec.name, "controller": result.controller_name, "seed": result.seed,
            "band_fraction": result.spec.setpoint.band_fraction, "reading_start_s": result.spec.reading.start_s,
            "metrics": result.metrics, "criteria": evaluate_criteria(result.spec.criteria, result.metrics)}


def write_trace_csv(path, trace: dict) -> None:
    cols = TRACE_COLUMNS
    n = len(trace["t_s"])
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(cols)
        num = {c: np.asarray(trace[c]) for c in cols}
        for k in range(n):
            row = []
            for c in cols:
                v = num[c][k]
                if c == "char_index":
                    row.append(int(v))
                elif c == "character":
                    row.append(str(v))
                else:
                    row.append(f"{float(v):.9g}")
            w.writerow(row)


def plot_force(result: RunResult, path) -> None:
    """True and estimated force against the setpoint, character boundaries marked."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    tr = result.trace
    t = tr["t_s"]
    band = result.spec.setpoint.band_fraction
    fig, (ax, ax2) = plt.subplots(2, 1, figsize=(11, 6), sharex=True, gridspec_kw={"height_ratios": [3, 1]})
    sp = tr["setpoint_n"]
    ax.fill_between(t, sp * (1 - band), sp * (1 + band), color="0.9", label=f"band +/-{band:.0%}")
    ax.plot(t, sp, "k--", lw=1, label="setpoint")
    ax.plot(t, tr["force_est_n"], color="tab:orange", lw=0.8, label="estimated (Wiener)")
    ax.plot(t, tr["force_true_n"], color="tab:blue", lw=1.0, label="true (finger)")
    starts = result.schedule.boundaries_s()
    starts = starts[starts <= t[-1]]
    if len(starts) <= 400:
        for s in starts:
            ax.axvline(s, color="0.75", lw=0.4, zorder=0)
    ax.axvline(result.spec.reading.start_s, color="tab:green", lw=1, label="reading starts")
    ax.set_ylabel("contact force (N)")
    ax.set_title(f"{result.spec.name}: {result.controller_name}, seed {result.seed}")
    ax.legend(loc="upper right", fontsize=8, ncol=3)
    ax.set_ylim(0, max(1.5 * float(np.max(sp)), float(np.max(tr["force_true_n"])) * 1.05))
    ax2.plot(t, tr["command_v"], color="tab:red", lw=0.8)
    ax2.set_ylabel("command (V)")
    ax2.set_xlabel("time (s)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_outputs(result: RunResult, out_dir, plot: bool = True) -> pathlib.Path:
    """Write metrics.json, trace.csv and force.png into ``out_dir`` (created if needed)."""
    out = pathlib.Path(out_dir)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = pathlib.Path(tempfile.mkdtemp(prefix=".ebraille-", dir=out.parent))
    try:
        (tmp / "metrics.json").write_text(json.dumps(metrics_document(result), indent=2) + "\n")
        write_trace_csv(tmp / "trace.csv", result.trace)
        if plot:
            plot_force(result, tmp / "force.png")
        out.mkdir(parents=True, exist_ok=True)
        for f in tmp.iterdir():
            os.replace(f, out / f.name)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return out
