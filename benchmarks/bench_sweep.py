"""Wall time of a population sweep: episodes one at a time, batched, local processes, Dask.

The sweep is 2 scenarios x 3 reading rates x 42 drawn readers x 2 controllers x 2
replicates (1,008 episodes, the plan of ``tests/test_sweep.py``) of 2 s each: reading starts
at 1.5 s, so every episode has 0.5 s of reading and every force metric is defined.
``--duration 1 --start 0.5`` runs one-second episodes whose reading starts at 0.5 s (the
scenarios' ``start_s`` replaced); ``--readers 417`` gives 10,008 episodes.  Rows:

* ``one at a time``: :func:`ebraille_sim.tools.sweep.run_episode` per episode (one plant per
  episode, the scenario runner's compiled loop);
* ``batched``: ``run_sweep(jobs=1)``: the episodes of a batch that share a duration run
  together, all their control loops in one compiled call
  (:func:`ebraille_sim.scenarios.runner.run_batch`,
  :func:`ebraille_sim.plant.engine.run`);
* ``local xN`` and ``dask``: batches distributed over worker processes.

Every executor must give the same rows (wall-clock metric aside); the script checks it and
prints each time as a ratio to the one-at-a-time run measured in the same process (last
line: the batched speed-up), and the CPU time per episode (this process and its workers),
which depends much less on the load of a shared machine than the wall time.  ``--single-limit K`` times one at a time on the first K
episodes only and compares those rows (for large sweeps).

Usage::

    python benchmarks/bench_sweep.py [--jobs N] [--workers N] [--readers K] [--duration S] [--start S]
                                     [--single-limit K] [--no-dask]

Reported numbers depend on the machine and on its load; quote the core count and the load
average printed with them.
"""
from __future__ import annotations

import argparse
import os
import pathlib
import platform
import resource
import tempfile
import time


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=os.cpu_count(), help="local worker processes")
    ap.add_argument("--workers", type=int, default=os.cpu_count(), help="Dask LocalCluster workers")
    ap.add_argument("--readers", type=int, default=42, help="readers per scenario (42 gives 1,008 episodes)")
    ap.add_argument("--duration", type=float, default=2.0, help="episode length, s (reading starts at 1.5 s)")
    ap.add_argument("--start", type=float, default=None, help="reading start, s (default: the scenarios' 1.5 s)")
    ap.add_argument("--single-limit", type=int, default=None,
                    help="time one at a time on the first K episodes only (default: all)")
    ap.add_argument("--no-dask", action="store_true", help="skip the Dask LocalCluster")
    args = ap.parse_args(argv)

    import dataclasses

    from ebraille_sim.scenarios.spec import load_scenario
    from ebraille_sim.tools import sweep as S

    with tempfile.TemporaryDirectory() as tmp:
        gains = pathlib.Path(tmp) / "soft.toml"
        gains.write_text('controller = "pid"\n[gains]\nkp_v_per_n = 1.5\nki_v_per_ns = 6.0\n')
        scenarios = [load_scenario(name) for name in ("steady_90wpm", "tremor_90wpm")]
        if args.start is not None:
            scenarios = [dataclasses.replace(s, reading=dataclasses.replace(s.reading, start_s=args.start))
                         for s in scenarios]
        t0 = time.perf_counter()
        plan = S.plan_sweep(scenarios, rates=[60, 90, 120], readers=args.readers,
                            controllers=["pid", str(gains)], seed=11, replicates=2, duration_s=args.duration)
        t_plan = time.perf_counter() - t0
        n = len(plan.episodes)
        print(f"machine: {platform.machine()}, {os.cpu_count()} logical cores, load average "
              f"{os.getloadavg()[0]:.1f} at start; python {platform.python_version()}")
        print(f"plan: {n} episodes of {args.duration:g} s simulated; planning (population draw + calibration) "
              f"{t_plan:.2f} s")
        S.run_sweep(S.plan_sweep(["steady_90wpm"], controllers=["pid"], duration_s=1.6), jobs=1,
                    progress=False)                                    # compile and warm the caches
        cpu: dict = {}

        def cpu_now() -> float:
            child = resource.getrusage(resource.RUSAGE_CHILDREN)
            return time.process_time() + child.ru_utime + child.ru_stime

        results = {}
        k = n if args.single_limit is None else min(n, args.single_limit)
        c0 = cpu_now()
        t0 = time.perf_counter()
        rows = [S.run_episode(plan, ep) for ep in plan.episodes[:k]]
        cpu["one at a time"] = (cpu_now() - c0) / k
        t_single = (time.perf_counter() - t0) * n / k
        results["one at a time"] = S.SweepResult(rows, S._columns(rows), t_single, "single", plan)
        if k < n:
            print(f"one at a time: {k} of {n} episodes timed, the time below scaled to all {n}")
        c0 = cpu_now()
        results["batched (jobs=1)"] = S.run_sweep(plan, jobs=1, progress=False)
        cpu["batched (jobs=1)"] = (cpu_now() - c0) / n
        if args.jobs > 1:
            c0 = cpu_now()
            results[f"local x{args.jobs}"] = S.run_sweep(plan, jobs=args.jobs, progress=False)
            cpu[f"local x{args.jobs}"] = (cpu_now() - c0) / n     # workers' start-up included
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
            same = S.identical_results(ref, S.SweepResult(res.rows[:k], res.columns, res.wall_s))
            print(f"{name:<24} {res.wall_s:7.1f} s   {n / res.wall_s:7.1f} episodes/s   "
                  f"{res.wall_s / (n * args.duration) * 1e3:6.2f} ms per episode-second   "
                  f"x{ref.wall_s / res.wall_s:5.2f} of one at a time   rows identical: {same}"
                  + (f"   CPU {cpu[name] * 1e3:.2f} ms per episode" if name in cpu else ""))
        print(f"load average at end: {os.getloadavg()[0]:.1f}")
        batched = results["batched (jobs=1)"]
        best = min(results.values(), key=lambda r: r.wall_s)
        print(f"fastest: {best.executor}, {best.wall_s:.1f} s for {n} episodes of {args.duration:g} s "
              f"({best.wall_s / n * 1e3:.2f} ms per episode)")
        print(f"batched / one at a time speed-up (same process, jobs=1): {ref.wall_s / batched.wall_s:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
