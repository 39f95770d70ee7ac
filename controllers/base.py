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

__all__ = ["Controller", "check_dt", "check_finite"]


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
        If ``dt_s`` is NaN, infinite, zero or negative.

    Examples
    --------
    >>> check_dt(1e-3)
    0.001
    >>> check_dt(0.0)
    Traceback (most recent call last):
    ...
    ValueError: dt_s must be finite and > 0, got 0.0
    """
    if not 0.0 < dt_s < math.inf:
        raise ValueError(f"dt_s must be finite and > 0, got {dt_s!r}")
    return float(dt_s)


def check_finite(name: str, value: float) -> float:
    """Return ``value`` as a float if it is finite.

    Parameters
    ----------
    name : str
        Argument name used in the error message.
    value : float
        Value to check.

    Returns
    -------
    float
        ``float(value)``.

    Raises
    ------
    ValueError
        If ``value`` is NaN or infinite.

    Examples
    --------
    >>> check_finite("force_est_n", float("nan"))
    Traceback (most recent call last):
    ...
    ValueError: force_est_n must be finite, got nan
    """
    if not math.isfinite(value):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return float(value)


def check_update_args(force_est_n: float, setpoint_n: float, dt_s: float) -> tuple[float, float, float]:
    """Validate the arguments of :meth:`Controller.update`; return them as floats.

    Raises
    ------
    ValueError
        One line naming the first bad argument (non-finite force or setpoint, dt_s not > 0).
    """
    return (check_finite("force_est_n", force_est_n), check_finite("setpoint_n", setpoint_n),
            check_dt(dt_s))
