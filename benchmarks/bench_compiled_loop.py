"""Speed of one scenario run: the compiled loop against the per-period loop and the kernel alone.

For 60 s of ``steady_90wpm`` with the built-in PID, without and with the safety supervisor
(``run_scenario(..., supervised=False)`` and the default), this reports, as the median of ``--repeat`` runs in one process:

* the wall time of the whole call and of its control loop, with the loop in one compiled
  call (:mod:`ebraille_sim.scenarios.compiled_loop`) and with one Python iteration per
  control period (the path of Python controllers);
* the compiled bound: the same number of physics steps in one call of
  :func:`ebraille_sim.plant.kernel.advance` with the command held, i.e. the plant without
  any controller, which no loop can beat.

Run:  python benchmarks/bench_compiled_loop.py [--repeat 3] [--duration 60] [--json FILE]
"""
from __future__ import annotations

import argparse
import json
import platform
import statistics
import time

import ebraille_sim
from ebraille_sim.plant import kernel
from ebraille_sim.plant.layout import U
from ebraille_sim.scenarios import runner


def _run(duration_s: float, compiled: bool, supervised: bool = False) -> tuple[float, float]:
    runner._USE_COMPILED_LOOP = compiled
    try:
        t0 = time.perf_counter()
        res = ebraille_sim.run_scenario("steady_90wpm", duration_s=duration_s, supervised=supervised)
        total = time.perf_counter() - t0
    finally:
        runner._USE_COMPILED_LOOP = True
    return total, duration_s / res.metrics["real_time_factor"]


def _kernel_only(duration_s: float) -> float:
    spec, _, run, _ = runner.prepare_run("steady_90wpm", duration_s=duration_s)
    plant = runner._plant_for(spec, run, "lumped")
    plant.inputs[0, U.command_v] = 1.0
    t0 = time.perf_counter()
    kernel.advance(plant.state[0], plant.params[0], plant.inputs[0], plant.substeps * run.n_steps)
    return time.perf_counter() - t0


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--duration", type=float, default=60.0)
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    for compiled in (True, False):                       # compile / load every cache first
        _run(0.2, compiled)
        _run(0.2, compiled, True)
    _kernel_only(0.2)
    rows = {}
    for label, fn in (("compiled loop", lambda: _run(a.duration, True)),
                      ("per-period loop", lambda: _run(a.duration, False)),
                      ("compiled, supervised", lambda: _run(a.duration, True, True)),
                      ("per-period, supervised", lambda: _run(a.duration, False, True))):
        runs = [fn() for _ in range(max(1, a.repeat))]
        rows[label] = {"total_s": statistics.median(r[0] for r in runs),
                       "loop_s": statistics.median(r[1] for r in runs)}
    bound = statistics.median(_kernel_only(a.duration) for _ in range(max(1, a.repeat)))
    doc = {"machine": f"{platform.machine()} python {platform.python_version()}", "duration_s": a.duration,
           "rows": rows, "kernel_only_s": bound}
    print(f"steady_90wpm, {a.duration:g} s, default pid, median of {a.repeat} ({doc['machine']})")
    print(f"{'':>22} {'total s':>8} {'loop s':>8} {'loop / bound':>12} {'bound / total':>13}")
    for label, r in rows.items():
        print(f"{label:>22} {r['total_s']:>8.3f} {r['loop_s']:>8.3f} {r['loop_s'] / bound:>12.2f} "
              f"{bound / r['total_s']:>13.2f}")
    print(f"{'kernel alone':>22} {'':>8} {bound:>8.3f} {1.0:>12.2f}")
    print(f"per-period / compiled loop: {rows['per-period loop']['loop_s'] / rows['compiled loop']['loop_s']:.2f}x "
          f"unsupervised, {rows['per-period, supervised']['loop_s'] / rows['compiled, supervised']['loop_s']:.2f}x "
          f"supervised; run_scenario (supervised) = {bound / rows['compiled, supervised']['total_s']:.2f} of the bound")
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(doc, fh, indent=2)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
