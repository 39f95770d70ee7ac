"""Compiled steps of the built-in controllers: state and parameters in flat float64 vectors.

Every built-in controller keeps its state in one float64 vector and its parameters in
another, with named slots (:data:`PS`, :data:`PP` for the PID family, :data:`LS`,
:data:`LP` for the LQG, :data:`DS`, :data:`DP` for the PID with the disturbance observer), and
advances through the Numba-compiled functions of this module.  The Python classes
(:class:`controllers.pid.PID`, :class:`controllers.schedule.ScheduledPID`,
:class:`controllers.friction.FrictionPID`, :class:`controllers.lqg.LQG`,
:class:`controllers.dob.DOBPID`) validate their arguments and call these functions, so a
controller stepped from Python and the same controller stepped inside the loop engine
(:mod:`ebraille_sim.plant.engine`) run the same code.  A controller's ``compiled()`` returns
``(kind, state, params)``: its kind (:data:`KIND_PID`, :data:`KIND_LQG` or :data:`KIND_DOB`)
and its live vectors; :func:`controller_step` and :func:`controller_reset` dispatch on the
kind.  A ``pid_dob`` with a refresh learner (:mod:`controllers.refresh`, Python) has no
compiled form: its class calls :func:`dob_step` with the learner's reference.

The arithmetic is written in the order of the recursions in :mod:`controllers.pid`,
:mod:`controllers.schedule`, :mod:`controllers.friction` and :mod:`controllers.lqg`, with
Python's ``min``/``max`` semantics (:func:`py_min`, :func:`py_max`), so a run gives the same
commands to the last bit whichever way it is stepped.

:func:`pid_step` and :func:`pid_reset` allocate nothing and are compiled without Numba's
reference counting (``_nrt=False``), and the dispatchers :func:`controller_step` and
:func:`controller_reset` are inlined into their callers: a compiled loop then steps the PID
without an atomic reference count per array per call, which cost more than the PID's own
arithmetic.  The LQG step allocates its small vectors and keeps the runtime (``_nrt=True``
set explicitly: a caller compiled without it, the loop engine, would otherwise pass it on).

PID family (one step for all variants, switched by the parameters):

* ``variant`` 0, the fixed-gain :class:`~controllers.pid.PID`: gains scaled by the pulp's
  stiffness ratio above ``schedule_above_n`` when ``schedule_above`` is set, a constant
  feedforward, the tracking gain fixed at construction;
* ``variant`` 1, the :class:`~controllers.schedule.ScheduledPID`: gain schedule on the
  setpoint or the estimate, tracking gain from the scheduled gains, the static reference map,
  the setpoint feedforward with its latched direction, and (``friction`` set) the friction
  direction latched on the force error of :class:`~controllers.friction.FrictionPID`.

Examples
--------
>>> from controllers import make
>>> c = make("pid")
>>> kind, state, params = c.compiled()
>>> kind == KIND_PID and state.shape == (len(PS),)
True
"""
from __future__ import annotations

import collections
import math

import numpy as np

from ebraille_sim.base.compiled import njit
from ebraille_sim.physics.fingertip import tangent_stiffness_n_per_m
from ebraille_sim.physics.params import TACTILE_FORCE_MAX_N, TACTILE_FORCE_MIN_N

__all__ = ["controller_resume", "integrator_floor", "resume_controller", "KIND_NONE", "KIND_PID", "KIND_LQG", "KIND_EXTERNAL", "KIND_DOB", "MAP_POINTS", "PS", "PP", "LS", "LP",
           "DS", "DP", "record", "pid_state", "pid_params", "lqg_state", "lqg_params", "lqg_order", "dob_state",
           "dob_params", "py_min", "py_max", "core_step", "core_reset", "pid_step", "pid_reset", "scheduled_gains",
           "map_reference", "model_feedforward_v", "feedforward_v", "lqg_step", "lqg_reset", "dob_step", "dob_reset",
           "controller_step", "controller_reset", "compiled_form"]

KIND_NONE = 0
"""No compiled form (a Python controller)."""
KIND_PID = 1
"""The PID family (:func:`pid_step`)."""
KIND_LQG = 2
"""The LQG (:func:`lqg_step`)."""
KIND_EXTERNAL = 3
"""A command handed in from outside each period: an agent's action, or the command a Python
controller returned (:mod:`ebraille_sim.plant.engine`); resets do not reach it."""
KIND_DOB = 4
"""The PID with the disturbance observer on the motor current (:func:`dob_step`)."""

