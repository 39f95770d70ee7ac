"""The loop engine: the one closed-loop body of the simulator, compiled.

One control period of one device is :func:`period`: write the period's varying plant inputs,
read what the firmware measured at the end of the previous period (the fed-back force and the
motor current), let the safety supervisor and the controller decide the motor command
(:func:`command`: the supervisor's begin -> inner controller -> end protocol, composed here and
nowhere else in compiled code), check it, hold it and advance the physics
(:func:`ebraille_sim.plant.kernel.advance`).

Everything that closes the loop calls it:

* :func:`run` steps ``m`` independent rows (devices) for ``k`` periods each and records the
  true and estimated force of every period and the trace columns :data:`KEPT` of every
  ``every``-th.  The scenario runner calls it for one run (one row, all periods), for a batch
  of runs (many rows) and, with the command of a Python controller handed in, for one period
  at a time (:func:`ebraille_sim.scenarios.runner.python_periods`, the one shim through which
  Python controllers and Python plants enter the loop).
* The Gymnasium env (:mod:`ebraille_sim.rl.env`) and its vector form call :func:`period` with
  the agent's action as an external command (``k = 1``), inside their own compiled step that
  then computes the reward and the observation; the residual env calls :func:`policy_period`
  with the agent's action handed to the policy.

The controller of a row is a kind of :mod:`controllers.compiled`: a built-in compiled
controller (:data:`~controllers.compiled.KIND_PID`, :data:`~controllers.compiled.KIND_LQG`,
:data:`~controllers.compiled.KIND_DOB`) stepped on its state and parameter vectors, or :data:`~controllers.compiled.KIND_EXTERNAL`, a
command handed in per period; one row may run a residual policy on its compiled design
(:func:`policy_period`, the policy's arrays handed to :func:`run` apart from the rows').  The
supervisor is optional per row (its state and configuration vectors,
:meth:`controllers.supervisor.Supervisor.compiled`).

Status codes (:func:`period`, :func:`run`): :data:`OK`; :data:`BAD_CONTROLLER_INPUT` (an
unsupervised built-in controller would have been handed a non-finite force or setpoint, which
its ``update`` rejects); :data:`BAD_COMMAND` (a non-finite command, which the plant rejects).
A row that fails stops at that period, its state that at the period's start.

Examples
--------
One row, the default PID unsupervised, 0.2 s at 200 Hz:

>>> import numpy as np
>>> from controllers import make
>>> from ebraille_sim.physics.params import DeviceParams
>>> from ebraille_sim.plant.backends import make_plant
>>> from ebraille_sim.plant.layout import S
>>> plant = make_plant([DeviceParams()], seeds=[1])
>>> kind, cs, cp = make("pid").compiled()
>>> rows = Rows.single(plant, kind, cs, cp, setpoint_n=np.full(40, 1.0))
>>> run(*rows.arguments(0, 40))
>>> int(rows.status[0]), rows.f_true.shape
(0, (1, 40))
"""
from __future__ import annotations

import math

import numpy as np

from controllers.compiled import KIND_EXTERNAL, controller_reset, controller_resume, controller_step, record
from controllers.features import Z_PREV_ACTION, _clip
from controllers.residual import (MODE_MLP, P_ACTION, P_FIRST, P_LIMIT, P_MODE, P_RESIDUAL, P_SUPPLY, advance_frame,
                                  mlp_action, restart_frames)
from controllers.supervisor import CF, supervise_begin, supervise_end
from ebraille_sim.base.compiled import entry_point, njit
from ebraille_sim.plant.kernel import advance
from ebraille_sim.plant.layout import S, U

__all__ = ["KEPT", "ROW", "OK", "BAD_CONTROLLER_INPUT", "BAD_COMMAND", "INNER_SKIPPED", "INNER_RAN", "INNER_RESTARTED",
           "Rows", "command", "inner_command", "period", "residual_period", "policy_period", "run", "NO_POLICY"]

KEPT = ("command_v", "fsr_voltage_v", "motor_current_a", "board_pos_m", "energy_j")
"""Rows of the ``kept`` array of :func:`run`, in order (trace column names)."""

