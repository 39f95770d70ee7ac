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
                   ``drop_window_s`` to below ``drop_keep_fraction`` of the estimate at the
                   start of that window, while pushing) starts a *freeze*: back off at
                   ``-retract_v`` for ``backoff_s`` then hold 0 V; contact regained
                   (estimate > ``contact_on_n`` and not falling) resumes the inner
                   controller from 0 V; no contact within ``contact_loss_timeout_s`` is
                   latched (an open FSR reads 0 V, i.e. no force, for good)
controller_nonfinite non-finite commands for longer than ``watchdog_timeout_s``
fsr_stuck          (travel) in contact, the estimate stays within ``stuck_tolerance_n`` while
                   the powered motor moves the board ``stuck_travel_m`` net (back and forth
                   cancels: the hysteresis compensation holds its estimate still while a
                   loop hunts inside the film's blind stretch)
fsr_implausible    moving forward, the force the current implies (lower edge of the friction
                   band) exceeds the recent estimate by ``implausible_n`` for
                   ``implausible_s``; or the travel since contact exceeds the soft reader's
                   compression for the estimate
fsr_no_contact     no contact within ``first_contact_travel_m`` of travel from the start
motor_stalled      pushing without moving for ``stall_time_s``, with no contact shown, or at
                   ``stall_fraction`` of the current limit while the push at the lower edge
                   of the friction band exceeds the recent estimate by ``implausible_n``
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

Compiled period
---------------
The supervisor's whole state (modes, detectors, the running min/max windows as ring buffers,
the event log) lives in one float64 array and its configuration in another
(:meth:`Supervisor.compiled`, :meth:`SupervisorConfig.pack`); one period is two compiled
functions around the inner controller, which a compiled loop calls directly::

    code, u, sp_inner = supervise_begin(sv, cfg, f, sp, dt, cur)       # cur NaN: no current
    if code == 1:                                   # run: the inner controller proposes
        u_inner = inner.update(f, sp_inner, dt, cur_or_None)
        code2, u, reset_cmd = supervise_end(sv, cfg, u_inner, f, sp, dt, cur)
        if code2 == 1:                              # finite command again: bumpless resume
            inner.reset(force_est_n=f, setpoint_n=sp_inner, command_v=reset_cmd)
    elif code == 2:                                 # contact regained: resume from 0 V
        inner.reset(force_est_n=f, setpoint_n=sp_inner, command_v=0.0)
    # the command is u

:meth:`Supervisor.update` is exactly this.  The windows are sized for control periods of at
least :data:`MIN_CONTROL_PERIOD_S`; the event log keeps :data:`EVENT_CAPACITY` events.

The two functions are compiled without Numba's reference counting (``_nrt=False``: they
allocate nothing) and every helper of a normal period is inlined into them; only the rare
paths (a fault, an event, the safe states) call out.  Counting the references of the two
arrays at every helper, an atomic operation each, would cost more than the period's own
arithmetic.

Examples
--------
>>> from controllers import make
>>> sup = Supervisor(make("pid"))
>>> sup.reset(force_est_n=0.0, setpoint_n=1.0)
>>> round(sup.update(0.0, 5.0, 1e-3), 4)      # setpoint clipped to 2.7 N; the PID's first step
0.0396
>>> round(sup.update(float("nan"), 1.0, 1e-3), 4)   # a NaN estimate: latched fault, retract (slew 0.6 V/ms)
-0.5604
>>> sup.fault, sup.mode
('fsr_out_of_range', 'retract')
"""
from __future__ import annotations

import collections
import dataclasses
import functools
import math
import operator
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from ebraille_sim.base.compiled import njit
from ebraille_sim.base.validation import check_bool, check_keys, check_number, replace_fields
from ebraille_sim.physics import limits
from ebraille_sim.physics.fingertip import compression_at_force_m, tangent_stiffness_n_per_m
from ebraille_sim.physics.params import FINGERS, TACTILE_FORCE_MAX_N, DeviceParams

from controllers.base import check_dt

__all__ = ["SupervisorConfig", "Supervisor", "RATED_CURRENT_A", "RATED_TO_STALL", "rated_current_a",
           "FORCE_CAP_LIMIT_N", "SAFE_FORCE_N", "device_limits", "supervise_begin", "supervise_end",
           "supervise_commands",
           "MIN_CONTROL_PERIOD_S", "MAX_WINDOW_SAMPLES", "EVENT_CAPACITY", "MODES", "FAULTS", "SV", "CF"]

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
_NUMERIC_FIELD_NAMES: list = []
_numeric_values = None
_FLOAT_ONLY = {float}


def _numeric_field_names() -> tuple:
    """The names of :class:`SupervisorConfig`'s numeric fields (every field but ``enabled``) and
    a getter of their values from an instance's ``__dict__`` (a tuple), made once."""
    global _numeric_values
    _NUMERIC_FIELD_NAMES.extend(f.name for f in dataclasses.fields(SupervisorConfig) if f.name != "enabled")
    _numeric_values = operator.itemgetter(*_NUMERIC_FIELD_NAMES)
    return _NUMERIC_FIELD_NAMES, _numeric_values


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
    """Net travel with an unchanged estimate that makes it stuck: twice the backlash plus the
    travel at the impact speed limit within one estimator period [D]."""
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
    drop_keep_fraction: float = 0.5
    """A fall by ``drop_n`` within ``drop_window_s`` is a loss of contact only if the estimate ends
    below this fraction of its value at the start of the window [E]: a lost contact takes the
    estimate to its no-load value, a partial unloading keeps most of it (a 0.2 mm strap slip
    on the pulp drops 1.0 N to 0.63-0.70 N within 30 ms and the finger stays in contact)."""
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
    """Fraction of the current limit at rest above which a motor that does not move, and whose push
    at the lower edge of the friction band exceeds the estimate by ``implausible_n``, is stalled [E]
    (creeping a 2.8 N hold forward against the break-away friction takes about 97 % of the limit,
    so the current alone does not tell a jam from a hold at the top of the range)."""
    implausible_n: float = 0.5
    """Margin by which the force the current implies may exceed the estimate [E]."""
    implausible_s: float = 0.2
    powered_current_a: float = 0.5e-3
    """Smallest motor current that shows the driver powers the motor [E] (a few counts of a
    current sense that resolves tens of microamperes): the back-EMF speed counts as travel only
    above it.  A cut supply draws no current, and its command would read as speed; a motor
    that moves while drawing less than its friction current (the finger pushing the board back
    as the drive retracts) is counted, so the travel integral follows a force loop that
    hunts back and forth."""
    enabled: bool = True

    def __post_init__(self):
        check_bool("enabled", self.enabled)
        d = self.__dict__
        values = (_numeric_values or _numeric_field_names()[1])(d)
        # floats, all positive, with a finite sum (no inf, no NaN) pass as check_number would return them
        if not (set(map(type, values)) == _FLOAT_ONLY and min(values) > 0.0 and sum(values) < math.inf):
            for name in _NUMERIC_FIELD_NAMES:
                v = d[name]
                if v is None:
                    v = _NOMINAL_LIMITS[name]
                elif type(v) is float and 0.0 < v < math.inf:
                    continue                        # what check_number returns unchanged
                object.__setattr__(self, name, check_number(name, v, lo=0.0, lo_open=True))
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
        if self.drop_keep_fraction > 1.0:
            raise ValueError(f"drop_keep_fraction = {self.drop_keep_fraction:g} must be at most 1 (a fraction of the "
                             f"estimate before the drop)")
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
        if cls is SupervisorConfig:                 # the defaults' fields replaced, then checked
            return replace_fields(_default_config(), **{**device_limits(device), **overrides})
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

    def pack(self) -> np.ndarray:
        """The configuration array the compiled period reads (:func:`supervise_begin`), computed once.

        Holds the fields and derived constants, the layout of the state array (ring buffer
        bases and capacities, sized for control periods of at least :data:`MIN_CONTROL_PERIOD_S`)
        and the speed envelope table.  The array is cached and shared: do not modify it.
        """
        packed = self.__dict__.get("_packed")
        if packed is None:
            packed = _packed_config(self)
            self.__dict__["_packed"] = packed
        return packed