MAP_POINTS = 57
"""Breakpoints of the static reference map of :class:`controllers.schedule.ScheduledPID`."""


def record(kind: str, names) -> tuple:
    """A read-only record of slot indices: ``R.integrator_v`` is the index of that slot.

    Compiled functions read its attributes as constants.
    """
    names = list(names)
    if len(set(names)) != len(names):
        raise ValueError(f"{kind}: duplicate slot names")
    return collections.namedtuple(kind, names)(*range(len(names)))


PS = record("PIDStateSlots", (
    "integrator_v", "derivative_v", "prev_derivative_input_n", "prev_error_n", "prev_saturation_residual_v",
    "primed", "prev_setpoint_n", "has_prev_setpoint", "direction"))
"""State of the PID family: the recursion of :class:`controllers.pid.PIDCore` (``primed``
1.0 once the derivative memory holds a sample), then the scheduled PID's last setpoint
(valid when ``has_prev_setpoint`` is 1.0) and its latched feedforward direction (+1 or -1)."""

PP = record("PIDParamSlots", (
    "variant", "kp_v_per_n", "ki_v_per_ns", "kd_vs_per_n", "derivative_filter_s", "setpoint_weight_p",
    "setpoint_weight_d", "u_min_v", "u_max_v", "tracking_gain_per_s", "feedforward_v", "schedule_above",
    "schedule_above_n", "finger_b_n_per_m", "finger_m_per_m", "relax_weight_inf",
    "schedule", "schedule_on_estimate", "reference_force_n", "tracking_time_given", "tracking_time_s",
    "feedforward", "command_per_force_v_per_n", "gear_mu", "coulomb_n", "back_emf_v_s_per_m",
    "rate_deadband_n_per_s", "reference_map", "friction", "friction_fraction", "hysteresis_fraction")
    + tuple(f"map_force_n{j}" for j in range(MAP_POINTS)) + tuple(f"map_estimate_n{j}" for j in range(MAP_POINTS)))
"""Parameters of the PID family.  Flags are 1.0 (on) or 0.0 (off).  ``variant`` 0 is the
fixed-gain PID (its ``tracking_gain_per_s`` and constant ``feedforward_v`` are used; gains
scaled above ``schedule_above_n`` when ``schedule_above`` is on), 1 the scheduled PID (its
gains are scheduled about ``reference_force_n`` when ``schedule`` is on, the tracking time is
derived from the scheduled gains unless ``tracking_time_given``).  ``finger_*`` and
``relax_weight_inf`` give the pulp's tangent stiffness for the schedules;
``command_per_force_v_per_n`` (``R / (kM g)``), ``gear_mu``, ``coulomb_n`` and
``back_emf_v_s_per_m`` (``kE g``) the feedforward; ``map_force_n*`` and ``map_estimate_n*``
the reference map."""

LS = record("LQGStateSlots", ("accumulated_s", "error_integral_n_s", "command_v", "observer"))
"""State of the LQG: time since its last sample (inf before the first), the integral of
the error, the held command, then the observer's ``order`` states from slot ``observer`` on."""

LP = record("LQGParamSlots", ("order", "sample_s", "u_min_v", "u_max_v", "u0_v", "y0_n", "nu_v_per_n", "kz",
                              "matrices"))
"""Parameters of the LQG: the model order ``n``, the sample period, the output limits, the
operating point ``(u0, y0)``, ``Nu`` and ``kz``, then from slot ``matrices`` on, in this
order: ``A`` (n x n, row-major), ``B``, ``C``, ``K``, ``L`` and ``Nx`` (n each)."""

DS = record("DOBStateSlots", PS._fields + ("disturbance_v", "back_emf_v", "command_v", "setpoint_n",
                                           "since_step_s", "wide_armed", "wide_error_n", "approached"))
"""State of the PID with the disturbance observer (:class:`controllers.dob.DOBPID`): the PID's
slots (:data:`PS`, at the same indices), the observer's estimate ``d_hat``, the filtered
back-EMF, the last command, the last setpoint and the time since it changed, whether the
wide-error gains are armed and the low-passed error that decides them (:func:`_wide_error`),
and whether the estimate has reached the approach's end since the last reset (:func:`_approach`)."""

