"""The supervisor's configuration: its policy, the thresholds and times a scenario may set
(:class:`SupervisorPolicy`), and the drive envelope it derives its limits from
(:class:`DriveEnvelope`, :func:`device_limits`): what the firmware knows, the part's datasheet
with the designer's margins and the unit's end-of-line calibration, never the unit's own
constants.  :class:`SupervisorConfig` holds both."""
from __future__ import annotations

import dataclasses
import functools
import math
import operator
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from controllers.supervisor.layout import _pack
from controllers.supervisor.motion import design_slip_cap_n
from ebraille_sim.base.fields import sourced
from ebraille_sim.base.validation import check_bool, check_keys, check_number, replace_fields
from ebraille_sim.physics import limits
from ebraille_sim.estimation.calibration import (CALIBRATION_CONVERSIONS, FORCE_GAUGE_TOLERANCE, FREE_RUN_V,
                                                 RESISTANCE_TEST_V, SPEED_REFERENCE_TOLERANCE, DriveCalibration,
                                                 calibrate_drive)
from ebraille_sim.physics.current_sense import averaged_error_a, mean_error_a, worst_case_error_a
from ebraille_sim.physics.fingertip import compression_at_force_m, tangent_stiffness_n_per_m
from ebraille_sim.physics.params import DRIVETRAINS, FINGERS, MOTORS, TACTILE_FORCE_MAX_N, DeviceParams

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


def _design_reader():
    """Pulp constants the impact bound assumes: the stiff preset [E] (the firmware does not know its
    reader; the population's stiffest draws, b x 2 and m x 1.15 of the nominal reader, stay below it)."""
    s = FINGERS["stiff"]
    return s.stiffness_b_n_per_m, s.exponent_m_per_m


ESTIMATOR_PERIOD_S = 0.01
"""Period of the force estimate, s: the paper's models run at 100 Hz ([R] seed paper); the
estimate holds its value in between."""


def _speed_limit(b: dict, rb: float, rm: float) -> float:
    """Speed at which the impact alone brings the design reader to the safe force (no tremor allowance), m/s."""
    e = limits.absorbed_energy_j(0.0, SAFE_FORCE_N, rb, rm)
    return limits.speed_for_energy_m_per_s(e, b["pinion_mass_kg"], b["board_mass_kg"], b["gear_efficiency"])


FRICTION_FALL = 0.20
"""Fraction by which the drive's friction (brushes, gearhead, guide rods) may fall in service
below what the line measured [E]: run-in of brushes and rods, warmer grease.  Friction always
opposes a push that raises the force, so the bound keeps the rest of it; for the nominal unit
what it keeps (0.48 N) is less than the motor's own friction alone (0.52 N at the rack)."""

GUIDE_COULOMB_MAX_N = 0.30
"""Largest Coulomb friction of the board's guide rods, N [E]: the top of the 0.05-0.3 N design
range (docs/model.md, parameters table 3); the plausibility rules' lower edge of the friction
band assumes it."""

BACKLASH_MAX_M = 0.2e-3
"""Largest backlash at the board, m [E]: the top of the 0.03-0.2 mm design range (parameters
table 3)."""

UNIT_FIELDS = {"motor": ("resistance_ohm", "torque_constant_nm_per_a", "back_emf_v_s_per_rad"),
               "drivetrain": ("gear_efficiency", "guide_coulomb_n", "backlash_m"),
               "current_sense": ("shunt_error", "gain_error", "offset_v")}
"""The constants that differ from unit to unit of one part (the population draws them): the
firmware knows their datasheet values only (:func:`datasheet_device`; a current chain's
datasheet has none of its unit's errors)."""


@functools.lru_cache(maxsize=None)
def _other_fields(cls, part: str) -> tuple:
    """The fields of the dataclass ``cls`` of ``part`` that are not :data:`UNIT_FIELDS`."""
    return tuple(f.name for f in dataclasses.fields(cls) if f.name not in UNIT_FIELDS[part])


def _differs_in_unit_fields_only(unit, sheet, part: str) -> bool:
    """Whether ``unit`` equals ``sheet`` in every field but the :data:`UNIT_FIELDS` of ``part``."""
    if type(unit) is not type(sheet):
        return False
    a, b = unit.__dict__, sheet.__dict__
    return all(a[k] == b[k] for k in _other_fields(type(unit), part))


def datasheet_device(device: DeviceParams) -> DeviceParams:
    """The device as its designer knows it: the motor and drive train of ``device`` with the
    :data:`UNIT_FIELDS` of their part's datasheet (the preset of the same name; a part with no
    preset is its own datasheet), the current chain without the unit's errors.  The reader and
    the FSR unit are not part of it (the firmware assumes design readers; the divider is
    calibrated)."""
    parts = {}
    for part, presets in (("motor", MOTORS), ("drivetrain", DRIVETRAINS)):
        unit = getattr(device, part)
        sheet = presets.get(unit.name, unit)
        if _differs_in_unit_fields_only(unit, sheet, part):
            parts[part] = sheet                 # the unit with the datasheet's values is the datasheet
        else:
            parts[part] = replace_fields(unit, **{f: getattr(sheet, f) for f in UNIT_FIELDS[part]})
    return replace_fields(device, current_sense=_datasheet_chain(device.current_sense), **parts)


