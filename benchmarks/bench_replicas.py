"""What the project's copies of library internals buy against the library calls, in one run.

Each copy reproduces a NumPy or SciPy result to the last bit in faster code.  For each, the
library call is put in its place (the modules' names rebound in this process only) and the
figure the copy exists for is measured with both, interleaved so both see the same load:

* ``seeds``: :class:`ebraille_sim.base.seeds.SeedNode` (``SeedSequence`` hashing compiled)
  against ``numpy.random.SeedSequence``, in the scalar env's reset;
* ``memo``: the bisection memo of the supervisor's speed envelope
  (:func:`ebraille_sim.physics.limits.drive_forces_for_impacts_n`) against the same
  bisection without it, in the scalar env's reset (a new device, a new envelope);
* ``csv``: trace.csv formatted in compiled code (:mod:`ebraille_sim.tools.csvformat`)
  against Python's ``%`` formatting of the same rows, for a 60 s steady_90wpm run, beside
  the run itself;
* ``butter``: the anti-alias filter designed by hand (``plant.lumped._antialias_filter``)
  against ``scipy.signal.butter``: one design per (cutoff, rate) pair, and the import of
  ``scipy.signal`` in a fresh interpreter that has imported the package and the kernel.

Every variant is checked to give the same trajectories (observations and rewards of the
env, the bytes of trace.csv, the filter coefficients) as the copy: on one machine the copies
are exact, so removing one moves no trajectory there.

A reset is the median over ``--repeat`` rounds of the mean of 200 resets of the unwrapped
scalar env at 200 Hz (the default episodes), in this thread's CPU time (``time.thread_time``,
which other jobs on the machine disturb less than wall time); it is also given in env steps
(the median step time of the same rounds).

Run:  python benchmarks/bench_replicas.py [--repeat 5] [--json FILE]
"""
from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time

import numpy as np

from ebraille_sim.rl.env import ContactForceEnv

RESETS = 200


def _library_seed_node(entropy, **kwargs):
    return np.random.SeedSequence(entropy, **kwargs)


def _patches(variant: str) -> list:
    """(module, name, value) rebindings that put the library call in place of ``variant``'s copy."""
    from controllers.supervisor import envelope as supervisor
    from ebraille_sim.rl import env
    from ebraille_sim.scenarios import population
    if variant == "seeds":
        return [(env, "SeedNode", _library_seed_node), (population, "SeedNode", _library_seed_node)]
    if variant == "memo":
        return [(supervisor, "_envelope_memo", lambda *args: np.empty(0))]
    return []


class patched:
    """Context manager: the rebindings of :func:`_patches` for ``variant``, undone on exit."""

    def __init__(self, variant: str):
        self.items = _patches(variant)

    def __enter__(self):
        self.saved = [(m, n, getattr(m, n)) for m, n, _ in self.items]
        for m, n, v in self.items:
            setattr(m, n, v)

    def __exit__(self, *exc):
        for m, n, v in self.saved:
            setattr(m, n, v)


def _episode_record(seed: int) -> tuple:
    """Observations and rewards of 3 episodes of the default env (a fixed action law)."""
    env = ContactForceEnv()
    obs, _ = env.reset(seed=seed)
    rows, rews = [obs], []
    for k in range(1500):
        obs, r, te, tr, _ = env.step(np.array([0.9 * np.sin(0.013 * k) + 0.2], np.float32))
        rows.append(obs)
        rews.append(r)
        if te or tr:
            obs, _ = env.reset()
            rows.append(obs)
    return np.array(rows), np.array(rews)


def _reset_and_step_s(env, a) -> tuple[float, float]:
    """Mean reset time and mean step time (s, this thread's CPU time) of ``RESETS`` resets,
    each followed by 10 steps."""
    t_reset = t_step = 0.0
    clock = time.thread_time
    for _ in range(RESETS):
        t0 = clock()
        env.reset()
        t1 = clock()
        for _ in range(10):
            env.step(a)
        t_step += clock() - t1
        t_reset += t1 - t0
    return t_reset / RESETS, t_step / (10 * RESETS)


