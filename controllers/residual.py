"""A learned, bounded correction on top of a design's controller: the residual policy.

The design's controller (a shipped design such as ``dob_100hz``, or any controller) runs
every control period as it would alone; a policy adds ``a * limit_v`` (``a`` in [-1, 1]) to
its command.  With ``a = 0`` the command is the design's, to the last bit, so a residual
policy starts from the design and training can only move away from it where the reward says
so.

The policy's observation is :data:`N_FRAME` numbers per frame, built from what the board
measures (:mod:`controllers.features`: force estimate, setpoint, error, filtered rate of the
estimate, error integral, the previous applied command and the sensed motor current), then
the previous residual action; ``history`` frames are stacked, newest first (``history *
N_FRAME`` numbers; older frames are zero until they exist).  The Gymnasium env
:class:`ebraille_sim.rl.residual.ResidualEnv` runs this class with the agent's action handed
in (:class:`ActionSlot`), so a trained policy meets in a scenario the observation it met in
training.

Sampling: the design runs at every ``update``; the policy is evaluated once per training
period (``control_rate_hz`` of its metadata) of the ``dt_s`` it is handed and its correction
held in between, as :class:`controllers.policy.PolicyController` holds its command.

The compiled policy's functions (:func:`mlp_action`, :func:`advance_frame`,
:func:`restart_frames`) keep Numba's reference counting (``_nrt=True`` set explicitly: the loop
engine, compiled without it, calls them and would otherwise pass that on).

Examples
--------
>>> import numpy as np
>>> import controllers
>>> base = controllers.make("pid_dob")
>>> res = ResidualPolicy(controllers.make("pid_dob"), ActionSlot(), limit_v=1.0, control_rate_hz=1000.0)
>>> for c in (base, res):
...     c.reset(force_est_n=0.0, setpoint_n=1.0)
>>> base.update(0.1, 1.0, 1e-3, 0.0) == res.update(0.1, 1.0, 1e-3, 0.0)
True
>>> res.observation.shape
(8,)
"""
from __future__ import annotations

import math

import numpy as np

from controllers.base import check_dt, check_finite
from controllers.compiled import resume_controller
from controllers.features import (CURRENT_SCALE_A, N_OBS, N_Z, OBS_HIGH, OBS_LOW, Z_EST_PREV, Z_PREV_ACTION, _clip,
                                  config_vector, observe, policy_action, write_observation)
from ebraille_sim.base.compiled import njit

__all__ = ["N_FRAME", "ActionSlot", "ResidualPolicy", "frame_bounds", "MAX_HISTORY", "advance_frame", "peek_frame",
           "restart_frames", "mlp_action", "P_FIRST", "P_RESIDUAL", "P_ACTION", "P_LIMIT", "P_SUPPLY",
           "P_MODE", "N_P", "MODE_HANDED", "MODE_MLP"]

N_FRAME = N_OBS + 1
"""Numbers per frame: the features of :mod:`controllers.features` and the previous residual action."""

MAX_HISTORY = 64
"""Most frames of a residual policy's observation."""

_PERIOD_TOL = 1e-6

P_FIRST, P_RESIDUAL, P_ACTION, P_LIMIT, P_SUPPLY, P_MODE = range(6)
"""Slots of a compiled residual policy's scalars (:meth:`ResidualPolicy.compiled_policy`): the next
frame is the first after a (re)start (1.0) or not; the residual action held, in [-1, 1]; the
action handed in (:data:`MODE_HANDED`); the correction at ``|a| = 1``, V; the driver supply
that scales the applied command, V; where the action comes from."""
N_P = 6
MODE_HANDED = 0.0
"""The action is handed in each period (``P_ACTION``: an env's agent)."""
MODE_MLP = 1.0
"""The action is the MLP actor's (:func:`mlp_action`) on the period's observation."""