_LAST_CHAIN: list = []
"""The current chain :func:`_datasheet_chain` was last given, and its datasheet."""


def _datasheet_chain(cs):
    """The current chain ``cs`` without its unit's errors; the one made last when ``cs`` differs
    from the chain given last only in those errors (the boards a population draws around one
    chain), so that their datasheet devices share one chain object (:func:`_datasheet_constants`)."""
    last = _LAST_CHAIN
    if last and _differs_in_unit_fields_only(cs, last[0], "current_sense"):
        return last[1]
    sheet = replace_fields(cs, shunt_error=0.0, gain_error=0.0, offset_v=0.0)
    last[:] = [cs, sheet]
    return sheet


def firmware_limits(sheet: DeviceParams, cal: DriveCalibration) -> dict:
    """The constants :class:`SupervisorConfig` carries, from what the firmware knows: the datasheet
    device ``sheet`` (:func:`datasheet_device`), the designer's margins and the unit's end-of-line
    calibration ``cal`` (:func:`~ebraille_sim.estimation.calibration.calibrate_drive`); see
    docs/safety.md.

    The push per ampere is the calibrated slope raised by the chain's gain bound, the gauge's
    tolerance and the slope's reading error; the friction current is the calibrated friction
    force (motor, gearhead and guide rods, as the push test met it moving forward) lowered by
    the gauge's tolerance and the reading error, of which :data:`FRICTION_FALL` may be lost in
    service; the back-EMF
    constant is the free run's, lowered by the speed reference's tolerance and the error of
    ``R i`` (the speed read high); the gear efficiency of the impact is the largest the
    calibrated push allows with that constant (``kM = kE`` in SI units).  Every constant is on
    the side that lowers the current and speed limits."""
    k = _datasheet_constants(sheet)
    b, rb, rm = k["bounds"], k["reader_b_n_per_m"], k["reader_m_per_m"]
    cs = sheet.current_sense
    e_avg = k["averaged_error_a"]
    i1, i2 = cal.test_currents_a
    slope_tol = 2.0 * k["mean_error_a"] / (i2 - i1) if i2 > i1 else math.inf   # zero cancels
    if not slope_tol < MAX_SLOPE_ERROR:
        raise ValueError(f"CurrentSenseParams: a reading of the chain (shunt_ohm {cs.shunt_ohm:g} ohm, gain_v_per_v "
                         f"{cs.gain_v_per_v:g}, adc_bits {cs.adc_bits}, adc_noise_lsb {cs.adc_noise_lsb:g}) is too "
                         f"coarse for the drive's calibration: the push per ampere would be known to "
                         f"{100 * slope_tol:.3g} % only (at most {100 * MAX_SLOPE_ERROR:g} %)")
    push_per_a = cal.push_force_per_a_n * (1.0 + cs.gain_error_max + cs.shunt_tolerance) / (
        (1.0 - FORCE_GAUGE_TOLERANCE) * (1.0 - slope_tol))
    friction_n = ((-cal.push_offset_n / (1.0 + FORCE_GAUGE_TOLERANCE) - push_per_a * (e_avg + slope_tol * abs(i1)))
                  * (1.0 - FRICTION_FALL))
    # the free run's speed from the line's reference and the armature's law: kE low by the
    # reference's tolerance and by the error of R i_read (the zero's and the means' errors)
    e_ri = cal.resistance_ohm * e_avg * (1.0 + abs(cal.free_run_current_a) * cal.resistance_ohm / RESISTANCE_TEST_V)
    v_free = (FREE_RUN_V - cal.resistance_ohm * cal.free_run_current_a) / cal.back_emf_v_s_per_m
    back_emf = cal.back_emf_v_s_per_m * (1.0 - SPEED_REFERENCE_TOLERANCE) - e_ri / v_free
    eta = min(1.0, push_per_a / back_emf)           # kM = kE in SI units: the largest efficiency the push allows
    drive = {"push_force_per_a_n": push_per_a, "friction_current_a": max(friction_n, 0.0) / push_per_a,
             "weight_n": b["weight_n"], "back_emf_v_s_per_m": back_emf,
             "pinion_mass_kg": b["pinion_mass_kg"], "board_mass_kg": b["board_mass_kg"], "gear_efficiency": eta}
    impact_mass = eta * b["pinion_mass_kg"] + b["board_mass_kg"]
    return {
        "motor_resistance_ohm": cal.resistance_ohm,
        "stall_current_a": sheet.driver_supply_v / cal.resistance_ohm,
        "rated_current_a": rated_current_a(sheet),
        "driver_supply_v": sheet.driver_supply_v,
        **drive,
        **k["readers"],
        "speed_hold_s": 0.5 * math.pi * math.sqrt(impact_mass / k["contact_stiffness_n_per_m"]),
        "stuck_travel_m": BACKLASH_MAX_M + ESTIMATOR_PERIOD_S * _speed_limit(drive, rb, rm),
        **k["travels_and_chain"],
    }


