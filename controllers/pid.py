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

Gain scaling above a force: with ``schedule_above_n = F_s`` the three gains are multiplied
by ``K(F_s) / K(r)`` at setpoints ``r > F_s``, ``K`` the relaxed tangent stiffness of the
pulp (:func:`pulp_stiffness_n_per_m`).  The loop gain from command to force is
proportional to ``K``, which grows about threefold from 1 to 3 N; the scaling keeps it
at its ``F_s`` value.  The derived tracking time depends only on gain ratios and is
unchanged.  The default controller scales above 1 N (:data:`DEFAULT_PID`).

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
from collections.abc import Mapping
from typing import Any

import numpy as np

from ebraille_sim.base.fields import sourced
from ebraille_sim.base.validation import check_finite, check_keys, check_number
from ebraille_sim.physics.fingertip import dynamic_stiffness_n_per_m, tangent_stiffness_n_per_m
from ebraille_sim.physics.params import TACTILE_FORCE_MAX_N, TACTILE_FORCE_MIN_N, DeviceParams

from controllers.base import check_update_args
from controllers.compiled import KIND_PID, PS, core_reset, core_step, pid_params, pid_reset, pid_state, pid_step

__all__ = ["DEFAULT_PID", "PID", "PIDConfig", "PIDCore", "pid_from_dict", "tracking_time_s", "pulp_stiffness_n_per_m",
           "fixed_gain_slots", "LOOP_CROSSOVER_HZ"]

_INF = math.inf


def tracking_time_s(kp: float, ki: float, kd: float, explicit: float | None = None) -> float:
    """Back-calculation time constant ``Tt`` of the gains (module docstring), s.

    Parameters
    ----------
    kp, ki, kd : float
        Proportional (V/N), integral (V/(N s)) and derivative (V s/N) gains, >= 0.
    explicit : float or None, optional
        A given ``Tt`` (``math.inf`` disables back-calculation); None derives it.

    Returns
    -------
    float
        ``math.inf`` when ``ki == 0``; else ``explicit`` if given; else ``sqrt(kd/ki)``
        when ``kd > 0``, otherwise ``kp/ki``.

    Examples
    --------
    >>> tracking_time_s(2.0, 8.0, 0.0)
    0.25
    >>> tracking_time_s(2.0, 0.0, 0.1)
    inf
    """
    if ki == 0.0:
        return _INF
    if explicit is not None:
        return explicit
    if kd > 0.0:
        return math.sqrt(kd / ki)
    return kp / ki


def tracking_gain_per_s(tt_s: float) -> float:
    """``1/Tt`` as used by :meth:`PIDCore.step`: 0 for ``Tt = inf``, inf for ``Tt = 0``."""
    return 0.0 if tt_s == _INF else (_INF if tt_s == 0.0 else 1.0 / tt_s)


LOOP_CROSSOVER_HZ = 6.4
"""Gain crossover of the default PID on the nominal reader at 1 N, Hz ([D]
:func:`ebraille_sim.analysis.margins.analyse_loop`: 6.43 Hz, 40.4 rad/s): the time scale of the loop,
at which :func:`pulp_stiffness_n_per_m` reads the pulp when asked for it."""


def pulp_stiffness_n_per_m(force_n: float, device: DeviceParams = DeviceParams(),
                           frequency_hz: float | None = None) -> float:
    """Stiffness of the pulp about a relaxed contact force ``force_n``, N/m.

    Without ``frequency_hz``: ``K(F) = b + m F / c0``, the tangent stiffness of the elastic law
    (:func:`ebraille_sim.physics.fingertip.tangent_stiffness_n_per_m`) at the elastic force
    ``F / c0`` on which a relaxed contact force ``F`` sits: the stiffness of an instant change,
    which the gain rules, the feedforward and the DOB's nominal model use.  With
    ``frequency_hz``: ``|K(jw)| = K(F) |G*(jw)|``
    (:func:`ebraille_sim.physics.fingertip.dynamic_stiffness_n_per_m`), e.g. at
    :data:`LOOP_CROSSOVER_HZ` 2.5 kN/m at 1 N against the instantaneous 8.6 kN/m.  The ratio
    of two forces' stiffnesses is the same at every frequency.

    Examples
    --------
    >>> round(pulp_stiffness_n_per_m(1.0)), round(pulp_stiffness_n_per_m(1.0, frequency_hz=LOOP_CROSSOVER_HZ))
    (8571, 2533)
    """
    f = device.finger
    if frequency_hz is not None:
        return dynamic_stiffness_n_per_m(f, force_n, frequency_hz)
    return tangent_stiffness_n_per_m(force_n / f.relax_weight_inf, f.stiffness_b_n_per_m, f.exponent_m_per_m)


