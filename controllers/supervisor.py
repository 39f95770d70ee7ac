"""Safety supervisor: wraps any controller and keeps the finger safe when something fails.

The supervisor sees what the controller sees (estimated force, setpoint, time step,
motor current) and the command the inner controller proposes.  In normal running it
only shapes that command; when it detects a fault it takes over.

Shaping (every period, in this order)
-------------------------------------
1. **Watchdog.**  A non-finite command is replaced by 0 V (the drive is not
   back-drivable, so the board holds still).  When the inner controller returns a finite
   command again it is reset bumplessly from 0 V and takes over at the next period; a
   non-finite stretch longer than ``watchdog_timeout_s`` is a latched fault.
2. **Force cap.**  The setpoint passed to the inner controller is clipped to
   ``force_cap_n - cap_margin_n``.  Inside the soft zone ``[cap - margin, cap]`` a pushing
   command is scaled by ``1 - v`` with ``v`` the degree of violation in [0, 1]; at or
   above the cap the command is ``-retract_v`` until the estimate is back below it.
3. **Rate limit.**  The command moves at most ``slew_v_per_s`` per second.
4. **Current and speed envelope** (with a current measurement).  The command is capped at
   the voltage that brings the motor current to a limit that depends on the rack speed read
   from the back-EMF (highest of the last ``speed_hold_s``): at rest the current whose
   steady push (:mod:`ebraille_sim.physics.limits` eq. 1) is ``safe_force_n`` less the
   pulp's own motion; moving, the current whose push plus the impact of the moving drive
   stays there; above the speed limit a braking current.  This bounds the true force
   whatever the sensor reads (derivation and numbers: docs/safety.md).

Faults (latched: safe retract, then hold)
-----------------------------------------
================== =====================================================================
cause              detection
================== =====================================================================
fsr_out_of_range   estimate above ``out_of_range_n`` (a short reads the supply: ~15 N),
                   or not finite
fsr_stuck          (without a current measurement) in contact, over ``stuck_window_s`` the
                   estimate stays above ``contact_lost_n`` and moves less than
                   ``stuck_tolerance_n`` while the command of ``stuck_response_s`` earlier
                   moved more than ``stuck_command_v``; with a current measurement the
                   travel rule below decides
motor_overcurrent  I^2 t: ``theta = int (i^2 - I_rated^2) dt`` (kept >= 0) exceeds
                   ``(I_stall^2 - I_rated^2) overload_time_s``
contact_lost       after contact (estimate > ``contact_on_n``), a loss of contact
                   (estimate < ``contact_lost_n``, or a drop by more than ``drop_n`` within
                   ``drop_window_s`` while pushing) starts a *freeze*: back off at
                   ``-retract_v`` for ``backoff_s`` then hold 0 V; contact regained
                   (estimate > ``contact_on_n`` and not falling) resumes the inner
                   controller from 0 V; no contact within ``contact_loss_timeout_s`` is
                   latched (an open FSR reads 0 V, i.e. no force, for good)
controller_nonfinite non-finite commands for longer than ``watchdog_timeout_s``
fsr_stuck          (travel) in contact, the estimate stays within ``stuck_tolerance_n`` while
                   the driven motor travels ``stuck_travel_m``
fsr_implausible    moving forward, the force the current implies (lower edge of the friction
                   band) exceeds the recent estimate by ``implausible_n`` for
                   ``implausible_s``; or the travel since contact exceeds the soft reader's
                   compression for the estimate
fsr_no_contact     no contact within ``first_contact_travel_m`` of travel from the start
motor_stalled      pushing without moving for ``stall_time_s``, with no contact shown or at
                   ``stall_fraction`` of the current limit
================== =====================================================================

A fall of the setpoint within ``release_window_s`` (refresh release, a step down) widens the
drop that counts as a loss of contact by that fall, and an estimate below ``contact_lost_n``
is a loss only while the setpoint asks for contact.

*Safe retract*: ``-retract_v`` until the board has moved back for at least
``retract_moving_s`` (motion is read from the current: a moving motor draws much less than
``retract_v / R``) and then stalls on the end stop, or for ``max_retract_s`` at most; then
0 V (hold).  A jammed motor keeps retracting at ``retract_v / R`` (below the rated current)
until it frees itself.  Without a current measurement the retract lasts ``retract_s``.

Scenario section ``[supervisor]`` (:func:`validate_section`, :func:`wrap_controller`):
every :class:`SupervisorConfig` field may be given; ``enabled = false`` disables it.

Examples
--------
>>> from controllers import make
>>> sup = Supervisor(make("pid"))
>>> sup.reset(force_est_n=0.0, setpoint_n=1.0)
>>> sup.update(0.0, 5.0, 1e-3)      # setpoint clipped to 2.7 N; slew limit 0.6 V per ms
0.6
>>> sup.update(float("nan"), 1.0, 1e-3)   # a NaN estimate: latched fault, retract begins
0.0
>>> sup.fault, sup.mode
('fsr_out_of_range', 'retract')
"""
from __future__ import annotations

