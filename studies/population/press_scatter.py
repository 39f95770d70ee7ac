"""What the film's press-to-press scatter costs, and whether a board could see it.

The FSR 402's single-part repeatability (``FSRParams.press_repeatability``, 2 %) scales the
film's resistance by a draw that holds for the whole press.  This study prints:

1. the nominal reader of ``steady_90wpm`` over seeds 1-12 (each seed draws its own press):
   the mean force held after the onset and its ratio to the mean estimate;
2. the file's own run with the scatter switched off (``press_repeatability = 0``);
3. over drawn readers, the force the motor current gives through the drive's end-of-line
   calibration (``push_force_per_a_n * i + push_offset_n``) against the true force, beside
   the FSR estimate against the true force.  It uses the plant's true current (the trace's
   ``motor_current_a``, plant truth): the best a current-sense chain could report.

    python studies/population/press_scatter.py --readers 30 --seed 777
"""
from __future__ import annotations

import dataclasses
import sys

import numpy as np

from ebraille_sim.estimation.calibration import calibrate_drive
from ebraille_sim.scenarios.runner import run_batch, run_scenario
from ebraille_sim.scenarios.spec import load_scenario
from shares import drawn_runs, reader_args

SETTLED_S = 3.0
"""Samples after this time are the held force (the onset settles within 1 s of the 1.5 s start)."""


def held(trace) -> tuple[float, float]:
    """Mean true force and mean estimate after :data:`SETTLED_S`, N."""
    m = trace["t_s"] > SETTLED_S
    return float(np.mean(trace["force_true_n"][m])), float(np.mean(trace["force_est_n"][m]))


def main(argv=None) -> int:
    a = reader_args(__doc__.splitlines()[0], 30, 777, argv, most=1000)
    if a is None:
        return 2
    spec = load_scenario("steady_90wpm")
    rows = [held(run_scenario(spec, seed=s).trace) for s in range(1, 13)]
    force = np.array([f for f, _ in rows])
    ratio = np.array([f / e for f, e in rows])
    print(f"steady_90wpm nominal reader, seeds 1-12: held force {np.round(force, 3).tolist()}")
    print(f"  min {force.min():.3f} max {force.max():.3f} mean {force.mean():.4f} sd {force.std():.4f} N; "
          f"force/estimate mean {ratio.mean():.4f} sd {ratio.std():.4f}")
    dev = spec.device
    flat = dataclasses.replace(dev, fsr=dataclasses.replace(dev.fsr, press_repeatability=0.0))
    r = run_scenario(dataclasses.replace(spec, device=flat))
    f, e = held(r.trace)
    print(f"  the file's run without the press scatter: held force {f:.4f} N, estimate {e:.4f} N, "
          f"force RMSE {r.metrics['force_rmse_n']:.4f} N")
    devs, runs = drawn_runs(spec, a.readers, a.seed, 12.0)
    cur, est = [], []
    for d, res in zip(devs, run_batch(runs, keep_traces=True)):
        cal = calibrate_drive(d)
        m = res.trace["t_s"] > SETTLED_S + 1.0
        true = np.mean(res.trace["force_true_n"][m])
        i_true = res.trace["motor_current_a"][m]                       # plant truth: the best a chain reads
        cur.append(np.mean(cal.push_force_per_a_n * i_true + cal.push_offset_n) / true)
        est.append(np.mean(res.trace["force_est_n"][m]) / true)
    cur, est = np.array(cur), np.array(est)
    print(f"{a.readers} drawn readers of seed {a.seed}, steady_90wpm 12 s, held force against the true force:")
    print(f"  from the motor current: mean {cur.mean():.3f} sd {cur.std():.3f} (range {cur.min():.2f} to {cur.max():.2f})")
    print(f"  the FSR estimate:       mean {est.mean():.4f} sd {est.std():.4f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