def stiffness_ratio(force_n: float, reference_force_n: float, device: DeviceParams = DeviceParams()) -> float:
    """``K(F_ref) / K(F)`` with ``K`` from :func:`pulp_stiffness_n_per_m`, ``F`` clipped to the
    tactile range [``TACTILE_FORCE_MIN_N``, ``TACTILE_FORCE_MAX_N``]."""
    return (pulp_stiffness_n_per_m(reference_force_n, device)
            / pulp_stiffness_n_per_m(min(max(force_n, TACTILE_FORCE_MIN_N), TACTILE_FORCE_MAX_N), device))


def fixed_gain_slots(config: PIDConfig) -> dict:
    """The slots of :data:`controllers.compiled.PP` of the fixed-gain PID (``variant`` 0) of
    ``config``, by name: gains, limits, tracking gain, constant feedforward and the gain scaling
    above ``schedule_above_n`` on the nominal pulp."""
    finger = DeviceParams().finger
    f_s = config.schedule_above_n
    return dict(variant=0.0, kp_v_per_n=config.kp_v_per_n, ki_v_per_ns=config.ki_v_per_ns,
                kd_vs_per_n=config.kd_vs_per_n, derivative_filter_s=config.derivative_filter_s,
                setpoint_weight_p=config.setpoint_weight_p, setpoint_weight_d=config.setpoint_weight_d,
                u_min_v=config.u_min_v, u_max_v=config.u_max_v,
                tracking_gain_per_s=tracking_gain_per_s(config.effective_tracking_time_s),
                feedforward_v=config.feedforward_v, schedule_above=0.0 if f_s is None else 1.0,
                schedule_above_n=0.0 if f_s is None else f_s, finger_b_n_per_m=finger.stiffness_b_n_per_m,
                finger_m_per_m=finger.exponent_m_per_m, relax_weight_inf=finger.relax_weight_inf)


class PIDCore:
    """The discrete PID recursion of the module docstring, with its state.

    One step of: P on the weighted setpoint ``b r - y``, forward-Euler integral with
    back-calculation anti-windup (tracking gain ``min(h / Tt, 1)``), backward-difference
    filtered derivative of ``c r - y``, output clamped to ``[u_min, u_max]``.  The gains
    are arguments of every step, so a caller may schedule them; :class:`PID` passes
    constants, :class:`controllers.schedule.ScheduledPID` scheduled gains, a feedforward
    and a mapped reference.  Arguments are not validated here (the callers do it once).
    The state lives in a float64 vector (slots :data:`controllers.compiled.PS`) and the
    recursion is the compiled :func:`controllers.compiled.core_step`.

    Parameters
    ----------
    state : ndarray or None, optional
        The state vector to work on (shared with the controller that owns it); None
        (default) makes a new one.

    Attributes
    ----------
    i : float
        Integrator ``I``, V.
    d : float
        Derivative term ``D``, V.
    w_prev : float
        ``c r - y`` of the last sample, N (meaningful once ``primed``).
    e_prev : float
        ``r - y`` of the last sample, N.
    res_prev : float
        Saturation residual ``u - v`` of the last sample, V.
    primed : bool
        False until the derivative memory holds a sample (no derivative kick).

    Examples
    --------
    >>> core = PIDCore()
    >>> core.step(0.0, 0.25, 1e-3, 2.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, -1.0, 1.0)
    0.5
    """

    __slots__ = ("s",)

    def __init__(self, state: np.ndarray | None = None) -> None:
        self.s = pid_state() if state is None else state
        self.clear()

    def _get(slot: int):
        return property(lambda self: float(self.s[slot]), lambda self, v: self.s.__setitem__(slot, v))

    i = _get(PS.integrator_v)
    d = _get(PS.derivative_v)
    w_prev = _get(PS.prev_derivative_input_n)
    e_prev = _get(PS.prev_error_n)
    res_prev = _get(PS.prev_saturation_residual_v)
    del _get

    @property
    def primed(self) -> bool:
        return bool(self.s[PS.primed] != 0.0)

    @primed.setter
    def primed(self, value: bool) -> None:
        self.s[PS.primed] = 1.0 if value else 0.0

    def clear(self) -> None:
        """Zero the state; the next step takes its measurement as derivative memory."""
        self.i = 0.0
        self.d = 0.0
        self.w_prev = 0.0
        self.e_prev = 0.0
        self.res_prev = 0.0
        self.primed = False

    def reset(self, y: float, r: float, u0: float, kp: float, b: float, c: float, ff: float) -> None:
        """Bumpless start: the next step with the same ``y, r`` (and gains) returns ``u0``.

        ``u0`` must already lie within the output limits.
        """
        core_reset(self.s, y, r, u0, kp, b, c, ff)

    def step(self, y: float, r: float, h: float, kp: float, ki: float, kd: float, tf: float,
             b: float, c: float, inv_tt: float, ff: float, umin: float, umax: float) -> float:
        """Advance one sample of length ``h`` (s) and return the clamped command (V).

        ``inv_tt`` is ``1/Tt`` (:func:`tracking_gain_per_s`), ``ff`` the feedforward added
        before the saturation, ``tf`` the derivative filter time constant (s).
        """
        return core_step(self.s, y, r, h, kp, ki, kd, tf, b, c, inv_tt, ff, umin, umax)


