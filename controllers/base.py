"""Controller protocol shared by every contact-force controller.

A controller sees only what the reader's microcontroller sees: the contact
force estimated from the FSR (N), the force setpoint (N), the time elapsed
since the previous call (s) and, when the drive measures it, the motor
current (A). It returns the motor command in volts.

Rules every implementation follows:

* Time is always an argument. A controller never reads a wall clock and never
  gates itself on a hidden sample rate; ``dt_s`` is the time since the
  previous ``update`` (or since ``reset``) and must be finite and > 0.
* ``reset`` gives a bumpless start: the first ``update`` after
  ``reset(..., command_v=u0)`` with the same force and setpoint returns ``u0``
  (clamped to the controller's output range).
* Invalid inputs raise ``ValueError`` with a one-line message that names the
  argument and its value.

Examples
--------
>>> from controllers import make
>>> ctrl = make("pid")
>>> ctrl.reset(force_est_n=0.5, setpoint_n=0.5, command_v=1.3)
>>> ctrl.update(0.5, 0.5, 1e-3)
1.3
"""

from __future__ import annotations

import math
from typing import Protocol, runtime_checkable

from ebraille_sim.base.validation import check_finite, check_positive

__all__ = ["Controller", "check_dt", "check_finite", "check_update_args", "check_reset_args"]

_INF = math.inf
_isfinite = math.isfinite


@runtime_checkable
class Controller(Protocol):
    """Discrete-time contact-force controller.

    Attributes
    ----------
    name : str
        Registry name of the controller family (e.g. ``"pid"``).
    """

    name: str

    def reset(self, *, force_est_n: float, setpoint_n: float, command_v: float = 0.0) -> None:
        """Re-initialise the internal state for a bumpless start.

        Parameters
        ----------
        force_est_n : float
            Current force estimate, N. Must be finite.
        setpoint_n : float
            Current force setpoint, N. Must be finite.
        command_v : float, optional
            Motor command the first ``update`` continues from, V.
            Default 0.0.

        Raises
        ------
        ValueError
            If an argument is not finite.
        """
        ...

    def update(
        self,
        force_est_n: float,
        setpoint_n: float,
        dt_s: float,
        motor_current_a: float | None = None,
    ) -> float:
        """Advance the controller by one sample and return the motor command.

        Parameters
        ----------
        force_est_n : float
            Force estimated from the FSR at this sample, N. Must be finite.
        setpoint_n : float
            Force setpoint at this sample, N. Must be finite.
        dt_s : float
            Time since the previous ``update`` (or ``reset``), s. Must be
            finite and > 0.
        motor_current_a : float or None, optional
            Measured motor current, A, if the drive provides it.

        Returns
        -------
        float
            Motor command, V.

        Raises
        ------
        ValueError
            If ``dt_s`` is not finite and > 0, or a force is not finite.
        """
        ...


def check_dt(dt_s: float) -> float:
    """Return ``dt_s`` as a float if it is finite and > 0.

    Parameters
    ----------
    dt_s : float
        Sample interval, s.

    Returns
    -------
    float
        ``float(dt_s)``.

    Raises
    ------
    ValueError
        If ``dt_s`` is not a number, NaN, infinite, zero or negative.

    Examples
    --------
    >>> check_dt(1e-3)
    0.001
    >>> check_dt(0.0)
    Traceback (most recent call last):
    ...
    ValueError: dt_s must be > 0, got 0.0
    """
    return check_positive("dt_s", dt_s)


def check_update_args(force_est_n: float, setpoint_n: float, dt_s: float) -> tuple[float, float, float]:
    """Validate the arguments of :meth:`Controller.update`; return them as floats.

    Raises
    ------
    ValueError
        One line naming the first bad argument (non-finite force or setpoint, dt_s not > 0).
    """
    try:
        if 0.0 < dt_s < _INF and _isfinite(force_est_n) and _isfinite(setpoint_n):
            return float(force_est_n), float(setpoint_n), float(dt_s)
    except TypeError:
        pass
    return (check_finite("force_est_n", force_est_n), check_finite("setpoint_n", setpoint_n),
            check_dt(dt_s))


def check_reset_args(force_est_n: float, setpoint_n: float, command_v: float) -> tuple[float, float, float]:
    """Validate the arguments of :meth:`Controller.reset`; return them as floats.

    Raises
    ------
    ValueError
        One line naming the first non-finite argument.
    """
    return (check_finite("force_est_n", force_est_n), check_finite("setpoint_n", setpoint_n),
            check_finite("command_v", command_v))