@functools.lru_cache(maxsize=256)
def _packed_config(c: SupervisorConfig) -> np.ndarray:
    """:func:`_pack` of ``c``, read-only, shared by equal configurations (a device drawn again, or
    the nominal device in every episode, packs once)."""
    packed = _pack(c)
    packed.flags.writeable = False
    return packed


_FIELD_NAMES: tuple[str, ...] = tuple(f.name for f in dataclasses.fields(SupervisorConfig))
_NOMINAL_LIMITS.update(device_limits(_NOMINAL))


@functools.lru_cache(maxsize=1)
def _default_config() -> SupervisorConfig:
    """``SupervisorConfig()``, made once: :meth:`SupervisorConfig.for_device` replaces its fields
    (``replace_fields`` runs the checks of ``__post_init__`` on the result, as the constructor
    does, and copies no attribute cached on it)."""
    return SupervisorConfig()


MIN_CONTROL_PERIOD_S = 1e-4
"""Shortest control period the detector windows are sized for, s: the nominal 10 kHz physics
step [E] (the control rate is a whole fraction of the physics rate; the shipped scenarios
control at 1 kHz).  A shorter period is a one-line error at :meth:`Supervisor.update`."""

MAX_WINDOW_SAMPLES = 1 << 15
"""Most samples one detector window is sized for [E]: a window longer than
``MAX_WINDOW_SAMPLES * MIN_CONTROL_PERIOD_S`` (3.3 s) raises the shortest period accepted to
its span over this count, so that a long window does not take megabytes."""

EVENT_CAPACITY = 256
"""Events the state array records after a reset; later ones are counted (the last entry of
:attr:`Supervisor.events` says how many were not recorded)."""

MODES = ("run", "freeze", "retract", "hold")
"""Modes by code (the ``mode`` slot of the state array)."""

FAULTS = ("fsr_out_of_range", "fsr_stuck", "motor_overcurrent", "contact_lost", "controller_nonfinite",
          "fsr_implausible", "fsr_no_contact", "motor_stalled")
"""Fault causes; the ``fault`` slot holds 0 (none) or the cause's position here plus one."""

_EVENT_TEXTS = ("fault {}: retract", "contact lost: freeze", "contact regained: resume",
                "non-finite command: hold", "finite command again: resume", "retracted: hold")
_EVENT_NAMES = ("fault", "contact_lost", "contact_regained", "nonfinite", "finite_again", "retracted")

_WINDOWS = ("est_win", "cmd_win", "sp_win", "speed_win")
"""Running min and max windows: the estimate (stuck rule), the delayed command (stuck rule
without a current), the setpoint (release) and the rack speed (held peak: only its maximum is
kept; its minimum's deque stays empty and the start of its ring holds the detectors' cached
compressions, :func:`_soft_compression_m`)."""
_QUEUES = ("cmd_delay", "drop_hist")
"""Plain time-ordered queues: the command delayed by ``stuck_response_s`` and the recent
estimates of the drop rule."""

_STATE_SCALARS = ("mode", "fault", "t", "u_prev", "theta", "nan_s", "in_contact", "freeze_t0", "retract_t0",
                  "moving_s", "speed", "accel", "travel_m", "stuck_ref_n", "stuck_travel_m", "contact_travel_m",
                  "contact_travel_set", "cut_t", "sp_last", "fall_t", "stall_s", "implausible_s", "current_limit_a",
                  "last_f", "event_count", "events_dropped", "first_dropped_t")
_CFG_SCALARS = ("force_cap_n", "cap_margin_n", "sp_max_n", "slew_v_per_s", "rated_current_sq_a2", "i2t_limit_a2s",
                "motor_resistance_ohm", "driver_supply_v", "back_emf_v_s_per_m", "powered_current_a",
                "moving_speed_m_per_s", "stuck_tolerance_n", "contact_lost_n", "contact_on_n", "stuck_travel_m",
                "soft_b_n_per_m", "soft_m_per_m", "release_window_s", "travel_follow_s", "implausible_n",
                "first_contact_travel_m", "contact_current_a", "stall_fraction", "current_limit_a", "stall_time_s",
                "push_force_per_a_n", "breakaway_friction_n", "push_weight_n", "guide_static_n", "impact_mass_kg",
                "implausible_s", "out_of_range_n", "stuck_response_s", "stuck_emf_v", "stuck_command_v",
                "drop_window_s", "drop_n", "drop_keep_fraction", "backoff_s", "contact_loss_timeout_s", "retract_v", "watchdog_timeout_s",
                "retract_s", "retract_moving_s", "max_retract_s", "min_dt_s", "events_base", "events_cap",
                "envelope_n", "envelope_base", "state_len")


def _record(kind: str, names, start: int = 0):
    """A read-only record of indices (a named tuple): compiled code reads its fields as constants."""
    return collections.namedtuple(kind, names)(*range(start, start + len(names)))


# A window is five consecutive state slots (t0, lo head, lo count, hi head, hi count) and five
# consecutive configuration slots (span, lo base, lo capacity, hi base, hi capacity); a queue
# is two of each (head, count; base, capacity).  The compiled helpers index from the first.
SV = _record("SupervisorStateSlots", _STATE_SCALARS
             + tuple(f"{w}_{s}" for w in _WINDOWS for s in ("t0", "lo_head", "lo_count", "hi_head", "hi_count"))
             + tuple(f"{q}_{s}" for q in _QUEUES for s in ("head", "count")))
"""Slots of the supervisor's state array (the ring buffers and the events follow them)."""
CF = _record("SupervisorConfigSlots", _CFG_SCALARS
             + tuple(f"{w}_{s}" for w in _WINDOWS for s in ("span", "lo_base", "lo_cap", "hi_base", "hi_cap"))
             + tuple(f"{q}_{s}" for q in _QUEUES for s in ("base", "cap")))
"""Slots of the supervisor's configuration array (the speed envelope table follows them)."""
MODE = _record("SupervisorModes", MODES)
FAULT = _record("SupervisorFaults", FAULTS, start=1)
EVENT = _record("SupervisorEvents", _EVENT_NAMES)
_N_HEADER = len(SV)


def _window_capacity(span_s: float, min_dt_s: float) -> int:
    """Entries a window or queue over ``span_s`` can hold at periods >= ``min_dt_s`` (with rounding margin)."""
    return int(max(span_s, 0.0) / min_dt_s * (1.0 + 1e-6)) + 4


