"""Start-up cost: ``import ebraille_sim``, ``ebraille-sim --help`` and a whole
``ebraille-sim run steady_90wpm`` against a bare interpreter start, measured in one run.

Each command runs in a fresh process ``--repeat`` times (after one warm-up run that fills
the compiled-code cache); the median wall time is reported with its ratio to the bare
``python -c pass`` start of the same run, so the ratios do not depend on the machine's speed.
Targets: ``import ebraille_sim`` under 0.5 s on an idle machine; the whole run command
(warm cache) under 1.08 s, i.e. 2.5 times faster than its 2.7 s before the loop was compiled.

Run:  python benchmarks/bench_start.py [--repeat 5] [--json FILE]
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time


def _median_wall(argv: list[str], repeat: int, cwd: str) -> float:
    subprocess.run(argv, check=True, capture_output=True, cwd=cwd)          # warm-up (compiled-code cache)
    walls = []
    for _ in range(max(1, repeat)):
        t0 = time.perf_counter()
        subprocess.run(argv, check=True, capture_output=True, cwd=cwd)
        walls.append(time.perf_counter() - t0)
    return statistics.median(walls)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    py = sys.executable
    cli = shutil.which("ebraille-sim", path=os.path.dirname(py)) or shutil.which("ebraille-sim")
    base = [cli] if cli else [py, "-m", "ebraille_sim"]
    work = tempfile.mkdtemp(prefix="bench-start-")
    cases = [("bare interpreter (python -c pass)", [py, "-c", "pass"]),
             ("import ebraille_sim", [py, "-c", "import ebraille_sim"]),
             ("ebraille-sim --help", base + ["--help"]),
             ("ebraille-sim run steady_90wpm (csv trace, plot)", base + ["run", "steady_90wpm", "--force", "--quiet",
                                                                       "--out", os.path.join(work, "a")]),
             ("ebraille-sim run steady_90wpm --trace none --no-plot", base + ["run", "steady_90wpm", "--force",
                                                                            "--quiet", "--trace", "none",
                                                                            "--no-plot", "--out",
                                                                            os.path.join(work, "b")])]
    res = {"machine": {"python": platform.python_version(), "cpus": os.cpu_count(), "platform": platform.platform(),
                       "load_average_1min_at_start": os.getloadavg()[0]}, "cases": []}
    bare = None
    for label, cmd in cases:
        wall = _median_wall(cmd, a.repeat, work)
        bare = wall if bare is None else bare
        res["cases"].append({"case": label, "median_wall_s": wall, "ratio_to_bare": wall / bare})
        print(f"{label:55s} {wall:7.3f} s  x{wall / bare:6.1f} bare start")
    shutil.rmtree(work, ignore_errors=True)
    res["machine"]["load_average_1min_at_end"] = os.getloadavg()[0]
    if a.json:
        with open(a.json, "w", encoding="utf-8") as fh:
            json.dump(res, fh, indent=2)
    imp, run = res["cases"][1], res["cases"][3]
    print(f"import ebraille_sim = {imp['ratio_to_bare']:.1f} bare starts ({imp['median_wall_s']:.2f} s, target < 0.5 s); "
          f"run steady_90wpm = {run['ratio_to_bare']:.1f} bare starts ({run['median_wall_s']:.2f} s, target < 1.08 s)")
    return res


if __name__ == "__main__":
    main()
