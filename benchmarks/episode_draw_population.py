"""Did the population's metrics move when the draws' random streams changed?  Old code and new, side by side.

A device population (and an episode) is now drawn from one NumPy ``Generator`` per device
(:func:`ebraille_sim.scenarios.population.device_variates`) instead of one generator per
component, so reader ``k`` of a sweep is another device than before: the random stream
changed, the distributions (:class:`~ebraille_sim.scenarios.population.PopulationSpec`) did
not.  This study runs the same sweep (``--readers`` drawn readers x ``--scenarios``, the PID
controller, ``--duration`` s each, :func:`ebraille_sim.tools.sweep.run_sweep`) with the code
of a reference checkout (``--ref``, a git worktree of the commit before the change, run in a
subprocess with that tree first on ``PYTHONPATH``) and with this checkout, and reports per
scenario and metric the median, ``CVaR_0.1`` of the loss and the share of readers with at
least 0.9 of the time in band, each with its sampling noise: a 95 % bootstrap interval
(``--boot`` resamples of the readers) for the median and the CVaR, the binomial standard
error for the share; and, for each drawn parameter of the readers, the p-value of a
two-sample Kolmogorov-Smirnov test of the old draws against the new, over the sweep's readers
and over ``--devices`` devices drawn without calibration.  Two populations of independent draws agree when their difference lies
within the combined noise (``|new - old| <= 2 sqrt(se_old^2 + se_new^2)``, the standard
errors from the bootstrap intervals).

Run:  python benchmarks/episode_draw_population.py --ref /work/wt-ref-857 [--readers 200]
      [--duration 12] [--jobs 2] [--devices 5000] [--json FILE]
"""
from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile

import numpy as np

SCENARIOS = ("steady_90wpm", "pressing_90wpm", "contact_onset")
METRICS = ("force_rmse_n", "force_mae_n", "in_band_fraction", "peak_force_n")
PARAMETERS = ("finger_b_n_per_m", "finger_m_per_m", "relax_c0", "fsr_k_ohm", "fsr_exponent", "fsr_hysteresis",
              "fsr_creep_per_decade", "r2_ohm", "gear_efficiency", "guide_coulomb_n", "backlash_m")
"""The readers' drawn parameters (sweep columns), compared by a two-sample Kolmogorov-Smirnov test."""


DEVICE_FIELDS = {"finger_b": ("finger", "stiffness_b_n_per_m"), "finger_m": ("finger", "exponent_m_per_m"),
                 "relax_c0": ("finger", "relax_weight_inf"), "fsr_k": ("fsr", "resistance_at_1n_ohm"),
                 "fsr_n": ("fsr", "exponent"), "fsr_hysteresis": ("fsr", "hysteresis_fraction"),
                 "fsr_creep": ("fsr", "creep_per_decade"), "motor_r": ("motor", "resistance_ohm"),
                 "motor_kt": ("motor", "torque_constant_nm_per_a"), "gear_efficiency": ("drivetrain", "gear_efficiency"),
                 "guide_coulomb": ("drivetrain", "guide_coulomb_n"), "backlash": ("drivetrain", "backlash_m")}
"""Every drawn device parameter, for the test of the draws alone (``--devices``, no calibration)."""


def collect(scenarios, readers: int, duration_s: float, jobs: int, seed: int, devices: int) -> dict:
    """Rows of the sweep in the code this interpreter imports (one per scenario and reader), and
    the drawn parameters of ``devices`` devices (uncalibrated)."""
    from ebraille_sim.scenarios.population import PopulationSpec, sample_devices
    from ebraille_sim.tools.sweep import plan_sweep, run_sweep
    plan = plan_sweep(list(scenarios), readers=readers, controllers=["pid"], seed=seed, duration_s=duration_s)
    rows = run_sweep(plan, jobs=jobs, progress=False).rows
    keep = ("scenario", "reader", "error") + METRICS + PARAMETERS
    devs = sample_devices(seed, devices, PopulationSpec(calibrate=False))
    return {"rows": [{k: r.get(k) for k in keep} for r in rows],
            "devices": {name: [getattr(getattr(d, part), field) for d in devs]
                        for name, (part, field) in DEVICE_FIELDS.items()}}


def _loss(values: np.ndarray, metric: str) -> np.ndarray:
    return 1.0 - values if metric == "in_band_fraction" else values


def _cvar(losses: np.ndarray, alpha: float = 0.1) -> float:
    x = np.sort(losses)[::-1]
    return float(np.mean(x[:max(1, math.ceil(alpha * x.size - 1e-9))]))


def stats(values: np.ndarray, metric: str, boot: int, rng: np.random.Generator) -> dict:
    """Median and CVaR_0.1 of the loss with bootstrap standard errors and 95 % intervals."""
    loss = _loss(values, metric)
    idx = rng.integers(0, values.size, size=(boot, values.size))
    med_b = np.median(values[idx], axis=1)
    cvar_b = np.array([_cvar(loss[i]) for i in idx])
    return {"n": int(values.size), "median": float(np.median(values)), "median_se": float(np.std(med_b)),
            "median_ci": [float(x) for x in np.percentile(med_b, [2.5, 97.5])],
            "cvar10": _cvar(loss), "cvar10_se": float(np.std(cvar_b)),
            "cvar10_ci": [float(x) for x in np.percentile(cvar_b, [2.5, 97.5])]}