def _pack(c: SupervisorConfig) -> np.ndarray:
    """The configuration array of ``c``: derived constants, buffer layout, speed envelope."""
    spans = {"est_win": c.stuck_window_s, "cmd_win": c.stuck_window_s - c.stuck_response_s,
             "sp_win": c.release_window_s, "speed_win": c.speed_hold_s,
             "cmd_delay": c.stuck_response_s, "drop_hist": c.drop_window_s}
    min_dt = max(MIN_CONTROL_PERIOD_S, max(spans.values()) / MAX_WINDOW_SAMPLES)
    vals = {
        "force_cap_n": c.force_cap_n, "cap_margin_n": c.cap_margin_n, "sp_max_n": c.force_cap_n - c.cap_margin_n,
        "slew_v_per_s": c.slew_v_per_s, "rated_current_sq_a2": c.rated_current_a ** 2,
        "i2t_limit_a2s": c.i2t_limit_a2s, "motor_resistance_ohm": c.motor_resistance_ohm,
        "driver_supply_v": c.driver_supply_v, "back_emf_v_s_per_m": c.back_emf_v_s_per_m,
        "powered_current_a": c.powered_current_a, "moving_speed_m_per_s": c.moving_speed_m_per_s,
        "stuck_tolerance_n": c.stuck_tolerance_n, "contact_lost_n": c.contact_lost_n,
        "contact_on_n": c.contact_on_n, "stuck_travel_m": c.stuck_travel_m, "soft_b_n_per_m": c.soft_b_n_per_m,
        "soft_m_per_m": c.soft_m_per_m, "release_window_s": c.release_window_s,
        "travel_follow_s": c.travel_follow_s, "implausible_n": c.implausible_n,
        "first_contact_travel_m": c.first_contact_travel_m, "contact_current_a": c.current_for_force_a(c.contact_on_n),
        "stall_fraction": c.stall_fraction, "current_limit_a": c.current_limit_a, "stall_time_s": c.stall_time_s,
        "push_force_per_a_n": c.push_force_per_a_n,
        "breakaway_friction_n": c.friction_breakaway_ratio * c.friction_current_a * c.push_force_per_a_n,
        "push_weight_n": -c.weight_n, "guide_static_n": c.guide_static_n, "impact_mass_kg": c.impact_mass_kg,
        "implausible_s": c.implausible_s, "out_of_range_n": c.out_of_range_n,
        "stuck_response_s": c.stuck_response_s, "stuck_emf_v": c.stuck_emf_v,
        "stuck_command_v": c.stuck_command_v, "drop_window_s": c.drop_window_s, "drop_n": c.drop_n,
        "drop_keep_fraction": c.drop_keep_fraction,
        "backoff_s": c.backoff_s, "contact_loss_timeout_s": c.contact_loss_timeout_s, "retract_v": c.retract_v,
        "watchdog_timeout_s": c.watchdog_timeout_s, "retract_s": c.retract_s,
        "retract_moving_s": c.retract_moving_s, "max_retract_s": c.max_retract_s, "min_dt_s": min_dt,
        "events_cap": EVENT_CAPACITY, "envelope_n": ENVELOPE_POINTS, "envelope_base": len(CF),
    }
    pos = _N_HEADER
    for w, span_key, lo_base, lo_cap, hi_base, hi_cap in _WINDOW_KEYS:
        cap = _window_capacity(spans[w], min_dt)
        vals[span_key] = spans[w]
        vals[lo_base], vals[lo_cap] = pos, cap
        pos += 2 * cap
        vals[hi_base], vals[hi_cap] = pos, cap
        pos += 2 * cap
    for q, base_key, cap_key in _QUEUE_KEYS:
        cap = _window_capacity(spans[q], min_dt)
        vals[base_key], vals[cap_key] = pos, cap
        pos += 2 * cap
    vals["events_base"] = pos
    vals["state_len"] = pos + 3 * EVENT_CAPACITY
    cfg = np.empty(len(CF) + 2 * ENVELOPE_POINTS)
    cfg[:len(CF)] = _config_values(vals)
    _envelope_table(c, cfg[len(CF):])
    return cfg


_WINDOW_KEYS = tuple((w, f"{w}_span", f"{w}_lo_base", f"{w}_lo_cap", f"{w}_hi_base", f"{w}_hi_cap") for w in _WINDOWS)
_QUEUE_KEYS = tuple((q, f"{q}_base", f"{q}_cap") for q in _QUEUES)
_config_values = operator.itemgetter(*CF._fields)
"""The keys :func:`_pack` fills for the windows and queues, and the getter of its values in the
order of :data:`CF` (made once)."""


def _initial_state(c: SupervisorConfig) -> np.ndarray:
    """The header of the state array after a reset (the ring buffers are empty by their counts):
    :func:`_reset_header` with the configuration's current limit."""
    h = _reset_header().copy()
    h[SV.current_limit_a] = c.current_limit_a
    return h


@functools.lru_cache(maxsize=1)
def _reset_header() -> np.ndarray:
    """The slots of a reset state header that no configuration changes (read-only, made once:
    every supervisor a reset makes starts from a copy)."""
    h = np.zeros(_N_HEADER)
    for name in ("stuck_ref_n", "contact_travel_m", "first_dropped_t") + tuple(f"{w}_t0" for w in _WINDOWS):
        h[getattr(SV, name)] = math.nan
    h[SV.cut_t] = -math.inf
    h[SV.sp_last] = math.inf
    h[SV.fall_t] = -math.inf
    h.flags.writeable = False
    return h


# ---- compiled period --------------------------------------------------------------------------

@njit(cache=True, inline="always")
def _pymin(a, b):
    """Python's ``min(a, b)``: ``a`` unless ``b < a`` (so a NaN in ``b`` gives ``a``)."""
    return b if b < a else a


@njit(cache=True, inline="always")
def _pymax(a, b):
    """Python's ``max(a, b)``: ``a`` unless ``b > a``."""
    return b if b > a else a


@njit(cache=True, inline="always")
def _at(sv, cfg, head, base, i):
    """Index in ``sv`` of the time of entry ``i`` (0: front) of the ring at slots ``head``/``base``.

    The head is below the capacity and ``i`` at most the count, so the ring wraps at most once:
    a compare and a subtraction stand for the remainder."""
    j = int(sv[head]) + i
    cap = int(cfg[base + 1])
    if j >= cap:
        j -= cap
    return int(cfg[base]) + 2 * j


@njit(cache=True, inline="always")
def _append(sv, cfg, head, base, t, x):
    n = int(sv[head + 1])
    if n >= int(cfg[base + 1]):
        raise ValueError("supervisor window full: the control period is below the shortest it was sized for")
    k = _at(sv, cfg, head, base, n)
    sv[k] = t
    sv[k + 1] = x
    sv[head + 1] = n + 1


@njit(cache=True, inline="always")
def _pop_front(sv, cfg, head, base):
    j = int(sv[head]) + 1
    sv[head] = 0 if j >= int(cfg[base + 1]) else j
    sv[head + 1] -= 1.0


@njit(cache=True, inline="always")
def _cut_front(sv, cfg, head, base, cut):
    """Drop the front entries older than ``cut`` (a window emptied this way is a configuration error)."""
    while True:
        if sv[head + 1] <= 0.0:
            raise ValueError("supervisor window empty: stuck_response_s must not exceed stuck_window_s")
        if sv[_at(sv, cfg, head, base, 0)] < cut:
            _pop_front(sv, cfg, head, base)
        else:
            break


