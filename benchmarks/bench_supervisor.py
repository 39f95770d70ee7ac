"""Cost of the safety supervisor's compiled period per control period, apart from the plant.

Runs ``steady_90wpm`` supervised (the default) with the PID once with its full trace and takes what the
controller saw in every control period: the fed-back estimate, the setpoint and the motor
current measured at the end of the previous period.  Those periods are then replayed in one
compiled loop without the plant, twice from a fresh start: through the PID alone, and through
the loop engine's command (:func:`ebraille_sim.plant.engine.command`: ``supervise_begin``, the
PID's step, ``supervise_end``, the resets they ask for).
The supervised replay must give the run's commands to the last bit (checked); the difference
of the two loops over the number of periods is the supervisor's cost per control period.

Times are this thread's CPU time (``time.thread_time``), which other jobs on the machine
disturb less than wall time; the shortest and the median of ``--repeat`` replays are printed.

Run:  python benchmarks/bench_supervisor.py [--repeat 25] [--duration 60]
"""
from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

import ebraille_sim
from controllers.compiled import compiled_form
from ebraille_sim.base.compiled import njit
from ebraille_sim.plant.engine import command
from ebraille_sim.plant.layout import S
from ebraille_sim.scenarios import runner

SCENARIO = "steady_90wpm"
CONTROLLER = "pid"
"""The inner controller of the replays: the PID, which reads no motor current (the trace
records the plant's current, not the firmware's reading that a current-reading controller
such as the default ``pid_dob`` is fed)."""


@njit(cache=True, _nrt=False)
def _replay(kind, cstate, cparams, supervised, sv, cfg, f_in, sp, cur_in, dt_s, out):
    """The engine's command over recorded inputs, without the plant; the commands go to ``out``.

    Compiled without Numba's reference counting, as the loop engine's :func:`~ebraille_sim.plant.engine.run`
    is: with it, each period would also count references to the arrays it hands on (atomic
    operations that the run does not make: 42 % of a profile's samples of the supervised replay)."""
    for k in range(f_in.shape[0]):
        out[k] = command(kind, cstate, cparams, 0.0, supervised, sv, cfg, f_in[k], sp[k], dt_s, cur_in[k])


def _recorded(duration_s: float):
    """``(estimate, setpoint, current, command)`` per control period of the supervised run."""
    tr = ebraille_sim.run_scenario(SCENARIO, CONTROLLER, duration_s=duration_s).trace
    spec, _, run, _ = runner.prepare_run(SCENARIO, CONTROLLER, duration_s=duration_s)
    f0 = runner._plant_for(spec, run, "lumped").state[0][S.force_est_n]
    f_in = np.concatenate([[f0], tr["force_est_n"][:-1]])
    cur_in = np.concatenate([[0.0], tr["motor_current_a"][:-1]])
    return f_in, np.asarray(tr["setpoint_n"], float), cur_in, np.asarray(tr["command_v"], float), run.dt_s


def _fresh(duration_s: float, f0: float, sp0: float, dt_s: float):
    """The run's PID and supervisor as :func:`ebraille_sim.scenarios.runner._closed_loop` starts them."""
    spec, _, _, ctrl = runner.prepare_run(SCENARIO, CONTROLLER, duration_s=duration_s)
    wrapped = runner.wrap_controller(spec, ctrl, dt_s, True)
    wrapped.reset(force_est_n=f0, setpoint_n=sp0, command_v=0.0)
    kind, cstate, cparams = compiled_form(ctrl)
    sv, cfg = wrapped.compiled()
    return kind, cstate, cparams, sv, cfg


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=25)
    ap.add_argument("--duration", type=float, default=60.0)
    a = ap.parse_args(argv)
    f_in, sp, cur_in, cmd, dt = _recorded(a.duration)
    n = f_in.size
    out = np.zeros(n)
    times = {False: [], True: []}
    for rep in range(max(1, a.repeat) + 1):
        for supervised in (False, True):
            kind, cstate, cparams, sv, cfg = _fresh(a.duration, float(f_in[0]), float(sp[0]), dt)
            t0 = time.thread_time()
            _replay(kind, cstate, cparams, supervised, sv, cfg, f_in, sp, cur_in, dt, out)
            if rep:                                   # the first round compiles or loads the cache
                times[supervised].append(time.thread_time() - t0)
            if supervised and not np.array_equal(out, cmd):
                raise SystemExit("the supervised replay does not give the run's commands")
    print(f"{SCENARIO}, {a.duration:g} s, {n} control periods, {a.repeat} replays (thread CPU time)")
    for stat, fn in (("shortest", min), ("median", statistics.median)):
        pid, sup = fn(times[False]), fn(times[True])
        print(f"{stat:>8}: PID alone {pid * 1e3:.2f} ms ({pid / n * 1e9:.0f} ns/period), supervised "
              f"{sup * 1e3:.2f} ms: the supervisor {(sup - pid) / n * 1e9:.0f} ns per control period")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