_LAST_CONSTANTS: list = []
"""The parts and gravity of the datasheet device :func:`_datasheet_constants` was last given, and
its constants."""


def _datasheet_constants(sheet: DeviceParams) -> dict:
    """What :func:`firmware_limits` takes from the datasheet device ``sheet`` alone, neither its
    supply nor the unit's calibration: the drive's bounds, the design readers, the current
    chain's errors and the limits that follow from these.  The dict made last is returned again
    for a datasheet device with the same motor, drive train and current chain objects and the
    same gravity (every unit a population draws around one device, :func:`datasheet_device`)."""
    last = _LAST_CONSTANTS
    key = (sheet.motor, sheet.drivetrain, sheet.current_sense)
    if last and all(a is b for a, b in zip(last[0], key)) and last[1] == sheet.gravity_m_per_s2:
        return last[2]
    rb, rm = _design_reader()
    soft = FINGERS["soft"]
    dt, cs = sheet.drivetrain, sheet.current_sense
    k = {"bounds": limits.drive_bounds(sheet), "reader_b_n_per_m": rb, "reader_m_per_m": rm,
         "averaged_error_a": averaged_error_a(cs, CALIBRATION_CONVERSIONS),
         "mean_error_a": mean_error_a(cs, CALIBRATION_CONVERSIONS),
         "contact_stiffness_n_per_m": tangent_stiffness_n_per_m(CONTACT_ON_N, rb, rm),
         "readers": {
             "friction_breakaway_ratio": sheet.motor.breakaway_ratio,
             "guide_static_n": GUIDE_COULOMB_MAX_N * dt.guide_breakaway_ratio,
             "soft_b_n_per_m": soft.stiffness_b_n_per_m,
             "soft_m_per_m": soft.exponent_m_per_m,
             "reader_b_n_per_m": rb,
             "reader_m_per_m": rm},
         "travels_and_chain": {
             "first_contact_travel_m": DESIGN_GAP_M + compression_at_force_m(
                 SAFE_FORCE_N, soft.stiffness_b_n_per_m, soft.exponent_m_per_m),
             "end_stop_travel_m": (dt.travel_max_m - dt.travel_min_m) * (1.0 - MAX_SLOPE_ERROR) - BACKLASH_MAX_M,
             "sense_gain_error_max": cs.gain_error_max + cs.shunt_tolerance,
             "sense_error_a": worst_case_error_a(cs, 0.0),
             "powered_current_a": worst_case_error_a(cs, 0.0) + 0.5e-3,
             "mesh_stiffness_n_per_m": dt.mesh_stiffness_n_per_m}}
    last[:] = [key, sheet.gravity_m_per_s2, k]
    return k


MAX_SLOPE_ERROR = 0.05
"""Largest relative error of the calibrated push per ampere that the chain's reading may leave
[E]; a coarser chain is refused (the envelope would be a guess)."""


def device_limits(device: DeviceParams) -> dict:
    """:func:`firmware_limits` of ``device``: its datasheet (:func:`datasheet_device`) and its
    drive's calibration (:func:`~ebraille_sim.estimation.calibration.calibrate_drive`, the only
    step that meets the unit's own constants).

    Raises ValueError (one line, naming the current chain's keys) when the chain cannot read the
    drive: a range below the datasheet's stall current (the shunt is sized for it) or a reading
    too coarse for the calibration (:class:`SupervisorConfig` refuses a worst-case error that
    leaves no current limit)."""
    sheet = datasheet_device(device)
    cs = sheet.current_sense
    stall_a = sheet.driver_supply_v / sheet.motor.resistance_ohm
    if not cs.range_a >= stall_a:
        raise ValueError(f"CurrentSenseParams: the chain reads at most {cs.range_a:.4g} A (reference_v "
                         f"{cs.reference_v:g} V over gain_v_per_v {cs.gain_v_per_v:g} x shunt_ohm {cs.shunt_ohm:g} "
                         f"ohm), below the drive's stall current {stall_a:.4g} A")
    return firmware_limits(sheet, calibrate_drive(device))


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
_MAY_BE_ZERO = {"friction_current_a"}
"""Numeric fields that may be 0: a friction current the calibration cannot tell from the guide
rods' largest friction is bounded by none."""


def _numeric_field_names() -> tuple:
    """The names of :class:`SupervisorConfig`'s numeric fields (every field but ``enabled``) and
    a getter of their values from an instance's ``__dict__`` (a tuple), made once."""
    global _numeric_values
    _NUMERIC_FIELD_NAMES.extend(f.name for f in dataclasses.fields(SupervisorConfig) if f.name != "enabled")
    _numeric_values = operator.itemgetter(*_NUMERIC_FIELD_NAMES)
    return _NUMERIC_FIELD_NAMES, _numeric_values


_DEVICE = "[D] device_limits: datasheet, margins and calibration"


def _derived(unit: str, doc: str, source: str = _DEVICE) -> Any:
    """A field of :class:`DriveEnvelope`: no default of its own (:func:`device_limits` fills it)."""
    return sourced(None, unit, source, doc=doc, envelope=True)


