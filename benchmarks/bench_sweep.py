"""Wall time of a 1,008-episode population sweep: serial, local processes and a Dask LocalCluster.

The sweep is 2 scenarios x 3 reading rates x 42 drawn readers x 2 controllers x 2
replicates of 1 s each (the plan of ``tests/test_sweep.py``).  Every executor must give
the same rows (wall-clock metric aside); the script checks it and prints the times.

Usage::

    python benchmarks/bench_sweep.py [--jobs N] [--workers N] [--no-serial] [--readers K]

Reported numbers depend on the machine and on its load; run on an otherwise idle machine
and quote the core count with them.
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
    ap.add_argument("--no-serial", action="store_true", help="skip the in-process serial run")
    args = ap.parse_args(argv)

    from ebraille_sim.tools import sweep as S

    with tempfile.TemporaryDirectory() as tmp:
        gains = pathlib.Path(tmp) / "soft.toml"
        gains.write_text('controller = "pid"\n[gains]\nkp_v_per_n = 1.5\nki_v_per_ns = 6.0\n')
        t0 = time.perf_counter()
        plan = S.plan_sweep(["steady_90wpm", "tremor_90wpm"], rates=[60, 90, 120], readers=args.readers,
                            controllers=["pid", str(gains)], seed=11, replicates=2, duration_s=1.0)
        t_plan = time.perf_counter() - t0
        n = len(plan.episodes)
        print(f"machine: {platform.machine()}, {os.cpu_count()} logical cores, load average "
              f"{os.getloadavg()[0]:.1f} at start; python {platform.python_version()}")
        print(f"plan: {n} episodes of 1.0 s simulated; planning (population draw + calibration) {t_plan:.2f} s")
        results = {}
        if not args.no_serial:
            results["serial"] = S.run_sweep(plan, jobs=1, progress=False)
        results[f"local x{args.jobs}"] = S.run_sweep(plan, jobs=args.jobs, progress=False)
        try:
            from dask.distributed import Client, LocalCluster
        except ImportError:
            print("dask.distributed not installed: pip install 'ebraille-sim[dist]'")
        else:
            t0 = time.perf_counter()
            with LocalCluster(n_workers=args.workers, threads_per_worker=1, processes=True,
                              dashboard_address=None) as cluster, Client(cluster) as client:
                t_start = time.perf_counter() - t0
                results[f"dask LocalCluster({args.workers})"] = S.run_sweep(plan, scheduler=client, progress=False)
            print(f"dask LocalCluster start-up: {t_start:.1f} s (not included below)")
        ref = next(iter(results.values()))
        for name, res in results.items():
            same = S.identical_results(ref, res)
            print(f"{name:<24} {res.wall_s:7.1f} s   {n / res.wall_s:7.1f} episodes/s   "
                  f"rows identical to {next(iter(results))}: {same}")
        print(f"load average at end: {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
