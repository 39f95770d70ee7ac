"""Reference controllers for the benchmark's bounds: fed the true contact force.

A real reader's controller sees the force *estimated* from the FSR.  To separate what the
drive can do from what the sensor chain lets a controller know, the benchmark
(:mod:`ebraille_sim.tools.benchmark`) also runs controllers that are handed the TRUE
contact force at the control rate: no FSR, no anti-alias filter, no 100 Hz estimator, no
estimator bias.  A controller asks for it by declaring ``feedback = "true_force"``; the
scenario runner (:func:`ebraille_sim.scenarios.runner.run_scenario`) then passes the true
force where it would pass the estimate, and every other input (setpoint, ``dt_s``, motor
current, the safety supervisor around it) stays the same.

:class:`TrueForce` wraps any controller this way.  The registered ``actuator_bound`` is the
PID with the setpoint feedforward and friction term of :mod:`controllers.schedule`, with
gains raised to what true-force feedback tolerates (no estimator lag in the loop), not
scheduled over force (the nominal pulp's schedule mistunes soft readers at these gains), and
without the static reference map (there is no estimator bias to undo).  It cannot be built into a reader; it is
the yardstick for what the motor, gearhead and pulp allow with perfect sensing.

Examples
--------
>>> from controllers import make
>>> c = make("actuator_bound")
>>> c.feedback
'true_force'
>>> c.reset(force_est_n=1.0, setpoint_n=1.0, command_v=0.0)
>>> isinstance(c.update(1.0, 1.0, 1e-3), float)
True
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from ebraille_sim.physics.fsr import F_EPS_N, N_PLAYS, hysteresis, inverse_hysteresis, log_force, play_widths

from controllers.base import Controller

__all__ = ["TrueForce", "HysteresisSeen", "ACTUATOR_BOUND_GAINS", "make_actuator_bound", "make_hysteresis_bound"]

ACTUATOR_BOUND_GAINS = {"kp_v_per_n": 10.0, "ki_v_per_ns": 100.0, "kd_vs_per_n": 0.05,
                        "derivative_filter_s": 0.001, "schedule": False}
"""Gains of ``actuator_bound`` (and ``hysteresis_bound``), fixed over force, chosen by hand with
true-force feedback and the safety supervisor on, over the standard suite's readers
(docs/benchmark.md): about 12 times the recommended PID's ``kp``.  Among kp 5-30 V/N and
ki 50-400 V/(N s) they gave the highest worst readers on refresh_120wpm (every character held
on every reader, where kp 20 loses readers to the supervisor's slew and current limits and
kp 30, ki 400 held none) and no lower one on steps, tremor, pressing, onset or battery sag."""


class TrueForce:
    """``inner`` fed the true contact force instead of the estimate.

    Parameters
    ----------
    inner : Controller
        Any controller; its ``update`` receives the true force as ``force_est_n``.
    name : str, optional
        Name on the leaderboard (default ``"true_force:" + inner.name``).
    """

    feedback = "true_force"

    def __init__(self, inner: Controller, name: str | None = None):
        if not hasattr(inner, "update") or not hasattr(inner, "reset"):
            raise TypeError(f"inner must implement the Controller protocol, got {type(inner).__name__}")
        self.inner = inner
        self.name = name or f"true_force:{getattr(inner, 'name', type(inner).__name__)}"

    @property
    def config(self):
        """The inner controller's gains (what a gains file for this entry sets)."""
        return self.inner.config

    def compiled(self):
        """The inner controller's compiled form ``(kind, state, params)``, or None without one
        (the runner feeds it the true force, as it does this wrapper)."""
        get = getattr(self.inner, "compiled", None)
        return get() if callable(get) else None

    def reset(self, *, force_est_n: float, setpoint_n: float, command_v: float = 0.0) -> None:
        """Reset the inner controller (``force_est_n`` is the true force here)."""
        self.inner.reset(force_est_n=force_est_n, setpoint_n=setpoint_n, command_v=command_v)

    def update(self, force_est_n: float, setpoint_n: float, dt_s: float, motor_current_a=None) -> float:
        """One sample of the inner controller (``force_est_n`` is the true force here)."""
        return self.inner.update(force_est_n, setpoint_n, dt_s, motor_current_a)