DP = record("DOBParamSlots", PP._fields + ("motor_r_ohm", "q_time_constant_s", "compensation_fraction",
                                           "max_compensation_v", "speed_read", "hold_damping_v_per_v",
                                           "hold_speed_filter_s", "hold_after_step_s", "hold_band_fraction",
                                           "wide_error_fraction", "wide_kp_v_per_n", "wide_ki_v_per_ns",
                                           "wide_filter_s", "approach_fraction", "approach_ki_v_per_ns"))
"""Parameters of the PID with the disturbance observer: the fixed-gain PID's slots (:data:`PP`,
``variant`` 0, gains scaled above ``schedule_above_n``), the nominal winding resistance, the
observer's, the hold damping's, the wide-error gains' and the approach's settings of
:class:`controllers.dob.DOBConfig`;
``speed_read`` is 1.0 when the back-EMF is filtered (a hold damping in some mode)."""

@njit(cache=True, inline="always")
def py_max(a, b):
    """Python's ``max(a, b)``: ``b`` only when ``b > a`` (so NaN and -0.0 behave alike)."""
    return b if b > a else a


@njit(cache=True, inline="always")
def py_min(a, b):
    """Python's ``min(a, b)``: ``b`` only when ``b < a``."""
    return b if b < a else a


@njit(cache=True, inline="always")
def _pulp_stiffness(p, force_n):
    """Relaxed tangent stiffness at ``force_n`` (:func:`controllers.pid.pulp_stiffness_n_per_m`), N/m."""
    return tangent_stiffness_n_per_m(force_n / p[PP.relax_weight_inf], p[PP.finger_b_n_per_m], p[PP.finger_m_per_m])


@njit(cache=True, inline="always")
def _stiffness_ratio(p, force_n, reference_force_n):
    """:func:`controllers.pid.stiffness_ratio` on the finger of ``p``."""
    return (_pulp_stiffness(p, reference_force_n)
            / _pulp_stiffness(p, py_min(py_max(force_n, TACTILE_FORCE_MIN_N), TACTILE_FORCE_MAX_N)))


@njit(cache=True)
def core_reset(s, y, r, u0, kp, b, c, ff):
    """:meth:`controllers.pid.PIDCore.reset` on the state vector ``s``."""
    s[PS.integrator_v] = u0 - kp * (b * r - y) - ff
    s[PS.derivative_v] = 0.0
    s[PS.prev_derivative_input_n] = c * r - y
    s[PS.prev_error_n] = 0.0
    s[PS.prev_saturation_residual_v] = 0.0
    s[PS.primed] = 1.0


@njit(cache=True)
def core_step(s, y, r, h, kp, ki, kd, tf, b, c, inv_tt, ff, umin, umax):
    """:meth:`controllers.pid.PIDCore.step` on the state vector ``s``; returns the command, V."""
    a = h * inv_tt
    if a > 1.0:
        a = 1.0
    i = s[PS.integrator_v] + ki * h * s[PS.prev_error_n] + a * s[PS.prev_saturation_residual_v]

    w = c * r - y
    if s[PS.primed] == 0.0:
        s[PS.prev_derivative_input_n] = w
        s[PS.primed] = 1.0
    d = (tf * s[PS.derivative_v] + kd * (w - s[PS.prev_derivative_input_n])) / (tf + h)

    v = kp * (b * r - y) + i + d + ff
    u = v
    if u > umax:
        u = umax
    elif u < umin:
        u = umin

    s[PS.integrator_v] = i
    s[PS.derivative_v] = d
    s[PS.prev_derivative_input_n] = w
    s[PS.prev_error_n] = r - y
    s[PS.prev_saturation_residual_v] = u - v
    return u


@njit(cache=True)
def scheduled_gains(p, force_n):
    """``(kp, ki, kd)`` of the scheduled PID at the scheduling force ``force_n``
    (:meth:`controllers.schedule.ScheduledPID.gains_at`)."""
    a = _stiffness_ratio(p, force_n, p[PP.reference_force_n]) if p[PP.schedule] != 0.0 else 1.0
    return p[PP.kp_v_per_n] * a, p[PP.ki_v_per_ns] * a, p[PP.kd_vs_per_n] * a


