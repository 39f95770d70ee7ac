"""Latched supervisor faults on healthy drawn readers: the false-latch check of the body-motion rules.

Runs each scenario (default: ``steady_90wpm``, ``contact_onset``, ``refresh_120wpm_1khz``) for
``--duration`` seconds on ``--readers`` readers drawn with ``--seed``
(:func:`ebraille_sim.scenarios.population.sample_devices`) and prints, per scenario, how many
runs latch a fault and the highest true force.  Run from the repository root::

    python studies/body_motion/population_check.py --readers 200 --seed 90321
"""
from __future__ import annotations

import argparse
import collections
import os
import pickle
import sys
import time

from ebraille_sim.scenarios.population import sample_devices
from ebraille_sim.scenarios.runner import run_scenario
from ebraille_sim.scenarios.spec import load_scenario

SCENARIOS = ("steady_90wpm", "contact_onset", "refresh_120wpm_1khz")


def check(scenario: str, devices, duration_s: float) -> dict:
    """Faults latched (by cause), the readers that latched, and the highest true force over ``devices``."""
    spec = load_scenario(scenario)
    causes = collections.Counter()
    latched = []
    peak = 0.0
    for k, dev in enumerate(devices):
        res = run_scenario(spec, device=dev, duration_s=duration_s, trace_every=None)
        fault = res.supervisor.get("fault")
        if fault is not None:
            causes[fault] += 1
            latched.append(k)
        peak = max(peak, float(res.metrics.get("peak_force_n", 0.0)))
    return {"latched": latched, "causes": dict(causes), "peak_n": peak}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--readers", type=int, default=200)
    ap.add_argument("--seed", type=int, default=90321)
    ap.add_argument("--duration", type=float, default=12.0)
    ap.add_argument("--scenario", action="append", help="only these scenarios (repeatable)")
    ap.add_argument("--devices", metavar="PATH", help="a pickle of the drawn readers: read if it exists, else written "
                    "(drawing and calibrating a reader takes seconds; a before/after comparison draws them once)")
    a = ap.parse_args(argv)
    if a.devices and os.path.exists(a.devices):
        with open(a.devices, "rb") as fh:
            seed, devices = pickle.load(fh)
        if seed != a.seed or len(devices) != a.readers:
            print(f"error: {a.devices} holds {len(devices)} readers of seed {seed}", file=sys.stderr)
            return 2
    else:
        devices = sample_devices(a.seed, a.readers)
        if a.devices:
            with open(a.devices, "wb") as fh:
                pickle.dump((a.seed, devices), fh)
    for name in a.scenario or SCENARIOS:
        t0 = time.time()
        r = check(name, devices, a.duration)
        print(f"{name}: {len(r['latched'])} of {a.readers} latched {r['causes']} readers {r['latched']}; "
              f"peak true force {r['peak_n']:.2f} N ({time.time() - t0:.0f} s)", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
