r"""Discrete PID contact-force controller with anti-windup and bumpless start.

The continuous-time law and its discretisation follow Åström & Hägglund,
*Advanced PID Control* (ISA, 2006), and Åström & Murray, *Feedback Systems*,
chapter "PID Control", section "Implementation"::

    u = sat( P + I + D + u_ff )
    P = kp (b r - y)
    dI/dt = ki (r - y) + (u - v) / Tt          (back-calculation)
    Tf dD/dt + D = kd d(c r - y)/dt             (filtered derivative)

with ``v = P + I + D + u_ff`` the unsaturated output, ``u = sat(v)`` the
output clamped to ``[u_min_v, u_max_v]``, ``r`` the setpoint (N) and ``y``
the force estimate (N). In the Åström-Hägglund parametrisation
``kp = K``, ``ki = K/Ti``, ``kd = K Td`` and ``Tf = Td/N``.

Discretisation (sample ``k``, ``h_k = t_k - t_{k-1}`` is the ``dt_s`` passed
to ``update``):

Integral, forward Euler::

    I_k = I_{k-1} + ki h_k e_{k-1} + a_k (u_{k-1} - v_{k-1}),
    a_k = min(h_k / Tt, 1),     e = r - y

The increment over ``[t_{k-1}, t_k]`` uses the error and saturation residual
of sample ``k-1``, so it is applied at sample ``k`` once ``h_k`` is known. The
tracking gain ``a_k`` is capped at 1: ``a_k = 1`` sets the integrator in one
step to the value that would have put the previous output exactly on the
limit (dead-beat tracking, ``Tt -> 0``), and the cap keeps the tracking loop
stable for any ``Tt >= 0`` and ``dt_s``. With constant error ``e`` and no
saturation, the integral output after reset is ``ki e h k`` at sample
``k = 0, 1, ...``.

Derivative, backward difference. Replace ``d/dt`` by
``(x_k - x_{k-1}) / h_k`` in ``Tf dD/dt + D = kd dw/dt`` with
``w = c r - y``::

    Tf (D_k - D_{k-1}) / h_k + D_k = kd (w_k - w_{k-1}) / h_k
    =>  D_k = (Tf D_{k-1} + kd (w_k - w_{k-1})) / (Tf + h_k)

The pole ``Tf / (Tf + h)`` lies in ``[0, 1)`` for every ``Tf >= 0``, so the
recursion is stable and never rings, even for ``Tf = 0`` (pure backward
difference), unlike Tustin, which puts the pole at ``-1`` as ``Tf -> 0``.
For a unit step in ``y`` at sample 0 with ``D_{-1} = 0`` and constant ``h``::

    D_k = -kd / (Tf + h) * (Tf / (Tf + h))**k,     k = 0, 1, ...

Tracking time default: when ``tracking_time_s`` is None it is derived from
the gains. Åström & Hägglund suggest ``Tt = sqrt(Ti Td)``; with
``Ti = kp/ki`` and ``Td = kd/kp`` this is ``sqrt(kd/ki)``, which is defined
even when ``kp = 0``. Without derivative action (``kd = 0``) it is
``Tt = Ti = kp/ki`` (0 for a pure I controller, i.e. dead-beat tracking).
Without integral action (``ki = 0``) there is nothing to wind up and
back-calculation is disabled whatever ``tracking_time_s`` says; the
integrator then holds the constant bias set by ``reset``. An explicit
``tracking_time_s = math.inf`` disables back-calculation (plain clamping),
which is useful as a reference.

Examples
--------
>>> from controllers.pid import PID, PIDConfig
>>> pid = PID(PIDConfig(kp_v_per_n=2.0, ki_v_per_ns=10.0))
>>> pid.reset(force_est_n=1.0, setpoint_n=1.0, command_v=0.5)
>>> pid.update(1.0, 1.0, 1e-3)      # bumpless: continues from 0.5 V
0.5
>>> pid.update(0.75, 1.0, 1e-3)     # P reacts now, I from the next sample
1.0
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from collections.abc import Mapping
from typing import Any

__all__ = ["DEFAULT_PID", "PID", "PIDConfig", "pid_from_dict"]

_INF = math.inf
_isfinite = math.isfinite


def _as_real(name: str, value: Any) -> float:
    """Return ``value`` as a float; reject bools, non-real values and NaN."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"{name} must be a real number, got {value!r}")
    value = float(value)
    if math.isnan(value):
        raise ValueError(f"{name} must not be NaN, got {value!r}")
    return value