ROW = record("KeptRows", KEPT)
"""Row of each kept column in ``kept`` (``ROW.command_v`` ...)."""

OK = 0
BAD_CONTROLLER_INPUT = 1
BAD_COMMAND = 2

NO_POLICY = (np.zeros(0), np.zeros(0), np.zeros((0, 0), dtype=np.float32), np.zeros(0, dtype=np.float32),
             np.zeros(0), np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.float32), np.zeros(0),
             np.zeros((0, 0), dtype=np.float32), np.zeros(0, dtype=np.float32))
"""The ``policy`` argument of :func:`run` when no row runs a residual policy: empty arrays of the
types of :meth:`controllers.residual.ResidualPolicy.compiled_policy`'s (one compiled ``run``
for both)."""

INNER_SKIPPED = 0
"""The supervisor decided the period's command without calling the inner controller."""
INNER_RAN = 1
"""The inner controller proposed the period's command."""
INNER_RESTARTED = 2
"""The supervisor reset or resumed the inner controller in the period (after it ran, or not)."""


@njit(cache=True, inline="always")
def command(kind, cstate, cparams, u_ext, supervised, sv, cfg, f, sp, dt, cur):
    """The motor command of one period, V: the supervisor's period around the inner controller.

    With ``supervised`` the supervisor runs its detectors (:func:`controllers.supervisor.supervise_begin`);
    when it lets the inner controller run, the controller of ``kind`` proposes a command on the
    supervisor's inner setpoint (``u_ext`` for :data:`~controllers.compiled.KIND_EXTERNAL`) and
    the supervisor shapes it (:func:`~controllers.supervisor.supervise_end`); when it asks for a
    bumpless reset (a finite command again, the first contact the search found) the built-in
    controller is reset, and after regained contact it resumes
    (:func:`~controllers.compiled.controller_resume`: its integrator not below 0 V).
    Without the supervisor the command is the controller's (or ``u_ext``).  ``cur`` is the
    measured motor current (NaN: none).
    """
    return inner_command(kind, cstate, cparams, u_ext, False, supervised, sv, cfg, f, sp, dt, cur)[0]


@njit(cache=True, inline="always")
def inner_command(kind, cstate, cparams, u_ext, residual, supervised, sv, cfg, f, sp, dt, cur):
    """:func:`command`, with ``residual``: the inner controller's command is the built-in
    controller's plus ``u_ext`` (a correction on a design, :class:`controllers.residual.ResidualPolicy`),
    shaped by the supervisor as the sum.

    Returns ``(u, inner, sp_inner)``: the command, what became of the inner controller
    (:data:`INNER_SKIPPED`, :data:`INNER_RAN`, :data:`INNER_RESTARTED`: reset or resumed by
    the supervisor, after running or not) and the setpoint it was handed (``sp`` without the
    supervisor).
    """
    if supervised:
        code, u, sp_inner = supervise_begin(sv, cfg, f, sp, dt, cur)
        inner = INNER_SKIPPED
        if code == 1:
            inner = INNER_RAN
            if kind == KIND_EXTERNAL:
                u_inner = u_ext
            else:
                u_inner = controller_step(kind, cstate, cparams, f, sp_inner, dt, cur)
                if residual:
                    u_inner = u_inner + u_ext
            code2, u, reset_cmd = supervise_end(sv, cfg, u_inner, f, sp, dt, cur)
            if code2 == 1:
                inner = INNER_RESTARTED
                if kind != KIND_EXTERNAL:
                    controller_reset(kind, cstate, cparams, f, sp_inner, reset_cmd)
            elif code2 == 2:
                inner = INNER_RESTARTED
                if kind != KIND_EXTERNAL:
                    controller_reset(kind, cstate, cparams, f, sp_inner, 0.0)
        elif code == 2:
            inner = INNER_RESTARTED
            if kind != KIND_EXTERNAL:
                controller_resume(kind, cstate, cparams, f, sp_inner)
        return u, inner, sp_inner
    if kind == KIND_EXTERNAL:
        return u_ext, INNER_RAN, sp
    u = controller_step(kind, cstate, cparams, f, sp, dt, cur)
    if residual:
        u = u + u_ext
    return u, INNER_RAN, sp