@dataclass(frozen=True)
class DriveEnvelope:
    """The drive and reader constants the supervisor derives its limits from: what the firmware
    of the device knows (:func:`device_limits`: the part's datasheet, the designer's margins and
    the unit's end-of-line calibration, never the unit's own constants).

    They follow from the scenario's ``[device]`` and are not settable in ``[supervisor]``: a
    scenario that gives one is refused, naming the key.  A None field takes the nominal
    device's value.
    """
    motor_resistance_ohm: float = _derived("ohm", "Armature resistance R as the at-rest calibration measured it.")
    stall_current_a: float = _derived("A", "Stall current: the driver supply over the calibrated R.")
    rated_current_a: float = _derived("A", "Continuous motor current (RATED_CURRENT_A of the motor, else its "
                                           "rated-to-stall ratio).", "[R] Faulhaber 0816 006 SR datasheet")
    driver_supply_v: float = _derived("V", "H-bridge supply: the terminal voltage is the command clipped to it.",
                                      "[D] the device's driver_supply_v")
    push_force_per_a_n: float = _derived("N/A", "Rack force per ampere through the gearhead when pushing: the "
                                                "calibrated slope raised by its margins.")
    friction_current_a: float = _derived("A", "Current the drive's friction takes moving forward: the calibrated "
                                              "friction lowered by its margins (0 allowed).")
    weight_n: float = _derived("N", "Weight of the board, counted as pushing (hand upside down).")
    back_emf_v_s_per_m: float = _derived("V s/m", "Back-EMF per rack speed: the free run's, lowered by its "
                                                  "margins (speed read high).")
    pinion_mass_kg: float = _derived("kg", "Rotor inertia at the rack line, J (N/r)^2.")
    board_mass_kg: float = _derived("kg", "Moving mass of the board and rack.", "[D] the datasheet drive train")
    gear_efficiency: float = _derived("-", "Gear efficiency of the impact's mass: the largest the calibrated push "
                                           "and back-EMF allow.")
    friction_breakaway_ratio: float = _derived("-", "Break-away over running friction of the motor.",
                                               "[D] the datasheet motor's breakaway_ratio")
    guide_static_n: float = _derived("N", "Break-away friction of the guide rods (lower edge of the plausibility "
                                          "band): the design range's largest.", "[E] design range 0.05-0.3 N")
    soft_b_n_per_m: float = _derived("N/m", "Pulp b of the softest reader preset: the most travel a force change "
                                            "can take.", "[D] FINGERS['soft']")
    soft_m_per_m: float = _derived("1/m", "Pulp exponent m of the softest reader preset.", "[D] FINGERS['soft']")
    reader_b_n_per_m: float = _derived("N/m", "Pulp b of the reader the impact bound assumes (the stiff preset: "
                                              "the firmware does not know its reader).", "[D] FINGERS['stiff']")
    reader_m_per_m: float = _derived("1/m", "Pulp exponent m of the reader the impact bound assumes (the stiff "
                                            "preset).", "[D] FINGERS['stiff']")
    speed_hold_s: float = _derived("s", "How long the highest recent speed sets the current limit: a quarter "
                                        "period of the impact mass on the design reader at contact.")
    """How long the highest recent speed sets the current limit: a quarter period of the impact
    mass on the design reader's stiffness at the contact threshold [D]."""
    stuck_travel_m: float = _derived("m", "Net travel with an unchanged estimate that makes it stuck: the design's "
                                          "largest backlash plus one estimator period at the speed limit.")
    """Net travel with an unchanged estimate that makes it stuck: one traverse of the design's
    largest backlash (:data:`BACKLASH_MAX_M`; the firmware does not know the unit's) plus the
    travel at the impact speed limit within one estimator period [D]."""
    first_contact_travel_m: float = _derived("m", "Travel from the start within which the first contact must "
                                                  "show: the design gap plus the soft reader's compression at the "
                                                  "safe force.")
    end_stop_travel_m: float = _derived("m", "Travel from the start beyond which a motor pushing without moving "
                                             "sits on the far end stop, not on a jam.")
    """Travel from the start beyond which a motor pushing at its limit without moving sits on the
    rack's far end stop, not on a jam [D]: the design travel less the travel integral's largest
    error (the back-EMF slope's calibration error, :data:`MAX_SLOPE_ERROR`, over the whole travel)
    and the design's largest backlash.  A finger beyond the board's reach is not a stalled motor:
    the stall rule's push-without-force branch does not count there (the current envelope still
    bounds the push, the i2t rule the heat)."""
    sense_gain_error_max: float = _derived("-", "Largest relative gain error of the current reading (amplifier "
                                                "gain error plus shunt tolerance).",
                                           "[D] the device's CurrentSenseParams")
    """Largest relative gain error of the board's current reading: the amplifier's gain error and
    the shunt's tolerance at their bounds (:class:`~ebraille_sim.physics.params.CurrentSenseParams`)."""
    sense_error_a: float = _derived("A", "Largest absolute error of one current reading beyond the gain error "
                                         "(zeroing residual, round-down, noise).",
                                    "[D] physics.current_sense.worst_case_error_a at 0 A")
    """Largest absolute error of one current reading beyond the gain error, A: zeroing residual,
    round-down and noise (:func:`ebraille_sim.physics.current_sense.worst_case_error_a` at 0 A)."""
    powered_current_a: float = _derived("A", "Smallest current reading that shows the driver powers the motor: "
                                             "0.5 mA above the worst reading at 0 A.",
                                        "[D] worst_case_error_a at 0 A + 0.5 mA [E]")
    """Smallest reading of the motor current that shows the driver powers the motor [D]: 0.5 mA
    above the largest reading of a motor at rest (the sensing chain's worst case at 0 A,
    :func:`~ebraille_sim.physics.current_sense.worst_case_error_a`, 3.1 mA), so that the chain's
    zero error and noise never read as power: the back-EMF speed counts as travel only above it.  A cut supply draws no current, and its command would read as speed; a motor
    that moves while drawing less than its friction current (the finger pushing the board back
    as the drive retracts) is counted, so the travel integral follows a force loop that
    hunts back and forth."""
    mesh_stiffness_n_per_m: float = _derived("N/m", "Stiffness of the gear mesh that holds the board while a slip "
                                                    "loads the pulp.", "[D] the device's drive train")
    """Stiffness of the gear mesh that holds the board, N/m: the board gives way on it as a slip
    loads the pulp (the drive train's nominal constant, [E] plastic mesh contact 1e4-1e5 N/m)."""