@dataclasses.dataclass(frozen=True)
class PIDConfig:
    """Gains and limits of the discrete PID controller.

    All values are stored as plain Python floats. See the module docstring
    for the control law and its discretisation.

    Parameters
    ----------
    kp_v_per_n : float
        Proportional gain ``kp``, V/N. Finite, >= 0.
    ki_v_per_ns : float, optional
        Integral gain ``ki = kp/Ti``, V/(N s). Finite, >= 0. Default 0.
    kd_vs_per_n : float, optional
        Derivative gain ``kd = kp Td``, V s/N. Finite, >= 0. Default 0.
    derivative_filter_s : float, optional
        Time constant ``Tf`` of the first-order filter on the derivative, s.
        Finite, >= 0; 0 gives an unfiltered backward difference. Default 0.
    setpoint_weight_p : float, optional
        Setpoint weight ``b`` in ``P = kp (b r - y)``. Finite, >= 0.
        Default 1.
    setpoint_weight_d : float, optional
        Setpoint weight ``c`` in the derivative of ``c r - y``. Finite, >= 0.
        Default 0 (derivative on measurement, no setpoint kick).
    u_min_v, u_max_v : float, optional
        Output limits, V. Finite, ``u_min_v < u_max_v``. Default -6, 6 (the
        motor drive's supply range).
    tracking_time_s : float or None, optional
        Back-calculation time constant ``Tt``, s. ``>= 0``; ``math.inf``
        disables back-calculation. None (default) derives it from the gains:
        ``sqrt(kd/ki)`` (= ``sqrt(Ti Td)``) when ``kd > 0``, else
        ``kp/ki`` (= ``Ti``); unused when ``ki = 0``.
    feedforward_v : float, optional
        Constant command added before saturation, V. Finite. Default 0.

    Raises
    ------
    ValueError
        One-line message naming the offending field and value.

    Examples
    --------
    >>> cfg = PIDConfig(kp_v_per_n=2.0, ki_v_per_ns=40.0, kd_vs_per_n=0.02)
    >>> round(cfg.effective_tracking_time_s, 6)
    0.022361
    >>> PIDConfig(kp_v_per_n=-1.0)
    Traceback (most recent call last):
    ...
    ValueError: kp_v_per_n must be >= 0, got -1.0
    """

    kp_v_per_n: float
    ki_v_per_ns: float = 0.0
    kd_vs_per_n: float = 0.0
    derivative_filter_s: float = 0.0
    setpoint_weight_p: float = 1.0
    setpoint_weight_d: float = 0.0
    u_min_v: float = -6.0
    u_max_v: float = 6.0
    tracking_time_s: float | None = None
    feedforward_v: float = 0.0

    def __post_init__(self) -> None:
        nonneg = (
            "kp_v_per_n",
            "ki_v_per_ns",
            "kd_vs_per_n",
            "derivative_filter_s",
            "setpoint_weight_p",
            "setpoint_weight_d",
        )
        for name in nonneg + ("u_min_v", "u_max_v", "feedforward_v"):
            value = _as_real(name, getattr(self, name))
            if not _isfinite(value):
                raise ValueError(f"{name} must be finite, got {value!r}")
            if name in nonneg and value < 0.0:
                raise ValueError(f"{name} must be >= 0, got {value!r}")
            object.__setattr__(self, name, value)
        if not self.u_min_v < self.u_max_v:
            raise ValueError(
                f"u_min_v must be < u_max_v, got u_min_v={self.u_min_v!r}, u_max_v={self.u_max_v!r}"
            )
        if self.tracking_time_s is not None:
            tt = _as_real("tracking_time_s", self.tracking_time_s)
            if tt < 0.0:
                raise ValueError(f"tracking_time_s must be >= 0 (inf disables), got {tt!r}")
            object.__setattr__(self, "tracking_time_s", tt)

    @property
    def effective_tracking_time_s(self) -> float:
        """Back-calculation time constant actually used, s.

        Returns
        -------
        float
            ``math.inf`` when ``ki_v_per_ns == 0`` (no integral action, no
            back-calculation); else ``tracking_time_s`` if given; else
            ``sqrt(kd/ki)`` when ``kd > 0``, otherwise ``kp/ki``.
        """
        if self.ki_v_per_ns == 0.0:
            return _INF
        if self.tracking_time_s is not None:
            return self.tracking_time_s
        if self.kd_vs_per_n > 0.0:
            return math.sqrt(self.kd_vs_per_n / self.ki_v_per_ns)
        return self.kp_v_per_n / self.ki_v_per_ns

    def to_dict(self) -> dict[str, float | None]:
        """Return the fields as a plain dict (inverse of :meth:`from_dict`).

        Returns
        -------
        dict
            Field name -> value.
        """
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], *, base: PIDConfig | None = None) -> PIDConfig:
        """Build a config from a mapping of field values.

        Parameters
        ----------
        d : Mapping[str, Any]
            Field name -> value. Fields not given take their value from
            ``base``.
        base : PIDConfig or None, optional
            Config supplying the omitted fields. None (default) uses
            :data:`DEFAULT_PID`.

        Returns
        -------
        PIDConfig

        Raises
        ------
        ValueError
            If ``d`` has a key that is not a field (the message names the
            key and lists the allowed keys) or a value is invalid.
        TypeError
            If ``d`` is not a mapping.

        Examples
        --------
        >>> PIDConfig.from_dict({"kp_v_per_n": 1.5}).kp_v_per_n
        1.5
        >>> PIDConfig.from_dict({"kp": 1.5})  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        ValueError: unknown PID gain key 'kp'; allowed keys: kp_v_per_n, ki_v_per_ns, ...
        """
        if not isinstance(d, Mapping):
            raise TypeError(f"PID gains must be a mapping, got {type(d).__name__}")
        allowed = _FIELD_NAMES
        for key in d:
            if key not in allowed:
                raise ValueError(f"unknown PID gain key {key!r}; allowed keys: {', '.join(allowed)}")
        return dataclasses.replace(DEFAULT_PID if base is None else base, **d)


