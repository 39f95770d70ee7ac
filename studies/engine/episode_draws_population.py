"""Did the metrics move when the random streams of the draws changed?  Old code and new, side by side.

Every random number of a drawn device, an env episode and a run's inputs now comes from one
compiled home, :mod:`ebraille_sim.scenarios.draws`: counter-based streams of a seed's key
(the device's five components, the episode's run seed and uniforms; the sensor seed and the
reading's and the disturbances' generators of a run seed) instead of NumPy ``SeedSequence``
children and their generators.  The random streams changed; the distributions
(:class:`~ebraille_sim.scenarios.episodes.EpisodeDistribution`,
:class:`~ebraille_sim.scenarios.population.PopulationSpec`, the disturbance models) and the
laws did not.  This study runs, with the code of a reference checkout (``--ref``, a tree of
the commit before the change, in a subprocess with that tree first on ``PYTHONPATH``) and
with this checkout:

* ``--episodes`` episodes of the scalar env's distribution (``EnvConfig().distribution()``,
  200 Hz, drawn readers, disturbances), episode ``k`` drawn from
  ``SeedSequence(seed, spawn_key=(k,))`` and run by the scenario runner with the scenario
  PID and its safety supervisor (``run_scenario(spec)``, the replay of an env episode);
* a population sweep (``--readers`` readers drawn by ``sample_devices`` x ``--scenarios``,
  the PID, ``--duration`` s each, :func:`ebraille_sim.tools.sweep.run_sweep`);

and reports per group and metric the median, ``CVaR_0.1`` of the loss and the share with at
least 0.9 of the time in band, each with its sampling noise: a 95 % bootstrap interval
(``--boot`` resamples) for the median and the CVaR, the binomial standard error for the
share.  Two populations of independent draws agree when their difference lies within the
combined noise (``|new - old| <= 2 sqrt(se_old^2 + se_new^2)``, the standard errors from the
bootstrap).  Per metric it also gives the p-value of a two-sample Kolmogorov-Smirnov test of
the old values against the new, and the same for the drawn episode parameters (rate, gap,
tremor and drift RMS, first setpoint, supply) and the sweep's reader parameters.

Run:  python studies/engine/episode_draws_population.py --ref REF_TREE [--episodes 400]
      [--readers 200] [--duration 12] [--jobs 1] [--json FILE]
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
METRICS = ("force_rmse_n", "force_mae_n", "in_band_fraction", "peak_force_n", "legible_char_fraction")
PARAMETERS = ("finger_b_n_per_m", "finger_m_per_m", "relax_c0", "fsr_k_ohm", "fsr_exponent", "fsr_hysteresis",
              "fsr_creep_per_decade", "r2_ohm", "gear_efficiency", "guide_coulomb_n", "backlash_m")
"""The readers' drawn parameters (sweep columns), compared by a two-sample Kolmogorov-Smirnov test."""


EPISODE_METRICS = ("force_rmse_n", "in_band_fraction", "char_in_band_fraction", "peak_force_n",
                   "legible_char_fraction")


def _episode_draws(spec) -> dict:
    d = spec.sections.get("disturbances", {})
    return {"wpm": spec.reading.wpm, "gap_m": spec.finger.gap_m, "setpoint_n": spec.setpoint.force_n,
            "tremor_rms_m": d["tremor"].rms_m if "tremor" in d else 0.0,
            "drift_rms_m": d["pressing"].rms_m if "pressing" in d else 0.0,
            "driver_supply_v": spec.device.driver_supply_v, "battery": float("battery" in d)}


def collect(scenarios, readers: int, duration_s: float, jobs: int, seed: int, episodes: int) -> dict:
    """The sweep's rows (one per scenario and reader) and the env episodes' draws and metrics,
    in the code this interpreter imports."""
    import numpy as np
    from ebraille_sim.rl.env import EnvConfig
    from ebraille_sim.scenarios.runner import run_scenario
    from ebraille_sim.tools.sweep import plan_sweep, run_sweep
    plan = plan_sweep(list(scenarios), readers=readers, controllers=["pid"], seed=seed, duration_s=duration_s)
    rows = run_sweep(plan, jobs=jobs, progress=False).rows
    keep = ("scenario", "reader", "error") + METRICS + PARAMETERS
    dist = EnvConfig().distribution()
    eps = []
    for k in range(episodes):
        spec = dist.draw(np.random.SeedSequence(seed, spawn_key=(k,)))
        m = run_scenario(spec, trace_every=None).metrics
        eps.append({**_episode_draws(spec), **{name: m.get(name) for name in EPISODE_METRICS},
                    "scenario": "env episodes", "error": None})
    return {"rows": [{k: r.get(k) for k in keep} for r in rows], "episodes": eps}


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