PID_FIELDS: dict[str, tuple[str, str]] = {
    "kp_v_per_n": ("V/N", "Proportional gain kp."),
    "ki_v_per_ns": ("V/(N s)", "Integral gain ki = kp/Ti."),
    "kd_vs_per_n": ("V s/N", "Derivative gain kd = kp Td."),
    "derivative_filter_s": ("s", "Time constant Tf of the derivative's first-order filter (0: unfiltered)."),
    "setpoint_weight_p": ("-", "Setpoint weight b of the proportional term, kp (b r - y)."),
    "setpoint_weight_d": ("-", "Setpoint weight c of the derivative of c r - y (0: derivative on measurement)."),
    "u_min_v": ("V", "Lower output limit."),
    "u_max_v": ("V", "Upper output limit."),
    "tracking_time_s": ("s", "Back-calculation time constant Tt of the anti-windup (None: from the gains; inf: "
                             "off)."),
    "feedforward_v": ("V", "Constant command added before the saturation."),
    "schedule_above_n": ("N", "Force above which the gains scale down with the pulp's stiffness (None: fixed "
                              "gains)."),
}
"""Unit and one-line description of the PID fields, shared by every config that carries them."""

GAIN_SOURCE = "[E] design setting (docs/tuning.md)"
"""Source tag of a controller's gains: chosen by design and tuning, not measured."""


