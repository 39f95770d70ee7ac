"""Wall time of a population sweep: episodes one at a time, batched, local processes, Dask.

The sweep is 2 scenarios x 3 reading rates x 42 drawn readers x 2 controllers x 2
replicates (1,008 episodes, the plan of ``tests/test_sweep.py``) of 2 s each: reading starts
at 1.5 s, so every episode has 0.5 s of reading and every force metric is defined.  Rows:

* ``one at a time``: :func:`ebraille_sim.tools.sweep.run_episode` per episode (one plant per
  episode, the scenario runner's loop);
* ``batched``: ``run_sweep(jobs=1)``: the episodes of a batch that share a scenario and a
  duration advance together, one compiled call per control period
  (:func:`ebraille_sim.scenarios.runner.run_batch`), each controller still called in Python;
* ``local xN`` and ``dask``: batches distributed over worker processes.

Every executor must give the same rows (wall-clock metric aside); the script checks it and
prints each time as a ratio to the one-at-a-time run measured in the same process (last
line: the batched speed-up).

Usage::

    python benchmarks/bench_sweep.py [--jobs N] [--workers N] [--readers K] [--duration S] [--no-dask]

Reported numbers depend on the machine and on its load; quote the core count and the load
average printed with them.
"""
from __future__ import annotations

import argparse
import os
import pathlib
import platform
import tempfile
import time


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=os.cpu_count(), help="local worker processes")
    ap.add_argument("--workers", type=int, default=os.cpu_count(), help="Dask LocalCluster workers")
    ap.add_argument("--readers", type=int, default=42, help="readers per scenario (42 gives 1,008 episodes)")
    ap.add_argument("--duration", type=float, default=2.0, help="episode length, s (reading starts at 1.5 s)")
    ap.add_argument("--no-dask", action="store_true", help="skip the Dask LocalCluster")
    args = ap.parse_args(argv)

    from ebraille_sim.tools import sweep as S

    with tempfile.TemporaryDirectory() as tmp:
        gains = pathlib.Path(tmp) / "soft.toml"
        gains.write_text('controller = "pid"\n[gains]\nkp_v_per_n = 1.5\nki_v_per_ns = 6.0\n')
        t0 = time.perf_counter()
        plan = S.plan_sweep(["steady_90wpm", "tremor_90wpm"], rates=[60, 90, 120], readers=args.readers,
                            controllers=["pid", str(gains)], seed=11, replicates=2, duration_s=args.duration)
        t_plan = time.perf_counter() - t0
        n = len(plan.episodes)
        print(f"machine: {platform.machine()}, {os.cpu_count()} logical cores, load average "
              f"{os.getloadavg()[0]:.1f} at start; python {platform.python_version()}")
        print(f"plan: {n} episodes of {args.duration:g} s simulated; planning (population draw + calibration) "
              f"{t_plan:.2f} s")
        S.run_sweep(S.plan_sweep(["steady_90wpm"], controllers=["pid"], duration_s=1.6), jobs=1,
                    progress=False)                                    # compile and warm the caches
        results = {}
        t0 = time.perf_counter()
        rows = [S.run_episode(plan, ep) for ep in plan.episodes]
        results["one at a time"] = S.SweepResult(rows, S._columns(rows), time.perf_counter() - t0, "single", plan)
        results["batched (jobs=1)"] = S.run_sweep(plan, jobs=1, progress=False)
        if args.jobs > 1:
            results[f"local x{args.jobs}"] = S.run_sweep(plan, jobs=args.jobs, progress=False)
        if not args.no_dask:
            try:
                from dask.distributed import Client, LocalCluster
            except ImportError:
                print("dask.distributed not installed: pip install 'ebraille-sim[dist]'")
            else:
                t0 = time.perf_counter()
                with LocalCluster(n_workers=args.workers, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, Client(cluster) as client:
                    t_start = time.perf_counter() - t0
                    results[f"dask LocalCluster({args.workers})"] = S.run_sweep(plan, scheduler=client,
                                                                                 progress=False)
                print(f"dask LocalCluster start-up: {t_start:.1f} s (not included below)")
        ref = results["one at a time"]
        failed = sum(1 for r in ref.rows if r["error"])
        empty = sum(1 for r in ref.rows if r.get("force_rmse_n") is None)
        print(f"failed episodes {failed}, episodes without force metrics {empty}")
        for name, res in results.items():
            same = S.identical_results(ref, res)
            print(f"{name:<24} {res.wall_s:7.1f} s   {n / res.wall_s:7.1f} episodes/s   "
                  f"{res.wall_s / (n * args.duration) * 1e3:6.2f} ms per episode-second   "
                  f"x{ref.wall_s / res.wall_s:5.2f} of one at a time   rows identical: {same}")
        print(f"load average at end: {os.getloadavg()[0]:.1f}")
        batched = results["batched (jobs=1)"]
        print(f"batched / one at a time speed-up (same process, jobs=1): {ref.wall_s / batched.wall_s:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
