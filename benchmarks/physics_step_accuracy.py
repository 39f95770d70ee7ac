"""Accuracy of the lumped plant's physics step: force error against a fine-step reference.

The number of physics steps per control period is set by the physics rate
(``RateParams.physics_rate_hz``, 10 kHz by default: 50 steps per 200 Hz env step, 10 per 1 kHz
scenario period), and it sets the cost of every loop (the kernel's steps are ~95 % of a
run's loop).  This measures what a coarser or finer step changes in the physics, with the
same inputs: for each reader, a closed-loop run of the scenario at the default rate records
its command per period; that command record (and the scenario's varying inputs) is then
replayed open loop through :func:`ebraille_sim.plant.kernel.advance` at each physics rate,
and the true contact force, the force estimate and the FSR ADC code at the end of every
control period are compared with a replay at ``--reference`` (100 kHz).  The sensor rate
(and with it the FSR noise sequence) is the same at every physics rate.

Readers: the scenario's own device and ``--readers`` drawn by
:func:`ebraille_sim.scenarios.population.sample_devices` (seed ``--seed``).  Rates for which
:func:`ebraille_sim.plant.lumped.check_step` refuses the stiff contact (``w h > 1``) are
reported as refused.

Printed per rate (over the readers): ``w h`` of the stiffest oscillation, the median and the
largest over readers of the largest |error| of the true force (mN), of its RMS error (mN),
of the largest |error| of the estimate (mN) and the share of periods whose ADC code differs.

With ``--population N`` it compares closed-loop metrics instead: ``N`` readers drawn with
``--seed`` each run the scenario (its PID and safety supervisor) at every rate of
``--rates`` (:func:`ebraille_sim.scenarios.runner.run_batch`), and per rate and metric it
prints the median and ``CVaR_0.1`` of the loss (the mean of the worst tenth: the largest
RMS errors and peaks, the smallest in-band fractions) with bootstrap standard errors
(``--boot`` resamples).  The current chain's noise is indexed by physics steps, so two rates
read different noise realisations: their metrics agree when the differences lie within the
sampling noise, not to the last digit.

Run:  python benchmarks/physics_step_accuracy.py [--scenario steady_90wpm] [--duration 12]
      [--readers 7] [--rates 5000 10000 20000] [--reference 100000] [--json FILE]
      python benchmarks/physics_step_accuracy.py --population 200 [--rates 5000 10000]
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
import statistics

import numpy as np

import ebraille_sim
from ebraille_sim.physics.params import RateParams
from ebraille_sim.plant import kernel
from ebraille_sim.plant.layout import S, U
from ebraille_sim.plant.lumped import check_step
from ebraille_sim.scenarios import runner
from ebraille_sim.scenarios.population import sample_devices


def replay(spec, run, device, physics_rate_hz: float, command_v: np.ndarray):
    """The true force, estimate and ADC code at the end of each period of ``command_v`` replayed
    open loop on ``device`` at ``physics_rate_hz``; and ``w h`` of that rate."""
    r = device.rates
    dev = dataclasses.replace(device, rates=RateParams(control_rate_hz=r.control_rate_hz,
                                                       sensor_rate_hz=r.sensor_rate_hz,
                                                       physics_rate_hz=physics_rate_hz))
    wh = check_step(dev)
    plant = runner._plant_for(dataclasses.replace(spec, device=dev), run, "lumped")
    s, p, u = plant.state[0], plant.params[0], plant.inputs[0]
    u[:] = run.initial_inputs()
    varying = [(U[name], arr) for name, arr in run.profiles.items()]
    n = len(command_v)
    out = np.empty((3, n))
    for k in range(n):
        for j, arr in varying:
            u[j] = arr[k]
        u[U.command_v] = command_v[k]
        kernel.advance(s, p, u, plant.substeps)
        out[0, k] = s[S.contact_force_n]
        out[1, k] = s[S.force_est_n]
        out[2, k] = s[S.fsr_code]
    return out, wh


POPULATION_METRICS = (("force_rmse_n", True), ("in_band_fraction", False), ("char_in_band_fraction", False),
                      ("peak_force_n", True))
"""Metrics of the population comparison, each with whether a larger value is the loss."""


def _median_cvar(x: np.ndarray, larger_is_loss: bool, boot: int, rng) -> dict:
    """Median and CVaR_0.1 of the loss of ``x`` with bootstrap standard errors."""
    def stats(v):
        w = np.sort(v if larger_is_loss else -v)[::-1]
        k = max(1, int(math.ceil(0.1 * w.size)))
        cvar = float(np.mean(w[:k]))
        return float(np.median(v)), cvar if larger_is_loss else -cvar
    med, cvar = stats(x)
    b = np.array([stats(x[rng.integers(0, x.size, x.size)]) for _ in range(boot)])
    return {"median": med, "median_se": float(np.std(b[:, 0])), "cvar10": cvar, "cvar10_se": float(np.std(b[:, 1]))}


def population(a) -> dict:
    """The closed-loop metrics of ``a.population`` drawn readers at each physics rate."""
    spec0, _, _, _ = runner.prepare_run(a.scenario, duration_s=a.duration)
    readers = sample_devices(a.seed, a.population, base=spec0.device)
    r0 = spec0.device.rates
    out = {}
    per_reader = {}
    print(f"{a.scenario}, {a.duration:g} s, {a.population} readers drawn with seed {a.seed}, the scenario's "
          f"controller and supervisor; medians and CVaR_0.1 of the loss, +/- bootstrap standard errors")
    for rate in a.rates:
        rates = RateParams(control_rate_hz=r0.control_rate_hz, sensor_rate_hz=r0.sensor_rate_hz,
                           physics_rate_hz=rate)
        runs = [{"scenario": spec0, "duration_s": a.duration, "device": dataclasses.replace(d, rates=rates)}
                for d in readers]
        res = runner.run_batch(runs, keep_traces=False)
        bad = [r for r in res if isinstance(r, Exception)]
        if bad:
            print(f"{rate:>8g} Hz: {len(bad)} runs failed, e.g. {bad[0]}")
            continue
        rng = np.random.default_rng(1)
        row = {}
        for name, larger in POPULATION_METRICS:
            x = np.array([r.metrics[name] for r in res], dtype=float)
            row[name] = _median_cvar(x, larger, a.boot, rng)
        out[str(rate)] = row
        per_reader[rate] = {name: np.array([r.metrics[name] for r in res], dtype=float)
                            for name, _ in POPULATION_METRICS}
        print(f"{rate:>8g} Hz  " + "  ".join(
            f"{name} {v['median']:.4f}+/-{v['median_se']:.4f} (CVaR {v['cvar10']:.4f}+/-{v['cvar10_se']:.4f})"
            for name, v in row.items()), flush=True)
    ref = r0.physics_rate_hz
    if ref in per_reader:
        print(f"the same readers against the default {ref:g} Hz: median and largest |difference| per reader")
        for rate, m in per_reader.items():
            if rate == ref:
                continue
            d = {name: np.abs(m[name] - per_reader[ref][name]) for name in m}
            out[str(rate)]["paired_vs_default"] = {name: {"median_abs": float(np.median(v)), "max_abs": float(np.max(v))}
                                                   for name, v in d.items()}
            print(f"{rate:>8g} Hz  " + "  ".join(f"{name} {np.median(v):.4f} / {np.max(v):.4f}"
                                                 for name, v in d.items()), flush=True)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="steady_90wpm")
    ap.add_argument("--duration", type=float, default=12.0)
    ap.add_argument("--readers", type=int, default=7)
    ap.add_argument("--seed", type=int, default=20261128)
    ap.add_argument("--rates", type=float, nargs="+", default=[2000.0, 5000.0, 10000.0, 20000.0])
    ap.add_argument("--reference", type=float, default=100000.0)
    ap.add_argument("--population", type=int, default=0)
    ap.add_argument("--boot", type=int, default=1000)
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    if a.readers < 0 or a.population < 0 or not a.duration > 0:
        ap.error("--readers and --population must be >= 0 and --duration positive")
    if a.population:
        doc = population(a)
        if a.json:
            with open(a.json, "w") as fh:
                json.dump({"scenario": a.scenario, "duration_s": a.duration, "readers": a.population,
                           "seed": a.seed, "per_rate": doc}, fh, indent=2)
        return 0
    spec0, _, run, _ = runner.prepare_run(a.scenario, duration_s=a.duration)
    devices = [spec0.device] + sample_devices(a.seed, a.readers, base=spec0.device)
    rows = {rate: [] for rate in a.rates}
    refused = {}
    for dev in devices:
        spec = dataclasses.replace(spec0, device=dev)
        command_v = ebraille_sim.run_scenario(spec, duration_s=a.duration).trace["command_v"]
        ref, _ = replay(spec, run, dev, a.reference, command_v)
        for rate in a.rates:
            try:
                got, wh = replay(spec, run, dev, rate, command_v)
            except ValueError as exc:
                refused[rate] = str(exc)
                continue
            d = got - ref
            rows[rate].append({"wh": wh, "max_force_err_mn": 1e3 * float(np.max(np.abs(d[0]))),
                               "rms_force_err_mn": 1e3 * float(np.sqrt(np.mean(d[0] ** 2))),
                               "max_estimate_err_mn": 1e3 * float(np.max(np.abs(d[1]))),
                               "code_differs": float(np.mean(d[2] != 0.0))})
    print(f"{a.scenario}, {a.duration:g} s, control {spec0.device.rates.control_rate_hz:g} Hz, "
          f"{len(devices)} readers (the scenario's and {a.readers} drawn, seed {a.seed}); "
          f"reference {a.reference:g} Hz; the command record of each closed-loop run replayed open loop")
    print(f"{'physics Hz':>10} {'w h':>5} {'max|dF| mN med/max':>19} {'rms dF mN med/max':>18} "
          f"{'max|dFest| mN med/max':>22} {'codes differing max':>20}")
    summary = {}
    for rate, rs in rows.items():
        if not rs:
            print(f"{rate:>10g}  refused: {refused.get(rate, '')[:90]}")
            continue
        col = {k: [r[k] for r in rs] for k in rs[0]}
        med, top = statistics.median, max
        summary[rate] = {k: {"median": med(v), "max": top(v)} for k, v in col.items()}
        print(f"{rate:>10g} {top(col['wh']):>5.2f} {med(col['max_force_err_mn']):>9.2f}/{top(col['max_force_err_mn']):<9.2f}"
              f"{med(col['rms_force_err_mn']):>9.3f}/{top(col['rms_force_err_mn']):<8.3f}"
              f"{med(col['max_estimate_err_mn']):>11.2f}/{top(col['max_estimate_err_mn']):<10.2f}"
              f"{top(col['code_differs']):>20.4f}")
    if a.json:
        with open(a.json, "w") as fh:
            json.dump({"scenario": a.scenario, "duration_s": a.duration, "readers": len(devices),
                       "reference_hz": a.reference, "per_rate": {str(k): v for k, v in summary.items()},
                       "per_reader": {str(k): v for k, v in rows.items()}}, fh, indent=2)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