_FIELD_NAMES: tuple[str, ...] = tuple(f.name for f in dataclasses.fields(PIDConfig))

DEFAULT_PID = PIDConfig(
    kp_v_per_n=2.0,
    ki_v_per_ns=8.0,
    kd_vs_per_n=0.0,
    derivative_filter_s=0.005,
    setpoint_weight_p=1.0,
    setpoint_weight_d=0.0,
    u_min_v=-6.0,
    u_max_v=6.0,
)
"""Provisional default gains used by ``controllers.make("pid")``."""

_STATE_KEYS: tuple[str, ...] = (
    "integrator_v",
    "derivative_v",
    "prev_derivative_input_n",
    "prev_error_n",
    "prev_saturation_residual_v",
)


class PID:
    """Discrete PID controller implementing :class:`controllers.base.Controller`.

    Forward-Euler integral with back-calculation anti-windup, backward-
    difference filtered derivative on ``c r - y``, output clamped to
    ``[u_min_v, u_max_v]``; see the module docstring for the recursions.

    A freshly constructed controller starts from zero integrator and
    derivative state and takes the first measurement as derivative memory
    (no derivative kick). Call :meth:`reset` for a bumpless start from a
    known command.

    Parameters
    ----------
    config : PIDConfig
        Gains and limits.

    Attributes
    ----------
    name : str
        ``"pid"``.
    config : PIDConfig
        Gains and limits (read-only).

    Examples
    --------
    >>> pid = PID(PIDConfig(kp_v_per_n=2.0, u_min_v=-1.0, u_max_v=1.0))
    >>> pid.update(0.0, 0.25, 1e-3)
    0.5
    >>> pid.update(0.0, 3.0, 1e-3)      # clamped to u_max_v
    1.0
    """

    name: str = "pid"

    __slots__ = (
        "_cfg",
        "_kp",
        "_ki",
        "_kd",
        "_tf",
        "_b",
        "_c",
        "_umin",
        "_umax",
        "_ff",
        "_inv_tt",
        "_i",
        "_d",
        "_w_prev",
        "_e_prev",
        "_res_prev",
        "_primed",
    )

    def __init__(self, config: PIDConfig) -> None:
        if not isinstance(config, PIDConfig):
            raise TypeError(f"config must be a PIDConfig, got {type(config).__name__}")
        self._cfg = config
        self._kp = config.kp_v_per_n
        self._ki = config.ki_v_per_ns
        self._kd = config.kd_vs_per_n
        self._tf = config.derivative_filter_s
        self._b = config.setpoint_weight_p
        self._c = config.setpoint_weight_d
        self._umin = config.u_min_v
        self._umax = config.u_max_v
        self._ff = config.feedforward_v
        tt = config.effective_tracking_time_s
        self._inv_tt = 0.0 if tt == _INF else (_INF if tt == 0.0 else 1.0 / tt)
        self._i = 0.0
        self._d = 0.0
        self._w_prev = 0.0
        self._e_prev = 0.0
        self._res_prev = 0.0
        self._primed = False

    @property
    def config(self) -> PIDConfig:
        """Gains and limits of this controller."""
        return self._cfg

    def __repr__(self) -> str:
        return f"PID({self._cfg!r})"

    def reset(self, *, force_est_n: float, setpoint_n: float, command_v: float = 0.0) -> None:
        """Re-initialise the state for a bumpless start from ``command_v``.

        Sets the integrator so that an ``update`` with the same force and
        setpoint returns ``command_v`` (clamped to the output limits; exact
        when the proportional term is 0, else to floating-point rounding of
        ``P + I``), zeroes
        the derivative and the pending integral increment, and stores
        ``c r - y`` as derivative memory so the first update has no
        derivative kick.

        Parameters
        ----------
        force_est_n : float
            Current force estimate ``y``, N. Finite.
        setpoint_n : float
            Current setpoint ``r``, N. Finite.
        command_v : float, optional
            Command to continue from, V. Finite. Default 0.

        Raises
        ------
        ValueError
            If an argument is not finite.

        Examples
        --------
        >>> pid = PID(PIDConfig(kp_v_per_n=2.0, ki_v_per_ns=5.0, setpoint_weight_p=0.5))
        >>> pid.reset(force_est_n=1.0, setpoint_n=1.0, command_v=1.3)
        >>> round(pid.update(1.0, 1.0, 1e-3), 12)   # P = -1 V absorbed by I
        1.3
        """
        if not _isfinite(force_est_n):
            raise ValueError(f"force_est_n must be finite, got {force_est_n!r}")
        if not _isfinite(setpoint_n):
            raise ValueError(f"setpoint_n must be finite, got {setpoint_n!r}")
        if not _isfinite(command_v):
            raise ValueError(f"command_v must be finite, got {command_v!r}")
        y = float(force_est_n)
        r = float(setpoint_n)
        u0 = min(max(float(command_v), self._umin), self._umax)
        self._i = u0 - self._kp * (self._b * r - y) - self._ff
        self._d = 0.0
        self._w_prev = self._c * r - y
        self._e_prev = 0.0
        self._res_prev = 0.0
        self._primed = True

    def update(
        self,
        force_est_n: float,
        setpoint_n: float,
        dt_s: float,
        motor_current_a: float | None = None,
    ) -> float:
        """Advance one sample and return the motor command.

        Parameters
        ----------
        force_est_n : float
            Force estimate ``y``, N. Finite.
        setpoint_n : float
            Setpoint ``r``, N. Finite.
        dt_s : float
            Time since the previous update or reset, s. Finite, > 0.
        motor_current_a : float or None, optional
            Ignored by this controller.

        Returns
        -------
        float
            Motor command ``u`` in ``[u_min_v, u_max_v]``, V.

        Raises
        ------
        ValueError
            If ``dt_s`` is not finite and > 0, or a force is not finite.
        """
        if not 0.0 < dt_s < _INF:
            raise ValueError(f"dt_s must be finite and > 0, got {dt_s!r}")
        if not _isfinite(force_est_n):
            raise ValueError(f"force_est_n must be finite, got {force_est_n!r}")
        if not _isfinite(setpoint_n):
            raise ValueError(f"setpoint_n must be finite, got {setpoint_n!r}")
        h = float(dt_s)
        y = float(force_est_n)
        r = float(setpoint_n)

        a = h * self._inv_tt
        if a > 1.0:
            a = 1.0
        i = self._i + self._ki * h * self._e_prev + a * self._res_prev

        w = self._c * r - y
        if not self._primed:
            self._w_prev = w
            self._primed = True
        tf = self._tf
        d = (tf * self._d + self._kd * (w - self._w_prev)) / (tf + h)

        v = self._kp * (self._b * r - y) + i + d + self._ff
        u = v
        if u > self._umax:
            u = self._umax
        elif u < self._umin:
            u = self._umin

        self._i = i
        self._d = d
        self._w_prev = w
        self._e_prev = r - y
        self._res_prev = u - v
        return u

    def state(self) -> dict[str, float | None]:
        """Return the internal state as a small dict of floats.

        Returns
        -------
        dict
            ``integrator_v`` (I, V), ``derivative_v`` (D, V),
            ``prev_derivative_input_n`` (``c r - y`` of the last sample, N;
            None before the first update of a never-reset controller),
            ``prev_error_n`` (``r - y`` of the last sample, N) and
            ``prev_saturation_residual_v`` (``u - v`` of the last sample, V).

        Examples
        --------
        >>> pid = PID(PIDConfig(kp_v_per_n=1.0))
        >>> pid.reset(force_est_n=0.0, setpoint_n=0.0, command_v=0.2)
        >>> pid.state()["integrator_v"]
        0.2
        """
        return {
            "integrator_v": self._i,
            "derivative_v": self._d,
            "prev_derivative_input_n": self._w_prev if self._primed else None,
            "prev_error_n": self._e_prev,
            "prev_saturation_residual_v": self._res_prev,
        }

    def set_state(self, state: Mapping[str, float | None]) -> None:
        """Restore a state produced by :meth:`state`.

        Parameters
        ----------
        state : Mapping[str, float]
            Must hold exactly the keys returned by :meth:`state`. All values
            finite, except ``prev_derivative_input_n`` which may be None
            (derivative memory not yet initialised).

        Raises
        ------
        ValueError
            On an unknown or missing key, or a non-finite value.
        """
        for key in state:
            if key not in _STATE_KEYS:
                raise ValueError(f"unknown PID state key {key!r}; allowed keys: {', '.join(_STATE_KEYS)}")
        for key in _STATE_KEYS:
            if key not in state:
                raise ValueError(f"missing PID state key {key!r}; required keys: {', '.join(_STATE_KEYS)}")
        values = {}
        for key in _STATE_KEYS:
            value = state[key]
            if key == "prev_derivative_input_n" and value is None:
                values[key] = None
                continue
            value = _as_real(key, value)
            if not _isfinite(value):
                raise ValueError(f"{key} must be finite, got {value!r}")
            values[key] = value
        w_prev = values["prev_derivative_input_n"]
        self._i = values["integrator_v"]
        self._d = values["derivative_v"]
        self._w_prev = 0.0 if w_prev is None else w_prev
        self._e_prev = values["prev_error_n"]
        self._res_prev = values["prev_saturation_residual_v"]
        self._primed = w_prev is not None


def pid_from_dict(d: Mapping[str, Any], *, base: PIDConfig | None = None) -> PID:
    """Build a :class:`PID` from a mapping of :class:`PIDConfig` fields.

    Parameters
    ----------
    d : Mapping[str, Any]
        Field name -> value; omitted fields take their value from ``base``.
    base : PIDConfig or None, optional
        Config supplying omitted fields; None (default) uses
        :data:`DEFAULT_PID`.

    Returns
    -------
    PID

    Raises
    ------
    ValueError
        On an unknown key (the message names it and lists the allowed keys)
        or an invalid value.

    Examples
    --------
    >>> pid_from_dict({"kp_v_per_n": 3.0}).config.kp_v_per_n
    3.0
    """
    return PID(PIDConfig.from_dict(d, base=base))
