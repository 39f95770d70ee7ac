"""Speed of one scenario run: the compiled loop against the per-period loop and two compiled references.

For 60 s of ``steady_90wpm`` with the default controller (``pid_dob``, compiled), without and with the safety supervisor
(``run_scenario(..., supervised=False)`` and the default), this reports, as the median of
``--repeat`` rounds in one process:

* the wall time of the whole call and of its control loop, with the loop in one call of the
  loop engine (:func:`ebraille_sim.plant.engine.run`) and with one Python iteration per control
  period (the shim of Python controllers, :func:`ebraille_sim.scenarios.runner.python_periods`);
* three references measured in the same rounds:

  - the all-compiled loop: physics, estimator, PID and trace of the same run in one compiled
    call (the control loop of the unsupervised compiled run, without building the inputs,
    the plant or the metrics); a supervised run is also compared with its own control loop
    (the same work with the supervisor's compiled period in it);
  - the kernel alone: the same number of physics steps in one call of
    :func:`ebraille_sim.plant.kernel.advance` with the command held, i.e. the plant without
    any controller, which no loop can beat;
  - the kernel per period: the same steps in one call of ``kernel.advance`` per control
    period from one compiled loop, the command held (what a loop that sets a command every
    period cannot avoid).

The last line splits ``run_scenario``'s time (supervised, the default) over the kernel alone
into its loop and the rest (inputs, plant, metrics).

Each round times every row once, one after the other, and the ratios are those of each round's
own times (their median is printed): on a shared machine the speed of the whole machine
changes by up to 1.6 times from one second to the next, and rows timed seconds apart would
compare two machines.

Run:  python benchmarks/bench_compiled_loop.py [--repeat 5] [--duration 60] [--json FILE]
"""
from __future__ import annotations

import argparse
import json
import platform
import statistics
import time

import numpy as np

import ebraille_sim
from ebraille_sim.base.compiled import njit
from ebraille_sim.plant import kernel
from ebraille_sim.plant.layout import S, U
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


@njit(cache=True)
def _advance_periods(s, p, u, n_sub, n_periods):
    for _ in range(n_periods):
        kernel.advance(s, p, u, n_sub)


def _kernel_per_period(duration_s: float) -> float:
    """The same physics steps as :func:`_kernel_only`, one call of ``kernel.advance`` per control
    period from one compiled loop (the command held): the least any loop that sets a command
    per period can cost."""
    spec, _, run, _ = runner.prepare_run("steady_90wpm", duration_s=duration_s)
    plant = runner._plant_for(spec, run, "lumped")
    plant.inputs[0, U.command_v] = 1.0
    t0 = time.perf_counter()
    _advance_periods(plant.state[0], plant.params[0], plant.inputs[0], plant.substeps, run.n_steps)
    return time.perf_counter() - t0


@njit(cache=True)
def _replay_periods(s, p, u, n_sub, slots, table, commands):
    for k in range(commands.shape[0]):
        for j in range(slots.shape[0]):
            u[slots[j]] = table[j, k]
        u[U.command_v] = commands[k]
        kernel.advance(s, p, u, n_sub)


def _replay_inputs(duration_s: float) -> tuple:
    """What :func:`_kernel_replay` replays: the plant of the run, its varying inputs per control
    period and the commands the supervised run applied (``run_scenario``'s trace), with the
    run's true force at its end (the replay must end on it)."""
    res = ebraille_sim.run_scenario("steady_90wpm", duration_s=duration_s)
    spec, _, run, _ = runner.prepare_run("steady_90wpm", duration_s=duration_s)
    plant = runner._plant_for(spec, run, "lumped")
    names = list(run.profiles)
    slots = np.array([U[name] for name in names], dtype=np.int64)
    table = np.zeros((len(names), run.n_steps))
    for j, name in enumerate(names):
        table[j] = np.asarray(run.profiles[name], dtype=float)[:run.n_steps]
    commands = np.ascontiguousarray(res.trace["command_v"], dtype=float)
    return plant, slots, table, commands, float(res.trace["force_true_n"][-1])


def _kernel_replay(replay: tuple) -> float:
    """The same physics substeps as the supervised run, replayed without any controller: one
    compiled loop that writes each period's inputs and the command the run applied, and calls
    ``kernel.advance`` (the plant moves as it did in the run; with the command held it sits at
    rest, and a body at rest skips the friction curve's ``exp``)."""
    plant, slots, table, commands, f_end = replay
    s, p, u = plant.state[0].copy(), plant.params[0].copy(), plant.inputs[0].copy()
    t0 = time.perf_counter()
    _replay_periods(s, p, u, plant.substeps, slots, table, commands)
    wall = time.perf_counter() - t0
    if s[S.contact_force_n] != f_end:
        raise RuntimeError(f"the replay ended on {s[S.contact_force_n]!r} N, the run on {f_end!r} N")
    return wall