@njit(cache=True, inline="always")
def _win_push(sv, cfg, w, wc, t, x, keep_min):
    """Running min/max push (monotonic deques) of the window at state slot ``w``, config slot ``wc``.

    The back of both deques is the last value pushed: a push leaves it there and a cut never
    reaches it (its time is the newest).  The deques are strictly monotonic, so the same value
    again pops just that entry from each and appends ``(t, x)`` in its place: that is done by
    writing the entry.  ``keep_min`` false keeps only the running maximum (a window whose
    minimum no rule reads; its minimum's deque is left empty)."""
    if math.isnan(sv[w]):
        sv[w] = t
    lo, hi = w + 1, w + 3
    if sv[hi + 1] > 0.0 and sv[_at(sv, cfg, hi, wc + 3, int(sv[hi + 1]) - 1) + 1] == x:
        k = _at(sv, cfg, hi, wc + 3, int(sv[hi + 1]) - 1)
        sv[k] = t
        sv[k + 1] = x
        if keep_min:
            k = _at(sv, cfg, lo, wc + 1, int(sv[lo + 1]) - 1)
            sv[k] = t
            sv[k + 1] = x
    else:
        if keep_min:
            while sv[lo + 1] > 0.0 and sv[_at(sv, cfg, lo, wc + 1, int(sv[lo + 1]) - 1) + 1] >= x:
                sv[lo + 1] -= 1.0
        while sv[hi + 1] > 0.0 and sv[_at(sv, cfg, hi, wc + 3, int(sv[hi + 1]) - 1) + 1] <= x:
            sv[hi + 1] -= 1.0
        if keep_min:
            _append(sv, cfg, lo, wc + 1, t, x)
        _append(sv, cfg, hi, wc + 3, t, x)
    cut = t - cfg[wc]
    if keep_min:
        _cut_front(sv, cfg, lo, wc + 1, cut)
    _cut_front(sv, cfg, hi, wc + 3, cut)


@njit(cache=True, inline="always")
def _win_lo(sv, cfg, w, wc):
    return sv[_at(sv, cfg, w + 1, wc + 1, 0) + 1]


@njit(cache=True, inline="always")
def _win_hi(sv, cfg, w, wc):
    return sv[_at(sv, cfg, w + 3, wc + 3, 0) + 1]


@njit(cache=True, inline="always")
def _win_range(sv, cfg, w, wc):
    return _win_hi(sv, cfg, w, wc) - _win_lo(sv, cfg, w, wc)


@njit(cache=True, inline="always")
def _win_full(sv, cfg, w, wc, t):
    return not math.isnan(sv[w]) and t - sv[w] >= cfg[wc]


@njit(cache=True)
def _event(sv, cfg, code, value):
    n = int(sv[SV.event_count])
    if n < int(cfg[CF.events_cap]):
        k = int(cfg[CF.events_base]) + 3 * n
        sv[k] = sv[SV.t]
        sv[k + 1] = code
        sv[k + 2] = value
        sv[SV.event_count] = n + 1
    else:
        if sv[SV.events_dropped] == 0.0:
            sv[SV.first_dropped_t] = sv[SV.t]
        sv[SV.events_dropped] += 1.0


@njit(cache=True)
def _trip(sv, cfg, cause):
    if sv[SV.fault] == 0.0:
        sv[SV.fault] = cause
        sv[SV.mode] = MODE.retract
        sv[SV.retract_t0] = sv[SV.t]
        sv[SV.moving_s] = 0.0
        _event(sv, cfg, EVENT.fault, cause)


@njit(cache=True, inline="always")
def _slew(sv, cfg, u, dt):
    du = cfg[CF.slew_v_per_s] * dt
    return _pymin(_pymax(u, sv[SV.u_prev] - du), sv[SV.u_prev] + du)


@njit(cache=True)
def _safe(sv, cfg, cur, dt):
    """Command of the latched safe state: retract, then hold at 0 V."""
    if sv[SV.mode] == MODE.retract:
        el = sv[SV.t] - sv[SV.retract_t0]
        if math.isnan(cur):
            done = el >= cfg[CF.retract_s]
        else:
            stalled = abs(cur) > 0.6 * cfg[CF.retract_v] / cfg[CF.motor_resistance_ohm]
            if not stalled and el > 0.01:
                sv[SV.moving_s] += dt
            done = (sv[SV.moving_s] >= cfg[CF.retract_moving_s] and stalled) or el >= cfg[CF.max_retract_s]
        if done:
            sv[SV.mode] = MODE.hold
            _event(sv, cfg, EVENT.retracted, 0.0)
        else:
            u = _slew(sv, cfg, -cfg[CF.retract_v], dt)
            sv[SV.u_prev] = u
            return u
    u = _slew(sv, cfg, 0.0, dt)
    sv[SV.u_prev] = u
    return u


@njit(cache=True, inline="always")
def _motion(sv, cfg, cur, dt):
    """Rack speed from the back-EMF of the last period, travel integral, held peak speed."""
    vs = cfg[CF.driver_supply_v]
    u = _pymin(_pymax(sv[SV.u_prev], -vs), vs)
    v = limits.rack_speed_from_emf_m_per_s(u, cur, cfg[CF.motor_resistance_ohm], cfg[CF.back_emf_v_s_per_m], 1.0)
    sv[SV.accel] = (v - sv[SV.speed]) / dt
    sv[SV.speed] = v
    if abs(cur) > cfg[CF.powered_current_a]:     # an unpowered motor (a cut supply) reads its command as speed
        sv[SV.travel_m] = _pymax(0.0, sv[SV.travel_m] + v * dt)
    _win_push(sv, cfg, SV.speed_win_t0, CF.speed_win_span, sv[SV.t], v, False)


@njit(cache=True, inline="always")
def _interp_envelope(cfg, x):
    """Current limit at speed ``x`` from the envelope table: linear between the points (``bisect_right``)."""
    n = int(cfg[CF.envelope_n])
    b = int(cfg[CF.envelope_base])
    if x <= cfg[b]:
        return cfg[b + n]
    if x >= cfg[b + n - 1]:
        return cfg[b + 2 * n - 1]
    lo, hi = 0, n
    while lo < hi:
        mid = (lo + hi) // 2
        if x < cfg[b + mid]:
            hi = mid
        else:
            lo = mid + 1
    if lo >= n:                       # x is NaN: no interval holds it
        return math.nan
    x0, x1, y0, y1 = cfg[b + lo - 1], cfg[b + lo], cfg[b + n + lo - 1], cfg[b + n + lo]
    return y0 + (y1 - y0) * (x - x0) / (x1 - x0)


@njit(cache=True, inline="always")
def _envelope_cap(sv, cfg, u, cur):
    """Largest command that keeps the next period's current within the speed-dependent limit."""
    v_held = _pymax(_win_hi(sv, cfg, SV.speed_win_t0, CF.speed_win_span), 0.0)
    i_lim = _interp_envelope(cfg, v_held)
    sv[SV.current_limit_a] = i_lim
    vs = cfg[CF.driver_supply_v]
    u_applied = _pymin(_pymax(sv[SV.u_prev], -vs), vs)
    return _pymin(u, u_applied + cfg[CF.motor_resistance_ohm] * (i_lim - cur))


