"""Speed of the identification: one fifth-order Wiener model on 60 s of 100 Hz data.

The data are the virtual bench's chirp record (6058 samples: 57.6 s of stepped chirp plus
the 2 s baseline and 1 s tail).  The identification runs with its defaults (input delay
searched over 0-3, two delay candidates, four starts each, 200 evaluations per
refinement).  Two references are measured in the same run so the ratios do not depend on
the machine: one :func:`scipy.signal.lfilter` pass of a fifth-order filter over the same
data, and a fifth-order linear output-error fit (delay given, one start).  Target: under
10 s for the Wiener fit.

Run:  python benchmarks/bench_identify.py [--repeat 3] [--json FILE]
"""
from __future__ import annotations

import argparse
import json
import os
import platform

import numpy as np
import scipy.signal

from ebraille_sim.identification import bench
from ebraille_sim.identification import sysid
from timing import best_of


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    rec = bench.run_profile(bench.PAPER_PROFILES["chirp"], seed=a.seed)
    u, y = rec.voltage_v, rec.force_n
    b, f = np.array([0.2, -0.1, 0.05, 0.02, 0.01]), np.real(np.poly([0.9, 0.5, -0.3, 0.2, 0.1]))

    t_filter, _ = best_of(lambda: scipy.signal.lfilter(b, f, u), max(a.repeat, 20))
    t_linear, _ = best_of(lambda: sysid.fit("linear", u, y, 5, nk=0, n_starts=1, n_delay_candidates=1), a.repeat)
    t_wiener, rep = best_of(lambda: sysid.fit_report("wiener", u, y, 5, seed=a.seed), a.repeat)

    doc = {"machine": f"{platform.machine()} {platform.processor() or ''} python {platform.python_version()} "
                      f"cpus {os.cpu_count()}",
           "samples": int(u.size), "duration_s": float(u.size * rec.dt_s),
           "reference_lfilter_s": t_filter, "reference_linear_oe_s": t_linear, "wiener5_s": t_wiener,
           "ratio_to_lfilter": t_wiener / t_filter, "ratio_to_linear_oe": t_wiener / t_linear,
           "wiener5_estimation_fitness": rep.fitness_pct, "wiener5_nk": rep.nk}
    print(f"identification speed, {u.size} samples ({doc['duration_s']:.1f} s at 100 Hz), {doc['machine']}")
    print(f"reference: one lfilter pass (order 5)        {t_filter * 1e3:9.3f} ms")
    print(f"reference: linear OE fit, order 5, nk given  {t_linear:9.3f} s")
    print(f"fifth-order Wiener, nk searched, 4 starts    {t_wiener:9.3f} s  "
          f"(fit {rep.fitness_pct:.2f} %, nk {rep.nk})")
    print(f"ratio Wiener / lfilter pass: {doc['ratio_to_lfilter']:.0f}   ratio Wiener / linear OE: "
          f"{doc['ratio_to_linear_oe']:.1f}")
    print(f"target < 10 s: {'met' if t_wiener < 10.0 else 'NOT met'} ({t_wiener:.2f} s, best of {a.repeat})")
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(doc, fh, indent=2)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