@njit(cache=True, _nrt=True)
def mlp_action(layers, weights, obs, buf):
    """The deterministic action of the MLP actor ``(layers, weights)`` (:meth:`controllers.policy.MlpActor.vectors`) on
    ``obs`` (float32), in float32 as :class:`controllers.policy.MlpActor` computes it (the sums
    in another order), clipped to [-1, 1] (or squashed by ``tanh``); ``buf`` is float32 scratch
    of twice the widest layer."""
    n = layers[0]
    relu = layers[1] == 1
    width = buf.shape[0] // 2
    h = buf[:width]
    g = buf[width:]
    d_in = layers[3]
    for i in range(d_in):
        h[i] = obs[i]
    pos = 0
    for j in range(n):
        d_out = layers[4 + j]
        b0 = pos + d_out * d_in
        for i in range(d_out):
            acc = np.float32(0.0)
            row = pos + i * d_in
            for q in range(d_in):
                acc += weights[row + q] * h[q]
            v = acc + weights[b0 + i]
            if j < n - 1:
                v = (v if v > np.float32(0.0) else np.float32(0.0)) if relu else np.tanh(v)
            g[i] = v
        pos = b0 + d_out
        for i in range(d_out):
            h[i] = g[i]
        d_in = d_out
    a = h[0]
    if layers[2] != 0:
        return float(np.tanh(a))
    return float(min(np.float32(1.0), max(np.float32(-1.0), a)))


def frame_bounds(history: int) -> tuple[np.ndarray, np.ndarray]:
    """``(low, high)`` of an observation of ``history`` frames (float32)."""
    lo = np.tile(np.append(OBS_LOW, np.float32(-1.0)), history).astype(np.float32)
    hi = np.tile(np.append(OBS_HIGH, np.float32(1.0)), history).astype(np.float32)
    return lo, hi


@njit(cache=True, _nrt=True)
def advance_frame(z, frames, c, force_est_n, setpoint_n, current_a, since_s, first, residual, obs):
    """One evaluation's observation: the features ``z`` advanced by ``since_s`` on the
    readings (only written, not advanced, on the ``first`` frame after a reset), pushed as the
    newest frame of ``frames`` (shape ``(history, N_FRAME)``, float32) with the previous
    residual action ``residual``; ``obs`` receives the stack, newest first."""
    for i in range(frames.shape[0] - 1, 0, -1):
        frames[i, :] = frames[i - 1, :]
    row = frames[0, :N_OBS]
    if first:
        write_observation(z, c, force_est_n, setpoint_n, current_a, row)
    else:
        observe(z, c, force_est_n, setpoint_n, current_a, since_s, row)
    frames[0, N_OBS] = residual
    n = frames.shape[1]
    for i in range(frames.shape[0]):
        obs[i * n:(i + 1) * n] = frames[i, :]


@njit(cache=True)
def peek_frame(z, frames, c, force_est_n, setpoint_n, current_a, since_s, first, residual, obs):
    """The observation :func:`advance_frame` would write, into ``obs``, with ``z`` and
    ``frames`` left as they are."""
    advance_frame(z.copy(), frames.copy(), c, force_est_n, setpoint_n, current_a, since_s, first, residual, obs)


@njit(cache=True, _nrt=True)
def restart_frames(z, frames, force_est_n, command_v, supply_v):
    """The features and frames of a (re)started policy (:meth:`ResidualPolicy.reset`): no
    rate, no integral, the command ``command_v`` as the previous one, no frames."""
    z[:] = 0.0
    z[Z_EST_PREV] = force_est_n
    z[Z_PREV_ACTION] = _clip(command_v / supply_v, -1.0, 1.0)
    frames[:] = 0.0


class ActionSlot:
    """A policy whose action is handed in from outside (an env's agent): ``predict`` returns
    :attr:`action` and keeps the observation it was shown."""

    def __init__(self):
        self.action = 0.0
        self.seen = None

    def predict(self, observation, deterministic: bool = True):
        self.seen = observation
        return np.array([self.action], dtype=np.float64), None