@njit(cache=True, inline="always")
def _rest_push_lower_edge_n(cfg, cur):
    """Least force (N) that the drive at current ``cur`` applies to the finger when nothing else
    takes it: the steady push bound with break-away friction, the weight against the push and the
    guide rods' break-away friction (the lower edge of the friction band)."""
    return (limits.push_force_bound_n(cur, cfg[CF.push_force_per_a_n], 1.0, 1.0, cfg[CF.breakaway_friction_n],
                                      cfg[CF.push_weight_n]) - cfg[CF.guide_static_n])


@njit(cache=True, inline="always")
def _soft_compression_m(sv, cfg, pair, force_n):
    """:func:`~ebraille_sim.physics.fingertip.compression_at_force_m` of ``force_n`` on the soft
    reader, through a one-entry cache: the ``pair``-th (force, compression) pair at the start of
    the speed window's unused minimum ring (:data:`_WINDOWS`).

    The estimate holds its value for an estimator period, so most periods ask for the force of
    the last call, and the law is computed again only when the force differs.  The pair depends
    on the configuration alone, so a reset keeps it; a ring of zeros holds the pair (0, 0), which
    is the law's value.  The callers' forces are positive or a sum with a positive margin, never
    a negative zero (which would compare equal to 0 with a compression of the other sign); a
    NaN never matches."""
    k = int(cfg[CF.speed_win_lo_base]) + 2 * pair
    if force_n != sv[k]:
        sv[k] = force_n
        sv[k + 1] = compression_at_force_m(force_n, cfg[CF.soft_b_n_per_m], cfg[CF.soft_m_per_m])
    return sv[k + 1]


@njit(cache=True, inline="always")
def _detect(sv, cfg, f, cur, dt):
    """The detectors that need the motor current; the fault code, or 0."""
    v = sv[SV.speed]
    moving = abs(v) > cfg[CF.moving_speed_m_per_s]
    in_contact = sv[SV.in_contact] != 0.0
    # a stuck code: the estimate does not change while the board travels
    if f > cfg[CF.contact_lost_n] and in_contact:
        if not abs(f - sv[SV.stuck_ref_n]) <= cfg[CF.stuck_tolerance_n]:
            sv[SV.stuck_ref_n] = f
            sv[SV.stuck_travel_m] = 0.0
        elif abs(cur) > cfg[CF.powered_current_a]:    # a powered motor: an unpowered one (a cut supply)
            # draws no current and its command reads as speed
            sv[SV.stuck_travel_m] += v * dt
            if abs(sv[SV.stuck_travel_m]) > cfg[CF.stuck_travel_m]:
                return FAULT.fsr_stuck
    else:
        sv[SV.stuck_ref_n] = math.nan
    # travel since the first contact against the compression the estimate allows on the soft reader
    if in_contact:
        if sv[SV.contact_travel_set] == 0.0:
            sv[SV.contact_travel_m] = sv[SV.travel_m]
            sv[SV.contact_travel_set] = 1.0
        elif f > cfg[CF.contact_on_n]:
            # the reference follows where the pulp's surface must be for the estimate shown,
            # at once on an intended release (the setpoint fell: the back-EMF integral's drift
            # over many presses in refresh mode does not add up) and slowly otherwise (the
            # finger drifts, presses and the strap slips over a session: only a fast mismatch,
            # a board running into the finger while the reading stays low, trips)
            target = sv[SV.travel_m] - _soft_compression_m(sv, cfg, 0, f)
            if sv[SV.t] - sv[SV.fall_t] <= cfg[CF.release_window_s]:
                sv[SV.contact_travel_m] = _pymax(sv[SV.contact_travel_m], target)
            else:
                sv[SV.contact_travel_m] = sv[SV.contact_travel_m] + (target - sv[SV.contact_travel_m]) * _pymin(
                    1.0, dt / cfg[CF.travel_follow_s])
        allowed = (_soft_compression_m(sv, cfg, 1, _win_hi(sv, cfg, SV.est_win_t0, CF.est_win_span)
                                       + cfg[CF.implausible_n]) + cfg[CF.stuck_travel_m])
        if sv[SV.travel_m] - sv[SV.contact_travel_m] > allowed:
            return FAULT.fsr_implausible
    # no contact within the travel the gap allows
    if not in_contact and sv[SV.travel_m] > cfg[CF.first_contact_travel_m]:
        return FAULT.fsr_no_contact
    # pushing and not moving: with no contact seen, or at the current limit with a push that does
    # not reach the finger (the lower edge of the friction band at rest above the estimate): a
    # motor creeping a held force forward against the full break-away friction also sits at the
    # limit, and its estimate accounts for the push
    if not moving and ((f < cfg[CF.contact_on_n] and cur > cfg[CF.contact_current_a])
                       or (cur > cfg[CF.stall_fraction] * cfg[CF.current_limit_a]
                           and _rest_push_lower_edge_n(cfg, cur) - _win_hi(sv, cfg, SV.est_win_t0, CF.est_win_span)
                           > cfg[CF.implausible_n])):
        sv[SV.stall_s] += dt
        if sv[SV.stall_s] > cfg[CF.stall_time_s]:
            return FAULT.motor_stalled
    else:
        sv[SV.stall_s] = 0.0
    # the force the current implies while the board moves forward, against the estimate
    if v > cfg[CF.moving_speed_m_per_s]:
        a = _pymax(sv[SV.accel], 0.0)
        # lower edge of the friction band: break-away friction, guide friction, weight against
        # the push, and the force that accelerates the rotor and the board
        f_lo = _rest_push_lower_edge_n(cfg, cur) - cfg[CF.impact_mass_kg] * a
        if f_lo - _win_hi(sv, cfg, SV.est_win_t0, CF.est_win_span) > cfg[CF.implausible_n]:
            sv[SV.implausible_s] += dt
            if sv[SV.implausible_s] > cfg[CF.implausible_s]:
                return FAULT.fsr_implausible
        else:
            sv[SV.implausible_s] = 0.0
    else:
        sv[SV.implausible_s] = 0.0
    return 0


