"""A whole scenario run of the lumped plant in one compiled call.

:func:`run_loop` does what the per-period loop of :func:`ebraille_sim.scenarios.runner._closed_loop`
does, for a controller with a compiled form (:mod:`controllers.compiled`): per control period
it writes the time-varying plant inputs, steps the controller (dispatched on its kind) on
the fed-back force, the setpoint and the motor current measured at the end of the previous
period (0.0 before the first), advances the plant by one period
(:func:`ebraille_sim.plant.kernel.advance`), and stores the true and estimated force of every
period and the kept trace columns (:data:`KEPT`) of every ``every``-th.  The operations are
the same, in the same order, so the trace is the per-period loop's to the last bit.

Supervised runs: with ``supervised`` true, every period goes through the safety supervisor's
compiled hooks ``supervise_begin`` and ``supervise_end`` of :mod:`controllers.supervisor`
(the same functions the Python :class:`controllers.supervisor.Supervisor` calls), which decide whether the inner controller runs, with which setpoint, and when it is
reset.  The hooks are module-level compiled functions, bound when this module is compiled,
so the loop stays one cacheable function.

Status codes returned by :func:`run_loop`: :data:`OK`; :data:`BAD_CONTROLLER_INPUT` (an
unsupervised controller would have been handed a non-finite force or setpoint, which its
``update`` rejects); :data:`BAD_COMMAND` (a non-finite command, which the plant rejects).  The
runner turns those into the errors the per-period loop raises.
"""
from __future__ import annotations

import math

import numpy as np

from controllers.compiled import controller_reset, controller_step, record
from ebraille_sim.base.compiled import njit
from ebraille_sim.plant.kernel import advance
from ebraille_sim.plant.layout import S, U

from controllers.supervisor import supervise_begin, supervise_end

__all__ = ["KEPT", "ROW", "OK", "BAD_CONTROLLER_INPUT", "BAD_COMMAND", "run_loop", "run_rows", "profile_arrays"]

KEPT = ("command_v", "fsr_voltage_v", "motor_current_a", "board_pos_m", "energy_j")
"""Rows of the ``kept`` array of :func:`run_loop`, in order (trace column names)."""

OK = 0
BAD_CONTROLLER_INPUT = 1
BAD_COMMAND = 2

ROW = record("KeptRows", KEPT)
"""Row of each kept column in ``kept`` (``ROW.command_v`` ...)."""


@njit(cache=True)
def run_loop(state, params, inputs, n_sub, kind, cstate, cparams, supervised, sv_state, sv_cfg,
             setpoint_n, dt_s, i_feedback, profile_slots, profiles, every, f_true, f_est, kept):
    """Run ``len(f_true)`` control periods of one device; return ``(status, period, value)``.

    Parameters
    ----------
    state, params, inputs : ndarray, 1-D
        The plant's state, parameter and input vectors (:mod:`ebraille_sim.plant.layout`),
        modified in place.
    n_sub : int
        Physics steps per control period.
    kind : int
        The controller's kind (:data:`controllers.compiled.KIND_PID`, ``KIND_LQG``).
    cstate, cparams : ndarray, 1-D
        The controller's live state and parameter vectors (state modified in place).
    supervised : bool
        Go through the supervisor hooks (``sv_state``, ``sv_cfg``: its live vectors; ignored
        when false).
    setpoint_n : ndarray, shape (n,)
        Setpoint per period, N.
    dt_s : float
        Control period, s.
    i_feedback : int
        State slot fed back as the force (``S.force_est_n``, or ``S.contact_force_n`` for a
        controller fed the true force).
    profile_slots : ndarray of int64, shape (m,)
        Input slots that vary over the run.
    profiles : ndarray, shape (m, n)
        Their values per period.
    every : int
        Keep the :data:`KEPT` columns at the end of periods ``every - 1, 2 every - 1, ...``;
        0 keeps none.
    f_true, f_est : ndarray, shape (n,)
        Filled with the true and estimated force at the end of every period, N.
    kept : ndarray, shape (len(KEPT), n // every)
        Filled with the kept columns.

    Returns
    -------
    tuple of (int, int, float)
        :data:`OK` with the number of periods run, or an error status, the period it
        happened in (the state is that at the start of that period) and the offending
        command (:data:`BAD_COMMAND`).
    """
    n = f_true.shape[0]
    f = state[i_feedback]
    cur = 0.0
    due = every - 1 if every > 0 else -1
    q = 0
    for k in range(n):
        for j in range(profile_slots.shape[0]):
            inputs[profile_slots[j]] = profiles[j, k]
        sp = setpoint_n[k]
        if supervised:
            code, c, sp_inner = supervise_begin(sv_state, sv_cfg, f, sp, dt_s, cur)
            if code == 1:
                u_inner = controller_step(kind, cstate, cparams, f, sp_inner, dt_s, cur)
                code2, c, reset_cmd = supervise_end(sv_state, sv_cfg, u_inner, f, sp, dt_s, cur)
                if code2 == 1:
                    controller_reset(kind, cstate, cparams, f, sp_inner, reset_cmd)
            elif code == 2:
                controller_reset(kind, cstate, cparams, f, sp_inner, 0.0)
        else:
            if not (math.isfinite(f) and math.isfinite(sp)):
                return BAD_CONTROLLER_INPUT, k, 0.0
            c = controller_step(kind, cstate, cparams, f, sp, dt_s, cur)
        if not math.isfinite(c):
            return BAD_COMMAND, k, c
        inputs[U.command_v] = c
        advance(state, params, inputs, n_sub)
        f = state[i_feedback]
        cur = state[S.current_a]
        f_true[k] = state[S.contact_force_n]
        f_est[k] = state[S.force_est_n]
        if k == due:
            kept[ROW.command_v, q] = c
            kept[ROW.fsr_voltage_v, q] = state[S.fsr_voltage_v]
            kept[ROW.motor_current_a, q] = cur
            kept[ROW.board_pos_m, q] = state[S.board_pos_m]
            kept[ROW.energy_j, q] = state[S.energy_j]
            q += 1
            due += every
    return OK, n, 0.0