@njit(cache=True)
def map_reference(p, setpoint_n):
    """The estimate regulated for the true-force setpoint (:meth:`controllers.schedule.ScheduledPID.reference`).

    Linear interpolation in the map, as ``numpy.interp`` computes it (the same rounding).
    """
    if p[PP.reference_map] == 0.0:
        return setpoint_n
    f0 = PP.map_force_n0
    e0 = PP.map_estimate_n0
    if setpoint_n <= TACTILE_FORCE_MIN_N:
        return setpoint_n * p[e0] / p[f0]
    last = MAP_POINTS - 1
    x = setpoint_n
    if x >= p[f0 + last]:
        return p[e0 + last]
    if x < p[f0]:
        return p[e0]
    lo = 0
    hi = last
    while hi - lo > 1:                       # p[f0 + lo] <= x < p[f0 + hi]
        mid = (lo + hi) // 2
        if p[f0 + mid] <= x:
            lo = mid
        else:
            hi = mid
    slope = (p[e0 + lo + 1] - p[e0 + lo]) / (p[f0 + lo + 1] - p[f0 + lo])
    out = slope * (x - p[f0 + lo]) + p[e0 + lo]
    if math.isnan(out):
        out = slope * (x - p[f0 + lo + 1]) + p[e0 + lo + 1]
        if math.isnan(out) and p[e0 + lo] == p[e0 + lo + 1]:
            out = p[e0 + lo]
    return out


@njit(cache=True)
def model_feedforward_v(p, setpoint_n, rate_n_per_s, direction):
    """The setpoint feedforward ``u_ff`` (:meth:`controllers.schedule.ScheduledPID.feedforward_v`), V."""
    if p[PP.feedforward] == 0.0:
        return 0.0
    r = py_max(setpoint_n, 0.0)
    if abs(rate_n_per_s) < p[PP.rate_deadband_n_per_s]:
        s = direction
    else:
        s = math.copysign(1.0, rate_n_per_s)
    k = _pulp_stiffness(p, py_max(r, TACTILE_FORCE_MIN_N))
    return (p[PP.command_per_force_v_per_n] * ((1.0 + s * p[PP.gear_mu]) * r + s * p[PP.coulomb_n])
            + p[PP.back_emf_v_s_per_m] * rate_n_per_s / k)


@njit(cache=True)
def feedforward_v(p, setpoint_n, rate_n_per_s, direction):
    """The feedforward the step adds: :func:`model_feedforward_v`, with its friction part scaled
    by ``friction_fraction`` when ``friction`` is on (:meth:`controllers.friction.FrictionPID.feedforward_v`)."""
    full = model_feedforward_v(p, setpoint_n, rate_n_per_s, direction)
    if p[PP.friction] == 0.0:
        return full
    frac = p[PP.friction_fraction]
    if frac == 1.0 or abs(rate_n_per_s) >= p[PP.rate_deadband_n_per_s]:
        return full
    middle = model_feedforward_v(p, setpoint_n, rate_n_per_s, 0.0)
    return middle + frac * (full - middle)


@njit(cache=True, inline="always")
def _tracking_gain(p, kp, ki, kd):
    """``1/Tt`` of the scheduled gains (:func:`controllers.pid.tracking_time_s`,
    :func:`controllers.pid.tracking_gain_per_s`)."""
    if ki == 0.0:
        tt = math.inf
    elif p[PP.tracking_time_given] != 0.0:
        tt = p[PP.tracking_time_s]
    elif kd > 0.0:
        tt = math.sqrt(kd / ki)
    else:
        tt = kp / ki
    return 0.0 if tt == math.inf else (math.inf if tt == 0.0 else 1.0 / tt)


@njit(cache=True, inline="always")
def _pid_gain_scale(p, r):
    """:meth:`controllers.pid.PIDConfig.gain_scale` at the setpoint ``r``."""
    f_s = p[PP.schedule_above_n]
    if p[PP.schedule_above] == 0.0 or not r > f_s:
        return 1.0
    return _stiffness_ratio(p, r, f_s)