@njit(cache=True, _nrt=False)
def supervise_begin(sv, cfg, f, sp, dt, cur):
    """First half of one supervised period: detectors, contact tracking, the safe states.

    Parameters
    ----------
    sv, cfg : ndarray of float64
        The state and configuration arrays of :meth:`Supervisor.compiled`.
    f : float
        Force estimate, N.
    sp : float
        Setpoint, N.
    dt : float
        Control period, s (at least the configuration's ``min_dt_s``).
    cur : float
        Measured motor current, A; NaN (or any non-finite value) when there is none.

    Returns
    -------
    code : int
        0: the command is ``u`` and the inner controller is not called.  1: call the inner
        controller with ``(f, sp_inner, dt, current)`` and pass its command to
        :func:`supervise_end`.  2: contact regained; reset the inner controller with
        ``force_est_n=f, setpoint_n=sp_inner, command_v=0.0``; the command is ``u`` (0 V).
    u : float
        Command, V (NaN for code 1).
    sp_inner : float
        Setpoint for the inner controller, N (clipped to ``force_cap_n - cap_margin_n``).
    """
    sv[SV.t] += dt
    t = sv[SV.t]
    has_cur = math.isfinite(cur)
    if not has_cur:
        cur = math.nan
    else:
        sv[SV.theta] = _pymax(0.0, sv[SV.theta] + (cur * cur - cfg[CF.rated_current_sq_a2]) * dt)
        _motion(sv, cfg, cur, dt)
    if sv[SV.mode] == MODE.retract or sv[SV.mode] == MODE.hold:
        return 0, _safe(sv, cfg, cur, dt), math.nan
    # detectors that latch
    if not math.isfinite(f) or f > cfg[CF.out_of_range_n]:
        _trip(sv, cfg, FAULT.fsr_out_of_range)
        return 0, _safe(sv, cfg, cur, dt), math.nan
    if sv[SV.theta] > cfg[CF.i2t_limit_a2s]:
        _trip(sv, cfg, FAULT.motor_overcurrent)
        return 0, _safe(sv, cfg, cur, dt), math.nan
    _win_push(sv, cfg, SV.est_win_t0, CF.est_win_span, t, f, True)
    if not has_cur:
        # the command window (the stuck rule without a current measurement) lags by the
        # estimator's response: a command that moved within the last ``stuck_response_s``
        # cannot have shown in the estimate yet
        _append(sv, cfg, SV.cmd_delay_head, CF.cmd_delay_base, t, sv[SV.u_prev])
        while True:
            k = _at(sv, cfg, SV.cmd_delay_head, CF.cmd_delay_base, 0)
            if not sv[k] <= t - cfg[CF.stuck_response_s]:
                break
            t_old, u_old = sv[k], sv[k + 1]
            _pop_front(sv, cfg, SV.cmd_delay_head, CF.cmd_delay_base)
            _win_push(sv, cfg, SV.cmd_win_t0, CF.cmd_win_span, t_old, u_old, True)
    sp_now = sp if math.isfinite(sp) else 0.0
    if sp_now < sv[SV.sp_last] - 1e-9:
        sv[SV.fall_t] = t                  # the setpoint fell: an intended release
    sv[SV.sp_last] = sp_now
    _win_push(sv, cfg, SV.sp_win_t0, CF.sp_win_span, t, sp_now, True)
    moving = (not has_cur) or abs(sv[SV.u_prev] - cfg[CF.motor_resistance_ohm] * cur) > cfg[CF.stuck_emf_v]
    # without a current measurement only: with one, the travel the back-EMF integral gives
    # decides (:func:`_detect`); ``u - R i`` of one period reads as motion inside the
    # gearhead's friction band and during a command step, where the board does not move
    if (not has_cur and moving and not math.isnan(sv[SV.cmd_win_t0]) and sv[SV.in_contact] != 0.0
            and _win_full(sv, cfg, SV.est_win_t0, CF.est_win_span, t)
            and _win_lo(sv, cfg, SV.est_win_t0, CF.est_win_span) > cfg[CF.contact_lost_n]
            and _win_range(sv, cfg, SV.est_win_t0, CF.est_win_span) < cfg[CF.stuck_tolerance_n]
            and _win_range(sv, cfg, SV.cmd_win_t0, CF.cmd_win_span) > cfg[CF.stuck_command_v]):
        _trip(sv, cfg, FAULT.fsr_stuck)
        return 0, _safe(sv, cfg, cur, dt), math.nan
    if has_cur and sv[SV.mode] == MODE.run:
        cause = _detect(sv, cfg, f, cur, dt)
        if cause != 0:
            _trip(sv, cfg, cause)
            return 0, _safe(sv, cfg, cur, dt), math.nan
    # contact tracking
    _append(sv, cfg, SV.drop_hist_head, CF.drop_hist_base, t, f)
    while sv[_at(sv, cfg, SV.drop_hist_head, CF.drop_hist_base, 0)] < t - cfg[CF.drop_window_s]:
        _pop_front(sv, cfg, SV.drop_hist_head, CF.drop_hist_base)
    f_then = sv[_at(sv, cfg, SV.drop_hist_head, CF.drop_hist_base, 0) + 1]
    if sv[SV.mode] == MODE.run:
        if f > cfg[CF.contact_on_n]:
            sv[SV.in_contact] = 1.0
        # an intended release (the setpoint fell, or asks for no contact) is not a loss
        released = _win_range(sv, cfg, SV.sp_win_t0, CF.sp_win_span)
        fell = t - sv[SV.fall_t] <= cfg[CF.release_window_s]
        lost = ((f < cfg[CF.contact_lost_n] and sp > cfg[CF.contact_on_n] and not fell)
                or (f_then - f > cfg[CF.drop_n] + _pymax(released, 0.0) and f < cfg[CF.drop_keep_fraction] * f_then
                    and sv[SV.u_prev] > 0.0
                    and t - sv[SV.cut_t] > cfg[CF.drop_window_s]))
        if sv[SV.in_contact] != 0.0 and lost:
            sv[SV.mode] = MODE.freeze
            sv[SV.freeze_t0] = t
            sv[SV.contact_travel_m] = math.nan       # the compression check starts again at the next contact
            sv[SV.contact_travel_set] = 0.0
            _event(sv, cfg, EVENT.contact_lost, 0.0)
    if sv[SV.mode] == MODE.freeze:
        since = t - sv[SV.freeze_t0]
        if f > cfg[CF.contact_on_n] and f >= f_then and since > cfg[CF.backoff_s]:
            sv[SV.mode] = MODE.run
            _event(sv, cfg, EVENT.contact_regained, 0.0)
            sv[SV.u_prev] = 0.0
            return 2, 0.0, _pymin(sp, cfg[CF.sp_max_n])
        if since > cfg[CF.contact_loss_timeout_s]:
            _trip(sv, cfg, FAULT.contact_lost)
            return 0, _safe(sv, cfg, cur, dt), math.nan
        u = -cfg[CF.retract_v] if since <= cfg[CF.backoff_s] else 0.0
        sv[SV.u_prev] = u
        return 0, u, math.nan
    return 1, math.nan, _pymin(sp, cfg[CF.sp_max_n])


@njit(cache=True, _nrt=False)
def supervise_end(sv, cfg, u, f, sp, dt, cur):
    """Second half of a period whose :func:`supervise_begin` gave code 1: shape the inner command.

    Parameters
    ----------
    sv, cfg : ndarray of float64
        As for :func:`supervise_begin`.
    u : float
        The inner controller's command, V (any value: a non-finite one is the watchdog's case).
    f, sp, dt, cur : float
        As passed to :func:`supervise_begin` in the same period.

    Returns
    -------
    code : int
        1: the command is finite again after a non-finite stretch; reset the inner controller
        with ``force_est_n=f, setpoint_n=sp_inner, command_v=reset_cmd``.  0 otherwise.
    u : float
        Command, V.
    reset_cmd : float
        Command to reset the inner controller from (code 1), V; NaN otherwise.
    """
    if not math.isfinite(cur):
        cur = math.nan
    if not math.isfinite(u):
        if sv[SV.nan_s] == 0.0:
            _event(sv, cfg, EVENT.nonfinite, 0.0)
        sv[SV.nan_s] += dt
        if sv[SV.nan_s] > cfg[CF.watchdog_timeout_s]:
            _trip(sv, cfg, FAULT.controller_nonfinite)
            return 0, _safe(sv, cfg, cur, dt), math.nan
        u = _slew(sv, cfg, 0.0, dt)
        sv[SV.u_prev] = u
        return 0, u, math.nan
    code = 0
    reset_cmd = math.nan
    if sv[SV.nan_s] > 0.0:
        sv[SV.nan_s] = 0.0
        _event(sv, cfg, EVENT.finite_again, 0.0)
        code = 1
        reset_cmd = sv[SV.u_prev]
        u = sv[SV.u_prev]
    u_inner = u
    lo = cfg[CF.force_cap_n] - cfg[CF.cap_margin_n]
    if f >= cfg[CF.force_cap_n]:
        u = -cfg[CF.retract_v]
    elif f > lo and u > 0.0:
        u *= 1.0 - (f - lo) / cfg[CF.cap_margin_n]
    u = _slew(sv, cfg, u, dt)
    if not math.isnan(cur):
        u = _envelope_cap(sv, cfg, u, cur)
    if u < u_inner - 1e-9:
        sv[SV.cut_t] = sv[SV.t]            # the supervisor held the push back: a drop that follows is its own
    sv[SV.u_prev] = u
    return code, u, reset_cmd