_SETTING = "[E] supervisor policy"


@dataclass(frozen=True)
class SupervisorPolicy:
    """The supervisor's policy: the thresholds and times a scenario's ``[supervisor]`` table
    may set (every other constant of :class:`SupervisorConfig` is the device's
    :class:`DriveEnvelope`)."""
    enabled: bool = sourced(True, "-", "scenario setting", doc="false: no supervisor (the controller's command "
                                                               "goes to the drive unshaped).")
    force_cap_n: float = sourced(TACTILE_FORCE_MAX_N, "N", "[R] seed paper: top of the tactile range",
                                 doc="Cap on the estimated force.", hi=FORCE_CAP_LIMIT_N)
    cap_margin_n: float = sourced(0.3, "N", _SETTING, doc="Width of the soft zone below the cap in which a pushing "
                                                          "command is scaled down; the setpoint is clipped below it.")
    safe_force_n: float = sourced(SAFE_FORCE_N, "N", "[E] 0.5 N above the 3 N top of the tactile range",
                                  doc="Bound on the true force that the current and speed envelope keeps whatever "
                                      "the sensor reads.", hi=FORCE_CAP_LIMIT_N)
    finger_motion_m: float = sourced(45e-6, "m", "[E] three times the 15 um RMS of physiological tremor",
                                     doc="Motion of the pulp toward a held board that the drive cannot prevent.")
    slew_v_per_s: float = sourced(600.0, "V/s", "[E] full scale (6 V) in one 10 ms estimator period",
                                  doc="Fastest change of the command.")
    overload_time_s: float = sourced(0.5, "s", "[E] motor thermal margin",
                                     doc="Time allowed at the stall current before the I^2 t trip.")
    retract_v: float = sourced(2.0, "V", _SETTING, doc="Voltage of the safe retract and of the back-off after a loss "
                                                       "of contact (applied as -retract_v).")
    retract_s: float = sourced(0.6, "s", _SETTING, doc="Length of the safe retract without a current measurement.")
    retract_moving_s: float = sourced(0.05, "s", _SETTING, doc="Time the board must have moved back before a stall "
                                                               "on the end stop ends the retract.")
    max_retract_s: float = sourced(10.0, "s", _SETTING, doc="Longest safe retract.")
    out_of_range_n: float = sourced(4.0, "N", "[E] above the cap, below the ~15 N of a shorted FSR",
                                    doc="Estimate above which the FSR is out of range (fault fsr_out_of_range).")
    stuck_window_s: float = sourced(0.1, "s", _SETTING, doc="Window of the stuck rule without a current "
                                                            "measurement.")
    stuck_response_s: float = sourced(0.05, "s", "[E] the 10 ms estimator period, its two-sample mean and the "
                                                 "20 Hz anti-alias filter (about 40 ms), rounded up",
                                      doc="Time the estimate needs to show a command's effect.")
    travel_follow_s: float = sourced(0.7, "s", "[D] half the pulp's slowest relaxation time constant (1.4 s)",
                                     doc="Time constant with which the travel check's reference follows where the "
                                         "pulp's surface must be.")
    """Time constant with which the travel check's reference follows where the pulp's surface must
    be, s [D]: half the pulp's slowest relaxation time constant (1.4 s), so that a soft pulp relaxing
    under a sustained load, pressing and drift do not add up; a board running into the finger
    faster than about the rule's allowance over this time while the reading stays low is caught.
    The fault matrix's withdrawn finger with a stuck reading breaks at 0.2-0.35 s (the trade-off:
    docs/safety.md, "The travel rule's follow time")."""
    stuck_tolerance_n: float = sourced(2e-3, "N", _SETTING, doc="Change of the estimate below which it counts as "
                                                                "unchanged (stuck rules).")
    stuck_command_v: float = sourced(0.25, "V", _SETTING, doc="Change of the delayed command above which a stuck "
                                                              "estimate is a fault (stuck rule without a current).")
    stuck_emf_v: float = sourced(0.05, "V", _SETTING, doc="Back-EMF above which the stuck rule without a current "
                                                          "counts the motor as moving.")
    contact_on_n: float = sourced(CONTACT_ON_N, "N", "[R] seed paper: bottom of the tactile range",
                                  doc="Estimate above which the board is taken to touch the finger.")
    contact_lost_n: float = sourced(0.1, "N", "[E] above the 0.063 N the paper's estimator reads with no load",
                                    doc="Estimate below which contact is lost (while the setpoint asks for contact).")
    drop_n: float = sourced(0.3, "N", _SETTING, doc="Fall of the estimate within drop_window_s that counts as a loss "
                                                    "of contact.")
    drop_window_s: float = sourced(0.03, "s", _SETTING, doc="Window of the drop rule.")
    drop_keep_fraction: float = sourced(0.5, "-", "[E] a 0.2 mm strap slip keeps 0.63-0.70 of 1.0 N",
                                        doc="A drop is a loss of contact only if the estimate ends below this "
                                            "fraction of its value at the start of the window.", hi=1.0)
    """A fall by ``drop_n`` within ``drop_window_s`` is a loss of contact only if the estimate ends
    below this fraction of its value at the start of the window [E]: a lost contact takes the
    estimate to its no-load value, a partial unloading keeps most of it (a 0.2 mm strap slip
    on the pulp drops 1.0 N to 0.63-0.70 N within 30 ms and the finger stays in contact)."""
    release_window_s: float = sourced(0.15, "s", "[E] estimator delay plus the controller's settling",
                                      doc="A fall of the setpoint within this time is an intended release, not a "
                                          "loss of contact.")
    backoff_s: float = sourced(0.05, "s", _SETTING, doc="Back-off at -retract_v after a loss of contact, before "
                                                        "holding 0 V.")
    contact_loss_timeout_s: float = sourced(0.6, "s", _SETTING, doc="A contact not regained within this time is a "
                                                                    "latched contact_lost fault.")
    watchdog_timeout_s: float = sourced(0.5, "s", _SETTING, doc="Non-finite commands for longer than this are a "
                                                                "latched controller_nonfinite fault.")
    moving_speed_m_per_s: float = sourced(0.5e-3, "m/s", "[E] back-EMF 0.05 V for the nominal drive",
                                          doc="Rack speed above which the motor is taken to move.")
    stall_time_s: float = sourced(0.5, "s", _SETTING, doc="A motor pushing with current but not moving while no "
                                                          "contact shows is stopped after this.")
    stall_fraction: float = sourced(0.95, "-", "[E] creeping a 2.8 N hold forward takes about 97 % of the limit",
                                    doc="Fraction of the current limit at rest above which a motor that does not move "
                                        "and whose push exceeds the estimate by implausible_n is stalled.")
    """Fraction of the current limit at rest above which a motor that does not move, and whose push
    at the lower edge of the friction band exceeds the estimate by ``implausible_n``, is stalled [E]
    (creeping a 2.8 N hold forward against the break-away friction takes about 97 % of the limit,
    so the current alone does not tell a jam from a hold at the top of the range)."""
    implausible_n: float = sourced(0.5, "N", _SETTING, doc="Margin by which the force the current implies may exceed "
                                                           "the estimate.")
    implausible_s: float = sourced(0.2, "s", _SETTING, doc="How long the implied force may exceed the estimate by "
                                                           "implausible_n before fsr_implausible.")
    slip_headroom_m: float = sourced(0.1e-3, "m", "[E] the largest strap slip of the wearer's own motion "
                                                  "(scenarios.disturbances.body_motion_budget)",
                                     doc="Strap slip toward the board that the setpoint leaves room for.")
    """Strap slip toward the board that the setpoint leaves room for, m: the largest the wearer's
    own motion produces ([E] 0.1 mm, :func:`ebraille_sim.scenarios.disturbances.body_motion_budget`).
    A slip ends before the estimate shows it and the held board draws no current for it, so the
    standing force must leave the room (:attr:`slip_setpoint_cap_n`)."""
    slip_time_s: float = sourced(0.02, "s", "[E] the fastest strap slip",
                                 doc="Duration of the slip the setpoint leaves room for.")
    search_gap_m: float = sourced(DESIGN_GAP_M, "m", "[E] the design gap (DESIGN_GAP_M): the largest gap at the start "
                                                   "of a session",
                                  doc="Gap to the pulp beyond which the board searches for the first contact at the "
                                      "re-approach speed.")
    """Gap to the pulp at the start of a session beyond which the board searches for the finger at
    the re-approach speed (:attr:`reapproach_command_v`) instead of the loop's command, m, until the
    first contact: a reader within the design gap is met by the loop's approach; with no contact
    beyond it (:attr:`search_travel_m` of travel) the finger may be lifted and come back onto the
    board at any moment, and the board must not have run far beyond where the finger rests.  The
    search ends at the first contact (the loop resumes from 0 V, as after a regained contact) or at
    ``first_contact_travel_m`` (``fsr_no_contact``)."""
    slip_away_m: float = sourced(0.5e-3, "m", "[E] 0.5 mm, scenarios.disturbances.body_motion_budget",
                                 doc="Strap slip away from the board that a re-approach after a loss of contact "
                                     "searches for.")
    """Strap slip away from the board that a re-approach after a loss of contact searches for, m:
    the largest the wearer's own motion produces ([E] 0.5 mm,
    :func:`ebraille_sim.scenarios.disturbances.body_motion_budget`).  Beyond it, plus the soft
    reader's compression at the contact threshold and the travel integral's margins
    (:attr:`reapproach_travel_m`), no contact means the finger is gone or the sensor reads none:
    ``contact_lost`` latches."""


