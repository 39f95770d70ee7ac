"""Memory and wall time of a long session: peak resident memory per simulated hour.

Each case runs in a fresh interpreter (so its peak resident set, ``ru_maxrss``, is its
own): the scenario (default ``everyday_session``) for ``--duration`` seconds (default one
hour) with the full trace at the control rate (``trace_every=1``, what ``run_scenario``
returns by default), with every 100th sample (``trace_every=100``), and without a trace
(``trace_every=None``; metrics only).  A 60 s run of the same scenario, measured in the same
script, gives the wall-time reference: the long run should take about ``duration / 60``
times as long (the target: within 1.2x of that, under 400 MB).  The metrics of the
three cases must be equal (wall-clock metric aside); the script checks it.

Run:  python benchmarks/bench_memory.py [--scenario everyday_session] [--duration 3600]
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys

_CHILD = r"""
import json, resource, sys, time
from ebraille_sim.scenarios.runner import run_scenario
name, duration, every = sys.argv[1], float(sys.argv[2]), sys.argv[3]
every = None if every == "none" else int(every)
run_scenario(name, duration_s=2.0, trace_every=every)                  # compile, warm the caches
t0 = time.perf_counter()
res = run_scenario(name, duration_s=duration, trace_every=every)
wall = time.perf_counter() - t0
trace_mb = sum(a.nbytes for a in res.trace.values()) / 2**20
metrics = {k: v for k, v in res.metrics.items() if k != "real_time_factor"}
print(json.dumps({"wall_s": wall, "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                  "trace_mb": trace_mb, "metrics": metrics}))
"""


def measure(scenario: str, duration: float, every) -> dict:
    """Run one case in a fresh interpreter; its wall time, peak RSS (MB), trace size and metrics."""
    out = subprocess.run([sys.executable, "-c", _CHILD, scenario, repr(duration), str(every).lower()],
                         capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="everyday_session")
    ap.add_argument("--duration", type=float, default=3600.0, help="simulated seconds of the long run")
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    print(f"machine: {platform.machine()}, {os.cpu_count()} logical cores, load average {os.getloadavg()[0]:.1f}; "
          f"python {platform.python_version()}")
    ref = measure(a.scenario, 60.0, "none")
    rows = {}
    for every in (1, 100, None):
        r = measure(a.scenario, a.duration, every)
        rows[str(every)] = r
        print(f"{a.scenario} {a.duration:g} s, trace_every={str(every):5s}: wall {r['wall_s']:7.1f} s "
              f"(x{r['wall_s'] / (ref['wall_s'] * a.duration / 60.0):4.2f} of {a.duration / 60:g} x the 60 s run), "
              f"peak RSS {r['peak_rss_mb']:7.0f} MB ({r['peak_rss_mb'] - ref['peak_rss_mb']:+7.0f} MB over the 60 s "
              f"run's {ref['peak_rss_mb']:.0f} MB), trace {r['trace_mb']:6.1f} MB")
    same = all(r["metrics"] == rows["1"]["metrics"] for r in rows.values())
    print(f"metrics identical across the cases: {same}; 60 s reference run {ref['wall_s']:.2f} s")
    print(f"load average at end {os.getloadavg()[0]:.1f}")
    r = rows["None"]
    print(f"peak RSS without a trace: {r['peak_rss_mb']:.0f} MB for {a.duration:g} s "
          f"(target < 400 MB per hour); wall ratio to {a.duration / 60:g} x 60 s: "
          f"{r['wall_s'] / (ref['wall_s'] * a.duration / 60.0):.2f}")
    if a.json:
        with open(a.json, "w", encoding="utf-8") as fh:
            json.dump({"reference_60s": ref, "cases": rows, "duration_s": a.duration}, fh, indent=2)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