# ---- Python wrapper -----------------------------------------------------------------------------

def _scalar(name: str) -> property:
    k = getattr(SV, name)

    def get(self) -> float:
        return float(self._sv[k])

    def set_(self, value: float) -> None:
        self._sv[k] = value

    return property(get, set_, doc=f"``{name}`` of the state array (see :func:`supervise_begin`).")


class Supervisor:
    """Safety wrapper around a :class:`~controllers.base.Controller` (see the module docstring).

    The state lives in a float64 array (:meth:`compiled`); the attributes below decode it.

    Attributes
    ----------
    mode : str
        ``"run"``, ``"freeze"`` (contact lost), ``"retract"`` or ``"hold"``.
    fault : str or None
        Cause of the latched fault, if any.
    events : list of (float, str)
        Time since reset (s) and a short description of every mode change.
    """

    def __init__(self, inner, config: SupervisorConfig = SupervisorConfig(), *, state_out: np.ndarray | None = None,
                 config_out: np.ndarray | None = None):
        """``state_out`` and ``config_out`` (both or neither): arrays to hold the state and the
        configuration from the start, as :meth:`bind` would move them there (the state is
        zeroed, the configuration copied in)."""
        if not isinstance(config, SupervisorConfig):
            raise TypeError(f"config must be a SupervisorConfig, got {type(config).__name__}")
        self.inner = inner
        self.config = config
        self.name = f"supervised({getattr(inner, 'name', type(inner).__name__)})"
        packed = config.pack()
        if (state_out is None) != (config_out is None):
            raise ValueError("state_out and config_out go together")
        if state_out is None:
            self._cfg = packed.copy()
            self._sv = np.zeros(int(self._cfg[CF.state_len]))
        else:
            n = int(packed[CF.state_len])
            if np.shape(state_out) != (n,) or np.shape(config_out) != packed.shape:
                raise ValueError(f"the supervisor needs arrays of lengths {n} and {packed.size}, got "
                                 f"{np.shape(state_out)} and {np.shape(config_out)}")
            config_out[:] = packed
            state_out[:] = 0.0
            self._cfg, self._sv = config_out, state_out
        self._sv0 = _initial_state(config)
        self._min_dt = float(self._cfg[CF.min_dt_s])
        self._clear()

    def compiled(self):
        """The live ``(state, config)`` float64 arrays of the compiled period, or None when disabled.

        :func:`supervise_begin` and :func:`supervise_end` advance ``state`` in place; the
        attributes of this object read it, before and after.  ``config`` holds the derived
        constants, the buffer layout and the speed envelope (:meth:`SupervisorConfig.pack`);
        the events are rows ``(time, code, value)`` inside ``state``.
        """
        if not self.config.enabled:
            return None
        return self._sv, self._cfg

    @property
    def min_control_period_s(self) -> float:
        """Shortest control period (s) the supervisor's window buffers are sized for."""
        return self._min_dt

    def bind(self, state_out: np.ndarray, config_out: np.ndarray) -> None:
        """Move the live arrays into ``state_out`` and ``config_out`` (e.g. one row each of a
        batch's 2-D arrays, stepped by :func:`supervise_commands`); this object then reads and
        resets those.

        Raises
        ------
        ValueError
            The arrays do not have the lengths of :meth:`compiled`'s.
        """
        if np.shape(state_out) != self._sv.shape or np.shape(config_out) != self._cfg.shape:
            raise ValueError(f"bind needs arrays of lengths {self._sv.size} and {self._cfg.size}, got "
                             f"{np.shape(state_out)} and {np.shape(config_out)}")
        state_out[:] = self._sv
        config_out[:] = self._cfg
        self._sv, self._cfg = state_out, config_out

    def _clear(self):
        self._sv[:_N_HEADER] = self._sv0

    def reset(self, *, force_est_n: float, setpoint_n: float, command_v: float = 0.0) -> None:
        """Clear faults and detectors and reset the inner controller bumplessly."""
        self._clear()
        self._sv[SV.u_prev] = float(command_v) if math.isfinite(command_v) else 0.0
        self.inner.reset(force_est_n=force_est_n, setpoint_n=min(setpoint_n, self._sp_max), command_v=command_v)

    @property
    def _sp_max(self) -> float:
        return self.config.force_cap_n - self.config.cap_margin_n

    @property
    def mode(self) -> str:
        return MODES[int(self._sv[SV.mode])]

    @mode.setter
    def mode(self, value: str) -> None:
        self._sv[SV.mode] = MODES.index(value)

    @property
    def fault(self) -> str | None:
        k = int(self._sv[SV.fault])
        return None if k == 0 else FAULTS[k - 1]

    @fault.setter
    def fault(self, value: str | None) -> None:
        self._sv[SV.fault] = 0 if value is None else FAULTS.index(value) + 1

    @property
    def in_contact(self) -> bool:
        return bool(self._sv[SV.in_contact])

    @in_contact.setter
    def in_contact(self, value: bool) -> None:
        self._sv[SV.in_contact] = bool(value)

    @property
    def contact_travel_m(self) -> float | None:
        return float(self._sv[SV.contact_travel_m]) if self._sv[SV.contact_travel_set] else None

    @property
    def events(self) -> list[tuple[float, str]]:
        sv = self._sv
        n = int(sv[SV.event_count])
        base = int(self._cfg[CF.events_base])
        out = []
        for t, code, value in sv[base:base + 3 * n].reshape(n, 3).tolist():
            text = _EVENT_TEXTS[int(code)]
            out.append((round(t, 6), text.format(FAULTS[int(value) - 1]) if code == EVENT.fault else text))
        dropped = int(sv[SV.events_dropped])
        if dropped:
            out.append((round(float(sv[SV.first_dropped_t]), 6),
                        f"event log full: {dropped} events from here on not recorded"))
        return out

    t = _scalar("t")
    u_prev = _scalar("u_prev")
    theta = _scalar("theta")
    nan_s = _scalar("nan_s")
    freeze_t0 = _scalar("freeze_t0")
    retract_t0 = _scalar("retract_t0")
    moving_s = _scalar("moving_s")
    speed = _scalar("speed")
    accel = _scalar("accel")
    travel_m = _scalar("travel_m")
    stuck_ref_n = _scalar("stuck_ref_n")
    stuck_travel_m = _scalar("stuck_travel_m")
    cut_t = _scalar("cut_t")
    sp_last = _scalar("sp_last")
    fall_t = _scalar("fall_t")
    stall_s = _scalar("stall_s")
    implausible_s = _scalar("implausible_s")
    current_limit_a = _scalar("current_limit_a")
    last_f = _scalar("last_f")

    def update(self, force_est_n: float, setpoint_n: float, dt_s: float, motor_current_a: float | None = None) -> float:
        """One period: run the detectors, then pass, shape or replace the inner command.

        An inner controller with an ``applied(command_v)`` method is told the command that
        left the supervisor, every period (a learned policy observes it, as it did in the
        env's safety layer)."""
        c = self.config
        if not 0.0 < dt_s < math.inf:
            check_dt(dt_s)
        if not c.enabled:
            return self.inner.update(force_est_n, setpoint_n, dt_s, motor_current_a)
        if dt_s < self._min_dt:
            raise ValueError(f"dt_s = {dt_s:g} s is below the {self._min_dt:g} s shortest control period the "
                             f"supervisor's windows are sized for (MIN_CONTROL_PERIOD_S, MAX_WINDOW_SAMPLES)")
        f = float(force_est_n)
        sp = float(setpoint_n)
        dt = float(dt_s)
        cur = math.nan if motor_current_a is None or not math.isfinite(motor_current_a) else float(motor_current_a)
        code, u, sp_inner = supervise_begin(self._sv, self._cfg, f, sp, dt, cur)
        if code == 1:
            u_inner = self.inner.update(f, sp_inner, dt_s, motor_current_a)
            code, u, reset_cmd = supervise_end(self._sv, self._cfg, float(u_inner), f, sp, dt, cur)
            if code == 1:
                self.inner.reset(force_est_n=f, setpoint_n=sp_inner, command_v=reset_cmd)
        elif code == 2:
            self.inner.reset(force_est_n=f, setpoint_n=sp_inner, command_v=0.0)
        applied = getattr(self.inner, "applied", None)
        if applied is not None:
            applied(u)
        return u


