"""The numbers of docs/estimators.md: the 100 Hz Wiener estimator against its 1 kHz version.

Run from the repository root (about a minute and a half)::

    python studies/estimators/make_estimator_numbers.py

Writes ``studies/estimators/fast_estimator.json`` and prints its tables:

* ``bench``: every profile of the virtual FSR bench (``PAPER_PROFILES``, seed 7) recorded
  at 100 Hz and at 1 kHz from the same seed (the 1 kHz record's every tenth sample is the
  100 Hz one's), conditioned as the paper did (baseline removed, zero-phase 40 Hz
  low-pass); each model simulated at its own rate on its record and compared on the 100 Hz
  instants with the conditioned load cell and with the noise-free force (``fitness`` and
  RMSE);
* ``closed_loop``: four scenarios, the default ``pid`` and ``pid_friction``, the 100 Hz
  estimator and the 1 kHz one with anti-alias cutoffs of 20, 50 and 100 Hz: estimate RMSE,
  in_band and char_in_band for the scenario's seed and the mean over it and seeds 1-4;
* ``loop``: the default PID's margins at 1 N from :func:`ebraille_sim.analysis.margins.analyse_loop`;
* ``retune``: the ``pid_scheduled`` and ``pid`` gains tuned for the 1 kHz path
  (``studies/estimators/gains_fast.toml``, ``gains_fast_pid.toml``) against the default PID and the shipped
  ``RECOMMENDED`` on the four scenarios (scenario seed and seeds 1-4; estimate RMSE, in_band,
  char_in_band, peak force), their margins on the nominal reader at the setpoints of
  ``setpoint_steps`` and 1 N, and the worst / median in-band fraction and worst peak force on the
  tuning set's five scenarios over eight held-out draws (``sample_devices(1, 8)``), all with the
  1 kHz estimator at 50 Hz anti-alias.  ``--no-retune`` skips it.
"""
from __future__ import annotations

import dataclasses
import json
import pathlib
import sys

import numpy as np

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(ROOT))

from ebraille_sim.estimation.blockmodels import fitness  # noqa: E402
from ebraille_sim.estimation.registry import load_estimator  # noqa: E402

OUT = HERE / "fast_estimator.json"
SLOW, FAST = "paper:wiener:5", "paper:wiener:5@1000"
SCENARIOS = ["steady_90wpm", "refresh_60wpm", "refresh_120wpm", "pressing_90wpm"]
CONTROLLERS = ["pid", "pid_friction"]
ESTIMATORS = [(SLOW, 20.0), (FAST, 20.0), (FAST, 50.0), (FAST, 100.0)]
METRICS = ("estimate_rmse_n", "in_band_fraction", "char_in_band_fraction")
FAST_GAINS = HERE / "gains_fast.toml"
FAST_PID_GAINS = HERE / "gains_fast_pid.toml"
FAST_STEPS = HERE / "setpoint_steps_fast.toml"
RETUNE_METRICS = METRICS + ("peak_force_n",)
RETUNE_RUNS = [("default PID", "pid", SLOW, 20.0), ("RECOMMENDED", "pid_scheduled", SLOW, 20.0),
               ("default PID", "pid", FAST, 50.0), ("RECOMMENDED", "pid_scheduled", FAST, 50.0),
               ("tuned for 1 kHz", str(FAST_GAINS), FAST, 50.0),
               ("tuned pid for 1 kHz", str(FAST_PID_GAINS), FAST, 50.0)]
RETUNE_FORCES = (0.6, 0.8, 1.0, 1.2, 2.0)
HELDOUT_SEED, HELDOUT_N = 1, 8


def bench() -> dict:
    from ebraille_sim.identification.bench import PAPER_PROFILES, BenchParams, run_profile
    slow, fast = load_estimator(SLOW), load_estimator(FAST)
    rows = {}
    for name, profile in PAPER_PROFILES.items():
        r100 = run_profile(profile, BenchParams(), seed=7)
        r1k = run_profile(profile, BenchParams(sample_rate_hz=1000.0), seed=7)
        assert np.array_equal(r1k.true_force_n[::10], r100.true_force_n)
        cell = r100.force_n
        true = r100.true_force_n - np.mean(r100.true_force_n[:r100.baseline_samples])
        row = {}
        for label, y in (("100hz", slow.simulate(r100.voltage_v)[0]), ("1khz", fast.simulate(r1k.voltage_v)[0][::10])):
            row[label] = {"fitness_load_cell_pct": fitness(cell, y),
                          "rmse_load_cell_n": float(np.sqrt(np.mean((y - cell) ** 2))),
                          "fitness_true_pct": fitness(true, y),
                          "rmse_true_n": float(np.sqrt(np.mean((y - true) ** 2)))}
        rows[name] = row
    return rows