def _compare_group(old_rows: list, new_rows: list, metrics, boot: int, rng) -> dict:
    out = {}
    for metric in metrics:
        side = {}
        for name, rows in (("old", old_rows), ("new", new_rows)):
            v = np.array([r[metric] for r in rows if not r["error"] and r[metric] is not None], dtype=float)
            side[name] = stats(v, metric, boot, rng)
            if metric == "in_band_fraction":
                p = float(np.mean(v >= 0.9))
                side[name]["share_ge_0.9"] = p
                side[name]["share_se"] = math.sqrt(max(p * (1 - p), 1.0 / v.size) / v.size)
        o, n = side["old"], side["new"]
        agree = {"median": abs(n["median"] - o["median"]) <= 2 * math.hypot(o["median_se"], n["median_se"]),
                 "cvar10": abs(n["cvar10"] - o["cvar10"]) <= 2 * math.hypot(o["cvar10_se"], n["cvar10_se"])}
        from scipy.stats import ks_2samp
        side["ks_pvalue"] = float(ks_2samp([r[metric] for r in old_rows if not r["error"] and r[metric] is not None],
                                           [r[metric] for r in new_rows if not r["error"] and r[metric] is not None]
                                           ).pvalue)
        if metric == "in_band_fraction":
            agree["share_ge_0.9"] = (abs(n["share_ge_0.9"] - o["share_ge_0.9"])
                                     <= 2 * math.hypot(o["share_se"], n["share_se"]))
        out[metric] = {"old": o, "new": n, "within_noise": agree, "ks_pvalue": side["ks_pvalue"]}
    return out


def compare(old: dict, new: dict, boot: int = 2000, seed: int = 1) -> dict:
    """Per group (the env episodes, each sweep scenario) and metric, the statistics of both
    populations and whether they agree; the KS p-values of the drawn parameters."""
    from scipy.stats import ks_2samp
    rng = np.random.default_rng(seed)
    out: dict = {"env episodes": _compare_group(old["episodes"], new["episodes"], EPISODE_METRICS, boot, rng)}
    draws = [k for k in old["episodes"][0] if k not in EPISODE_METRICS and k not in ("scenario", "error")]
    out["episode draws (KS p-value)"] = {
        k: float(ks_2samp([r[k] for r in old["episodes"]], [r[k] for r in new["episodes"]]).pvalue) for k in draws}
    old_rows, new_rows = old["rows"], new["rows"]
    for scen in sorted({r["scenario"] for r in old_rows}):
        out[scen] = _compare_group([r for r in old_rows if r["scenario"] == scen],
                                   [r for r in new_rows if r["scenario"] == scen], METRICS, boot, rng)
    first = min(r["scenario"] for r in old_rows)           # the same readers in every scenario
    out["sweep readers (KS p-value)"] = {
        name: float(ks_2samp([r[name] for r in old_rows if r["scenario"] == first],
                             [r[name] for r in new_rows if r["scenario"] == first]).pvalue) for name in PARAMETERS}
    out["sweep rows"] = {"readers equal": all(a[k] == b[k] for a, b in zip(old_rows, new_rows) for k in PARAMETERS)}
    return out


def format_table(result: dict) -> str:
    lines = [f"{'scenario':15s} {'metric':17s} {'median old':>21s} {'median new':>21s} "
             f"{'CVaR10 old':>21s} {'CVaR10 new':>21s}  within noise"]
    for scen, per in result.items():
        if "KS" in scen or scen == "sweep rows":
            lines.append(f"{scen}: " + ", ".join(f"{k} {v:.3g}" if isinstance(v, float) else f"{k} {v}"
                                                 for k, v in per.items()))
            continue
        for metric, r in per.items():
            o, n, a = r["old"], r["new"], r["within_noise"]
            lines.append(f"{scen:15s} {metric:17s} {o['median']:10.5f} +/- {o['median_se']:.5f} "
                         f"{n['median']:10.5f} +/- {n['median_se']:.5f} {o['cvar10']:10.5f} +/- {o['cvar10_se']:.5f} "
                         f"{n['cvar10']:10.5f} +/- {n['cvar10_se']:.5f}  "
                         + ", ".join(f"{k} {'yes' if v else 'NO'}" for k, v in a.items())
                         + f", KS p {r['ks_pvalue']:.3g}")
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
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--boot", type=int, default=2000)
    ap.add_argument("--episodes", type=int, default=400)
    ap.add_argument("--json")
    ap.add_argument("--collect", help=argparse.SUPPRESS)         # write this code's rows to a file
    a = ap.parse_args(argv)
    if a.collect:
        with open(a.collect, "w") as fh:
            json.dump(collect(a.scenarios, a.readers, a.duration, a.jobs, a.seed, a.episodes), fh)
        return 0
    if not a.ref:
        ap.error("--ref is required")
    rows = {}
    here = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    with tempfile.TemporaryDirectory() as tmp:
        for name, tree in (("old", os.path.abspath(a.ref)), ("new", here)):
            path = os.path.join(tmp, f"{name}.json")
            env = dict(os.environ, PYTHONPATH=tree + os.pathsep + os.environ.get("PYTHONPATH", ""))
            cmd = [sys.executable, os.path.abspath(__file__), "--collect", path, "--readers", str(a.readers),
                   "--duration", str(a.duration), "--jobs", str(a.jobs), "--seed", str(a.seed),
                   "--episodes", str(a.episodes), "--scenarios",
                   *a.scenarios]
            subprocess.run(cmd, env=env, cwd=tmp, check=True)
            with open(path) as fh:
                rows[name] = json.load(fh)
    result = compare(rows["old"], rows["new"], a.boot)
    print(f"{a.episodes} env episodes; {a.readers} readers x {len(a.scenarios)} scenarios, {a.duration:g} s each; "
          f"PID; old: {a.ref}, new: {here}")
    print(format_table(result))
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(result, fh, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