def pid_field(name: str, default: Any = dataclasses.MISSING, source: str = GAIN_SOURCE) -> Any:
    """A PID field (:data:`PID_FIELDS`) declared with :func:`~ebraille_sim.base.fields.sourced`."""
    unit, doc = PID_FIELDS[name]
    return sourced(default, unit, source, doc=doc)


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
    schedule_above_n : float or None, optional
        Force ``F_s`` above which the gains are scaled down with the pulp's stiffness:
        at a setpoint ``r > F_s`` every gain is multiplied by ``K(F_s) / K(r)``
        (:func:`stiffness_ratio`, nominal finger), so the loop gain, which grows with
        ``K``, stays at its value at ``F_s``.  Within the tactile range
        [0.2, 3] N; None (default) keeps the gains fixed at every force.

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

    kp_v_per_n: float = pid_field("kp_v_per_n")
    ki_v_per_ns: float = pid_field("ki_v_per_ns", 0.0)
    kd_vs_per_n: float = pid_field("kd_vs_per_n", 0.0)
    derivative_filter_s: float = pid_field("derivative_filter_s", 0.0)
    setpoint_weight_p: float = pid_field("setpoint_weight_p", 1.0)
    setpoint_weight_d: float = pid_field("setpoint_weight_d", 0.0)
    u_min_v: float = pid_field("u_min_v", -6.0, "[R] the drive's -6 V supply")
    u_max_v: float = pid_field("u_max_v", 6.0, "[R] the drive's 6 V supply")
    tracking_time_s: float | None = pid_field("tracking_time_s", None)
    feedforward_v: float = pid_field("feedforward_v", 0.0)
    schedule_above_n: float | None = pid_field("schedule_above_n", None)

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
            lo = 0.0 if name in nonneg else None
            object.__setattr__(self, name, check_number(name, getattr(self, name), lo=lo))
        if not self.u_min_v < self.u_max_v:
            raise ValueError(
                f"u_min_v must be < u_max_v, got u_min_v={self.u_min_v!r}, u_max_v={self.u_max_v!r}"
            )
        if self.tracking_time_s is not None:
            tt = check_number("tracking_time_s", self.tracking_time_s, lo=0.0, finite=False)
            object.__setattr__(self, "tracking_time_s", tt)
        if self.schedule_above_n is not None:
            object.__setattr__(self, "schedule_above_n", check_number(
                "schedule_above_n", self.schedule_above_n, TACTILE_FORCE_MIN_N, TACTILE_FORCE_MAX_N))

    def gain_scale(self, setpoint_n: float) -> float:
        """Factor on ``kp, ki, kd`` at ``setpoint_n``: ``K(F_s) / K(r)`` above ``schedule_above_n``, else 1.

        Examples
        --------
        >>> cfg = PIDConfig(kp_v_per_n=2.0, schedule_above_n=1.0)
        >>> cfg.gain_scale(0.5), round(cfg.gain_scale(3.0), 3)
        (1.0, 0.34)
        """
        f_s = self.schedule_above_n
        if f_s is None or not setpoint_n > f_s:
            return 1.0
        return stiffness_ratio(setpoint_n, f_s)

    def at(self, force_n: float) -> PIDConfig:
        """The fixed-gain config this one runs with at the setpoint ``force_n`` (for analysis)."""
        a = self.gain_scale(force_n)
        return dataclasses.replace(self, kp_v_per_n=self.kp_v_per_n * a, ki_v_per_ns=self.ki_v_per_ns * a,
                                   kd_vs_per_n=self.kd_vs_per_n * a, schedule_above_n=None)

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
        return tracking_time_s(self.kp_v_per_n, self.ki_v_per_ns, self.kd_vs_per_n, self.tracking_time_s)

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
        ValueError: unknown key 'kp' in PID gains; allowed: kp_v_per_n, ki_v_per_ns, ...
        """
        if not isinstance(d, Mapping):
            raise TypeError(f"PID gains must be a mapping, got {type(d).__name__}")
        check_keys("PID gains", d, _FIELD_NAMES)
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
    schedule_above_n=1.0,
)
"""Default gains of ``controllers.make("pid")``: a hand design at 1 N, scaled down with the
pulp's stiffness above 1 N (``schedule_above_n``).  With fixed gains this loop oscillates
at 2 N and a step of the setpoint from 1 to 3 N overshoots to about 9.7 N; scaled, the
same step peaks at about 3.04 N."""

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

    __slots__ = ("_cfg", "_core", "_p")

    def __init__(self, config: PIDConfig) -> None:
        if not isinstance(config, PIDConfig):
            raise TypeError(f"config must be a PIDConfig, got {type(config).__name__}")
        self._cfg = config
        self._p = pid_params(**fixed_gain_slots(config))
        self._core = PIDCore()

    def compiled(self) -> tuple[int, np.ndarray, np.ndarray]:
        """``(kind, state, params)`` of the compiled step (:mod:`controllers.compiled`): the
        live vectors, so a compiled loop leaves its final state in this controller."""
        return KIND_PID, self._core.s, self._p

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
        y = check_finite("force_est_n", force_est_n)
        r = check_finite("setpoint_n", setpoint_n)
        pid_reset(self._core.s, self._p, y, r, check_finite("command_v", command_v))

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
        y, r, h = check_update_args(force_est_n, setpoint_n, dt_s)
        return pid_step(self._core.s, self._p, y, r, h)

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
        core = self._core
        return {
            "integrator_v": core.i,
            "derivative_v": core.d,
            "prev_derivative_input_n": core.w_prev if core.primed else None,
            "prev_error_n": core.e_prev,
            "prev_saturation_residual_v": core.res_prev,
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
        check_keys("PID state", state, _STATE_KEYS)
        for key in _STATE_KEYS:
            if key not in state:
                raise ValueError(f"missing PID state key {key!r}; required keys: {', '.join(_STATE_KEYS)}")
        values = {}
        for key in _STATE_KEYS:
            value = state[key]
            if key == "prev_derivative_input_n" and value is None:
                values[key] = None
                continue
            values[key] = check_finite(key, value)
        w_prev = values["prev_derivative_input_n"]
        core = self._core
        core.i = values["integrator_v"]
        core.d = values["derivative_v"]
        core.w_prev = 0.0 if w_prev is None else w_prev
        core.e_prev = values["prev_error_n"]
        core.res_prev = values["prev_saturation_residual_v"]
        core.primed = w_prev is not None


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
