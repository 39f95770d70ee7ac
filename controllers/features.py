"""Observation features of a learned contact-force controller, computed from the microcontroller's signals.

One definition, compiled, shared by the Gymnasium environment (:mod:`ebraille_sim.rl.env`),
its vectorised form and :class:`controllers.policy.PolicyController`, so a policy sees the
same observation in training and as a scenario controller.

The observation (shape ``(N_OBS,)``, float32) is built from the force estimate, the
setpoint, the motor current and a few carried features ``z`` (previous estimate, filtered
rate of the estimate, clipped error integral, previous action), scaled by a per-controller
configuration vector ``c`` (slots ``C_*``).
"""
from __future__ import annotations

import math

import numpy as np

from ebraille_sim.base.compiled import njit

__all__ = ["N_OBS", "OBS_LOW", "OBS_HIGH", "N_Z", "N_C", "config_vector", "observe", "write_observation",
           "reset_features", "policy_action"]

N_OBS = 7
OBS_LOW = np.array([-1.0, 0.0, -2.0, -3.0, -1.0, -1.0, -3.0], dtype=np.float32)
OBS_HIGH = np.array([2.0, 1.0, 2.0, 3.0, 1.0, 1.0, 3.0], dtype=np.float32)

CURRENT_SCALE_A = 6.0 / 21.2
"""Default current scale of the observation: stall current of the nominal Faulhaber
0816 006 SR at its 6 V supply, A ([D] U/R, R = 21.2 ohm).  The env passes its base device's
``driver_supply_v / resistance_ohm`` to :func:`config_vector` and records it in the policy
metadata (``current_scale_a``)."""
RATE_SCALE_N_PER_S = 10.0
ERROR_SCALE_N = 1.0

# env-state slots (per env, float64): carried between steps by observe()
Z_EST_PREV, Z_RATE, Z_INT, Z_PREV_ACTION, Z_STEP = range(5)
N_Z = 5
# config slots (per env, float64)
(C_DT, C_FS, C_WARN, C_SAFE, C_RATE_ALPHA, C_INT_GAIN, C_CMD_SCALE, C_WU, C_WV, C_CURRENT_SCALE) = range(10)
N_C = 10


@njit(cache=True, inline="always")
def _clip(x, lo, hi):
    if x < lo:
        return lo
    if x > hi:
        return hi
    return x


@njit(cache=True)
def write_observation(z, c, force_est_n, setpoint_n, current_a, obs):
    """Fill ``obs`` (shape (7,)) from the estimate, setpoint, current and carried state ``z``."""
    fs = c[C_FS]
    obs[0] = _clip(force_est_n / fs, -1.0, 2.0)
    obs[1] = _clip(setpoint_n / fs, 0.0, 1.0)
    obs[2] = _clip((setpoint_n - force_est_n) / fs, -2.0, 2.0)
    obs[3] = _clip(z[Z_RATE] / RATE_SCALE_N_PER_S, -3.0, 3.0)
    obs[4] = z[Z_INT]
    obs[5] = z[Z_PREV_ACTION]
    obs[6] = _clip(current_a / c[C_CURRENT_SCALE], -3.0, 3.0)


@njit(cache=True)
def observe(z, c, force_est_n, setpoint_n, current_a, dt_s, obs):
    """Advance the microcontroller-side features by ``dt_s`` and write the observation.

    Parameters
    ----------
    z : ndarray, shape (N_Z,)
        Carried features (previous estimate, filtered rate, error integral, previous
        action); updated in place.  ``z[Z_PREV_ACTION]`` must already hold the action just
        applied.
    c : ndarray, shape (N_C,)
        Configuration (scales, filter gains).
    force_est_n, setpoint_n, current_a : float
        The microcontroller's readings at the new sample (N, N, A).
    dt_s : float
        Time since the previous sample, s.
    obs : ndarray, shape (7,), float32
        Output.
    """
    raw = (force_est_n - z[Z_EST_PREV]) / dt_s
    z[Z_RATE] += c[C_RATE_ALPHA] * (raw - z[Z_RATE])
    z[Z_EST_PREV] = force_est_n
    z[Z_INT] = _clip(z[Z_INT] + dt_s * c[C_INT_GAIN] * (setpoint_n - force_est_n) / c[C_FS], -1.0, 1.0)
    write_observation(z, c, force_est_n, setpoint_n, current_a, obs)


def reset_features(z, force_est_n: float) -> None:
    """Carried features at the start of an episode (no rate, no integral, no action)."""
    z[:] = 0.0
    z[Z_EST_PREV] = force_est_n


def config_vector(control_rate_hz: float, safe_force_n: float, warn_force_n: float, rate_filter_s: float,
                  integral_time_s: float, driver_supply_v: float, effort_weight: float = 0.0,
                  violation_weight: float = 0.0, current_scale_a: float = CURRENT_SCALE_A) -> np.ndarray:
    """The configuration vector ``c`` of :func:`observe` (and of the env's reward).

    ``safe_force_n`` scales the forces, ``rate_filter_s`` is the time constant of the
    rate's low-pass, ``integral_time_s`` that of the error integral, ``driver_supply_v``
    turns an action in [-1, 1] into volts, ``current_scale_a`` (A, > 0) scales the motor
    current (the stall current at the driver supply, :data:`CURRENT_SCALE_A` by default).
    """
    if not (np.isfinite(current_scale_a) and current_scale_a > 0):
        raise ValueError(f"current_scale_a must be a positive number, got {current_scale_a!r}")
    c = np.zeros(N_C)
    dt = 1.0 / control_rate_hz
    c[C_DT] = dt
    c[C_FS] = safe_force_n
    c[C_WARN] = warn_force_n
    c[C_SAFE] = safe_force_n
    c[C_RATE_ALPHA] = dt / (rate_filter_s + dt)
    c[C_INT_GAIN] = 1.0 / integral_time_s
    c[C_CMD_SCALE] = driver_supply_v
    c[C_WU] = effort_weight
    c[C_WV] = violation_weight
    c[C_CURRENT_SCALE] = current_scale_a
    return c


def policy_action(model, obs, deterministic: bool, what: str = "policy") -> float:
    """The learned ``model``'s action on ``obs``, a scalar clipped to [-1, 1]; a non-finite action is
    a one-line ``ValueError`` naming ``what`` returned it (never a NaN command)."""
    action, _ = model.predict(obs, deterministic=deterministic)
    a = float(np.asarray(action, dtype=np.float64).reshape(-1)[0])
    if not math.isfinite(a):
        raise ValueError(f"the {what} returned a non-finite action {a!r}")
    return min(1.0, max(-1.0, a))
