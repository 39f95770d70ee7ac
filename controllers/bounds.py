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

from typing import Any

from controllers.base import Controller

__all__ = ["TrueForce", "ACTUATOR_BOUND_GAINS", "make_actuator_bound"]

ACTUATOR_BOUND_GAINS = {"kp_v_per_n": 30.0, "ki_v_per_ns": 400.0, "kd_vs_per_n": 0.05,
                        "derivative_filter_s": 0.001, "schedule": False}
"""Gains of ``actuator_bound``, fixed over force, chosen by hand with true-force feedback on
``pressing_90wpm``, ``setpoint_steps`` and ``refresh_60/120wpm`` over the standard suite's
readers (docs/benchmark.md): about 35 times the recommended PID's ``kp``; doubling them again changes
no worst case by more than 0.01."""


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