@njit(cache=True, inline="always")
def period(state, params, inputs, n_sub, kind, cstate, cparams, u_ext, u_max, supervised, sv, cfg, sp, dt,
           i_feedback, slots, table, k):
    """One closed-loop control period ``k`` of one device; returns ``(status, command_v)``.

    Writes period ``k``'s varying inputs (``inputs[slots[j]] = table[j, k]``), reads the
    fed-back force (state slot ``i_feedback``) and the firmware's reading of the motor current
    (``S.current_meas_a``, through the board's sensing chain) at the end of the previous period, decides the command (:func:`command`), clips it to ``+/- u_max`` (an env's
    action range; ``inf`` for none: the driver clips to its supply inside the plant), holds it
    and advances the plant by ``n_sub`` physics steps.  A non-finite command, or an unsupervised
    built-in controller handed a non-finite input, returns its status with the plant not
    advanced.
    """
    out = residual_period(state, params, inputs, n_sub, kind, cstate, cparams, u_ext, u_max, False, supervised, sv,
                          cfg, sp, dt, i_feedback, slots, table, k)
    return out[0], out[1]


@njit(cache=True, inline="always")
def residual_period(state, params, inputs, n_sub, kind, cstate, cparams, u_ext, u_max, residual, supervised, sv,
                    cfg, sp, dt, i_feedback, slots, table, k):
    """:func:`period`, with ``residual`` the command of :func:`inner_command` (the built-in
    controller's plus the correction ``u_ext``, inside the supervisor).

    Returns ``(status, command_v, inner, sp_inner, f, cur)``: besides :func:`period`'s, what
    became of the inner controller and the setpoint it was handed (:func:`inner_command`), and
    the force and current the period read (``cur`` NaN when the reading is not finite).
    """
    for j in range(slots.shape[0]):
        inputs[int(slots[j])] = table[j, k]
    f = state[i_feedback]
    cur = state[S.current_meas_a]             # the firmware's reading (physics.current_sense), not the plant's
    if not math.isfinite(cur):
        cur = math.nan
    if not supervised and kind != KIND_EXTERNAL and not (math.isfinite(f) and math.isfinite(sp)):
        return BAD_CONTROLLER_INPUT, 0.0, INNER_SKIPPED, sp, f, cur
    u, inner, sp_inner = inner_command(kind, cstate, cparams, u_ext, residual, supervised, sv, cfg, f, sp, dt, cur)
    if not math.isfinite(u):
        return BAD_COMMAND, u, inner, sp_inner, f, cur
    if u > u_max:
        u = u_max
    elif u < -u_max:
        u = -u_max
    inputs[U.command_v] = u
    advance(state, params, inputs, n_sub)
    return OK, u, inner, sp_inner, f, cur