@njit(cache=True, _nrt=False)
def pid_reset(s, p, y, r, command_v):
    """Bumpless reset of a PID-family controller (``reset`` of the classes)."""
    u0 = py_min(py_max(command_v, p[PP.u_min_v]), p[PP.u_max_v])
    if p[PP.variant] == 0.0:
        core_reset(s, y, r, u0, p[PP.kp_v_per_n] * _pid_gain_scale(p, r), p[PP.setpoint_weight_p],
                   p[PP.setpoint_weight_d], p[PP.feedforward_v])
        return
    for j in range(len(PS)):
        s[j] = 0.0
    s[PS.direction] = 1.0
    kp, _, _ = scheduled_gains(p, y if p[PP.schedule_on_estimate] != 0.0 else r)
    core_reset(s, y, map_reference(p, r), u0, kp, p[PP.setpoint_weight_p], p[PP.setpoint_weight_d],
               feedforward_v(p, r, 0.0, 1.0))
    s[PS.prev_setpoint_n] = r
    s[PS.has_prev_setpoint] = 1.0


@njit(cache=True, _nrt=False)
def pid_step(s, p, y, r, h):
    """One sample of a PID-family controller (``update`` of the classes); returns the command, V."""
    if p[PP.variant] == 0.0:
        kp = p[PP.kp_v_per_n]
        ki = p[PP.ki_v_per_ns]
        kd = p[PP.kd_vs_per_n]
        if p[PP.schedule_above] != 0.0:
            a = _pid_gain_scale(p, r)
            kp = kp * a
            ki = ki * a
            kd = kd * a
        return core_step(s, y, r, h, kp, ki, kd, p[PP.derivative_filter_s], p[PP.setpoint_weight_p],
                         p[PP.setpoint_weight_d], p[PP.tracking_gain_per_s], p[PP.feedforward_v],
                         p[PP.u_min_v], p[PP.u_max_v])
    if p[PP.friction] != 0.0:
        e = map_reference(p, r) - y
        tol = p[PP.hysteresis_fraction] * py_max(r, TACTILE_FORCE_MIN_N)
        if e > tol:
            s[PS.direction] = 1.0
        elif e < -tol:
            s[PS.direction] = -1.0
    rate = 0.0 if s[PS.has_prev_setpoint] == 0.0 else (r - s[PS.prev_setpoint_n]) / h
    s[PS.prev_setpoint_n] = r
    s[PS.has_prev_setpoint] = 1.0
    if abs(rate) >= p[PP.rate_deadband_n_per_s]:
        s[PS.direction] = math.copysign(1.0, rate)
    kp, ki, kd = scheduled_gains(p, y if p[PP.schedule_on_estimate] != 0.0 else r)
    inv_tt = _tracking_gain(p, kp, ki, kd)
    return core_step(s, y, map_reference(p, r), h, kp, ki, kd, p[PP.derivative_filter_s],
                     p[PP.setpoint_weight_p], p[PP.setpoint_weight_d], inv_tt,
                     feedforward_v(p, r, rate, s[PS.direction]), p[PP.u_min_v], p[PP.u_max_v])


def pid_state() -> np.ndarray:
    """A cleared PID-family state vector (no derivative memory, direction +1)."""
    s = np.zeros(len(PS))
    s[PS.direction] = 1.0
    return s


def pid_params(**values) -> np.ndarray:
    """A PID-family parameter vector: the named slots of :data:`PP` set, the others 0."""
    p = np.zeros(len(PP))
    for name, value in values.items():
        p[PP._fields.index(name)] = value
    return p


def lqg_order(p) -> int:
    """The model order ``n`` of an LQG parameter vector."""
    return int(p[LP.order])


def lqg_state(order: int) -> np.ndarray:
    """A cleared LQG state vector of a model of ``order`` states."""
    s = np.zeros(LS.observer + order)
    s[LS.accumulated_s] = math.inf
    return s


def lqg_params(*, sample_s, u_min_v, u_max_v, u0_v, y0_n, nu_v_per_n, kz, A, B, C, K, L, Nx) -> np.ndarray:
    """An LQG parameter vector (:data:`LP`) from the design's scalars and matrices."""
    n = A.shape[0]
    head = np.zeros(LP.matrices)
    head[LP.order] = n
    head[LP.sample_s] = sample_s
    head[LP.u_min_v] = u_min_v
    head[LP.u_max_v] = u_max_v
    head[LP.u0_v] = u0_v
    head[LP.y0_n] = y0_n
    head[LP.nu_v_per_n] = nu_v_per_n
    head[LP.kz] = kz
    return np.concatenate([head] + [np.ascontiguousarray(m, dtype=float).ravel() for m in (A, B, C, K, L, Nx)])


