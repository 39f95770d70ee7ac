"""LQG force controller: Kalman observer and LQ state feedback with integral action.

The controller is handed its design model: a discrete-time ``control.StateSpace`` from
the command (held over a sample) to the estimated force, with the operating point
``(u0, y0)`` it was linearised at.  The registered ``"lqg"`` uses the sampled-data plant of
:func:`ebraille_sim.analysis.sampled.linearize` at the estimator rate for the nominal device
at ``design_force_n`` (:func:`ebraille_sim.analysis.design.make_lqg`).  The controller is therefore a sampled-data controller at the
estimator period ``sample_s`` (0.01 s): the measured signal only changes at that rate.
It accumulates the ``dt_s`` it is given and acts when a full ``sample_s`` has elapsed,
holding its command in between (its rate is a named, documented parameter, not a hidden
gate: with ``sample_s`` equal to the control period it acts on every call).

Per sample ``n`` (deviations from the design operating point ``(u0, y0)``)::

    x^  <- x^ + L (y_n - C x^)                         (Kalman measurement update)
    z   <- z + Ts (y_n - r_n)                          (integral of the error, only while
                                                        the command is not saturated)
    u_n = u0 + Nu dr - K (x^ - Nx dr) - kz z           (2-DOF: reference feedforward)
    x^  <- A x^ + B (sat(u_n) - u0)                    (prediction with the applied command)

with ``dr = r_n - y0`` and ``(Nx, Nu)`` the model's steady state for the output ``dr``.
``K, kz`` come from ``control.dlqr`` on the model augmented with the integrator (weights
``q_force`` on the force error, ``q_integral`` on its integral, ``r_command`` on the
command); ``L`` from ``control.dlqe`` with process noise ``w_command_v`` on the command
(friction and stiction act there) and measurement noise ``v_force_n`` (estimate noise).

Examples
--------
>>> import control
>>> from controllers.lqg import LQG, LQGConfig
>>> model = control.ss([[0.9]], [[0.1]], [[1.0]], [[0.0]], dt=0.01)   # a toy first-order plant
>>> c = LQG(LQGConfig(), model, command_v=0.5, estimate_n=1.0)
>>> c.reset(force_est_n=1.0, setpoint_n=1.0, command_v=0.5)
>>> abs(c.update(1.0, 1.0, 1e-3) - 0.5) < 0.6
True
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import control
import numpy as np

from ebraille_sim.base.fields import sourced
from ebraille_sim.base.validation import check_number, replace_checked

from controllers.base import check_reset_args, check_update_args
from controllers.compiled import KIND_LQG, lqg_params, lqg_reset, lqg_state, lqg_step
from controllers.pid import GAIN_SOURCE, pid_field

__all__ = ["LQGConfig", "LQG", "design", "config_from"]


@dataclass(frozen=True)
class LQGConfig:
    """Weights and design point of :class:`LQG`."""
    design_force_n: float = sourced(1.0, "N", GAIN_SOURCE, doc="Force at which the plant is linearised for the "
                                                               "design.")
    q_force: float = sourced(1.0, "1/N^2", GAIN_SOURCE, doc="LQR weight on the squared force error.")
    q_integral: float = sourced(60.0, "1/(N^2 s^2)", GAIN_SOURCE, doc="LQR weight on the squared integral of the "
                                                                      "force error.")
    r_command: float = sourced(0.08, "1/V^2", GAIN_SOURCE, doc="LQR weight on the squared command.")
    w_command_v: float = sourced(0.3, "V", GAIN_SOURCE, doc="Kalman filter: process noise on the command "
                                                            "(friction and stiction act there).")
    v_force_n: float = sourced(0.01, "N", GAIN_SOURCE, doc="Kalman filter: measurement noise of the estimate.")
    sample_s: float = sourced(0.01, "s", "[R] seed paper: the 100 Hz estimator period",
                              doc="Sampling period of the controller (the estimator's).")
    u_min_v: float = pid_field("u_min_v", -6.0, "[R] the drive's -6 V supply")
    u_max_v: float = pid_field("u_max_v", 6.0, "[R] the drive's 6 V supply")

    def __post_init__(self):
        for f in dataclasses.fields(self):
            limits = {} if f.name in ("u_min_v", "u_max_v") else {"lo": 0.0, "lo_open": True}
            object.__setattr__(self, f.name, check_number(f.name, getattr(self, f.name), **limits))
        if not self.u_min_v < self.u_max_v:
            raise ValueError(f"u_min_v must be < u_max_v, got u_min_v={self.u_min_v!r}, u_max_v={self.u_max_v!r}")

    @classmethod
    def from_dict(cls, d, *, base: LQGConfig | None = None) -> LQGConfig:
        """A config from field values; omitted fields from ``base`` (default ``LQGConfig()``).

        Raises
        ------
        ValueError
            On an unknown key (named, with the allowed ones) or an invalid value.
        """
        return replace_checked(cls() if base is None else base, **d)


def design(config: LQGConfig, plant: control.StateSpace, command_v: float, estimate_n: float) -> dict:
    """Matrices of the LQG design (model, gains, operating point).

    Parameters
    ----------
    config : LQGConfig
    plant : control.StateSpace
        Discrete-time single-input single-output design model, command (V) to the
        estimated force (N), sampled at ``config.sample_s``.
    command_v, estimate_n : float
        The operating point the model was linearised at.
    """
    if not (plant.isdtime(strict=True) and plant.ninputs == 1 and plant.noutputs == 1):
        raise ValueError("the LQG design model must be a discrete-time SISO state space")
    if not math.isclose(plant.dt, config.sample_s):
        raise ValueError(f"sample_s ({config.sample_s:g}) must equal the estimator period ({plant.dt:g} s)")
    A, B, C = plant.A, plant.B, plant.C
    n = A.shape[0]
    ts = plant.dt
    Aa = np.block([[A, np.zeros((n, 1))], [ts * C, np.ones((1, 1))]])
    Ba = np.vstack([B, np.zeros((1, 1))])
    Q = np.zeros((n + 1, n + 1))
    Q[:n, :n] = config.q_force * (C.T @ C)
    Q[n, n] = config.q_integral
    Ka, _, _ = control.dlqr(Aa, Ba, Q, [[config.r_command]])
    L, _, _ = control.dlqe(A, B, C, [[config.w_command_v ** 2]], [[config.v_force_n ** 2]])
    # steady state of the model for a unit output
    M = np.block([[A - np.eye(n), B], [C, np.zeros((1, 1))]])
    sol = np.linalg.solve(M, np.concatenate([np.zeros(n), [1.0]]))
    return {"A": A, "B": B, "C": C, "K": Ka[:, :n], "kz": float(Ka[0, n]), "L": np.asarray(L),
            "Nx": sol[:n], "Nu": float(sol[n]), "u0": float(command_v), "y0": float(estimate_n), "plant": plant,
            "state_labels": plant.state_labels}


class LQG:
    """Sampled-data LQG controller (see the module docstring)."""

    name = "lqg"

    def __init__(self, config: LQGConfig, model: control.StateSpace, command_v: float, estimate_n: float):
        self.config = config
        d = design(config, model, command_v, estimate_n)
        self._d = d
        self._A, self._B, self._C = d["A"], d["B"][:, 0], d["C"][0]
        self._K, self._kz, self._L = d["K"][0], d["kz"], d["L"][:, 0]
        self._Nx, self._Nu, self._u0, self._y0 = d["Nx"], d["Nu"], d["u0"], d["y0"]
        self._p = lqg_params(sample_s=config.sample_s, u_min_v=config.u_min_v, u_max_v=config.u_max_v,
                             u0_v=self._u0, y0_n=self._y0, nu_v_per_n=self._Nu, kz=self._kz, A=self._A,
                             B=self._B, C=self._C, K=self._K, L=self._L, Nx=self._Nx)
        self._s = lqg_state(self._A.shape[0])

    def compiled(self) -> tuple[int, np.ndarray, np.ndarray]:
        """``(kind, state, params)`` of the compiled step (:mod:`controllers.compiled`): the
        live vectors, so a compiled loop leaves its final state in this controller."""
        return KIND_LQG, self._s, self._p

    def statespace(self) -> control.StateSpace:
        """The linear controller at ``sample_s``: inputs (setpoint, estimate), output command deviation.

        States: the observer's prediction and the integrator.  Used by
        :func:`ebraille_sim.analysis.sampled.loop_models` for the margins and Ms.
        """
        A, B, C, L, K, kz = self._A, self._B[:, None], self._C[None, :], self._L[:, None], self._K[None, :], self._kz
        ts, Nx, Nu = self.config.sample_s, self._Nx[:, None], self._Nu
        n = A.shape[0]
        # x^+|n = (I - L C) x^ + L y ; u = -K x^+|n - kz z+ + (Nu + K Nx) r ; z+ = z + ts (y - r)
        # predicted x^(n+1) = A x^+|n + B u
        Mx = np.eye(n) - L @ C
        ux = -K @ Mx
        uy = -K @ L - kz * ts
        ur = Nu + K @ Nx + kz * ts
        uz = -kz
        Ac = np.block([[A @ Mx + B @ ux, B * uz], [np.zeros((1, n)), np.ones((1, 1))]])
        Bc = np.block([[B * ur, A @ L + B * uy], [np.array([[-ts, ts]])]])
        Cc = np.hstack([ux, [[uz]]])
        Dc = np.array([[ur[0, 0], uy[0, 0]]])
        return control.ss(Ac, Bc, Cc, Dc, dt=ts, inputs=["setpoint_n", "force_est_n"], outputs=["command_v"])

    def reset(self, *, force_est_n: float, setpoint_n: float, command_v: float = 0.0) -> None:
        """Bumpless start: the observer at the model's steady state for ``force_est_n``, the
        integrator so that the first command equals ``command_v`` (clamped to the limits)."""
        force_est_n, setpoint_n, command_v = check_reset_args(force_est_n, setpoint_n, command_v)
        lqg_reset(self._s, self._p, force_est_n, setpoint_n, command_v)

    def update(self, force_est_n: float, setpoint_n: float, dt_s: float, motor_current_a=None) -> float:
        """One call: a new command once a full ``sample_s`` has elapsed, else the held one (V)."""
        y, r, h = check_update_args(force_est_n, setpoint_n, dt_s)
        return lqg_step(self._s, self._p, y, r, h)


def config_from(**gains) -> LQGConfig:
    """:class:`LQGConfig` from keyword arguments; an unknown key is a one-line error."""
    return LQGConfig.from_dict(gains)