import bisect
import dataclasses
import functools
import math
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from ebraille_sim.base.validation import check_bool, check_keys, check_number
from ebraille_sim.physics import limits
from ebraille_sim.physics.fingertip import compression_at_force_m, tangent_stiffness_n_per_m
from ebraille_sim.physics.params import FINGERS, TACTILE_FORCE_MAX_N, DeviceParams

from controllers.base import check_dt

__all__ = ["SupervisorConfig", "Supervisor", "RATED_CURRENT_A", "RATED_TO_STALL", "rated_current_a",
           "FORCE_CAP_LIMIT_N", "SAFE_FORCE_N", "device_limits"]

_NOMINAL = DeviceParams()

FORCE_CAP_LIMIT_N = TACTILE_FORCE_MAX_N + 1.0
"""Largest admissible ``force_cap_n``, N: the 3 N top of the tactile range ([R] seed paper)
plus 1 N of margin [E] for a cap set above the reading force.  The cap exists to keep the
board from pressing the finger harder than reading needs; one far above the tactile range
would not protect it."""

RATED_CURRENT_A: dict[str, float] = {"faulhaber_0816_006sr": 0.19}
"""Continuous (rated) motor current by motor preset, A ([R] Faulhaber 0816 006 SR datasheet).
A motor without an entry is rated at :data:`RATED_TO_STALL` of its stall current."""

RATED_TO_STALL = 0.19 / (6.0 / 21.2)
"""Rated over stall current at the nominal supply, [E] the Faulhaber 0816's ratio (0.67)."""


SAFE_FORCE_N = 3.5
"""Default bound on the true finger force, N: half a newton above the 3 N top of the tactile
range ([R] seed paper) [E], below :data:`FORCE_CAP_LIMIT_N`."""

CONTACT_ON_N = 0.2
"""Estimate above which the board is taken to touch the finger, N: the 0.2 N bottom of the
tactile range ([R] seed paper)."""

DESIGN_GAP_M = 2e-3
"""Largest board-to-pulp gap at the start of a session, m [E] (the shipped scenarios use 1-2 mm)."""


def _design_reader(device: DeviceParams):
    """Pulp constants the impact bound assumes: the stiffer of the device's reader and the stiff preset [E]."""
    f, s = device.finger, FINGERS["stiff"]
    return max(f.stiffness_b_n_per_m, s.stiffness_b_n_per_m), max(f.exponent_m_per_m, s.exponent_m_per_m)


ESTIMATOR_PERIOD_S = 0.01
"""Period of the force estimate, s: the paper's models run at 100 Hz ([R] seed paper); the
estimate holds its value in between."""


def _speed_limit(b: dict, rb: float, rm: float) -> float:
    """Speed at which the impact alone brings the design reader to the safe force (no tremor allowance), m/s."""
    e = limits.absorbed_energy_j(0.0, SAFE_FORCE_N, rb, rm)
    return limits.speed_for_energy_m_per_s(e, b["pinion_mass_kg"], b["board_mass_kg"], b["gear_efficiency"])


def device_limits(device: DeviceParams) -> dict:
    """The drive and reader constants of ``device`` that :class:`SupervisorConfig` carries (see docs/safety.md)."""
    b = limits.drive_bounds(device)
    rb, rm = _design_reader(device)
    soft = FINGERS["soft"]
    k_contact = tangent_stiffness_n_per_m(CONTACT_ON_N, rb, rm)
    dt = device.drivetrain
    return {
        "motor_resistance_ohm": device.motor.resistance_ohm,
        "stall_current_a": device.driver_supply_v / device.motor.resistance_ohm,
        "rated_current_a": rated_current_a(device),
        "driver_supply_v": device.driver_supply_v,
        "push_force_per_a_n": b["push_force_per_a_n"],
        "friction_current_a": b["friction_current_a"],
        "weight_n": b["weight_n"],
        "back_emf_v_s_per_m": b["back_emf_v_s_per_m"],
        "pinion_mass_kg": b["pinion_mass_kg"],
        "board_mass_kg": b["board_mass_kg"],
        "gear_efficiency": b["gear_efficiency"],
        "friction_breakaway_ratio": device.motor.breakaway_ratio,
        "guide_static_n": dt.guide_coulomb_n * dt.guide_breakaway_ratio,
        "soft_b_n_per_m": soft.stiffness_b_n_per_m,
        "soft_m_per_m": soft.exponent_m_per_m,
        "reader_b_n_per_m": rb,
        "reader_m_per_m": rm,
        "speed_hold_s": 0.5 * math.pi * math.sqrt(b["impact_mass_kg"] / k_contact),
        "stuck_travel_m": 2.0 * dt.backlash_m + ESTIMATOR_PERIOD_S * _speed_limit(b, rb, rm),
        "first_contact_travel_m": DESIGN_GAP_M + compression_at_force_m(
            SAFE_FORCE_N, soft.stiffness_b_n_per_m, soft.exponent_m_per_m),
    }