@njit(cache=True, inline="always")
def _lqg_blocks(p):
    """``(n, A, B, C, K, L, Nx)`` of an LQG parameter vector (views of ``p``)."""
    n = int(p[LP.order])
    a0 = LP.matrices
    b0 = a0 + n * n
    A = p[a0:b0].reshape((n, n))
    B = p[b0:b0 + n]
    C = p[b0 + n:b0 + 2 * n]
    K = p[b0 + 2 * n:b0 + 3 * n]
    L = p[b0 + 3 * n:b0 + 4 * n]
    Nx = p[b0 + 4 * n:b0 + 5 * n]
    return n, A, B, C, K, L, Nx


@njit(cache=True, _nrt=True)
def lqg_reset(s, p, y, r, command_v):
    """Bumpless reset of the LQG (:meth:`controllers.lqg.LQG.reset`)."""
    n, A, B, C, K, L, Nx = _lqg_blocks(p)
    x0 = LS.observer
    s[LS.accumulated_s] = math.inf
    u0 = py_min(py_max(command_v, p[LP.u_min_v]), p[LP.u_max_v])
    dr = r - p[LP.y0_n]
    x = Nx * (y - p[LP.y0_n])
    s[x0:x0 + n] = x
    u_wo = p[LP.u0_v] + p[LP.nu_v_per_n] * dr - np.dot(K, x - Nx * dr)
    s[LS.error_integral_n_s] = -(u0 - u_wo) / p[LP.kz] if p[LP.kz] != 0 else 0.0
    s[LS.command_v] = u0


@njit(cache=True, _nrt=True)
def lqg_step(s, p, force_est_n, setpoint_n, dt_s):
    """One call of the sampled-data LQG (:meth:`controllers.lqg.LQG.update`); returns the command, V."""
    ts = p[LP.sample_s]
    acc = s[LS.accumulated_s]
    acc = acc + dt_s if math.isfinite(acc) else ts
    s[LS.accumulated_s] = acc
    if acc < ts - 1e-9:
        return s[LS.command_v]
    s[LS.accumulated_s] = acc - ts
    n, A, B, C, K, L, Nx = _lqg_blocks(p)
    x0 = LS.observer
    u0 = p[LP.u0_v]
    y = force_est_n - p[LP.y0_n]
    dr = setpoint_n - p[LP.y0_n]
    x = s[x0:x0 + n] + L * (y - np.dot(C, s[x0:x0 + n]))
    z = s[LS.error_integral_n_s]
    z_new = z + ts * (y - dr)
    v = u0 + p[LP.nu_v_per_n] * dr - np.dot(K, x - Nx * dr) - p[LP.kz] * z_new
    u = py_min(py_max(v, p[LP.u_min_v]), p[LP.u_max_v])
    if u == v:
        s[LS.error_integral_n_s] = z_new
    else:
        v = u0 + p[LP.nu_v_per_n] * dr - np.dot(K, x - Nx * dr) - p[LP.kz] * z
        u = py_min(py_max(v, p[LP.u_min_v]), p[LP.u_max_v])
    s[x0:x0 + n] = np.dot(A, x) + B * (u - u0)
    s[LS.command_v] = u
    return u


def dob_state() -> np.ndarray:
    """A cleared state vector of the PID with the disturbance observer."""
    s = np.zeros(len(DS))
    s[DS.direction] = 1.0
    return s


def dob_params(**values) -> np.ndarray:
    """A parameter vector of the PID with the disturbance observer: the named slots of :data:`DP`
    set, the others 0."""
    p = np.zeros(len(DP))
    for name, value in values.items():
        p[DP._fields.index(name)] = value
    return p


@njit(cache=True, inline="always")
def _dob_compensation_v(s, p):
    """``f d_hat`` clamped to ``+/- max_compensation_v``, V."""
    lim = p[DP.max_compensation_v]
    return py_min(py_max(p[DP.compensation_fraction] * s[DS.disturbance_v], -lim), lim)