def reset_table(repeat: int) -> dict:
    """Median reset time (us and env steps) of the env as shipped and with each copy replaced."""
    variants = ["copies", "seeds", "memo", "all"]
    ref = [_episode_record(s) for s in (0, 11)]
    for v in variants[1:]:
        with patched(v) if v != "all" else _all():
            got = [_episode_record(s) for s in (0, 11)]
        for (o1, r1), (o2, r2) in zip(ref, got):
            assert np.array_equal(o1, o2) and np.array_equal(r1, r2), f"{v}: the trajectories moved"
    env = ContactForceEnv()
    env.reset(seed=0)
    a = np.full(1, 0.1, np.float32)
    times = {v: ([], []) for v in variants}
    for v in variants:                                     # warm-up (compilation, caches)
        with patched(v) if v != "all" else _all():
            _reset_and_step_s(env, a)
    for k in range(repeat):
        for v in variants[k % len(variants):] + variants[:k % len(variants)]:     # each first in turn
            with patched(v) if v != "all" else _all():
                r, s = _reset_and_step_s(env, a)
            times[v][0].append(r)
            times[v][1].append(s)
    out = {}
    for v in variants:
        r, s = statistics.median(times[v][0]), statistics.median(times[v][1])
        out[v] = {"reset_us": 1e6 * r, "step_us": 1e6 * s, "reset_in_steps": r / s}
    return out


class _all:
    """Every copy of the env's reset replaced at once."""

    def __enter__(self):
        self.ctx = [patched("seeds"), patched("memo")]
        for c in self.ctx:
            c.__enter__()

    def __exit__(self, *exc):
        for c in reversed(self.ctx):
            c.__exit__(*exc)


def micro_table(repeat: int) -> dict:
    """Per-call times (us) of each copy and its library call, on the inputs a reset gives them."""
    from controllers.supervisor import SupervisorConfig, _envelope_table, ENVELOPE_POINTS
    from ebraille_sim.base.seeds import SeedNode
    from ebraille_sim.physics.params import DeviceParams
    from ebraille_sim.scenarios.population import sample_devices
    from controllers.supervisor import envelope as supervisor

    def per_call(fn, n):
        best = float("inf")
        for _ in range(repeat):
            t0 = time.perf_counter()
            for _ in range(n):
                fn()
            best = min(best, (time.perf_counter() - t0) / n)
        return 1e6 * best

    out = {}

    def seeds(make):
        root = make(12345)
        kids = root.spawn(3)
        for c in kids:
            np.random.default_rng(c)
    out["seed_tree_3_children_3_generators"] = {"copy_us": per_call(lambda: seeds(SeedNode), 2000),
                                                "library_us": per_call(lambda: seeds(np.random.SeedSequence), 2000)}
    devices = sample_devices(3, 50) + [DeviceParams()]
    configs = [SupervisorConfig.for_device(d) for d in devices]
    table = np.empty(2 * ENVELOPE_POINTS)
    saved = supervisor._envelope_memo

    def envelopes():
        for c in configs:
            _envelope_table(c, table)
    with_memo = per_call(envelopes, 20) / len(configs)
    supervisor._envelope_memo = lambda *args: np.empty(0)
    try:
        without = per_call(envelopes, 20) / len(configs)
    finally:
        supervisor._envelope_memo = saved
    out["envelope_table"] = {"copy_us": with_memo, "library_us": without}
    for row in out.values():
        row["ratio_library_to_copy"] = row["library_us"] / row["copy_us"]
    return out