def rated_current_a(device: DeviceParams) -> float:
    """Continuous current of ``device``'s motor, A (:data:`RATED_CURRENT_A`, else the ratio)."""
    m = device.motor
    if m.name in RATED_CURRENT_A:
        return RATED_CURRENT_A[m.name]
    return RATED_TO_STALL * device.driver_supply_v / m.resistance_ohm


_NOMINAL_LIMITS: dict = {}


@dataclass(frozen=True)
class SupervisorConfig:
    """Limits and detector settings of :class:`Supervisor` (SI units in the names).

    The motor, drive and reader constants default to the nominal device's
    (:class:`DeviceParams`, :func:`device_limits`); :meth:`for_device` derives them from
    another device.  Every numeric field must be a positive finite number.
    """
    force_cap_n: float = TACTILE_FORCE_MAX_N
    """Cap on the estimated force (upper end of the tactile range, [R] seed paper)."""
    cap_margin_n: float = 0.3
    safe_force_n: float = SAFE_FORCE_N
    """Bound on the true force that the current and speed envelope keeps whatever the sensor reads."""
    finger_motion_m: float = 45e-6
    """Motion of the pulp toward a held board that the drive cannot prevent, m: three times the
    15 um RMS of physiological tremor [E] (the tremor scenarios' amplitude)."""
    slew_v_per_s: float = 600.0
    """Full scale (6 V) in 10 ms, one estimator period."""
    rated_current_a: float = None  # type: ignore[assignment]
    """Continuous motor current (:func:`rated_current_a`)."""
    stall_current_a: float = None  # type: ignore[assignment]
    """Stall current at the driver supply, [D] U / R."""
    overload_time_s: float = 0.5
    """Time allowed at the stall current before the I^2 t trip [E]."""
    motor_resistance_ohm: float = None  # type: ignore[assignment]
    """Armature resistance R of the device's motor (back-EMF ``u - R i`` and motion detection)."""
    driver_supply_v: float = None  # type: ignore[assignment]
    """H-bridge supply: the terminal voltage is the command clipped to it."""
    push_force_per_a_n: float = None  # type: ignore[assignment]
    """eta kM N/r, N/A: rack force per ampere through the gearhead in the pushing direction [D]."""
    friction_current_a: float = None  # type: ignore[assignment]
    """T_f / kM, A: current that the motor's own friction torque takes [D]."""
    weight_n: float = None  # type: ignore[assignment]
    """m_b g, N: weight of the board, counted as pushing (hand upside down) [D]."""
    back_emf_v_s_per_m: float = None  # type: ignore[assignment]
    """kE N/r, V s/m: back-EMF per rack speed [D]."""
    pinion_mass_kg: float = None  # type: ignore[assignment]
    """J (N/r)^2, kg: rotor inertia at the rack line [D]."""
    board_mass_kg: float = None  # type: ignore[assignment]
    gear_efficiency: float = None  # type: ignore[assignment]
    friction_breakaway_ratio: float = None  # type: ignore[assignment]
    guide_static_n: float = None  # type: ignore[assignment]
    """Break-away friction of the guide rods, N (the plausibility band's lower edge)."""
    reader_b_n_per_m: float = None  # type: ignore[assignment]
    """Pulp b of the reader the impact bound assumes (the stiffer of the device's and the stiff preset)."""
    reader_m_per_m: float = None  # type: ignore[assignment]
    speed_hold_s: float = None  # type: ignore[assignment]
    """How long the highest recent speed sets the current limit: a quarter period of the impact
    mass on the design reader's stiffness at the contact threshold [D]."""
    stuck_travel_m: float = None  # type: ignore[assignment]
    """Travel with an unchanged estimate that makes it stuck: twice the backlash plus the travel
    at the impact speed limit within one estimator period [D]."""
    first_contact_travel_m: float = None  # type: ignore[assignment]
    """Travel from the start within which the first contact must show: the design gap plus the
    soft reader's compression at the safe force [D]."""
    soft_b_n_per_m: float = None  # type: ignore[assignment]
    """Pulp b of the softest reader preset: the most travel a force change can take."""
    soft_m_per_m: float = None  # type: ignore[assignment]
    retract_v: float = 2.0
    retract_s: float = 0.6
    retract_moving_s: float = 0.05
    max_retract_s: float = 10.0
    out_of_range_n: float = 4.0
    stuck_window_s: float = 0.1
    stuck_response_s: float = 0.05
    travel_follow_s: float = 5.0
    """Time constant with which the travel check's reference follows the finger's slow motion
    (drift, pressing, strap slips) [E]: a board running into the finger faster than this while
    the reading stays low is caught."""
    """Time the estimate needs to show a command's effect [E]: the 10 ms estimator period, its
    two-sample mean and the 20 Hz anti-alias filter (about 40 ms), rounded up."""
    stuck_tolerance_n: float = 2e-3
    stuck_command_v: float = 0.25
    stuck_emf_v: float = 0.05
    contact_on_n: float = CONTACT_ON_N
    contact_lost_n: float = 0.1
    """Above the 0.063 N that the paper's estimator reads with no load (and with an open FSR)."""
    drop_n: float = 0.3
    drop_window_s: float = 0.03
    release_window_s: float = 0.15
    """A fall of the setpoint within this time is an intended release, not a loss of contact [E]
    (estimator delay plus the controller's settling)."""
    backoff_s: float = 0.05
    contact_loss_timeout_s: float = 0.6
    watchdog_timeout_s: float = 0.5
    moving_speed_m_per_s: float = 0.5e-3
    """Rack speed above which the motor is taken to move (back-EMF 0.05 V for the nominal drive) [E]."""
    stall_time_s: float = 0.5
    """A motor pushing with current but not moving while no contact shows is stopped after this [E]."""
    stall_fraction: float = 0.95
    """Fraction of the current limit at rest above which a motor that does not move is stalled [E]
    (holding the 2.7 N top setpoint takes about 85 % of it)."""
    implausible_n: float = 0.5
    """Margin by which the force the current implies may exceed the estimate [E]."""
    implausible_s: float = 0.2
    enabled: bool = True

    def __post_init__(self):
        for f in dataclasses.fields(self):
            if f.name == "enabled":
                check_bool(f.name, self.enabled)
                continue
            v = getattr(self, f.name)
            if v is None:
                v = _NOMINAL_LIMITS[f.name]
            object.__setattr__(self, f.name, check_number(f.name, v, lo=0.0, lo_open=True))
        if self.force_cap_n > FORCE_CAP_LIMIT_N:
            raise ValueError(f"force_cap_n = {self.force_cap_n:g} N is above the {FORCE_CAP_LIMIT_N:g} N safe limit "
                             f"(the {TACTILE_FORCE_MAX_N:g} N top of the tactile range, [R] seed paper, plus "
                             f"1 N margin): a cap above it would let the board press harder than reading needs")
        if self.safe_force_n > FORCE_CAP_LIMIT_N:
            raise ValueError(f"safe_force_n = {self.safe_force_n:g} N is above the {FORCE_CAP_LIMIT_N:g} N safe "
                             f"limit: the bound on the true force may not exceed the largest admissible cap")
        if self.envelope_force_n <= self.contact_on_n:
            raise ValueError(f"safe_force_n = {self.safe_force_n:g} N leaves no force for reading once "
                             f"finger_motion_m ({self.finger_motion_m:g} m) is allowed for")
        if self.cap_margin_n >= self.force_cap_n:
            raise ValueError(f"cap_margin_n ({self.cap_margin_n:g}) must be below force_cap_n "
                             f"({self.force_cap_n:g})")
        if self.out_of_range_n <= self.force_cap_n:
            raise ValueError(f"out_of_range_n ({self.out_of_range_n:g}) must exceed force_cap_n "
                             f"({self.force_cap_n:g})")
        if self.contact_lost_n >= self.contact_on_n:
            raise ValueError(f"contact_lost_n ({self.contact_lost_n:g}) must be below contact_on_n "
                             f"({self.contact_on_n:g})")
        if self.stall_current_a <= self.rated_current_a:
            raise ValueError(f"stall_current_a ({self.stall_current_a:g}) must exceed rated_current_a "
                             f"({self.rated_current_a:g})")
        if self.gear_efficiency > 1.0:
            raise ValueError(f"gear_efficiency = {self.gear_efficiency:g} must be at most 1")

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], device: DeviceParams | None = None) -> SupervisorConfig:
        """:meth:`for_device` with the fields of a mapping; an unknown key is a one-line error."""
        check_keys("SupervisorConfig", d, _FIELD_NAMES)
        return cls.for_device(_NOMINAL if device is None else device, **d)

    @classmethod
    def for_device(cls, device: DeviceParams, **overrides: Any) -> SupervisorConfig:
        """The defaults with the motor, drive and reader constants of ``device``, then ``overrides``.

        ``motor_resistance_ohm`` is the motor's R, ``stall_current_a`` the driver supply
        over R, ``rated_current_a`` from :func:`rated_current_a`; the drive and reader
        constants from :func:`device_limits`.

        Examples
        --------
        >>> SupervisorConfig.for_device(DeviceParams()) == SupervisorConfig()
        True
        """
        check_keys("SupervisorConfig", overrides, _FIELD_NAMES)
        return cls(**{**device_limits(device), **overrides})

    @property
    def i2t_limit_a2s(self) -> float:
        """Trip level of the I^2 t integral, A^2 s."""
        return (self.stall_current_a ** 2 - self.rated_current_a ** 2) * self.overload_time_s

    @property
    def impact_mass_kg(self) -> float:
        """eta M_p + m_b, kg: the mass whose kinetic energy reaches the finger (physics.limits eq. 2)."""
        return self.gear_efficiency * self.pinion_mass_kg + self.board_mass_kg

    def push_force_n(self, current_a: float, friction_scale: float = 1.0, weight_n: float | None = None) -> float:
        """Steady force the drive pushes with at ``current_a`` (physics.limits eq. 1), N.

        The constants are already at the rack line and through the gearhead, so the law is
        called with ``kM = eta kM N/r``, ``N/r = eta = 1`` and ``T_f = friction_scale I_f eta kM N/r``.
        """
        return limits.push_force_bound_n(current_a, self.push_force_per_a_n, 1.0, 1.0,
                                         friction_scale * self.friction_current_a * self.push_force_per_a_n,
                                         self.weight_n if weight_n is None else weight_n)

    def current_for_force_a(self, force_n: float) -> float:
        """Current at which :meth:`push_force_n` equals ``force_n``, A."""
        return limits.current_for_push_force_a(force_n, self.push_force_per_a_n, 1.0, 1.0,
                                               self.friction_current_a * self.push_force_per_a_n, self.weight_n)

    @functools.cached_property
    def envelope_force_n(self) -> float:
        """Force the drive may produce, N: ``safe_force_n`` less what :attr:`finger_motion_m` adds on
        the design reader at the safe force (tangent stiffness ``b + m F``)."""
        k = tangent_stiffness_n_per_m(self.safe_force_n, self.reader_b_n_per_m, self.reader_m_per_m)
        return self.safe_force_n - k * self.finger_motion_m

    @functools.cached_property
    def current_limit_a(self) -> float:
        """Current limit at rest: the steady push bound equals :attr:`envelope_force_n`, A."""
        return self.current_for_force_a(self.envelope_force_n)

    def drive_force_limit_n(self, speed_m_per_s: float) -> float:
        """Largest drive force at ``speed_m_per_s`` whose impact still peaks at :attr:`envelope_force_n` (N; < 0: brake)."""
        e = limits.impact_energy_j(max(speed_m_per_s, 0.0), self.pinion_mass_kg, self.board_mass_kg,
                                   self.gear_efficiency)
        return limits.drive_force_for_impact_n(e, self.envelope_force_n, self.reader_b_n_per_m, self.reader_m_per_m)

    @property
    def speed_limit_m_per_s(self) -> float:
        """Approach speed at which the impact alone reaches :attr:`envelope_force_n` on the design reader, m/s."""
        e = limits.absorbed_energy_j(0.0, self.envelope_force_n, self.reader_b_n_per_m, self.reader_m_per_m)
        return limits.speed_for_energy_m_per_s(e, self.pinion_mass_kg, self.board_mass_kg, self.gear_efficiency)


