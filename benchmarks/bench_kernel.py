"""Cost of one physics step of the kernel, and of the C library's ``exp`` against its ``expm1``.

* kernel: nanoseconds per physics step of :func:`ebraille_sim.plant.kernel.advance` on one
  device of ``steady_90wpm`` pressing the pulp at a held 1 V (one call of ``--steps`` steps),
  and the same steps one control period per call;
* ``exp(x) - 1`` and ``expm1(x)``: nanoseconds per call in a compiled loop over the pulp
  law's range of ``x = m d`` above ``ln 2`` (0.7 to 2.4: 0.2 to 2 N), where
  :func:`ebraille_sim.physics.fingertip.exp_minus_one` takes the first.

Each figure is the median of ``--repeat`` rounds in one process, the rows of a round timed one
after the other, and the ratio ``expm1 / (exp - 1)`` that of each round's own times.

Run:  python benchmarks/bench_kernel.py [--repeat 7] [--steps 600000]
"""
from __future__ import annotations

import argparse
import math
import statistics
import time

import numpy as np

from ebraille_sim.base.compiled import njit
from ebraille_sim.plant import kernel
from ebraille_sim.plant.layout import U
from ebraille_sim.scenarios import runner


@njit(cache=True)
def _sum_exp_minus_one(x):
    acc = 0.0
    for v in x:
        acc += math.exp(v) - 1.0
    return acc


@njit(cache=True)
def _sum_expm1(x):
    acc = 0.0
    for v in x:
        acc += math.expm1(v)
    return acc


@njit(cache=True)
def _per_period(s, p, u, n_sub, n_periods):
    for _ in range(n_periods):
        kernel.advance(s, p, u, n_sub)


def _plant():
    spec, _, run, _ = runner.prepare_run("steady_90wpm", duration_s=1.0)
    plant = runner._plant_for(spec, run, "lumped")
    plant.inputs[0, U.command_v] = 1.0
    kernel.advance(plant.state[0], plant.params[0], plant.inputs[0], 20000)     # pressing the pulp
    return plant


def _kernel_ns(steps: int, per_period: bool) -> float:
    plant = _plant()
    s, p, u = plant.state[0], plant.params[0], plant.inputs[0]
    t0 = time.perf_counter()
    if per_period:
        _per_period(s, p, u, plant.substeps, steps // plant.substeps)
    else:
        kernel.advance(s, p, u, steps)
    return (time.perf_counter() - t0) / steps * 1e9


def _call_ns(fn, x) -> float:
    t0 = time.perf_counter()
    fn(x)
    return (time.perf_counter() - t0) / x.size * 1e9


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--steps", type=int, default=600000)
    a = ap.parse_args(argv)
    if a.repeat < 1 or a.steps < 1000:
        ap.error("--repeat must be at least 1 and --steps at least 1000")
    x = np.random.default_rng(0).uniform(0.7, 2.4, 1_000_000)
    _kernel_ns(1000, False), _kernel_ns(1000, True), _call_ns(_sum_exp_minus_one, x[:10]), _call_ns(_sum_expm1, x[:10])
    rounds = []
    for _ in range(a.repeat):
        rounds.append({"kernel": _kernel_ns(a.steps, False), "kernel per period": _kernel_ns(a.steps, True),
                       "exp(x) - 1": _call_ns(_sum_exp_minus_one, x), "expm1(x)": _call_ns(_sum_expm1, x)})
    med = {k: statistics.median(r[k] for r in rounds) for k in rounds[0]}
    ratio = statistics.median(r["expm1(x)"] / r["exp(x) - 1"] for r in rounds)
    print(f"medians of {a.repeat} rounds, ns: kernel {med['kernel']:.1f} per physics step "
          f"({med['kernel per period']:.1f} one control period per call); exp(x) - 1 {med['exp(x) - 1']:.1f}, "
          f"expm1(x) {med['expm1(x)']:.1f} per call (expm1 / exp: {ratio:.1f}x)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