@njit(cache=True, _nrt=False)
def dob_reset(s, p, y, r, command_v):
    """Bumpless reset of the PID with the disturbance observer (:meth:`controllers.dob.DOBPID.reset`)."""
    u0 = py_min(py_max(command_v, p[PP.u_min_v]), p[PP.u_max_v])
    s[DS.disturbance_v] = u0
    s[DS.back_emf_v] = 0.0
    s[DS.command_v] = u0
    s[DS.setpoint_n] = r
    s[DS.since_step_s] = math.inf
    s[DS.wide_armed] = 0.0
    s[DS.wide_error_n] = y - r
    s[DS.approached] = 0.0
    _approach(s, p, y, r)
    core_reset(s, y, r, u0, p[PP.kp_v_per_n] * _pid_gain_scale(p, r), p[PP.setpoint_weight_p],
               p[PP.setpoint_weight_d], _dob_compensation_v(s, p))


@njit(cache=True, inline="always")
def _approach(s, p, y, r):
    """Whether the PID's integral runs at ``approach_ki_v_per_ns`` this sample: the estimate ``y``
    has not reached ``approach_fraction`` of the reference ``r`` since the last reset (the board
    is still on its way to the finger; 0: off)."""
    if s[DS.approached] == 0.0 and (p[DP.approach_fraction] <= 0.0 or y >= p[DP.approach_fraction] * r):
        s[DS.approached] = 1.0
    return s[DS.approached] == 0.0


@njit(cache=True, inline="always")
def _wide_error(s, p, e, r, stepped, h):
    """Whether the PID runs on the wide-error gains this sample: the error ``e = y - r`` through
    its first-order low-pass (time constant ``wide_filter_s``; 0: the error itself) is more than
    ``wide_error_fraction`` of the reference ``r``, and the filtered error has been within that
    band at least once since the last reset or setpoint change (``stepped``: the setpoint
    changed this sample; the filter restarts from the step's error), so an onset or a step runs
    on the hold's gains until it first arrives."""
    if stepped:
        s[DS.wide_armed] = 0.0
        s[DS.wide_error_n] = e                              # the step's error seen at once
    tf = p[DP.wide_filter_s]
    if tf > 0.0:
        s[DS.wide_error_n] += -math.expm1(-h / tf) * (e - s[DS.wide_error_n])
        e = s[DS.wide_error_n]
    if abs(e) <= p[DP.wide_error_fraction] * r:
        s[DS.wide_armed] = 1.0
        return False
    return s[DS.wide_armed] != 0.0


@njit(cache=True, _nrt=False)
def dob_step(s, p, y, r, r_loop, kv, h, cur):
    """One sample of the PID with the disturbance observer (:meth:`controllers.dob.DOBPID.update`,
    the law of :mod:`controllers.dob`): the observer on the measured current ``cur`` (A; NaN:
    none, the estimate held), the PID on the reference ``r_loop`` (the setpoint, or the setpoint
    with a refresh learner's correction) with the compensation as its feedforward and, while
    the filtered error is wide (:func:`_wide_error`), the wide-error gains, until the estimate
    first reaches the approach's end (:func:`_approach`) the approach's integral, then the hold
    damping ``-kv e`` in a hold of the setpoint ``r``; returns the command, V."""
    speed = p[DP.speed_read] != 0.0
    if cur == cur:
        r_ohm = p[DP.motor_r_ohm]
        if speed:
            s[DS.back_emf_v] += -math.expm1(-h / p[DP.hold_speed_filter_s]) * (
                s[DS.command_v] - r_ohm * cur - s[DS.back_emf_v])
        s[DS.disturbance_v] += -math.expm1(-h / p[DP.q_time_constant_s]) * (r_ohm * cur - s[DS.disturbance_v])
    a = _pid_gain_scale(p, r_loop)
    kp, ki = p[PP.kp_v_per_n], p[PP.ki_v_per_ns]
    stepped = r != s[DS.setpoint_n]
    if p[DP.wide_error_fraction] > 0.0 and _wide_error(s, p, y - r_loop, r_loop, stepped, h):
        kp, ki = p[DP.wide_kp_v_per_n], p[DP.wide_ki_v_per_ns]
    if _approach(s, p, y, r_loop):
        ki = p[DP.approach_ki_v_per_ns]
    u = core_step(s, y, r_loop, h, kp * a, ki * a, p[PP.kd_vs_per_n] * a,
                  p[PP.derivative_filter_s], p[PP.setpoint_weight_p], p[PP.setpoint_weight_d],
                  p[PP.tracking_gain_per_s], _dob_compensation_v(s, p), p[PP.u_min_v], p[PP.u_max_v])
    s[DS.since_step_s] = 0.0 if stepped else s[DS.since_step_s] + h
    s[DS.setpoint_n] = r
    if speed:
        if s[DS.since_step_s] >= p[DP.hold_after_step_s] and abs(y - r) < p[DP.hold_band_fraction] * r:
            u = py_min(py_max(u - kv * s[DS.back_emf_v], p[PP.u_min_v]), p[PP.u_max_v])
        s[DS.command_v] = u
    return u