@njit(cache=True)
def run_rows(states, params, inputs, n_sub, kinds, cstates, cparams, supervised, sv_states, sv_cfgs,
             setpoints, dt_s, i_feedback, profile_slots, profile_counts, profiles, every, f_true, f_est, kept,
             status, periods, values):
    """:func:`run_loop` of several independent runs (rows) in one compiled call.

    Row ``r`` is the run of :func:`run_loop` with the ``r``-th row of every per-row array;
    the rows share the number of periods, the control period, the substeps and the fed-back
    slot.  Each row is the very same computation as a call of :func:`run_loop` of its own,
    so its trace is that call's to the last bit.

    Parameters
    ----------
    states, params, inputs : ndarray, shape (m, ...)
        The plants' state, parameter and input rows (modified in place).
    n_sub : int
        Physics steps per control period.
    kinds : ndarray of int64, shape (m,)
        Controller kind per row.
    cstates, cparams : ndarray, shape (m, k)
        Controller state and parameter vectors, zero-padded to a common length.
    supervised : ndarray of bool, shape (m,)
        Whether each row goes through the supervisor hooks.
    sv_states, sv_cfgs : ndarray, shape (m, k)
        The supervisors' state and configuration vectors, zero-padded (unused rows: zeros).
    setpoints : ndarray, shape (m, n)
        Setpoint per row and period, N.
    dt_s : float
        Control period, s.
    i_feedback : int
        State slot fed back as the force.
    profile_slots : ndarray of int64, shape (m, p)
        Varying input slots per row (the first ``profile_counts[r]`` are used).
    profile_counts : ndarray of int64, shape (m,)
    profiles : ndarray, shape (m, p, n)
        Their values per period.
    every : int
        As :func:`run_loop` (0 keeps no trace column).
    f_true, f_est : ndarray, shape (m, n)
        Filled with the true and estimated force of every period, N.
    kept : ndarray, shape (m, len(KEPT), n // every)
        Filled with the kept columns.
    status, periods : ndarray of int64, shape (m,)
        Filled with each row's status and period (:func:`run_loop`'s first two returns).
    values : ndarray, shape (m,)
        Filled with each row's offending command.
    """
    for r in range(states.shape[0]):
        c = profile_counts[r]
        st, k, v = run_loop(states[r], params[r], inputs[r], n_sub, kinds[r], cstates[r], cparams[r],
                            supervised[r], sv_states[r], sv_cfgs[r], setpoints[r], dt_s, i_feedback,
                            profile_slots[r, :c], profiles[r, :c], every, f_true[r], f_est[r], kept[r])
        status[r] = st
        periods[r] = k
        values[r] = v


def profile_arrays(profiles: dict, n: int) -> tuple[np.ndarray, np.ndarray]:
    """``(slots, table)`` for :func:`run_loop` from a run's ``{input name: per-period array}``
    (the array whose rows they are when they are one's, as a run's inputs are: no copy)."""
    from ebraille_sim.scenarios.inputs import profile_table
    names = list(profiles)
    slots = np.array([U[name] for name in names], dtype=np.int64)
    table = profile_table(profiles, n)
    if table is not None:
        return slots, table
    table = np.zeros((len(names), n))
    for j, name in enumerate(names):
        table[j] = np.asarray(profiles[name], dtype=float)[:n]
    return slots, table