def make_actuator_bound(**gains: Any) -> TrueForce:
    """Registry factory ``"actuator_bound"``: scheduled PID + friction feedforward on the true force.

    ``gains`` override :data:`ACTUATOR_BOUND_GAINS` (fields of
    :class:`controllers.schedule.ScheduleConfig`).
    """
    from controllers.schedule import make_feedforward
    inner = make_feedforward(**{"reference_map": False, **ACTUATOR_BOUND_GAINS, **gains})
    return TrueForce(inner, name="actuator_bound")


class HysteresisSeen:
    """``inner`` fed the true contact force as the FSR's hysteresis lets a firmware know it.

    Each sample the true force passes through the unit's play operators, the law the plant's
    film applies (:func:`ebraille_sim.physics.fsr.hysteresis`, widths and weights of
    :func:`ebraille_sim.physics.fsr.play_widths`), and then through their exact inverse
    (:func:`ebraille_sim.physics.fsr.inverse_hysteresis`), the step the hysteresis-compensated
    estimator takes, without the film's conduction law, ADC, noise, creep, filter or 100 Hz
    rate.  What the inner controller sees is the true force except in the stretch after a
    reversal that the film does not show: there it holds the last force the film did show.

    Parameters
    ----------
    inner : Controller
        Any controller; its ``update`` receives the force so seen as ``force_est_n``.
    fsr : FSRParams
        The unit whose film is modelled (its ``hysteresis_fraction``).
    name : str, optional
        Name on the leaderboard.

    Examples
    --------
    >>> from ebraille_sim.physics.params import FSRParams
    >>> c = make_hysteresis_bound(FSRParams())
    >>> c.reset(force_est_n=1.0, setpoint_n=1.0)
    >>> [round(c.seen_force_n(f), 3) for f in (1.1, 1.2, 1.17, 1.15, 1.14)]   # blind for 3.2 % down
    [1.1, 1.2, 1.2, 1.15, 1.14]
    """

    feedback = "true_force"

    def __init__(self, inner: Controller, fsr, name: str = "hysteresis_bound"):
        if not hasattr(inner, "update") or not hasattr(inner, "reset"):
            raise TypeError(f"inner must implement the Controller protocol, got {type(inner).__name__}")
        widths, weights = play_widths(fsr)
        self.inner = inner
        self.name = name
        self._p = np.array([*widths, *weights], dtype=float)
        self._film = np.zeros(N_PLAYS)
        self._inv = np.zeros(N_PLAYS)
        self._x = log_force(0.0)

    @property
    def config(self):
        """The inner controller's gains."""
        return self.inner.config

    def compiled(self):
        """None: the film's operators run in the per-period path."""
        return None

    def seen_force_n(self, force_n: float) -> float:
        """Advance the film and its inverse by one sample of the true force; the force seen, N."""
        f = max(float(force_n), 0.0)
        l_out = math.log(hysteresis(f, self._film, 0, self._p, 0, N_PLAYS, N_PLAYS) + F_EPS_N)
        self._x = inverse_hysteresis(l_out, self._x, self._inv, 0, self._p, 0, N_PLAYS, N_PLAYS)
        return math.exp(self._x) - F_EPS_N

    def reset(self, *, force_est_n: float, setpoint_n: float, command_v: float = 0.0) -> None:
        """Both operators on their loading branch at the present true force ``force_est_n`` (as
        after a press to it); reset the inner controller."""
        self._x = log_force(max(float(force_est_n), 0.0))
        self._film[:] = self._x - self._p[:N_PLAYS]
        self._inv[:] = self._film
        self.inner.reset(force_est_n=force_est_n, setpoint_n=setpoint_n, command_v=command_v)

    def update(self, force_est_n: float, setpoint_n: float, dt_s: float, motor_current_a=None) -> float:
        """One sample of the inner controller on the force seen (``force_est_n`` is the true force)."""
        return self.inner.update(self.seen_force_n(force_est_n), setpoint_n, dt_s, motor_current_a)


def make_hysteresis_bound(fsr, **gains: Any) -> HysteresisSeen:
    """The benchmark's ``hysteresis_bound``: ``actuator_bound``'s controller behind ``fsr``'s hysteresis.

    ``gains`` override :data:`ACTUATOR_BOUND_GAINS`.
    """
    return HysteresisSeen(make_actuator_bound(**gains).inner, fsr)