_FIELD_NAMES: tuple[str, ...] = tuple(f.name for f in dataclasses.fields(SupervisorConfig))
_NOMINAL_LIMITS.update(device_limits(_NOMINAL))


class _Window:
    """Running min and max over the last ``span_s`` seconds (monotonic deques)."""

    def __init__(self, span_s: float):
        self.span = span_s
        self.lo: deque = deque()
        self.hi: deque = deque()
        self.t0 = None

    def push(self, t: float, x: float) -> None:
        if self.t0 is None:
            self.t0 = t
        lo, hi = self.lo, self.hi
        while lo and lo[-1][1] >= x:
            lo.pop()
        while hi and hi[-1][1] <= x:
            hi.pop()
        item = (t, x)
        lo.append(item)
        hi.append(item)
        cut = t - self.span
        while lo[0][0] < cut:
            lo.popleft()
        while hi[0][0] < cut:
            hi.popleft()

    def full(self, t: float) -> bool:
        return self.t0 is not None and t - self.t0 >= self.span

    def range(self) -> float:
        return self.hi[0][1] - self.lo[0][1]


class Supervisor:
    """Safety wrapper around a :class:`~controllers.base.Controller` (see the module docstring).

    Attributes
    ----------
    mode : str
        ``"run"``, ``"freeze"`` (contact lost), ``"retract"`` or ``"hold"``.
    fault : str or None
        Cause of the latched fault, if any.
    events : list of (float, str)
        Time since reset (s) and a short description of every mode change.
    """

    def __init__(self, inner, config: SupervisorConfig = SupervisorConfig()):
        if not isinstance(config, SupervisorConfig):
            raise TypeError(f"config must be a SupervisorConfig, got {type(config).__name__}")
        self.inner = inner
        self.config = config
        self.name = f"supervised({getattr(inner, 'name', type(inner).__name__)})"
        self._envelope = _envelope(config)
        self._clear()

    def _clear(self):
        c = self.config
        self.mode = "run"
        self.fault = None
        self.events = []
        self.t = 0.0
        self.u_prev = 0.0
        self.theta = 0.0
        self.nan_s = 0.0
        self.in_contact = False
        self.freeze_t0 = 0.0
        self.retract_t0 = 0.0
        self.moving_s = 0.0
        self.est_win = _Window(c.stuck_window_s)
        self.cmd_win = _Window(c.stuck_window_s - c.stuck_response_s)
        self.cmd_delay: deque = deque()
        self.drop_hist: deque = deque()
        self.sp_win = _Window(c.release_window_s)
        self.speed_win = _Window(c.speed_hold_s)
        self.speed = 0.0
        self.accel = 0.0
        self.travel_m = 0.0
        self.stuck_ref_n = math.nan
        self.stuck_travel_m = 0.0
        self.contact_travel_m = None
        self.cut_t = -math.inf
        self.sp_last = math.inf
        self.fall_t = -math.inf
        self.stall_s = 0.0
        self.implausible_s = 0.0
        self.current_limit_a = c.current_limit_a
        self.last_f = 0.0

    def reset(self, *, force_est_n: float, setpoint_n: float, command_v: float = 0.0) -> None:
        """Clear faults and detectors and reset the inner controller bumplessly."""
        self._clear()
        self.u_prev = float(command_v) if math.isfinite(command_v) else 0.0
        self.inner.reset(force_est_n=force_est_n, setpoint_n=min(setpoint_n, self._sp_max), command_v=command_v)

    @property
    def _sp_max(self) -> float:
        return self.config.force_cap_n - self.config.cap_margin_n

    def _event(self, text: str) -> None:
        self.events.append((round(self.t, 6), text))

    def _trip(self, cause: str) -> None:
        if self.fault is None:
            self.fault = cause
            self.mode = "retract"
            self.retract_t0 = self.t
            self.moving_s = 0.0
            self._event(f"fault {cause}: retract")

    def _slew(self, u: float, dt: float) -> float:
        du = self.config.slew_v_per_s * dt
        return min(max(u, self.u_prev - du), self.u_prev + du)

    def _motion(self, cur: float, dt_s: float) -> None:
        """Rack speed from the back-EMF of the last period, travel integral, held peak speed."""
        c = self.config
        u = min(max(self.u_prev, -c.driver_supply_v), c.driver_supply_v)
        v = limits.rack_speed_from_emf_m_per_s(u, cur, c.motor_resistance_ohm, c.back_emf_v_s_per_m, 1.0)
        self.accel = (v - self.speed) / dt_s
        self.speed = v
        if abs(cur) > 0.5 * c.friction_current_a:     # an unpowered motor (a cut supply) reads its command as speed
            self.travel_m = max(0.0, self.travel_m + v * dt_s)
        self.speed_win.push(self.t, v)

    def _envelope_cap(self, u: float, cur: float) -> float:
        """Largest command that keeps the next period's current within the speed-dependent limit."""
        c = self.config
        v_held = max(self.speed_win.hi[0][1], 0.0)
        i_lim = _interp(self._envelope, v_held)
        self.current_limit_a = i_lim
        u_applied = min(max(self.u_prev, -c.driver_supply_v), c.driver_supply_v)
        return min(u, u_applied + c.motor_resistance_ohm * (i_lim - cur))

    def _detect(self, f: float, sp: float, cur: float, dt_s: float) -> str | None:
        """The detectors that need the motor current; the cause of a fault, or None."""
        c = self.config
        v = self.speed
        moving = abs(v) > c.moving_speed_m_per_s
        # a stuck code: the estimate does not change while the board travels
        if f > c.contact_lost_n and self.in_contact:
            if not abs(f - self.stuck_ref_n) <= c.stuck_tolerance_n:
                self.stuck_ref_n = f
                self.stuck_travel_m = 0.0
            elif abs(cur) > 0.5 * c.friction_current_a:     # a driven motor: an unpowered one (a cut supply)
                # draws no current and its command reads as speed
                self.stuck_travel_m += abs(v) * dt_s
                if self.stuck_travel_m > c.stuck_travel_m:
                    return "fsr_stuck"
        else:
            self.stuck_ref_n = math.nan
        # travel since the first contact against the compression the estimate allows on the soft reader
        if self.in_contact:
            if self.contact_travel_m is None:
                self.contact_travel_m = self.travel_m
            elif f > c.contact_on_n:
                # the reference follows where the pulp's surface must be for the estimate shown,
                # at once on an intended release (the setpoint fell: the back-EMF integral's drift
                # over many presses in refresh mode does not add up) and slowly otherwise (the
                # finger drifts, presses and the strap slips over a session: only a fast mismatch,
                # a board running into the finger while the reading stays low, trips)
                target = self.travel_m - compression_at_force_m(f, c.soft_b_n_per_m, c.soft_m_per_m)
                if self.t - self.fall_t <= c.release_window_s:
                    self.contact_travel_m = max(self.contact_travel_m, target)
                else:
                    self.contact_travel_m += (target - self.contact_travel_m) * min(1.0, dt_s / c.travel_follow_s)
            allowed = (compression_at_force_m(self.est_win.hi[0][1] + c.implausible_n, c.soft_b_n_per_m,
                                              c.soft_m_per_m) + c.stuck_travel_m)
            if self.travel_m - self.contact_travel_m > allowed:
                return "fsr_implausible"
        # no contact within the travel the gap allows
        if not self.in_contact and self.travel_m > c.first_contact_travel_m:
            return "fsr_no_contact"
        # pushing and not moving: with no contact seen, or at the current limit
        if not moving and ((f < c.contact_on_n and cur > c.current_for_force_a(c.contact_on_n))
                           or cur > c.stall_fraction * c.current_limit_a):
            self.stall_s += dt_s
            if self.stall_s > c.stall_time_s:
                return "motor_stalled"
        else:
            self.stall_s = 0.0
        # the force the current implies while the board moves forward, against the estimate
        if v > c.moving_speed_m_per_s:
            a = max(self.accel, 0.0)
            # lower edge of the friction band: break-away friction, guide friction, weight against
            # the push, and the force that accelerates the rotor and the board
            f_lo = (c.push_force_n(cur, c.friction_breakaway_ratio, -c.weight_n) - c.guide_static_n
                    - c.impact_mass_kg * a)
            if f_lo - self.est_win.hi[0][1] > c.implausible_n:
                self.implausible_s += dt_s
                if self.implausible_s > c.implausible_s:
                    return "fsr_implausible"
            else:
                self.implausible_s = 0.0
        else:
            self.implausible_s = 0.0
        return None

    def update(self, force_est_n: float, setpoint_n: float, dt_s: float, motor_current_a: float | None = None) -> float:
        """One period: run the detectors, then pass, shape or replace the inner command."""
        c = self.config
        if not 0.0 < dt_s < math.inf:
            check_dt(dt_s)
        if not c.enabled:
            return self.inner.update(force_est_n, setpoint_n, dt_s, motor_current_a)
        self.t += dt_s
        t = self.t
        f = float(force_est_n)
        cur = None if motor_current_a is None or not math.isfinite(motor_current_a) else float(motor_current_a)
        if cur is not None:
            self.theta = max(0.0, self.theta + (cur * cur - c.rated_current_a ** 2) * dt_s)
            self._motion(cur, dt_s)
        if self.mode in ("retract", "hold"):
            return self._safe(cur, dt_s)
        # detectors that latch
        if not math.isfinite(f) or f > c.out_of_range_n:
            self._trip("fsr_out_of_range")
            return self._safe(cur, dt_s)
        if self.theta > c.i2t_limit_a2s:
            self._trip("motor_overcurrent")
            return self._safe(cur, dt_s)
        self.est_win.push(t, f)
        if cur is None:
            # the command window (the stuck rule without a current measurement) lags by the
            # estimator's response: a command that moved within the last ``stuck_response_s``
            # cannot have shown in the estimate yet
            self.cmd_delay.append((t, self.u_prev))
            while self.cmd_delay[0][0] <= t - c.stuck_response_s:
                self.cmd_win.push(*self.cmd_delay.popleft())
        sp_in = float(setpoint_n)
        sp_now = sp_in if math.isfinite(sp_in) else 0.0
        if sp_now < self.sp_last - 1e-9:
            self.fall_t = t                  # the setpoint fell: an intended release
        self.sp_last = sp_now
        self.sp_win.push(t, sp_now)
        moving = cur is None or abs(self.u_prev - c.motor_resistance_ohm * cur) > c.stuck_emf_v
        # without a current measurement only: with one, the travel the back-EMF integral gives
        # decides (:meth:`_detect`); ``u - R i`` of one period reads as motion inside the
        # gearhead's friction band and during a command step, where the board does not move
        if (cur is None and moving and self.cmd_win.t0 is not None and self.in_contact and self.est_win.full(t) and self.est_win.lo[0][1] > c.contact_lost_n
                and self.est_win.range() < c.stuck_tolerance_n and self.cmd_win.range() > c.stuck_command_v):
            self._trip("fsr_stuck")
            return self._safe(cur, dt_s)
        if cur is not None and self.mode == "run":
            cause = self._detect(f, sp_in, cur, dt_s)
            if cause is not None:
                self._trip(cause)
                return self._safe(cur, dt_s)
        # contact tracking
        self.drop_hist.append((t, f))
        while self.drop_hist[0][0] < t - c.drop_window_s:
            self.drop_hist.popleft()
        f_then = self.drop_hist[0][1]
        if self.mode == "run":
            if f > c.contact_on_n:
                self.in_contact = True
            # an intended release (the setpoint fell, or asks for no contact) is not a loss
            released = self.sp_win.range()
            fell = t - self.fall_t <= c.release_window_s
            lost = ((f < c.contact_lost_n and sp_in > c.contact_on_n and not fell)
                    or (f_then - f > c.drop_n + max(released, 0.0) and self.u_prev > 0.0
                        and t - self.cut_t > c.drop_window_s))
            if self.in_contact and lost:
                self.mode = "freeze"
                self.freeze_t0 = t
                self.contact_travel_m = None          # the compression check starts again at the next contact
                self._event("contact lost: freeze")
        if self.mode == "freeze":
            if f > c.contact_on_n and f >= f_then and t - self.freeze_t0 > c.backoff_s:
                self.mode = "run"
                self._event("contact regained: resume")
                self.inner.reset(force_est_n=f, setpoint_n=min(setpoint_n, self._sp_max), command_v=0.0)
                self.u_prev = 0.0
                return 0.0
            if t - self.freeze_t0 > c.contact_loss_timeout_s:
                self._trip("contact_lost")
                return self._safe(cur, dt_s)
            u = -c.retract_v if t - self.freeze_t0 <= c.backoff_s else 0.0
            self.u_prev = u
            return u
        # run: the inner controller, watchdog, cap, slew, current and speed envelope
        sp = min(sp_in, self._sp_max)
        u = self.inner.update(f, sp, dt_s, motor_current_a)
        if not math.isfinite(u):
            if self.nan_s == 0.0:
                self._event("non-finite command: hold")
            self.nan_s += dt_s
            if self.nan_s > c.watchdog_timeout_s:
                self._trip("controller_nonfinite")
                return self._safe(cur, dt_s)
            u = self._slew(0.0, dt_s)
            self.u_prev = u
            return u
        if self.nan_s > 0.0:
            self.nan_s = 0.0
            self._event("finite command again: resume")
            self.inner.reset(force_est_n=f, setpoint_n=sp, command_v=self.u_prev)
            u = self.u_prev
        u_inner = u
        lo = c.force_cap_n - c.cap_margin_n
        if f >= c.force_cap_n:
            u = -c.retract_v
        elif f > lo and u > 0.0:
            u *= 1.0 - (f - lo) / c.cap_margin_n
        u = self._slew(u, dt_s)
        if cur is not None:
            u = self._envelope_cap(u, cur)
        if u < u_inner - 1e-9:
            self.cut_t = t               # the supervisor held the push back: a drop that follows is its own
        self.u_prev = u
        return u

    def _safe(self, cur, dt_s) -> float:
        """Command of the latched safe state: retract, then hold at 0 V."""
        c = self.config
        if self.mode == "retract":
            el = self.t - self.retract_t0
            if cur is None:
                done = el >= c.retract_s
            else:
                stalled = abs(cur) > 0.6 * c.retract_v / c.motor_resistance_ohm
                if not stalled and el > 0.01:
                    self.moving_s += dt_s
                done = (self.moving_s >= c.retract_moving_s and stalled) or el >= c.max_retract_s
            if done:
                self.mode = "hold"
                self._event("retracted: hold")
            else:
                u = self._slew(-c.retract_v, dt_s)
                self.u_prev = u
                return u
        u = self._slew(0.0, dt_s)
        self.u_prev = u
        return u


def _envelope(c: SupervisorConfig) -> tuple[list[float], list[float]]:
    """Current limit against rack speed: (speeds, currents), from rest to beyond the speed limit.

    At each speed the drive force may not exceed :meth:`SupervisorConfig.drive_force_limit_n`;
    beyond :attr:`SupervisorConfig.speed_limit_m_per_s` the limit is a braking current.
    """
    v_max = c.speed_limit_m_per_s
    speeds = [v_max * k / 32 for k in range(33)]
    currents = [c.current_for_force_a(max(c.drive_force_limit_n(v), 0.0)) for v in speeds]
    speeds.append(1.05 * v_max)
    currents.append(-c.friction_current_a)
    return speeds, currents


def _interp(table: tuple[list[float], list[float]], x: float) -> float:
    xs, ys = table
    if x <= xs[0]:
        return ys[0]
    if x >= xs[-1]:
        return ys[-1]
    k = bisect.bisect_right(xs, x)
    x0, x1, y0, y1 = xs[k - 1], xs[k], ys[k - 1], ys[k]
    return y0 + (y1 - y0) * (x - x0) / (x1 - x0)