POLICY_KEYS: tuple[str, ...] = tuple(f.name for f in dataclasses.fields(SupervisorPolicy))
"""The keys a scenario's ``[supervisor]`` table may set."""
ENVELOPE_KEYS: tuple[str, ...] = tuple(f.name for f in dataclasses.fields(DriveEnvelope))
"""The constants derived from the device (:func:`device_limits`), not settable in a scenario."""


def check_policy(where: str, d: Mapping[str, Any]) -> None:
    """Refuse a key of ``d`` that is no :data:`POLICY_KEYS` entry, in one line: an envelope
    constant is named as such (it comes from ``[device]`` and its calibration)."""
    for k in d:
        if k in ENVELOPE_KEYS:
            raise ValueError(f"{k} is not a supervisor setting: it is derived from [device] (datasheet and "
                             f"calibration); set the device instead")
    check_keys(where, d, POLICY_KEYS)


@dataclass(frozen=True)
class SupervisorConfig(DriveEnvelope, SupervisorPolicy):
    """Limits and detector settings of :class:`Supervisor` (SI units in the names): the
    :class:`SupervisorPolicy` a scenario sets and the :class:`DriveEnvelope` the device gives.

    The envelope defaults to what the firmware of the nominal device knows
    (:class:`DeviceParams`, :func:`device_limits`: datasheet, margins, calibration);
    :meth:`for_device` derives it for another device.  Every numeric field must be a positive
    finite number (``friction_current_a`` may be 0).
    """

    @functools.cached_property
    def reapproach_speed_m_per_s(self) -> float:
        """Rack speed of the re-approach after a loss of contact, m/s: the speed at which the push of
        the re-approach's command against a held pulp (:attr:`reapproach_command_v` at stall, the
        steady push bound) plus the impact of the board arriving at that speed peaks at
        :attr:`setpoint_max_n` on the design reader (eq. 1-3 of docs/safety.md; bisection to 1 um/s).
        Blind (an open sensor reads no contact) the re-approach presses no harder than the loop may
        ask; the current envelope bounds it on top."""
        from controllers.supervisor.envelope import _envelope_memo, reapproach_speed_m_per_s
        return reapproach_speed_m_per_s(self.speed_limit_m_per_s, self.pinion_mass_kg, self.board_mass_kg,
                                        self.gear_efficiency, self.setpoint_max_n, self.reader_b_n_per_m,
                                        self.reader_m_per_m, self.back_emf_v_s_per_m, self.motor_resistance_ohm,
                                        self.friction_current_a, self.push_force_per_a_n, self.weight_n,
                                        _envelope_memo(self.setpoint_max_n, self.reader_b_n_per_m, self.reader_m_per_m))

    def _reapproach_command_v(self, speed_m_per_s: float) -> float:
        return self.back_emf_v_s_per_m * speed_m_per_s + self.motor_resistance_ohm * self.friction_current_a

    @property
    def reapproach_command_v(self) -> float:
        """Command of the re-approach, V: the back-EMF of :attr:`reapproach_speed_m_per_s` plus the
        calibrated friction current through R (the board moves at that speed against the friction
        the firmware knows; a unit with more friction moves slower)."""
        return self._reapproach_command_v(self.reapproach_speed_m_per_s)

    @property
    def reapproach_travel_m(self) -> float:
        """Travel beyond the board's position at a loss of contact within which a re-approach must
        find the finger, m: :attr:`slip_away_m`, the soft reader's compression at ``contact_on_n``,
        the travel at :attr:`reapproach_speed_m_per_s` within the estimate's lag
        (``stuck_response_s``) and ``stuck_travel_m`` (the backlash the back-EMF integral counts and
        one estimator period of travel)."""
        return (self.slip_away_m + compression_at_force_m(self.contact_on_n, self.soft_b_n_per_m, self.soft_m_per_m)
                + self.reapproach_speed_m_per_s * self.stuck_response_s + self.stuck_travel_m)

    @property
    def search_travel_m(self) -> float:
        """Travel before the first contact beyond which the board searches at the re-approach
        speed, m: :attr:`search_gap_m`, the soft reader's compression at ``contact_on_n`` (a reader
        at that gap has shown contact by then, the estimate's lag aside) and the largest backlash
        the back-EMF integral counts."""
        return (self.search_gap_m + compression_at_force_m(self.contact_on_n, self.soft_b_n_per_m, self.soft_m_per_m)
                + BACKLASH_MAX_M)

    @functools.cached_property
    def slip_setpoint_cap_n(self) -> float:
        """Largest setpoint, N, from which a slip of ``slip_headroom_m`` at constant speed over
        ``slip_time_s`` brings the fully relaxed design reader, behind the gear mesh, to ``safe_force_n``
        (:func:`controllers.supervisor.motion.design_slip_cap_n`)."""
        return design_slip_cap_n(self.safe_force_n, self.slip_headroom_m, self.slip_time_s, self.reader_b_n_per_m,
                                 self.reader_m_per_m, self.mesh_stiffness_n_per_m)

    @property
    def setpoint_max_n(self) -> float:
        """Setpoint the inner controller is given at most, N: ``force_cap_n - cap_margin_n`` or
        :attr:`slip_setpoint_cap_n`, the lower."""
        return min(self.force_cap_n - self.cap_margin_n, self.slip_setpoint_cap_n)

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
                object.__setattr__(self, name, check_number(name, v, lo=0.0, lo_open=name not in _MAY_BE_ZERO))
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
        if self.slip_setpoint_cap_n <= self.contact_on_n:
            raise ValueError(f"slip_headroom_m = {self.slip_headroom_m:g} m over slip_time_s = {self.slip_time_s:g} s "
                             f"leaves a setpoint of {self.slip_setpoint_cap_n:.3g} N, not above contact_on_n "
                             f"({self.contact_on_n:g} N): no force is left for reading")
        if not self.sensed_limit_a(self.current_limit_a) > 2.0 * self.powered_current_a:
            raise ValueError(f"sense_error_a = {1e3 * self.sense_error_a:.3g} mA (the current chain's worst-case "
                             f"reading error: CurrentSenseParams adc_bits, adc_noise_lsb, zero_samples, shunt_ohm, "
                             f"gain_v_per_v) leaves no current limit: the {1e3 * self.current_limit_a:.3g} mA limit "
                             f"at rest reads as {1e3 * self.sensed_limit_a(self.current_limit_a):.3g} mA, not above "
                             f"twice powered_current_a ({1e3 * self.powered_current_a:.3g} mA)")

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], device: DeviceParams | None = None) -> SupervisorConfig:
        """:meth:`for_device` with the policy of a mapping; a key that is no :data:`POLICY_KEYS`
        entry (unknown, or a :data:`ENVELOPE_KEYS` constant) is a one-line error."""
        return cls.for_device(_NOMINAL if device is None else device, **d)

    @classmethod
    def for_device(cls, device: DeviceParams, *, envelope_overrides: Mapping[str, Any] | None = None,
                   **policy: Any) -> SupervisorConfig:
        """The :class:`DriveEnvelope` the firmware of ``device`` knows with the defaults' policy,
        then ``policy`` (:data:`POLICY_KEYS` only).

        The envelope comes from :func:`device_limits`: the part's datasheet with the designer's
        margins and the unit's calibration (``motor_resistance_ohm`` the R it measured,
        ``stall_current_a`` the driver supply over it, ``rated_current_a`` from
        :func:`rated_current_a` of the datasheet).  ``envelope_overrides`` replaces envelope
        constants (:data:`ENVELOPE_KEYS`) for tests and studies of the envelope itself; a
        scenario cannot set them.

        Examples
        --------
        >>> SupervisorConfig.for_device(DeviceParams()) == SupervisorConfig()
        True
        >>> SupervisorConfig.for_device(DeviceParams(), board_mass_kg=1.0)
        Traceback (most recent call last):
        ...
        ValueError: board_mass_kg is not a supervisor setting: it is derived from [device] (datasheet and calibration); set the device instead
        """
        check_policy("SupervisorConfig", policy)
        limits_ = device_limits(device)
        if envelope_overrides:
            check_keys("the drive envelope", envelope_overrides, ENVELOPE_KEYS)
            limits_.update(envelope_overrides)
        if cls is SupervisorConfig:                 # the defaults' fields replaced, then checked
            return replace_fields(_default_config(), **{**limits_, **policy})
        return cls(**{**limits_, **policy})

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

    def sensed_limit_a(self, true_limit_a: float) -> float:
        """The reading at which the worst-case sensor still means at most ``true_limit_a`` of true
        current, A: ``i (1 - e_gain) - e_abs`` (a reading high by the gain error and the
        absolute error; the safety bounds hold with the worst unit of the chain)."""
        return true_limit_a * (1.0 - self.sense_gain_error_max) - self.sense_error_a

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


_NOMINAL_LIMITS.update(device_limits(_NOMINAL))
if set(_NOMINAL_LIMITS) != set(ENVELOPE_KEYS):
    raise ImportError(f"device_limits and DriveEnvelope disagree: {sorted(set(_NOMINAL_LIMITS) ^ set(ENVELOPE_KEYS))}")


@functools.lru_cache(maxsize=1)
def _default_config() -> SupervisorConfig:
    """``SupervisorConfig()``, made once: :meth:`SupervisorConfig.for_device` replaces its fields
    (``replace_fields`` runs the checks of ``__post_init__`` on the result, as the constructor
    does, and copies no attribute cached on it)."""
    return SupervisorConfig()