@njit(cache=True, inline="always")
def policy_period(state, params, inputs, n_sub, kind, cstate, cparams, supervised, sv, cfg, sp, dt, i_feedback,
                  slots, table, k, p, z, frames, obs, c, layers, weights, zc, fc, buf):
    """One period of a residual policy (:class:`controllers.residual.ResidualPolicy`, its arrays
    from :meth:`~controllers.residual.ResidualPolicy.compiled_policy`) on its design's compiled
    controller, inside the supervisor when ``supervised``; returns ``(status, command_v)``.

    The correction is the action handed in (``p[P_ACTION]``) or the MLP actor's on the frame the
    period pushes (computed on copies first: the policy advances only when the supervisor calls
    it); :func:`residual_period` runs the period; then the policy does what its ``update``,
    ``reset``/``resume`` and ``applied`` do when the supervisor calls them: the frame pushed and
    the action held when it ran, the history forgotten when it was restarted, the command that
    left the supervisor kept as the previous one.
    """
    first = p[P_FIRST] != 0.0
    if p[P_MODE] == MODE_MLP:
        f0 = state[i_feedback]
        cur0 = state[S.current_meas_a]
        if not math.isfinite(cur0):
            cur0 = math.nan
        sp0 = sp
        if supervised and cfg[CF.sp_max_n] < sp:
            sp0 = cfg[CF.sp_max_n]
        for i in range(z.shape[0]):                # copies without a temporary: run allocates nothing
            zc[i] = z[i]
        for i in range(frames.shape[0]):
            for j in range(frames.shape[1]):
                fc[i, j] = frames[i, j]
        advance_frame(zc, fc, c, f0, sp0, cur0, dt, first, p[P_RESIDUAL], obs)
        a = mlp_action(layers, weights, obs, buf)
    else:
        a = p[P_ACTION]
    status, u, inner, sp_inner, f, cur = residual_period(state, params, inputs, n_sub, kind, cstate, cparams,
                                                         a * p[P_LIMIT], math.inf, True, supervised, sv, cfg, sp, dt,
                                                         i_feedback, slots, table, k)
    if status != OK:
        return status, u
    if inner == INNER_RAN:
        advance_frame(z, frames, c, f, sp_inner, cur, dt, first, p[P_RESIDUAL], obs)
        p[P_FIRST] = 0.0
        p[P_RESIDUAL] = a
    elif inner == INNER_RESTARTED:
        restart_frames(z, frames, f, 0.0, p[P_SUPPLY])
        p[P_FIRST] = 1.0
        p[P_RESIDUAL] = 0.0
    if supervised:
        z[Z_PREV_ACTION] = _clip(u / p[P_SUPPLY], -1.0, 1.0)
    return status, u


@njit(cache=True, inline="always")
def _record(st, u, k, every, f_true, f_est, kept):
    """Record the end of period ``k`` of one row (:func:`run`)."""
    f_true[k] = st[S.contact_force_n]
    f_est[k] = st[S.force_est_n]
    if every > 0 and (k + 1) % every == 0:
        q = (k + 1) // every - 1
        kept[ROW.command_v, q] = u
        kept[ROW.fsr_voltage_v, q] = st[S.fsr_voltage_v]
        kept[ROW.motor_current_a, q] = st[S.current_a]   # plant truth: the trace's record
        kept[ROW.board_pos_m, q] = st[S.board_pos_m]
        kept[ROW.energy_j, q] = st[S.energy_j]


@njit(cache=True, _nrt=False)
def run(states, params, inputs, n_sub, kinds, cstates, cparams, u_ext, supervised, sv_states, sv_cfgs,
        setpoints, dt, i_feedback, slots, counts, tables, k0, n_periods, every, f_true, f_est, kept,
        status, periods, values, policy_row, policy):
    """Periods ``k0 .. k0 + n_periods - 1`` of every row whose ``status`` is :data:`OK`.

    Row ``r`` is one device: its plant rows (``states[r]``, ``params[r]``, ``inputs[r]``,
    modified in place), its controller (``kinds[r]``, ``cstates[r]``, ``cparams[r]``, or the
    external command ``u_ext[r]`` held over these periods), its supervisor (``supervised[r]``,
    ``sv_states[r]``, ``sv_cfgs[r]``), its setpoint per period (``setpoints[r, k]``) and its
    varying inputs (the first ``counts[r]`` of ``slots[r]``, values ``tables[r, j, k]``).  Rows
    share the number of physics steps ``n_sub``, the control period ``dt`` and the fed-back
    state slot.  Each row is computed on its own, so a row's trace is that of a run of the row
    alone, to the last bit.

    Row ``policy_row`` (-1: none) runs a residual policy on its compiled design instead
    (:func:`policy_period`; its controller is the design, its ``u_ext`` unused): ``policy`` holds
    the policy's arrays (:meth:`controllers.residual.ResidualPolicy.compiled_policy`), :data:`NO_POLICY`
    when no row has one.

    Recording (skipped when ``f_true`` has no columns): ``f_true[r, k]`` and ``f_est[r, k]``
    are the true and estimated force at the end of period ``k``; with ``every`` > 0 the end of
    period ``k`` with ``(k + 1) % every == 0`` fills column ``(k + 1) // every - 1`` of
    ``kept[r]`` (rows :data:`KEPT`).  A row that fails gets its status, ``periods[r]`` the
    period it failed in and ``values[r]`` the offending command; a row that runs gets
    ``periods[r] = k0 + n_periods``.

    Compiled without Numba's reference counting (``_nrt=False``, like the kernel): the loop
    allocates nothing (the LQG step, which does, keeps its own runtime, ``_nrt=True``).
    """
    p, z, frames, obs, fc_scales, layers, weights, zc, fc, buf = policy
    recording = f_true.shape[1] > 0
    for r in range(states.shape[0]):
        if status[r] != OK:
            continue
        st = states[r]
        inp = inputs[r]
        c = counts[r]
        rs = slots[r, :c]
        rt = tables[r, :c]
        own = r == policy_row
        periods[r] = k0 + n_periods
        for k in range(k0, k0 + n_periods):
            if own:
                code, u = policy_period(st, params[r], inp, n_sub, kinds[r], cstates[r], cparams[r], supervised[r],
                                        sv_states[r], sv_cfgs[r], setpoints[r, k], dt, i_feedback, rs, rt, k, p, z,
                                        frames, obs, fc_scales, layers, weights, zc, fc, buf)
            else:
                code, u = period(st, params[r], inp, n_sub, kinds[r], cstates[r], cparams[r], u_ext[r], math.inf,
                                 supervised[r], sv_states[r], sv_cfgs[r], setpoints[r, k], dt, i_feedback, rs, rt, k)
            if code != OK:
                status[r] = code
                periods[r] = k
                values[r] = u
                break
            if recording:
                _record(st, u, k, every, f_true[r], f_est[r], kept[r])


