"""Latched supervisor faults on healthy drawn readers: the false-latch check of the supervisor.

Runs every non-fault shipped scenario (default; or ``--scenario``) for ``--duration`` seconds on
``--readers`` readers drawn around the scenario's device with each ``--seed``
(:func:`ebraille_sim.scenarios.population.sample_devices`, each unit calibrated for its own FSR
unit), with the scenario's controller and each ``--controller`` (a design runs on its own
firmware), the supervisor on.  No fault is injected and no motion is added beyond the
scenario's own, so every latch is a false trip: the reader loses the session.  Prints per
scenario, controller and seed the latches by cause and the highest true force, and writes every
latch with its reader's drawn parameters and the supervisor's events to ``--out`` (JSON).
``-j`` runs the scenarios in that many processes.  Run from the repository root::

    python studies/body_motion/population_check.py --readers 1000 --seed 31337 --seed 271828 \
        --controller dob_learn_1khz --out runs/population_latches.json -j 2
"""
from __future__ import annotations

import argparse
import collections
import concurrent.futures
import json
import sys
import time

from ebraille_sim.scenarios.population import sample_devices
from ebraille_sim.scenarios.runner import run_batch
from ebraille_sim.scenarios.spec import list_scenarios, load_scenario

CHUNK = 100
"""Runs per call of the batched runner (their plants advance together)."""


def non_fault_scenarios() -> list[str]:
    """The shipped scenarios that inject no fault."""
    return [n for n in list_scenarios() if not n.startswith("fault_")]


def reader_params(dev) -> dict:
    """The drawn parameters that tell one reader and unit from another."""
    f, s, m, d = dev.finger, dev.fsr, dev.motor, dev.drivetrain
    return {"finger_b_n_per_m": f.stiffness_b_n_per_m, "finger_m_per_m": f.exponent_m_per_m,
            "relax_c0": f.relax_weight_inf, "fsr_r_at_1n_ohm": s.resistance_at_1n_ohm,
            "fsr_exponent": s.exponent, "fsr_hysteresis": s.hysteresis_fraction, "fsr_creep": s.creep_per_decade,
            "motor_r_ohm": m.resistance_ohm, "gear_efficiency": d.gear_efficiency,
            "guide_coulomb_n": d.guide_coulomb_n, "backlash_m": d.backlash_m}


def check(scenario: str, controller: str | None, seed: int, readers: int, duration_s: float) -> dict:
    """Latches (cause, reader index, drawn parameters, events) and the highest true force."""
    spec = load_scenario(scenario)
    devices = sample_devices(seed, readers, base=spec.device)
    runs = [{"scenario": spec, "seed": spec.seed + 7 * i, "duration_s": duration_s, "device": d,
             **({} if controller is None else {"controller": controller})} for i, d in enumerate(devices)]
    causes = collections.Counter()
    latched, errors = [], []
    peak = 0.0
    for j in range(0, len(runs), CHUNK):
        for k, res in enumerate(run_batch(runs[j:j + CHUNK], keep_traces=False), start=j):
            if isinstance(res, Exception):
                errors.append(f"reader {k}: {res}")
                continue
            peak = max(peak, float(res.metrics.get("peak_force_n", 0.0)))
            fault = (res.supervisor or {}).get("fault")
            if fault is not None:
                causes[fault] += 1
                latched.append({"reader": k, "fault": fault, "params": reader_params(devices[k]),
                                "in_band": res.metrics.get("in_band_fraction"),
                                "events": res.supervisor.get("events", [])[:12]})
    return {"scenario": scenario, "controller": controller or spec.controller.name, "seed": seed,
            "readers": readers, "duration_s": duration_s, "causes": dict(causes), "latched": latched,
            "peak_n": peak, "errors": errors}


def _job(args) -> dict:
    t0 = time.time()
    r = check(*args)
    r["wall_s"] = time.time() - t0
    return r


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--readers", type=int, default=200)
    ap.add_argument("--seed", type=int, action="append", help="population seed (repeatable; default 90321)")
    ap.add_argument("--duration", type=float, default=12.0)
    ap.add_argument("--scenario", action="append", help="only these scenarios (repeatable; default: every "
                    "shipped scenario that injects no fault)")
    ap.add_argument("--controller", action="append", default=[],
                    help="a controller or design to run besides the scenario's own (repeatable)")
    ap.add_argument("--no-own", action="store_true", help="skip the scenario's own controller")
    ap.add_argument("-j", "--jobs", type=int, default=1)
    ap.add_argument("--out", help="write every row (latches with reader parameters) here as JSON")
    a = ap.parse_args(argv)
    if a.readers < 1 or a.jobs < 1 or a.duration <= 0:
        print("error: --readers and --jobs must be at least 1 and --duration positive", file=sys.stderr)
        return 2
    controllers = ([] if a.no_own else [None]) + a.controller
    jobs = [(sc, c, s, a.readers, a.duration) for s in (a.seed or [90321]) for c in controllers
            for sc in (a.scenario or non_fault_scenarios())]
    rows = []
    with concurrent.futures.ProcessPoolExecutor(a.jobs) as pool:
        for r in pool.map(_job, jobs):
            rows.append(r)
            print(f"{r['scenario']:22s} {r['controller']:16s} seed {r['seed']}: {len(r['latched'])} of {r['readers']} "
                  f"latched {r['causes']} readers {[x['reader'] for x in r['latched']][:10]}; peak true force "
                  f"{r['peak_n']:.2f} N; {len(r['errors'])} errors ({r['wall_s']:.0f} s)", flush=True)
            if a.out:
                with open(a.out, "w", encoding="utf-8") as fh:
                    json.dump(rows, fh, indent=1)
    total = sum(len(r["latched"]) for r in rows)
    print(f"total: {total} latches over {sum(r['readers'] for r in rows)} runs")
    return 0


if __name__ == "__main__":
    sys.exit(main())