def compare(old: dict, new: dict, boot: int = 2000, seed: int = 1) -> dict:
    """Per scenario and metric, the statistics of both populations and whether they agree; the
    KS p-values of the readers' parameters and of the devices' parameters."""
    old_rows, new_rows = old["rows"], new["rows"]
    rng = np.random.default_rng(seed)
    out: dict = {}
    for scen in sorted({r["scenario"] for r in old_rows}):
        out[scen] = {}
        for metric in METRICS:
            side = {}
            for name, rows in (("old", old_rows), ("new", new_rows)):
                v = np.array([r[metric] for r in rows if r["scenario"] == scen and not r["error"]
                              and r[metric] is not None], dtype=float)
                side[name] = stats(v, metric, boot, rng)
                if metric == "in_band_fraction":
                    p = float(np.mean(v >= 0.9))
                    side[name]["share_ge_0.9"] = p
                    side[name]["share_se"] = math.sqrt(max(p * (1 - p), 1.0 / v.size) / v.size)
            o, n = side["old"], side["new"]
            agree = {"median": abs(n["median"] - o["median"]) <= 2 * math.hypot(o["median_se"], n["median_se"]),
                     "cvar10": abs(n["cvar10"] - o["cvar10"]) <= 2 * math.hypot(o["cvar10_se"], n["cvar10_se"])}
            if metric == "in_band_fraction":
                agree["share_ge_0.9"] = (abs(n["share_ge_0.9"] - o["share_ge_0.9"])
                                         <= 2 * math.hypot(o["share_se"], n["share_se"]))
            out[scen][metric] = {"old": o, "new": n, "within_noise": agree}
    from scipy.stats import ks_2samp
    first = min(r["scenario"] for r in old_rows)           # the same readers in every scenario
    out["drawn parameters (KS p-value)"] = {
        name: float(ks_2samp([r[name] for r in old_rows if r["scenario"] == first],
                             [r[name] for r in new_rows if r["scenario"] == first]).pvalue) for name in PARAMETERS}
    n_dev = len(next(iter(old["devices"].values())))
    out[f"drawn devices, {n_dev} each (KS p-value)"] = {
        name: float(ks_2samp(old["devices"][name], new["devices"][name]).pvalue) for name in DEVICE_FIELDS}
    return out


def format_table(result: dict) -> str:
    lines = [f"{'scenario':15s} {'metric':17s} {'median old':>21s} {'median new':>21s} "
             f"{'CVaR10 old':>21s} {'CVaR10 new':>21s}  within noise"]
    for scen, per in result.items():
        if scen.startswith("drawn"):           # KS p-values
            lines.append(f"{scen}: " + ", ".join(f"{k} {v:.2f}" for k, v in per.items()))
            continue
        for metric, r in per.items():
            o, n, a = r["old"], r["new"], r["within_noise"]
            lines.append(f"{scen:15s} {metric:17s} {o['median']:10.5f} +/- {o['median_se']:.5f} "
                         f"{n['median']:10.5f} +/- {n['median_se']:.5f} {o['cvar10']:10.5f} +/- {o['cvar10_se']:.5f} "
                         f"{n['cvar10']:10.5f} +/- {n['cvar10_se']:.5f}  "
                         + ", ".join(f"{k} {'yes' if v else 'NO'}" for k, v in a.items()))
            if "share_ge_0.9" in o:
                lines.append(f"{'':15s} {'share >= 0.9':17s} {o['share_ge_0.9']:10.4f} +/- {o['share_se']:.4f} "
                             f"{n['share_ge_0.9']:10.4f} +/- {n['share_se']:.4f}")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ref", help="checkout of the old code (a git worktree)")
    ap.add_argument("--readers", type=int, default=200)
    ap.add_argument("--duration", type=float, default=12.0)
    ap.add_argument("--scenarios", nargs="+", default=list(SCENARIOS))
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--boot", type=int, default=2000)
    ap.add_argument("--devices", type=int, default=5000, help="devices drawn for the test of the draws alone")
    ap.add_argument("--json")
    ap.add_argument("--collect", help=argparse.SUPPRESS)         # write this code's rows to a file
    a = ap.parse_args(argv)
    if a.collect:
        with open(a.collect, "w") as fh:
            json.dump(collect(a.scenarios, a.readers, a.duration, a.jobs, a.seed, a.devices), fh)
        return 0
    if not a.ref:
        ap.error("--ref is required")
    rows = {}
    here = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    with tempfile.TemporaryDirectory() as tmp:
        for name, tree in (("old", os.path.abspath(a.ref)), ("new", here)):
            path = os.path.join(tmp, f"{name}.json")
            env = dict(os.environ, PYTHONPATH=tree + os.pathsep + os.environ.get("PYTHONPATH", ""))
            cmd = [sys.executable, os.path.abspath(__file__), "--collect", path, "--readers", str(a.readers),
                   "--duration", str(a.duration), "--jobs", str(a.jobs), "--seed", str(a.seed),
                   "--devices", str(a.devices), "--scenarios",
                   *a.scenarios]
            subprocess.run(cmd, env=env, cwd=tmp, check=True)
            with open(path) as fh:
                rows[name] = json.load(fh)
    result = compare(rows["old"], rows["new"], a.boot)
    print(f"{a.readers} readers x {len(a.scenarios)} scenarios, {a.duration:g} s each, PID; old: {a.ref}, new: {here}")
    print(format_table(result))
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(result, fh, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