class ResidualPolicy:
    """The design's controller ``base`` plus ``limit_v`` times a policy's action (module docstring).

    Parameters
    ----------
    base : controller
        The design's controller (``reset``/``update``; ``applied`` is forwarded when it has one).
    model : object
        ``predict(obs, deterministic) -> (action, state)`` on observations of ``history *
        N_FRAME`` float32 numbers: an SB3 model, :class:`controllers.policy.MlpActor` or
        :class:`ActionSlot`.
    limit_v : float
        The correction at ``|a| = 1``, V (> 0).
    control_rate_hz : float
        The rate the policy was trained at (the design's control rate), Hz.
    history : int
        Frames stacked in the observation, in [1, :data:`MAX_HISTORY`].
    safe_force_n, warn_force_n, rate_filter_s, integral_time_s, driver_supply_v, current_scale_a
        The feature scales (:func:`controllers.features.config_vector`).
    deterministic : bool
        The policy's mean action.
    """

    name = "residual"

    def __init__(self, base, model, limit_v: float, control_rate_hz: float, history: int = 1,
                 safe_force_n: float = 3.0, warn_force_n: float = 2.0, rate_filter_s: float = 0.02,
                 integral_time_s: float = 0.1, driver_supply_v: float = 6.0,
                 current_scale_a: float = CURRENT_SCALE_A, deterministic: bool = True):
        if not (isinstance(limit_v, (int, float)) and math.isfinite(limit_v) and limit_v > 0):
            raise ValueError(f"limit_v must be a positive number of volts, got {limit_v!r}")
        if not (isinstance(control_rate_hz, (int, float)) and math.isfinite(control_rate_hz) and control_rate_hz > 0):
            raise ValueError(f"control_rate_hz must be a positive number, got {control_rate_hz!r}")
        if isinstance(history, bool) or not isinstance(history, (int, np.integer)) or not 1 <= history <= MAX_HISTORY:
            raise ValueError(f"history must be a whole number in [1, {MAX_HISTORY}], got {history!r}")
        if not driver_supply_v > 0:
            raise ValueError(f"driver_supply_v must be > 0, got {driver_supply_v!r}")
        self.base = base
        self.model = model
        self.limit_v = float(limit_v)
        self.history = int(history)
        self.deterministic = bool(deterministic)
        self.period_s = 1.0 / float(control_rate_hz)
        self.supply_v = float(driver_supply_v)
        self._c = config_vector(float(control_rate_hz), safe_force_n, warn_force_n, rate_filter_s, integral_time_s,
                                self.supply_v, current_scale_a=current_scale_a)
        self._z = np.zeros(N_Z)
        self._frames = np.zeros((self.history, N_FRAME), dtype=np.float32)
        self._obs = np.zeros(self.history * N_FRAME, dtype=np.float32)
        self._since_s = 0.0
        self._first = True
        self.residual = 0.0
        self.residual_v = 0.0

    @property
    def observation(self) -> np.ndarray:
        """The observation the policy was last shown (a view)."""
        return self._obs

    def reset(self, *, force_est_n: float, setpoint_n: float, command_v: float = 0.0) -> None:
        """Reset the design's controller and forget the history; the next ``update`` evaluates."""
        fe = check_finite("force_est_n", force_est_n)
        check_finite("setpoint_n", setpoint_n)
        u0 = check_finite("command_v", command_v)
        self.base.reset(force_est_n=force_est_n, setpoint_n=setpoint_n, command_v=command_v)
        self._restart(fe, u0)

    def resume(self, *, force_est_n: float, setpoint_n: float) -> None:
        """The supervisor's resume after regained contact: the design's controller resumes as it
        does alone (:func:`controllers.compiled.resume_controller`: from 0 V, a PID-family or
        disturbance-observer integrator not below 0 V), and the history is forgotten."""
        fe = check_finite("force_est_n", force_est_n)
        check_finite("setpoint_n", setpoint_n)
        resume_controller(self.base, force_est_n=force_est_n, setpoint_n=setpoint_n)
        self._restart(fe, 0.0)

    def _restart(self, force_est_n: float, command_v: float) -> None:
        restart_frames(self._z, self._frames, force_est_n, command_v, self.supply_v)
        self._since_s = 0.0
        self._first = True
        self.residual = 0.0
        self.residual_v = 0.0

    def applied(self, command_v: float) -> None:
        """The command that reached the drive (V), from a supervisor: observed as the previous
        command, and told to the design's controller when it listens."""
        u = float(command_v)
        if math.isfinite(u):
            self._z[Z_PREV_ACTION] = min(1.0, max(-1.0, u / self.supply_v))
        applied = getattr(self.base, "applied", None)
        if applied is not None:
            applied(command_v)

    def peek(self, force_est_n: float, setpoint_n: float, dt_s: float, current_a: float) -> np.ndarray:
        """The observation the next :meth:`update` with these arguments shows the policy,
        without changing anything (an env shows it to its agent before the period)."""
        obs = np.empty_like(self._obs)
        peek_frame(self._z, self._frames, self._c, float(force_est_n), float(setpoint_n), float(current_a),
                   self._since_s + dt_s, self._first, self.residual, obs)
        return obs

    def compiled_policy(self, dt_s: float, handed: bool = False):
        """The arrays of the loop engine's residual period (:func:`ebraille_sim.plant.engine.policy_period`)
        over this policy's live features and frames, or None when it has none.

        ``(p, z, frames, obs, c, layers, weights, z_scratch, frames_scratch, buf)``: the scalars
        (slots ``P_*``, from this policy's), the features, the frame stack, the observation,
        the feature scales, the MLP actor (:meth:`controllers.policy.MlpActor.vectors`) and scratch.  ``handed``: the
        action is handed in each period (an env's agent), the model unused; otherwise the
        model must be a deterministic MLP actor.  The policy must evaluate every period of
        ``dt_s`` (its training rate at least the loop's).
        """
        if handed:
            mlp = (np.zeros(4, dtype=np.int64), np.zeros(0, dtype=np.float32))
        else:
            vectors = getattr(self.model, "vectors", None)
            mlp = vectors() if self.deterministic and callable(vectors) else None
        if mlp is None or dt_s < self.period_s * (1.0 - _PERIOD_TOL):
            return None
        p = np.zeros(N_P)
        p[P_FIRST] = 1.0 if self._first else 0.0
        p[P_RESIDUAL] = self.residual
        p[P_LIMIT] = self.limit_v
        p[P_SUPPLY] = self.supply_v
        p[P_MODE] = MODE_HANDED if handed else MODE_MLP
        buf = np.zeros(2 * int(max(mlp[0][3:].max(initial=1), 1)), dtype=np.float32)
        return (p, self._z, self._frames, self._obs, self._c, mlp[0], mlp[1], np.zeros_like(self._z),
                np.zeros_like(self._frames), buf)

    def took(self, p) -> None:
        """Take the scalars of a compiled run's ``p`` (:meth:`compiled_policy`) back."""
        self._first = bool(p[P_FIRST] != 0.0)
        self.residual = float(p[P_RESIDUAL])
        self.residual_v = self.residual * self.limit_v
        self._since_s = 0.0

    def update(self, force_est_n: float, setpoint_n: float, dt_s: float,
               motor_current_a: float | None = None) -> float:
        """The design's command plus the (held) correction, V."""
        dt = check_dt(dt_s)
        fe = check_finite("force_est_n", force_est_n)
        sp = check_finite("setpoint_n", setpoint_n)
        ia = 0.0 if motor_current_a is None else check_finite("motor_current_a", motor_current_a)
        u = self.base.update(force_est_n, setpoint_n, dt_s, motor_current_a)
        self._since_s += dt
        if self._first or self._since_s >= self.period_s * (1.0 - _PERIOD_TOL):
            advance_frame(self._z, self._frames, self._c, fe, sp, ia, self._since_s, self._first, self.residual,
                          self._obs)
            self._first = False
            self._since_s = 0.0
            self.residual = policy_action(self.model, self._obs, self.deterministic, "residual policy")
            self.residual_v = self.residual * self.limit_v
        return u + self.residual_v