def _envelope(c: SupervisorConfig) -> tuple[list[float], list[float]]:
    """Current limit against rack speed: (speeds, currents), from rest to beyond the speed limit.

    At each speed the drive force may not exceed :meth:`SupervisorConfig.drive_force_limit_n`;
    beyond :attr:`SupervisorConfig.speed_limit_m_per_s` the limit is a braking current.
    :func:`_envelope_into` computes the same table in one compiled call (what :meth:`SupervisorConfig.pack`
    uses); ``tests/test_reset_cost.py`` checks that both agree to the last bit.
    """
    v_max = c.speed_limit_m_per_s
    speeds = [v_max * k / 32 for k in range(33)]
    currents = [c.current_for_force_a(max(c.drive_force_limit_n(v), 0.0)) for v in speeds]
    speeds.append(1.05 * v_max)
    currents.append(-c.friction_current_a)
    return speeds, currents


ENVELOPE_POINTS = 34
"""Rows of the speed envelope table: 33 speeds from rest to the speed limit and one beyond it."""

_impact_energy_j = njit(cache=True)(limits.impact_energy_j)
_current_for_push_force_a = njit(cache=True)(limits.current_for_push_force_a)


ENVELOPE_MEMO_NODES = 1 << 14
"""Midpoints one of the envelope's bisection memos keeps (0.4 MB; :func:`_envelope_memo`)."""


@functools.lru_cache(maxsize=8)
def _envelope_memo(envelope_force_n: float, reader_b_n_per_m: float, reader_m_per_m: float) -> np.ndarray:
    """The bisection memo of the envelopes with this force and design reader, the most recently
    used eight kept: the design reader is the stiffer of the device's and the stiff preset, so
    most devices of a population share one (and their envelopes one tree of midpoints)."""
    return limits.new_bisection_memo(ENVELOPE_MEMO_NODES)


@njit(cache=True)
def _envelope_into(out, v_max, pinion_mass_kg, board_mass_kg, gear_efficiency, envelope_force_n, reader_b_n_per_m,
                   reader_m_per_m, push_force_per_a_n, friction_current_a, weight_n, memo):
    """:func:`_envelope` of a configuration's constants written into ``out`` (speeds, then currents):
    the laws of :meth:`SupervisorConfig.drive_force_limit_n` and :meth:`SupervisorConfig.current_for_force_a`
    (:mod:`ebraille_sim.physics.limits`) in one compiled loop; ``memo`` keeps the bisections'
    midpoints (:func:`ebraille_sim.physics.limits.drive_forces_for_impacts_n`)."""
    n = ENVELOPE_POINTS
    energies = np.empty(n - 1)
    for k in range(n - 1):
        v = v_max * k / 32
        out[k] = v
        energies[k] = _impact_energy_j(_pymax(v, 0.0), pinion_mass_kg, board_mass_kg, gear_efficiency)
    forces = np.empty(n - 1)
    limits.drive_forces_for_impacts_n(energies, envelope_force_n, reader_b_n_per_m, reader_m_per_m, forces, memo)
    for k in range(n - 1):
        out[n + k] = _current_for_push_force_a(_pymax(forces[k], 0.0), push_force_per_a_n, 1.0, 1.0,
                                               friction_current_a * push_force_per_a_n, weight_n)
    out[n - 1] = 1.05 * v_max
    out[2 * n - 1] = -friction_current_a


def _envelope_table(c: SupervisorConfig, out: np.ndarray) -> None:
    """Write :func:`_envelope` of ``c`` into ``out`` (length ``2 * ENVELOPE_POINTS``) in one compiled call."""
    _envelope_into(out, c.speed_limit_m_per_s, c.pinion_mass_kg, c.board_mass_kg, c.gear_efficiency,
                   c.envelope_force_n, c.reader_b_n_per_m, c.reader_m_per_m, c.push_force_per_a_n,
                   c.friction_current_a, c.weight_n,
                   _envelope_memo(c.envelope_force_n, c.reader_b_n_per_m, c.reader_m_per_m))


@njit(cache=True)
def supervise_commands(sv2, cfg2, rows, commands_v, force_est_n, setpoint_n, dt_s, current_a, out_v):
    """One period of several supervisors whose inner controller returns a given command.

    Row ``r`` of ``sv2``/``cfg2`` is a supervisor's state and configuration
    (:meth:`Supervisor.bind`); its inner controller (an agent's action, which ignores resets)
    commands ``commands_v[r]``.  For every ``r`` in ``rows`` this is
    :meth:`Supervisor.update` (:func:`supervise_begin`, the inner command,
    :func:`supervise_end`) and writes the shaped command to ``out_v[r]``; a non-finite
    ``current_a[r]`` means no measurement.
    """
    for r in rows:
        cur = current_a[r] if math.isfinite(current_a[r]) else math.nan
        code, u, sp_inner = supervise_begin(sv2[r], cfg2[r], force_est_n[r], setpoint_n[r], dt_s, cur)
        if code == 1:
            code, u, reset_cmd = supervise_end(sv2[r], cfg2[r], commands_v[r], force_est_n[r], setpoint_n[r],
                                               dt_s, cur)
        out_v[r] = u