@njit(cache=True, inline="always")
def controller_step(kind, s, p, force_est_n, setpoint_n, dt_s, motor_current_a):
    """One ``update`` of a compiled controller of ``kind`` (``motor_current_a``, A, NaN for none,
    is read by :data:`KIND_DOB` only)."""
    if kind == KIND_PID:
        return pid_step(s, p, force_est_n, setpoint_n, dt_s)
    if kind == KIND_DOB:
        return dob_step(s, p, force_est_n, setpoint_n, setpoint_n, p[DP.hold_damping_v_per_v], dt_s, motor_current_a)
    return lqg_step(s, p, force_est_n, setpoint_n, dt_s)


@njit(cache=True, inline="always")
def controller_reset(kind, s, p, force_est_n, setpoint_n, command_v):
    """``reset`` of a compiled controller of ``kind``."""
    if kind == KIND_PID:
        pid_reset(s, p, force_est_n, setpoint_n, command_v)
    elif kind == KIND_DOB:
        dob_reset(s, p, force_est_n, setpoint_n, command_v)
    else:
        lqg_reset(s, p, force_est_n, setpoint_n, command_v)


@njit(cache=True, inline="always")
def controller_resume(kind, s, p, force_est_n, setpoint_n):
    """The reset of a compiled controller of ``kind`` when the supervisor resumes it after a
    regained contact: bumpless from 0 V (:func:`controller_reset`), with a PID-family or
    disturbance-observer integrator raised to 0 V when the reset would start it below.

    The returning finger reads under the setpoint for some milliseconds after its impact; a
    bumpless start from 0 V then puts ``-kp e`` in the integrator and the board retracts from
    the finger it has just found.  The start of a session keeps the plain reset: there the
    negative integrator is the soft start of the approach and bounds the onset's overshoot.
    """
    controller_reset(kind, s, p, force_est_n, setpoint_n, 0.0)
    integrator_floor(kind, s)


@njit(cache=True, inline="always")
def integrator_floor(kind, s):
    """Raise a PID-family or disturbance-observer integrator that starts below 0 V to 0 V (the
    resume's rule, :func:`controller_resume`); other kinds are left as they are."""
    if (kind == KIND_PID or kind == KIND_DOB) and s[PS.integrator_v] < 0.0:
        s[PS.integrator_v] = 0.0


def compiled_form(controller):
    """``controller.compiled()`` when it has one: ``(kind, state, params)``, else None."""
    get = getattr(controller, "compiled", None)
    return get() if callable(get) else None


def resume_controller(controller, *, force_est_n: float, setpoint_n: float) -> None:
    """:func:`controller_resume` on a controller object: its ``reset`` from 0 V, then, for a
    controller with a compiled PID-family or disturbance-observer form, the integrator raised
    to 0 V when the reset started it below (a controller without one keeps the plain reset).  A
    controller with its own ``resume(force_est_n=, setpoint_n=)`` (a wrapper around a design,
    :class:`controllers.residual.ResidualPolicy`) resumes by it."""
    resume = getattr(controller, "resume", None)
    if resume is not None:
        resume(force_est_n=force_est_n, setpoint_n=setpoint_n)
        return
    controller.reset(force_est_n=force_est_n, setpoint_n=setpoint_n, command_v=0.0)
    form = compiled_form(controller)
    if form is not None:
        integrator_floor(form[0], form[1])