def _seed_runs(spec, ctrl, model, cutoff, metrics) -> dict:
    """``spec`` with ``ctrl`` and the estimator ``model`` at ``cutoff``, at the scenario seed and seeds 1-4."""
    from ebraille_sim.scenarios.runner import run_scenario
    est = dataclasses.replace(spec.device.estimator, model=model, antialias_cutoff_hz=cutoff)
    dev = dataclasses.replace(spec.device, estimator=est)
    runs = [run_scenario(spec, controller=ctrl, device=dev, seed=s, trace_every=None).metrics
            for s in (spec.seed, 1, 2, 3, 4)]
    mean = {}
    for k in metrics:
        vals = [r[k] for r in runs if r[k] is not None]
        mean[k] = float(np.mean(vals)) if vals else None
    return {"scenario_seed": {k: runs[0][k] for k in metrics}, "mean_5_seeds": mean}


def closed_loop() -> dict:
    from ebraille_sim.scenarios.spec import load_scenario
    out = {}
    for scn in SCENARIOS:
        spec = load_scenario(scn)
        for ctrl in CONTROLLERS:
            for model, cutoff in ESTIMATORS:
                out[f"{scn} {ctrl} {model} aa{cutoff:g}"] = {
                    "scenario": scn, "controller": ctrl, "model": model, "antialias_cutoff_hz": cutoff,
                    **_seed_runs(spec, ctrl, model, cutoff, METRICS)}
    return out


def loop() -> dict:
    import controllers
    from ebraille_sim.analysis.margins import analyse_loop
    from ebraille_sim.physics.params import DeviceParams, EstimatorParams
    out = {}
    for model, cutoff in ESTIMATORS:
        dev = DeviceParams(estimator=EstimatorParams(model=model, antialias_cutoff_hz=cutoff))
        s = analyse_loop(controllers.make("pid"), dev, 1.0).summary()
        out[f"{model} aa{cutoff:g}"] = {k: float(s[k]) for k in ("gain_margin", "phase_margin_deg", "ms",
                                                                  "gain_crossover_hz", "step_Overshoot")}
    return out