def _padded(rows: list, dtype=float) -> np.ndarray:
    """Rows of different lengths as one zero-padded 2-D array (at least one column)."""
    out = np.zeros((len(rows), max([len(r) for r in rows] + [1])), dtype=dtype)
    for i, r in enumerate(rows):
        out[i, :len(r)] = r
    return out


class Rows:
    """The arrays of :func:`run` for ``m`` rows, packed once (see :meth:`pack`).

    Attributes hold :func:`run`'s arguments by name; :meth:`arguments` lists them for a span of
    periods.  The controller and supervisor vectors are copies (zero-padded to a common
    length): :meth:`copy_back` returns their final values to the vectors they were packed from,
    which the controller and supervisor objects read.
    """

    def __init__(self, states, params, inputs, n_sub, kinds, cstates, cparams, supervised, sv_states, sv_cfgs,
                 setpoints, dt, i_feedback, slots, counts, tables, every, n_record, sources=()):
        m = states.shape[0]
        self.states, self.params, self.inputs, self.n_sub = states, params, inputs, int(n_sub)
        self.kinds, self.cstates, self.cparams = kinds, cstates, cparams
        self.supervised, self.sv_states, self.sv_cfgs = supervised, sv_states, sv_cfgs
        self.setpoints, self.dt, self.i_feedback = setpoints, float(dt), int(i_feedback)
        self.slots, self.counts, self.tables = slots, counts, tables
        self.every = int(every)
        self.u_ext = np.zeros(m)
        self.f_true = np.zeros((m, n_record))
        self.f_est = np.zeros((m, n_record))
        self.kept = np.zeros((m, len(KEPT), n_record // self.every if self.every > 0 else 0))
        self.status = np.zeros(m, dtype=np.int64)
        self.periods = np.zeros(m, dtype=np.int64)
        self.values = np.zeros(m)
        self.policy_row = -1
        self.policy = NO_POLICY
        self._sources = list(sources)

    @classmethod
    def pack(cls, plant_rows, controllers, supervisors, setpoints, dt, i_feedback, profiles, every, n_record):
        """Rows from per-row parts.

        Parameters
        ----------
        plant_rows : list of (state, params, inputs)
            Each row's plant vectors (copied).
        controllers : list of (kind, cstate, cparams)
            Each row's controller (:func:`controllers.compiled.compiled_form`; ``(KIND_EXTERNAL,
            empty, empty)`` for a command handed in).
        supervisors : list of (sv_state, sv_cfg) or None
            Each row's supervisor vectors, None for none.
        setpoints : ndarray, shape (m, n)
        profiles : list of dict
            Each row's varying inputs ``{input name: per-period array}``.
        every, n_record : int
            Keep the :data:`KEPT` columns every ``every``-th period (0: none); record
            ``n_record`` periods (0: nothing).
        """
        n_sub = plant_rows[0][3]
        states = np.array([p[0] for p in plant_rows])
        params = np.array([p[1] for p in plant_rows])
        inputs = np.array([p[2] for p in plant_rows])
        kinds = np.array([c[0] for c in controllers], dtype=np.int64)
        cstates = _padded([c[1] for c in controllers])
        cparams = _padded([c[2] for c in controllers])
        supervised = np.array([s is not None for s in supervisors], dtype=np.bool_)
        sv_states = _padded([np.zeros(0) if s is None else s[0] for s in supervisors])
        sv_cfgs = _padded([np.zeros(0) if s is None else s[1] for s in supervisors])
        n = setpoints.shape[1]
        counts = np.array([len(p) for p in profiles], dtype=np.int64)
        width = max([1] + counts.tolist())
        slots = np.zeros((len(profiles), width), dtype=np.int64)
        tables = np.zeros((len(profiles), width, n))
        for r, prof in enumerate(profiles):
            for j, (name, arr) in enumerate(prof.items()):
                slots[r, j] = U[name]
                tables[r, j] = arr[:n]
        sources = [(c[1], None if s is None else s[0]) for c, s in zip(controllers, supervisors)]
        return cls(states, params, inputs, n_sub, kinds, cstates, cparams, supervised, sv_states, sv_cfgs,
                   setpoints, dt, i_feedback, slots, counts, tables, every, n_record, sources)

    @classmethod
    def single(cls, plant, kind, cstate, cparams, setpoint_n, supervisor=None, profiles=None, every=0,
               n_record=None, dt=None, i_feedback=S.force_est_n):
        """One row from a one-device lumped ``plant`` (its vectors copied), for examples and tests."""
        n = len(setpoint_n)
        return cls.pack([(plant.state[0], plant.params[0], plant.inputs[0], plant.substeps)],
                        [(kind, cstate, cparams)], [supervisor], np.asarray(setpoint_n, dtype=float)[None, :],
                        plant.control_dt_s if dt is None else dt, i_feedback, [profiles or {}], every,
                        n if n_record is None else n_record)

    def arguments(self, k0: int, n_periods: int) -> tuple:
        """:func:`run`'s arguments for periods ``k0 .. k0 + n_periods - 1``."""
        return (self.states, self.params, self.inputs, self.n_sub, self.kinds, self.cstates, self.cparams,
                self.u_ext, self.supervised, self.sv_states, self.sv_cfgs, self.setpoints, self.dt,
                self.i_feedback, self.slots, self.counts, self.tables, k0, n_periods, self.every, self.f_true,
                self.f_est, self.kept, self.status, self.periods, self.values, self.policy_row, self.policy)

    def give_policy(self, r: int, policy: tuple) -> None:
        """Let row ``r`` run a residual policy on its compiled design: ``policy`` the policy's
        arrays (:meth:`controllers.residual.ResidualPolicy.compiled_policy`, stepped in place)."""
        self.policy_row, self.policy = int(r), policy

    def stepper(self):
        """:func:`run` for these rows' argument types without the dispatcher's check of every
        argument on each call (:func:`ebraille_sim.base.compiled.entry_point`): for one period per
        call, as the per-period shim steps."""
        return entry_point(run, *self.arguments(0, 1))

    def copy_back(self) -> None:
        """Write the rows' final controller and supervisor vectors into the vectors they were
        packed from."""
        for r, (cs, sv) in enumerate(self._sources):
            cs[:] = self.cstates[r, :len(cs)]
            if sv is not None:
                sv[:] = self.sv_states[r, :len(sv)]
