"""Real-time factor of the pymunk mechanism on a reading scenario, against the lumped plant.

Both backends run the same scenario (default: ``steady_90wpm`` for 20 s of simulated
reading) in the same process, one after the other and repeated; the best of the repeats
is kept for each (the least disturbed by other load on the machine).  The real-time
factor is simulated time over the wall-clock time of the closed loop, as measured by
the runner (``metrics["real_time_factor"]``).  The target is a pymunk
real-time factor of at least 20.

Run::

    python benchmarks/bench_mechanism.py [--scenario steady_90wpm] [--duration 20] [--repeats 3]
"""
from __future__ import annotations

import argparse
import os
import platform
import sys


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="steady_90wpm")
    ap.add_argument("--duration", type=float, default=20.0, help="simulated seconds per run")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args(argv)
    if args.repeats < 1 or not args.duration > 0:
        print("error: --repeats must be >= 1 and --duration > 0", file=sys.stderr)
        return 2

    from ebraille_sim.scenarios.runner import run_scenario

    # warm-up: compile the kernel and load the estimator for both backends
    for backend in ("lumped", "pymunk"):
        run_scenario(args.scenario, duration_s=0.2, backend=backend)
    best = {"lumped": 0.0, "pymunk": 0.0}
    for _ in range(args.repeats):
        for backend in best:
            res = run_scenario(args.scenario, duration_s=args.duration, backend=backend)
            best[backend] = max(best[backend], res.metrics["real_time_factor"])
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"load average {load:.2f}, Python {platform.python_version()}")
    print(f"scenario {args.scenario}, {args.duration:g} s simulated, best of {args.repeats}")
    print(f"lumped (numba kernel, reference): real-time factor {best['lumped']:8.1f}")
    print(f"pymunk mechanism:                 real-time factor {best['pymunk']:8.1f}")
    print(f"ratio pymunk / lumped: {best['pymunk'] / best['lumped']:.3f}")
    ok = best["pymunk"] >= 20.0
    print(f"requirement pymunk >= 20x real time: {'met' if ok else 'NOT met'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