def retune() -> dict:
    """The tuned 1 kHz design against the default PID and ``RECOMMENDED`` (see the module docstring)."""
    import controllers
    from controllers.pid import PID, DEFAULT_PID
    from controllers.schedule import RECOMMENDED, ScheduledPID
    from ebraille_sim.analysis.robust import evaluate, family_ms_controller, standard_scenarios, summarise
    from ebraille_sim.analysis.margins import analyse_loop
    from ebraille_sim.physics.params import DeviceParams, EstimatorParams
    from ebraille_sim.scenarios.population import sample_devices
    from ebraille_sim.scenarios.spec import load_scenario
    tuned = controllers.make(str(FAST_GAINS)).config
    tuned_pid = controllers.make(str(FAST_PID_GAINS)).config
    runs = {}
    for scn in SCENARIOS:
        spec = load_scenario(scn)
        for label, ctrl, model, cutoff in RETUNE_RUNS:
            runs[f"{scn} | {label} | {model} aa{cutoff:g}"] = {
                "scenario": scn, "controller": label, "model": model, "antialias_cutoff_hz": cutoff,
                **_seed_runs(spec, ctrl, model, cutoff, RETUNE_METRICS)}
    fast = DeviceParams(estimator=EstimatorParams(model=FAST, antialias_cutoff_hz=50.0))
    designs = {"default PID": DEFAULT_PID, "RECOMMENDED": RECOMMENDED, "tuned for 1 kHz": tuned,
               "tuned pid for 1 kHz": tuned_pid}
    loop = {}
    for label, cfg in designs.items():
        at = family_ms_controller(cfg)
        rows = []
        for f in RETUNE_FORCES:
            s = analyse_loop(cfg if not callable(at) else at(f), fast, f).summary()
            rows.append({"force_n": f, **{k: float(s[k]) for k in ("gain_margin", "phase_margin_deg", "ms",
                                                                    "gain_crossover_hz", "step_Overshoot")}})
        loop[label] = rows
    makers = {"default PID": lambda: PID(DEFAULT_PID), "RECOMMENDED": lambda: ScheduledPID(RECOMMENDED),
              "tuned for 1 kHz": lambda: ScheduledPID(tuned), "tuned pid for 1 kHz": lambda: PID(tuned_pid)}
    primary = load_scenario(str(FAST_STEPS))
    pop = [(f"heldout_{k}", d) for k, d in enumerate(sample_devices(HELDOUT_SEED, HELDOUT_N, base=primary.device))]
    heldout = {}
    for sc in standard_scenarios(primary):
        heldout[sc.name] = {}
        for label, make in makers.items():
            m = summarise(evaluate(make, pop, sc.spec, duration_s=sc.duration_s))
            heldout[sc.name][label] = {"in_band_worst": m["in_band_fraction"]["worst"],
                                       "in_band_median": m["in_band_fraction"]["median"],
                                       "peak_force_worst_n": m["peak_force_n"]["worst"]}
    keys = ("kp_v_per_n", "ki_v_per_ns", "kd_vs_per_n")
    return {"gains": {k: getattr(tuned, k) for k in keys}, "gains_pid": {k: getattr(tuned_pid, k) for k in keys},
            "closed_loop": runs, "loop": loop, "heldout": heldout}


def _fmt(v) -> str:
    return "-" if v is None else f"{v:.3f}"


def main(argv=None) -> int:
    import argparse
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--no-retune", action="store_true", help="skip the tuned 1 kHz design's numbers")
    args = ap.parse_args(argv)
    doc = {"bench": bench(), "closed_loop": closed_loop(), "loop": loop()}
    if not args.no_retune:
        doc["retune"] = retune()
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(json.dumps(doc, indent=1) + "\n")
    print("profile | fit 100 Hz | fit 1 kHz | RMSE 100 Hz | RMSE 1 kHz  (load cell; N)")
    for name, row in doc["bench"].items():
        a, b = row["100hz"], row["1khz"]
        print(f"{name} | {a['fitness_load_cell_pct']:.1f} | {b['fitness_load_cell_pct']:.1f} | "
              f"{a['rmse_load_cell_n']:.3f} | {b['rmse_load_cell_n']:.3f}")
    print("scenario controller model aa | est RMSE | in_band | char_in_band (scenario seed; mean of 5)")
    for key, row in doc["closed_loop"].items():
        s, m = row["scenario_seed"], row["mean_5_seeds"]
        print(key, "|", " | ".join(f"{_fmt(s[k])} ({_fmt(m[k])})" for k in METRICS))
    for key, row in doc["loop"].items():
        print(key, {k: round(v, 3) for k, v in row.items()})
    if "retune" in doc:
        r = doc["retune"]
        print("tuned for 1 kHz:", {k: round(v, 5) for k, v in r["gains"].items()})
        print("tuned pid for 1 kHz:", {k: round(v, 5) for k, v in r["gains_pid"].items()})
        print("scenario | controller | model | est RMSE | in_band | char_in_band | peak (scenario seed; mean of 5)")
        for key, row in r["closed_loop"].items():
            s, m = row["scenario_seed"], row["mean_5_seeds"]
            print(key, "|", " | ".join(f"{_fmt(s[k])} ({_fmt(m[k])})" for k in RETUNE_METRICS))
        for label, rows in r["loop"].items():
            for row in rows:
                print(label, {k: round(v, 3) for k, v in row.items()})
        print("held-out draws: in-band worst / median (worst peak N)")
        for scn, row in r["heldout"].items():
            print(scn, "|", " | ".join(f"{c}: {v['in_band_worst']:.3f} / {v['in_band_median']:.3f} "
                                       f"({v['peak_force_worst_n']:.2f})" for c, v in row.items()))
    print(f"wrote {OUT}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
