"""Wall time of a population sweep: 1,000 drawn readers x 5 scenarios x 12 s (target: under
5 minutes on 2 cores).

The sweep is ``ebraille-sim sweep steady_90wpm steady_120wpm contact_onset pressing_90wpm
everyday_session --readers 1000 --duration 12 -j 2`` (5,000 episodes, the default
controller, the supervisor on), planned and run through :mod:`ebraille_sim.tools.sweep`:
the population draw with each unit's assembly calibration, then batches of episodes on
local worker processes (or a Dask cluster with ``--scheduler``).  The population report of
the sweep (:func:`ebraille_sim.tools.sweep.population`) is printed with the times.

A shared machine's load changes the wall time, so the script also times one compiled run of
one episode (the nominal reader of ``steady_90wpm``, 12 s, :func:`run_scenario`, best of
three) in the same process and prints the sweep as a multiple of it, with the CPU time per
episode (this process and its workers) and the load average.

Usage::

    python benchmarks/bench_population.py [--readers N] [--jobs N] [--duration S] [--seed K]
                                          [--scheduler ADDRESS]
"""
from __future__ import annotations

import argparse
import os
import platform
import resource
import time

SCENARIOS = ("steady_90wpm", "steady_120wpm", "contact_onset", "pressing_90wpm", "everyday_session")
TARGET_S = 300.0


def cpu_now() -> float:
    """CPU time of this process and its finished children, s."""
    child = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + child.ru_utime + child.ru_stime


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--readers", type=int, default=1000, help="readers per scenario (default 1000)")
    ap.add_argument("--jobs", type=int, default=2, help="local worker processes (default 2)")
    ap.add_argument("--duration", type=float, default=12.0, help="episode length, s (default 12)")
    ap.add_argument("--seed", type=int, default=0, help="population seed (default 0)")
    ap.add_argument("--scheduler", default=None, help="Dask scheduler address instead of local processes")
    args = ap.parse_args(argv)

    from timing import best_of
    from ebraille_sim.scenarios.runner import run_scenario
    from ebraille_sim.tools import sweep as S

    print(f"machine: {platform.machine()}, {os.cpu_count()} logical cores, load average "
          f"{os.getloadavg()[0]:.1f} at start; python {platform.python_version()}")
    S.run_sweep(S.plan_sweep(["steady_90wpm"], readers=2, duration_s=2.0), jobs=1, progress=False)   # compile
    t0, c0 = time.perf_counter(), cpu_now()
    plan = S.plan_sweep(list(SCENARIOS), readers=args.readers, seed=args.seed, duration_s=args.duration)
    t_plan = time.perf_counter() - t0
    n = len(plan.episodes)
    t_one, _ = best_of(lambda: run_scenario(plan.specs["steady_90wpm"], seed=1, duration_s=args.duration,
                                            trace_every=None), 3)
    t1 = time.perf_counter()
    res = S.run_sweep(plan, jobs=args.jobs, scheduler=args.scheduler, progress=False)
    t_run = time.perf_counter() - t1
    cpu = cpu_now() - c0
    total = t_plan + t_run
    failed = sum(1 for r in res.rows if r["error"])
    print(S.format_population(S.population(res, worst=1)))
    print(f"\n{n} episodes of {args.duration:g} s ({len(SCENARIOS)} scenarios x {args.readers} readers) on "
          f"{res.executor}, {failed} failed")
    print(f"plan (population draw + calibration) {t_plan:.1f} s, run {t_run:.1f} s, total {total:.1f} s "
          f"(target {TARGET_S:g} s: {'met' if total < TARGET_S else 'NOT met'})")
    print(f"one compiled run (steady_90wpm, {args.duration:g} s, this process): {t_one * 1e3:.1f} ms; "
          f"the sweep is {total / t_one:.0f} of them ({total / t_one / n:.3f} per episode)")
    print(f"CPU {cpu / n * 1e3:.1f} ms per episode (this process and its workers); load average at end "
          f"{os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
