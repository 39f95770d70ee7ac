"""Optimisers for the design search compared on one objective, budget and seeds.

The objective is :class:`ebraille_sim.tools.design_search.DesignSearch`'s (the benchmark's
score over training readers; default: the quick suite, one training reader, the default
space on one firmware preset, no start points, so that the optimiser alone finds the
design).  Each optimiser gets the same number of evaluations on the unit cube of the space
from the same seeds:

* ``de``: SciPy's differential evolution as the search runs it (Latin hypercube start,
  deferred updating);
* ``optuna``: Optuna's TPE sampler (``optuna.samplers.TPESampler(seed=...)``), one trial at a time;
* ``cma``: ``cma.CMAEvolutionStrategy`` from the cube's centre, sigma 0.3, bounds [0, 1];
* ``random``: uniform points (the floor).

Prints the best training score after each quarter of the budget per optimiser and seed, the
mean over seeds, and the wall time (shared machine: compare within one run).  optuna and cma
are optional: a missing one is skipped with a line.

Measured (shared 2-core machine, load average 5-8), mean best training score over seeds 1-3 /
worst seed at the end:

* default space on fast_1khz (12 coordinates), 1 training reader, 40 evaluations: de 91.98 /
  91.14, optuna 92.49 / 91.60, cma 91.41 / 89.69, random 89.13 / 87.19;
* default space on both presets (23 coordinates), 2 training readers, 48 evaluations
  (``--firmware all --readers 2 --evaluations 48``): de 83.82 / 81.61, optuna 87.84 / 85.66,
  cma 87.47 / 82.21.

Usage::

    python benchmarks/design_search_optimisers.py [--evaluations N] [--seeds K] [--firmware NAME]
                                                  [--suite quick] [--readers N] [-j N]
"""
from __future__ import annotations

import argparse
import dataclasses
import time

import numpy as np


def _search(args, seed):
    from ebraille_sim.tools.design_search import DesignSearch, default_space
    space = default_space(None if args.firmware == "all" else [args.firmware])
    space = dataclasses.replace(space, arms=tuple(dataclasses.replace(a, starts=()) for a in space.arms))
    return DesignSearch(space, suite=args.suite, readers=args.readers, seed=seed, evaluations=args.evaluations,
                        jobs=args.jobs)


def _values(ds, xs):
    return ds._evaluate([ds.space.decode(x) for x in xs])


def run_de(args, seed):
    ds = _search(args, seed)
    ds.run()
    return [h["value"] for h in ds.history]


def run_random(args, seed):
    ds = _search(args, seed)
    rng = np.random.default_rng(seed)
    return _values(ds, rng.random((args.evaluations, ds.space.dimensions)))


def run_optuna(args, seed):
    import optuna
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    ds = _search(args, seed)
    study = optuna.create_study(direction="maximize", sampler=optuna.samplers.TPESampler(seed=seed))
    out = []
    for _ in range(args.evaluations):
        t = study.ask()
        x = [t.suggest_float(f"x{i}", 0.0, 1.0) for i in range(ds.space.dimensions)]
        v = _values(ds, [x])[0]
        study.tell(t, v)
        out.append(v)
    return out


def run_cma(args, seed):
    import cma
    ds = _search(args, seed)
    es = cma.CMAEvolutionStrategy([0.5] * ds.space.dimensions, 0.3,
                                  {"bounds": [0.0, 1.0], "seed": seed + 1, "verbose": -9})
    out = []
    while len(out) < args.evaluations:
        xs = es.ask()[: args.evaluations - len(out)]
        vs = _values(ds, xs)
        out += vs
        if len(xs) == es.popsize:
            es.tell(xs, [-v for v in vs])
    return out


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--evaluations", type=int, default=40)
    p.add_argument("--seeds", type=int, default=3)
    p.add_argument("--firmware", default="fast_1khz", help="a firmware preset, or 'all' (the default space)")
    p.add_argument("--suite", default="quick")
    p.add_argument("--readers", type=int, default=1)
    p.add_argument("-j", "--jobs", type=int, default=1)
    p.add_argument("--only", nargs="*", default=["de", "optuna", "cma", "random"])
    args = p.parse_args()
    import os
    print(f"{os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f}; suite {args.suite}, "
          f"{args.readers} training reader(s), firmware {args.firmware}, {args.evaluations} evaluations, "
          f"seeds 1..{args.seeds}, no start points")
    fns = {"de": run_de, "optuna": run_optuna, "cma": run_cma, "random": run_random}
    quarters = [max(1, round(args.evaluations * q)) for q in (0.25, 0.5, 0.75, 1.0)]
    for name in args.only:
        bests, t0 = [], time.perf_counter()
        for seed in range(1, args.seeds + 1):
            try:
                vals = fns[name](args, seed)
            except ImportError as exc:
                print(f"{name}: skipped ({exc})")
                break
            run = np.maximum.accumulate(vals)
            bests.append([run[q - 1] for q in quarters])
            print(f"{name} seed {seed}: best after {quarters} evaluations: "
                  + ", ".join(f"{v:.2f}" for v in bests[-1]), flush=True)
        if bests:
            m = np.mean(bests, axis=0)
            print(f"{name}: mean best {', '.join(f'{v:.2f}' for v in m)}; worst seed at the end "
                  f"{min(b[-1] for b in bests):.2f}; {time.perf_counter() - t0:.0f} s", flush=True)


if __name__ == "__main__":
    main()
