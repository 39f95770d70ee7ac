"""Speed of the closed loop: 60 s of reading at a 1 kHz control rate.

Reports the real-time factor (simulated seconds per wall second; target >= 60) for the
default physics rate, how it scales with the physics rate, and a same-run reference: the
wall time of the controller alone (60 000 PID updates, the part of the loop that stays in
Python), so the ratio (full loop / controller alone) is independent of the machine's speed.

Run:  python benchmarks/bench_loop.py [--repeat 3] [--json FILE]
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import platform

import controllers
import ebraille_sim
from ebraille_sim.physics.params import RateParams
from ebraille_sim.scenarios.spec import load_scenario
from timing import best_of


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--duration", type=float, default=60.0)
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    spec = load_scenario("steady_90wpm")
    ebraille_sim.run_scenario(spec, duration_s=0.5)               # compile / warm caches

    def controller_only():
        pid = controllers.make("pid")
        pid.reset(force_est_n=0.0, setpoint_n=1.0)
        upd = pid.update
        y = 0.9
        for _ in range(int(a.duration * 1000)):
            upd(y, 1.0, 1e-3, 0.0)

    t_ref, _ = best_of(controller_only, a.repeat)
    rows = []
    for phys in (5000.0, 10000.0, 20000.0, 50000.0):
        dev = dataclasses.replace(spec.device, rates=RateParams(control_rate_hz=1000.0, sensor_rate_hz=1000.0,
                                                                physics_rate_hz=phys))
        s = dataclasses.replace(spec, device=dev)
        wall, res = best_of(lambda: ebraille_sim.run_scenario(s, duration_s=a.duration), a.repeat)
        rows.append({"physics_rate_hz": phys, "wall_s": wall,
                     "real_time_factor_loop": res.metrics["real_time_factor"],
                     "real_time_factor_total": a.duration / wall,
                     "ratio_to_controller_only": wall / t_ref,
                     "in_band_fraction": res.metrics["in_band_fraction"]})
    doc = {"machine": f"{platform.machine()} {platform.processor() or ''} python {platform.python_version()}",
           "duration_s": a.duration, "control_rate_hz": 1000.0,
           "reference_controller_only_s": t_ref, "rows": rows}
    print(f"closed loop, {a.duration:g} s of reading at 1 kHz control ({doc['machine']})")
    print(f"reference: controller alone {t_ref * 1e3:.1f} ms for {int(a.duration * 1000)} updates")
    print(f"{'physics Hz':>10} {'wall s':>8} {'RTF loop':>9} {'RTF total':>9} {'x ref':>7} {'in band':>8}")
    for r in rows:
        print(f"{r['physics_rate_hz']:>10.0f} {r['wall_s']:>8.3f} {r['real_time_factor_loop']:>9.1f} "
              f"{r['real_time_factor_total']:>9.1f} {r['ratio_to_controller_only']:>7.1f} {r['in_band_fraction']:>8.3f}")
    default = next(r for r in rows if r["physics_rate_hz"] == 10000.0)
    ok = default["real_time_factor_total"] >= 60.0
    print(f"target RTF >= 60 at the default 10 kHz physics rate: {'met' if ok else 'NOT met'} "
          f"({default['real_time_factor_total']:.0f})")
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(doc, fh, indent=2)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