ROWS = (("compiled loop", True, False), ("per-period loop", False, False),
        ("compiled, supervised", True, True), ("per-period, supervised", False, True))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--duration", type=float, default=60.0)
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    if a.repeat < 1 or not a.duration > 0:
        ap.error("--repeat must be at least 1 and --duration positive")
    for compiled in (True, False):                       # compile / load every cache first
        _run(0.2, compiled)
        _run(0.2, compiled, True)
    _kernel_only(0.2)
    _kernel_per_period(0.2)
    _kernel_replay(_replay_inputs(0.2))
    replay = _replay_inputs(a.duration)
    rounds = []
    for _ in range(a.repeat):
        r = {label: _run(a.duration, compiled, supervised) for label, compiled, supervised in ROWS}
        r["kernel alone"] = _kernel_only(a.duration)
        r["kernel per period"] = _kernel_per_period(a.duration)
        r["kernel replay"] = _kernel_replay(replay)
        rounds.append(r)
    med = statistics.median
    rows = {label: {"total_s": med(r[label][0] for r in rounds), "loop_s": med(r[label][1] for r in rounds)}
            for label, _, _ in ROWS}
    bound = med(r["kernel alone"] for r in rounds)
    loop_ref = med(r["compiled loop"][1] for r in rounds)
    of_loop = {label: med(r["compiled loop"][1] / r[label][0] for r in rounds) for label, _, _ in ROWS}
    of_kernel = {label: med(r["kernel alone"] / r[label][0] for r in rounds) for label, _, _ in ROWS}
    of_own = {label: med(r[label][1] / r[label][0] for r in rounds) for label, _, _ in ROWS}
    doc = {"machine": f"{platform.machine()} python {platform.python_version()}", "duration_s": a.duration,
           "rows": rows, "kernel_only_s": bound, "all_compiled_loop_s": loop_ref,
           "all_compiled_loop_over_total": of_loop, "own_loop_over_total": of_own, "kernel_over_total": of_kernel,
           "rounds": [{k: list(v) if isinstance(v, tuple) else v for k, v in r.items()} for r in rounds]}
    print(f"steady_90wpm, {a.duration:g} s, default controller, medians of {a.repeat} rounds ({doc['machine']})")
    print(f"{'':>22} {'total s':>8} {'loop s':>8} {'own loop / total':>17} {'all-compiled / total':>21} "
          f"{'kernel / total':>15}")
    for label, r in rows.items():
        print(f"{label:>22} {r['total_s']:>8.3f} {r['loop_s']:>8.3f} {of_own[label]:>17.2f} {of_loop[label]:>21.2f} "
              f"{of_kernel[label]:>15.2f}")
    print(f"{'all-compiled loop':>22} {'':>8} {loop_ref:>8.3f}")
    print(f"{'kernel alone':>22} {'':>8} {bound:>8.3f}")
    print(f"{'kernel per period':>22} {'':>8} {med(r['kernel per period'] for r in rounds):>8.3f}")
    print(f"{'kernel replay':>22} {'':>8} {med(r['kernel replay'] for r in rounds):>8.3f}")
    sup = "compiled, supervised"
    over = {"total": med(r[sup][0] / r["kernel alone"] for r in rounds),
            "loop": med(r[sup][1] / r["kernel alone"] for r in rounds),
            "outside_loop": med((r[sup][0] - r[sup][1]) / r["kernel alone"] for r in rounds),
            "kernel_per_period": med(r["kernel per period"] / r["kernel alone"] for r in rounds)}
    over_replay = {"total": med(r[sup][0] / r["kernel replay"] for r in rounds),
                   "loop": med(r[sup][1] / r["kernel replay"] for r in rounds),
                   "outside_loop": med((r[sup][0] - r[sup][1]) / r["kernel replay"] for r in rounds)}
    doc["supervised_over_kernel_replay"] = over_replay
    doc["kernel_replay_s"] = med(r["kernel replay"] for r in rounds)
    doc["supervised_over_kernel"] = over
    print(f"run_scenario (supervised) / kernel alone: {over['total']:.2f}x (target <= 1.3) = its loop "
          f"{over['loop']:.2f}x + outside the loop (inputs, plant, metrics) {over['outside_loop']:.2f}x; "
          f"the kernel called once per period alone {over['kernel_per_period']:.2f}x")
    print(f"run_scenario (supervised) / the kernel replaying the run's inputs: {over_replay['total']:.2f}x "
          f"(target <= 1.3) = its loop {over_replay['loop']:.2f}x + outside the loop "
          f"{over_replay['outside_loop']:.2f}x")
    print(f"per-period / compiled loop: {rows['per-period loop']['loop_s'] / rows['compiled loop']['loop_s']:.2f}x "
          f"unsupervised, {rows['per-period, supervised']['loop_s'] / rows['compiled, supervised']['loop_s']:.2f}x "
          f"supervised; run_scenario (supervised) = {of_own['compiled, supervised']:.2f} of its own compiled loop, "
          f"{of_loop['compiled, supervised']:.2f} of the unsupervised all-compiled loop, "
          f"{of_kernel['compiled, supervised']:.2f} of the kernel alone")
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(doc, fh, indent=2)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