def csv_table(repeat: int, tmp) -> dict:
    """trace.csv of a 60 s steady_90wpm run, formatted in compiled code and in Python."""
    from ebraille_sim.scenarios.runner import run_scenario
    from ebraille_sim.tools import report
    from ebraille_sim.tools import csvformat
    res = run_scenario("steady_90wpm", seed=3)
    saved = csvformat.csv_body
    paths = {"copy": tmp / "copy.csv", "library": tmp / "python.csv"}

    def write(kind):
        if kind == "library":
            csvformat.csv_body = lambda columns: None        # the Python formatting of the same rows
        try:
            report.write_trace_csv(paths[kind], res.trace)
        finally:
            csvformat.csv_body = saved
    t_run = min(_timed(lambda: run_scenario("steady_90wpm", seed=3)) for _ in range(repeat))
    times = {k: min(_timed(lambda: write(k)) for _ in range(repeat)) for k in paths}
    assert paths["copy"].read_bytes() == paths["library"].read_bytes()
    rows = len(res.trace["t_s"])
    return {"rows": rows, "run_ms": 1e3 * t_run, "copy_ms": 1e3 * times["copy"],
            "library_ms": 1e3 * times["library"], "ratio_library_to_copy": times["library"] / times["copy"]}


def _timed(fn) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def butter_table(repeat: int) -> dict:
    """The hand design against scipy.signal.butter: one call each, and scipy.signal's import."""
    import scipy.signal
    from ebraille_sim.plant.lumped import _antialias_filter
    fc, fs = 120.0, 1000.0
    bb, aa = scipy.signal.butter(2, fc, fs=fs)
    mine = _antialias_filter.__wrapped__(fc, fs)
    assert list(mine[0]) == bb.tolist() and list(mine[1]) == aa.tolist()
    copy_us = 1e6 * min(_timed(lambda: _antialias_filter.__wrapped__(fc, fs)) for _ in range(50 * repeat))
    lib_us = 1e6 * min(_timed(lambda: scipy.signal.butter(2, fc, fs=fs)) for _ in range(50 * repeat))
    code = ("import time, ebraille_sim.plant.kernel, ebraille_sim.scenarios.runner, sys;"
            "had = 'scipy.signal' in sys.modules; t = time.perf_counter(); import scipy.signal;"
            "print(had, time.perf_counter() - t)")
    imports = []
    for _ in range(repeat):
        had, s = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                                check=True).stdout.split()
        imports.append(float(s))
    return {"copy_us": copy_us, "library_us": lib_us, "scipy_signal_loaded_by_the_runner": had == "True",
            "scipy_signal_import_ms": 1e3 * statistics.median(imports)}


def main(argv=None) -> int:
    import pathlib
    import tempfile
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    out = {"resets": reset_table(args.repeat), "calls": micro_table(args.repeat)}
    with tempfile.TemporaryDirectory() as d:
        out["trace_csv"] = csv_table(args.repeat, pathlib.Path(d))
    out["butter"] = butter_table(args.repeat)
    r0 = out["resets"]["copies"]
    print(f"env reset, 200 Hz (median of {args.repeat} rounds of {RESETS}):")
    for v, row in out["resets"].items():
        print(f"  {v:8s} {row['reset_us']:7.0f} us  {row['reset_in_steps']:6.1f} steps  "
              f"({row['reset_us'] - r0['reset_us']:+.0f} us against the copies)")
    print("per call (best of rounds):")
    for k, row in out["calls"].items():
        print(f"  {k:36s} copy {row['copy_us']:8.2f} us  library {row['library_us']:8.2f} us  "
              f"x{row['ratio_library_to_copy']:.2f}")
    c = out["trace_csv"]
    print(f"trace.csv of steady_90wpm, 60 s ({c['rows']} rows): compiled {c['copy_ms']:.1f} ms, Python "
          f"{c['library_ms']:.1f} ms (x{c['ratio_library_to_copy']:.1f}); the run itself {c['run_ms']:.1f} ms")
    b = out["butter"]
    print(f"anti-alias design: by hand {b['copy_us']:.1f} us, scipy.signal.butter {b['library_us']:.1f} us "
          f"(once per cutoff and rate); import scipy.signal after the runner: {b['scipy_signal_import_ms']:.0f} ms"
          f" (already loaded: {b['scipy_signal_loaded_by_the_runner']})")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(out, fh, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
