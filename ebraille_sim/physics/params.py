"""Physical parameters of the device, the reader and the sensor, with units and sources.

Every parameter set is a frozen dataclass whose field names carry SI units
(``resistance_ohm``, ``mass_kg``).  Every field carries two pieces of metadata:
``unit`` and ``source``.  Source tags follow ``docs/model.md``:

``[R]``  read in a datasheet or paper (the reference is named),
``[D]``  derived by calculation from ``[R]`` values (the formula is named),
``[E]``  engineering estimate (the reasoning is named; calibrate before trusting).

Derived quantities (reflected mass, reflected friction, Prony decay factors...)
are computed by properties or by :func:`ebraille_sim.plant.lumped.pack_params`, never stored.
The static helpers here (``elastic_force_n``, ``resistance_ohm``, ``divider_v``...) call
the very law functions of :mod:`~ebraille_sim.physics.fingertip` and
:mod:`~ebraille_sim.physics.fsr` that the compiled loop runs.

Examples
--------
>>> from ebraille_sim.physics.params import MOTORS, FINGERS
>>> MOTORS["faulhaber_0816_006sr"].resistance_ohm
21.2
>>> round(FINGERS["nominal"].stiffness_b_n_per_m, 1)
264.0
>>> source_of(MOTORS["faulhaber_0816_006sr"], "torque_constant_nm_per_a")[:3]
'[R]'
"""
from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass
from typing import Any

from ebraille_sim.base.fields import sourced
from ebraille_sim.base.validation import check_number, replace_checked
from ebraille_sim.physics import fingertip as _fingertip
from ebraille_sim.physics import fsr as _fsr

__all__ = [
    "MotorParams", "DriveTrainParams", "FingerParams", "FSRParams", "CircuitParams",
    "EstimatorParams", "RateParams", "DeviceParams",
    "MOTORS", "DRIVETRAINS", "FINGERS", "FSRS",
    "source_of", "unit_of", "describe", "replace_checked", "check_finite",
]


TACTILE_FORCE_MIN_N = 0.2
TACTILE_FORCE_MAX_N = 3.0
"""Range of contact forces at which a reading finger feels the display ([R] seed paper:
tactile forces 0.2-3 N).  Setpoints are bounded by it."""

STANDARD_GRAVITY_M_PER_S2 = 9.81
"""Gravity at the reader, m/s^2 ([R] standard gravity 9.80665 (CGPM 1901) to three figures;
local gravity on Earth spans 9.78-9.83)."""


ADC_BITS_MAX = 24
"""Finest resolution of an analogue-to-digital converter, bits ([R] 24-bit sigma-delta
converters are the finest sold, e.g. TI ADS1256, Analog Devices AD7190)."""


def _adc_step_v(ref_v: float, bits: int) -> float:
    """Voltage of one step of a ``bits``-bit ADC on the reference ``ref_v``: V_ref / 2^bits (V)."""
    return ref_v / (2 ** bits)


def _adc_top_code(bits: int) -> float:
    """Largest code of a ``bits``-bit ADC, 2^bits - 1."""
    return float(2 ** bits - 1)


def _p(default: Any, unit: str, source: str, doc: str = ""):
    return sourced(default, unit, source, **({"doc": doc} if doc else {}))


FAULHABER = "[R] Faulhaber 0816 K 006 SR datasheet table"
MAXON = "[R] maxon DCX 6 M 3 V datasheet excerpt"
POLOLU = "[R] Pololu micro metal gearmotor LP 6 V 100:1 datasheet"


def check_finite(obj) -> None:
    """Raise ``ValueError`` naming the first non-finite or negative-where-forbidden field.

    Parameters
    ----------
    obj : dataclass instance
        Every float field must be finite.  Fields whose metadata has
        ``"positive": True`` must be > 0; fields with ``"nonneg": True`` >= 0.
    """
    d = obj.__dict__
    for name, positive, nonneg in _finite_plan(type(obj)):
        v = d[name]
        if type(v) is float and (v > 0.0 if positive else (v >= 0.0 if nonneg else -math.inf < v < math.inf)) \
                and v < math.inf:
            continue                    # the common case: a finite float within its bound
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            continue
        if isinstance(v, float) and not math.isfinite(v):
            raise ValueError(f"{type(obj).__name__}.{name} must be finite, got {v}")
        if positive and not v > 0:
            raise ValueError(f"{type(obj).__name__}.{name} must be > 0, got {v}")
        if nonneg and v < 0:
            raise ValueError(f"{type(obj).__name__}.{name} must be >= 0, got {v}")


@functools.lru_cache(maxsize=None)
def _finite_plan(cls) -> tuple:
    """``(name, positive, nonneg)`` of every field of the dataclass ``cls``, in order (read once per class)."""
    return tuple((f.name, bool(f.metadata.get("positive")), bool(f.metadata.get("nonneg")))
                 for f in dataclasses.fields(cls))


def _pos(default, unit, source, doc: str = ""):
    return sourced(default, unit, source, positive=True, **({"doc": doc} if doc else {}))


def _nn(default, unit, source, doc: str = ""):
    return sourced(default, unit, source, nonneg=True, **({"doc": doc} if doc else {}))


class _Checked:
    def __post_init__(self):
        check_finite(self)


@dataclass(frozen=True)
class MotorParams(_Checked):
    """Brushed DC motor (armature circuit and rotor).

    Electrical: ``L di/dt = V - R i - kE w``; mechanical torque ``kM i`` minus
    brush/bearing friction.  The friction torque equals the torque that the
    no-load current produces, ``kM * I0``.
    """
    name: str = "faulhaber_0816_006sr"
    sources: tuple = ()
    """Per-preset (field, source) pairs overriding the class-level source of those fields."""
    nominal_voltage_v: float = _pos(6.0, "V", FAULHABER,
                                    doc="Rated terminal voltage of the motor (the default driver supply).")
    resistance_ohm: float = _pos(21.2, "ohm", FAULHABER, doc="Armature resistance R.")
    inductance_h: float = _pos(217e-6, "H", FAULHABER, doc="Armature inductance L.")
    torque_constant_nm_per_a: float = _pos(4.12e-3, "N m/A", FAULHABER, doc="Torque constant kM.")
    back_emf_v_s_per_rad: float = _pos(
        4.116e-3, "V s/rad", "[R] Faulhaber 0816 006 SR: kE = 0.431 mV/rpm = 0.431e-3*60/(2 pi)",
        doc="Back-EMF constant kE.")
    rotor_inertia_kg_m2: float = _pos(0.052e-7, "kg m^2", FAULHABER + " (0.052 g cm^2)", doc="Rotor inertia J.")
    friction_torque_nm: float = _nn(0.034e-3, "N m", FAULHABER,
                                    doc="Brush and bearing friction torque (the no-load current's torque).")
    breakaway_ratio: float = _pos(
        1.25, "-", "[E] static/kinetic friction ratio 1.2-1.5 for sliding polymer/metal pairs "
        "(POM on steel mu_s/mu_k = 0.25/0.2, [R] Stagnoli)", doc="Static over kinetic friction of the motor.")
    viscous_friction_nm_s_per_rad: float = _nn(
        0.0, "N m s/rad", "[E] datasheet friction is given as a constant torque; no viscous term",
        doc="Viscous friction of the rotor.")
    # datasheet performance values used only for cross-checks
    no_load_speed_rpm: float = _pos(13500.0, "rpm", FAULHABER,
                                    doc="Datasheet no-load speed at the rated voltage (cross-checks only).")
    no_load_current_a: float = _nn(8.3e-3, "A", FAULHABER, doc="Datasheet no-load current (cross-checks only).")
    stall_torque_nm: float = _pos(1.13e-3, "N m", FAULHABER,
                                  doc="Datasheet stall torque at the rated voltage (cross-checks only).")

    @property
    def electrical_time_constant_s(self) -> float:
        """L/R in seconds."""
        return self.inductance_h / self.resistance_ohm

    @property
    def mechanical_time_constant_s(self) -> float:
        """R J / (kM kE) in seconds (datasheet: 6.5 ms for the 0816 006 SR)."""
        return self.resistance_ohm * self.rotor_inertia_kg_m2 / (
            self.torque_constant_nm_per_a * self.back_emf_v_s_per_rad)

    def stall_torque_at(self, voltage_v: float) -> float:
        """Shaft torque at zero speed, N m: kM V/R minus the friction torque."""
        return self.torque_constant_nm_per_a * voltage_v / self.resistance_ohm - self.friction_torque_nm

    def no_load_speed_at(self, voltage_v: float) -> float:
        """Steady speed with no load, rad/s: (V - R I_f)/kE with I_f = T_f/kM."""
        i_f = self.friction_torque_nm / self.torque_constant_nm_per_a
        return (voltage_v - self.resistance_ohm * i_f) / self.back_emf_v_s_per_rad


MOTORS: dict[str, MotorParams] = {
    "faulhaber_0816_006sr": MotorParams(),
    "maxon_dcx6m_3v": MotorParams(
        name="maxon_dcx6m_3v",
        nominal_voltage_v=3.0,
        resistance_ohm=8.9,
        inductance_h=40e-6,
        torque_constant_nm_per_a=1.56e-3,
        back_emf_v_s_per_rad=1.55e-3,
        rotor_inertia_kg_m2=0.015e-7,
        friction_torque_nm=1.56e-3 * 17.1e-3,
        no_load_speed_rpm=17500.0,
        no_load_current_a=17.1e-3,
        stall_torque_nm=0.524e-3,
        sources=(
            ("nominal_voltage_v", MAXON), ("no_load_speed_rpm", MAXON), ("no_load_current_a", MAXON),
            ("stall_torque_nm", MAXON),
            ("resistance_ohm", "[D] U/I_stall = 3 V/0.336 A from the maxon DCX 6 M 3 V datasheet"),
            ("torque_constant_nm_per_a", "[D] M_H/I_H = 0.524 mN m/0.336 A (maxon DCX 6 M 3 V)"),
            ("back_emf_v_s_per_rad", "[D] (U - I0 R)/w0 from the maxon no-load point"),
            ("friction_torque_nm", "[D] kM x no-load current 17.1 mA"),
            ("inductance_h", "[E] not in the excerpt; 20-60 uH for a 6 mm coreless motor"),
            ("rotor_inertia_kg_m2", "[E] not in the excerpt; 0.01-0.02 g cm^2 for a 6 mm rotor"),
        ),
    ),
    "pololu_lp_6v": MotorParams(
        name="pololu_lp_6v",
        nominal_voltage_v=6.0,
        resistance_ohm=16.7,
        inductance_h=0.3e-3,
        torque_constant_nm_per_a=4.15e-3,
        back_emf_v_s_per_rad=4.15e-3,
        rotor_inertia_kg_m2=0.075e-7,
        friction_torque_nm=4.15e-3 * 0.02 / 1.0,
        no_load_speed_rpm=130.0 * 100.37,
        no_load_current_a=0.02,
        stall_torque_nm=72.6e-3 / (100.37 * 0.51),
        sources=(
            ("nominal_voltage_v", POLOLU), ("no_load_current_a", POLOLU),
            ("no_load_speed_rpm", "[D] 130 rpm at the output x 100.37 (Pololu datasheet)"),
            ("stall_torque_nm", "[D] 7.4 kg mm at the output / (100.37 x 0.51) (Pololu datasheet)"),
            ("resistance_ohm", "[D] 6 V / 0.36 A stall current (Pololu datasheet)"),
            ("torque_constant_nm_per_a", "[D] (U - I0 R)/w0 from the Pololu no-load point"),
            ("back_emf_v_s_per_rad", "[D] equal to kt in SI units"),
            ("friction_torque_nm", "[D] kt x no-load current 20 mA"),
            ("inductance_h", "[E] iron-core 10 mm motor, 0.1-0.5 mH"),
            ("rotor_inertia_kg_m2", "[E] 0.05-0.1 g cm^2"),
        ),
    ),
}
"""Motor presets.  Sources of the non-default presets (see docs/model.md):

* ``maxon_dcx6m_3v``: [R] maxon DCX 6 M 3 V datasheet (no-load speed/current, stall torque
  and current); R = U/I_stall and kM = M_H/I_H are [D]; J = 0.015 g cm^2 and L = 40 uH are
  [E] (not printed in the excerpt; ranges 0.01-0.02 g cm^2 and 20-60 uH).
* ``pololu_lp_6v``: [R] Pololu LP 6 V 100.37:1 datasheet (130 rpm, 20 mA no-load, 0.36 A
  stall); R = 6/0.36 and kt = (U - I0 R)/w0 are [D]; J and L are [E].  Its gearbox is the
  ``pololu_100`` drive train.
"""


@dataclass(frozen=True)
class DriveTrainParams(_Checked):
    """Gearhead, pinion, racks and board, guide rods, backlash and end stops.

    All forces and positions are expressed at the rack (board) line.
    """
    name: str = "planetary_64"
    sources: tuple = ()
    """Per-preset (field, source) pairs overriding the class-level source of those fields."""
    gear_ratio: float = _pos(64.0, "-", "[E] three-stage planetary head (4:1 per stage) for the "
                             "0816 series; catalogue ratios 4:1-1024:1 [R] Faulhaber", doc="Gearhead reduction N.")
    gear_efficiency: float = _pos(0.6, "-", "[R] 81 % per planetary stage (Citizen) gives 0.53 for "
                                  "3 stages [D]; 0.7 at 43:1 [R] Faulhaber 16/7; 0.6 chosen [E]",
                                  doc="Gearhead efficiency eta (a fraction).")
    pinion_radius_m: float = _pos(2.5e-3, "m", "[E] module 0.3 mm, 16 teeth -> 2.4 mm",
                                  doc="Pitch radius r of the pinion on the rack.")
    moving_mass_kg: float = _pos(6e-3, "kg", "[E] two plastic racks, board and 3x2 display",
                                 doc="Mass of the racks, board and display that move.")
    backlash_m: float = _nn(0.1e-3, "m", "[E] rack mesh 0.01-0.03 mm plus 1-3 deg gearhead play x r",
                            doc="Backlash at the board.")
    mesh_stiffness_n_per_m: float = _pos(3e4, "N/m", "[E] plastic mesh contact 1e4-1e5 N/m",
                                         doc="Stiffness of the gear mesh at the rack.")
    mesh_damping_ratio: float = _nn(0.3, "-", "[E] polymer mesh loss", doc="Damping ratio of the gear mesh.")
    guide_coulomb_n: float = _nn(0.10, "N", "[E] guide rods 0.05-0.3 N", doc="Coulomb friction of the guide rods.")
    guide_viscous_n_s_per_m: float = _nn(1.0, "N s/m", "[E] guide rods 0.5-5 N s/m",
                                         doc="Viscous friction of the guide rods.")
    guide_breakaway_ratio: float = _pos(1.25, "-", "[R] POM on steel mu_s/mu_k = 0.25/0.2 (Stagnoli)",
                                        doc="Static over kinetic friction of the guide rods.")
    stribeck_velocity_m_per_s: float = _pos(0.5e-3, "m/s", "[E] 0.1-1 mm/s",
                                            doc="Stribeck velocity of the friction's fall from break-away.")
    travel_min_m: float = _p(0.0, "m", "[E] board fully retracted",
                             doc="Board position at the near end stop (fully retracted).")
    travel_max_m: float = _p(6e-3, "m", "[E] rack travel of a finger-worn frame",
                             doc="Board position at the far end stop.")

    def __post_init__(self):
        super().__post_init__()
        if not self.gear_efficiency <= 1.0:
            raise ValueError(f"DriveTrainParams.gear_efficiency = {self.gear_efficiency:g} must be in (0, 1]: "
                             f"it is a fraction (60 % is 0.6), and above 1 the gearhead would deliver more "
                             f"power than the motor puts in")
        if not self.travel_max_m > self.travel_min_m:
            raise ValueError(f"DriveTrainParams.travel_max_m ({self.travel_max_m:g} m) must be above "
                             f"travel_min_m ({self.travel_min_m:g} m): the board needs a travel range to move in")

    @property
    def transmission_m_per_rad(self) -> float:
        """Rack travel per motor-shaft radian, r/N (m/rad)."""
        return self.pinion_radius_m / self.gear_ratio

    @property
    def gear_loss_coefficient(self) -> float:
        """Load-proportional friction of the gearhead, mu = 1/eta - 1 (-)."""
        return 1.0 / self.gear_efficiency - 1.0


DRIVETRAINS: dict[str, DriveTrainParams] = {
    "planetary_64": DriveTrainParams(),
    "planetary_16": DriveTrainParams(name="planetary_16", gear_ratio=16.0, gear_efficiency=0.66,
                                     backlash_m=0.08e-3, sources=(
                                         ("gear_ratio", "[E] two planetary stages of 4:1"),
                                         ("gear_efficiency", "[D] 0.81^2 from 81 % per stage [R] Citizen"),
                                         ("backlash_m", "[E] fewer stages, less accumulated play"))),
    "pololu_100": DriveTrainParams(name="pololu_100", gear_ratio=100.37, gear_efficiency=0.51,
                                   backlash_m=0.15e-3, sources=(
                                       ("gear_ratio", POLOLU),
                                       ("gear_efficiency", "[D] 72.6 mN m/(4.15 mN m/A x 0.34 A x 100.37) at stall"),
                                       ("backlash_m", "[E] 2-5 deg at the output x r (not published)"))),
}
"""Drive-train presets.  ``planetary_16``: two stages, 0.81^2 = 0.66 [D]; ``pololu_100``:
[R] Pololu 100.37:1, efficiency at stall 0.51 [D], backlash 2-5 deg at the output [E]."""


@dataclass(frozen=True)
class FingerParams(_Checked):
    """Fingertip pulp in normal indentation by a flat board (quasi-linear viscoelastic).

    Instantaneous elastic force ``Fe(d) = (b/m)(exp(m d) - 1)`` for compression d > 0;
    reduced relaxation ``G(t) = c0 + c1 e^{-t/tau1} + c2 e^{-t/tau2} + c3 e^{-t/tau3}``
    with ``c0 + c1 + c2 + c3 = 1``; the contact force is the hereditary integral of
    ``G`` against ``dFe``, clipped at zero (the board can leave the pulp).
    """
    name: str = "nominal"
    sources: tuple = ()
    """Per-preset (field, source) pairs overriding the class-level source of those fields."""
    stiffness_b_n_per_m: float = _pos(264.0, "N/m", "[E] solved through 1.4 mm at 1 N and 2.4 mm at "
                                      "4 N, checked against Hertz E = 0.1 MPa (parameters table 1.2)",
                                      doc="Pulp stiffness b of the elastic law F = (b/m)(exp(m d) - 1).")
    exponent_m_per_m: float = _pos(1246.0, "1/m", "[E] as stiffness_b_n_per_m",
                                   doc="Pulp exponent m of the elastic law.")
    relax_weight_inf: float = _pos(0.15, "-", "[D] c0 of the Prony series: with c1-c3, a 100 ms half-sine tap "
                                   "to 2 N dissipates 81 % of its work ([R] Jindrich et al. 2003, J Biomech "
                                   "36:497: 81 % in voluntary tapping) at the [R] relaxation times; not unique: "
                                   "81 % needs c0 <= 0.2 with most weight at 4 ms",
                                   doc="Prony weight c0: the part of the force that never relaxes.")
    relax_weight_1: float = _nn(0.75, "-", "[D] c1, as relax_weight_inf", doc="Prony weight c1 (fast relaxation).")
    relax_weight_2: float = _nn(0.05, "-", "[D] c2, as relax_weight_inf", doc="Prony weight c2 (middle relaxation).")
    relax_weight_3: float = _nn(0.05, "-", "[D] c3, as relax_weight_inf", doc="Prony weight c3 (slow relaxation).")
    relax_tau_1_s: float = _pos(0.004, "s", "[R] Pawluk & Howe 1999, J Biomech Eng 121:178",
                                doc="Time constant of the fast relaxation.")
    relax_tau_2_s: float = _pos(0.070, "s", "[R] Pawluk & Howe 1999", doc="Time constant of the middle relaxation.")
    relax_tau_3_s: float = _pos(1.4, "s", "[R] Pawluk & Howe 1999", doc="Time constant of the slow relaxation.")

    def __post_init__(self):
        super().__post_init__()
        s = self.relax_weight_inf + self.relax_weight_1 + self.relax_weight_2 + self.relax_weight_3
        if abs(s - 1.0) > 1e-9:
            raise ValueError(f"FingerParams relaxation weights must sum to 1, got {s:.6g}")

    def elastic_force_n(self, d_m: float) -> float:
        """Instantaneous elastic force at compression ``d_m`` (0 for d <= 0)."""
        return _fingertip.elastic_force(float(d_m), self.stiffness_b_n_per_m, self.exponent_m_per_m)

    def compression_at_m(self, force_n: float, relaxed: bool = False) -> float:
        """Compression that gives ``force_n``; ``relaxed`` uses the long-time force c0 Fe."""
        f = _fingertip.relaxed_elastic_force_n(float(force_n), self.relax_weight_inf) if relaxed else float(force_n)
        return _fingertip.compression_at_force_m(f, self.stiffness_b_n_per_m, self.exponent_m_per_m)


FINGERS: dict[str, FingerParams] = {
    "soft": FingerParams(name="soft", stiffness_b_n_per_m=141.0, exponent_m_per_m=1080.0, sources=(
        ("stiffness_b_n_per_m", "[E] solved through 2.0 mm at 1 N and 3.2 mm at 4 N"),
        ("exponent_m_per_m", "[E] as stiffness_b_n_per_m"))),
    "nominal": FingerParams(),
    "stiff": FingerParams(name="stiff", stiffness_b_n_per_m=540.0, exponent_m_per_m=1448.0, sources=(
        ("stiffness_b_n_per_m", "[E] solved through 0.9 mm at 1 N and 1.7 mm at 4 N"),
        ("exponent_m_per_m", "[E] as stiffness_b_n_per_m"))),
}
"""Reader presets [E]: soft 2.0 mm at 1 N, nominal 1.4 mm, stiff 0.9 mm (instantaneous law)."""


@dataclass(frozen=True)
class FSRParams(_Checked):
    """Interlink FSR 402 as a force-to-resistance transducer.

    Conductance ``G = 1/R_standoff + F_c^n / k`` where ``F_c`` is the force after the
    mechanical lag, the hysteresis operator and the hereditary creep
    (:func:`ebraille_sim.physics.fsr.creep_force`: conductance rising under a held force
    by about ``exponent * creep_per_decade`` per decade, recovering when unloaded).
    """
    name: str = "fsr402_nominal"
    sources: tuple = ()
    """Per-preset (field, source) pairs overriding the class-level source of those fields."""
    resistance_at_1n_ohm: float = _pos(10e3, "ohm", "[D] power-law fit through Interlink/Adafruit "
                                       "points 0.2 N-30 k, 1 N-6 k, 10 N-1 k; spread 6-27 k",
                                       doc="Film resistance at 1 N (the scale of the power law in force).")
    exponent: float = _pos(0.9, "-", "[D] same fit; 0.75-1.0", doc="Exponent of the resistance's power law in force.")
    standoff_resistance_ohm: float = _pos(10e6, "ohm", "[R] FSR 402 datasheet: > 10 MOhm unloaded",
                                          doc="Resistance with no load.")
    hysteresis_fraction: float = _nn(0.10, "-", "[R] FSR 402 datasheet: +10 % average (R_F+ - R_F-)/R_F+, "
                                     "taken at 1000 g, creep included; the play operators carry the part the "
                                     "creep does not (physics.fsr.play_loop_fraction)",
                                     doc="Width of the loading/unloading loop, a fraction of the loading resistance.")
    creep_per_decade: float = _nn(
        0.0275, "-", "[D] hereditary creep of the crept force per decade of load time, such that a held force's "
        "conductance rises 12 % from 1 s to 48 h (Sensitronics, standard FSR ink at 2 psi [R]: "
        "drift_log log10(t), t in s); 2.4 %/decade in conductance at 0.1-1 s, 2.1 % at 1000 s, inside the FSR 402 datasheet's "
        "< 5 % per log10(time) [R]", doc="Creep of the force reading per decade of load time.")
    creep_tau_min_s: float = _pos(0.01, "s", "[E] fastest creep term: the film settles in tens of ms "
                                  "after its 1-2 ms mechanical rise [R] Interlink guide",
                                  doc="Fastest time constant of the creep law.")
    creep_tau_max_s: float = _pos(1e6, "s", "[D] slowest creep term, 11.6 days: the log-time law holds over "
                                  "the datasheet's drift test (1 kg for 35 days [R]) and Sensitronics' 48 h [R]; "
                                  "one term per decade from creep_tau_min_s",
                                  doc="Slowest time constant of the creep law.")
    load_threshold_n: float = _pos(0.02, "N", "[E] film in contact with the electrodes: below the "
                                   "0.1 N actuation force [R]; the creep acts and a press starts above it",
                                   doc="Force at which the film meets the electrodes.")
    actuation_force_n: float = _pos(0.1, "N", "[R] FSR 402 datasheet (2010): actuation force 0.1 N (400-series "
                                    "sheet: ~0.2 N min); the power-law path conducts half its law there",
                                    doc="Force F_a at which the film turns on.")
    turn_on_steepness: float = _pos(4.0, "-", "[E] exponent m of the turn-on 1/(1 + (F_a/F)^m): the resistance at "
                                    "the actuation force is 160 kOhm, above the guide's > 100 kOhm before turn-on "
                                    "[R], and the power law is met within 6 % from 2 F_a (0.2 N: 45 kOhm; "
                                    "Adafruit/Interlink table 30 kOhm [R], inside the k spread)",
                                    doc="Exponent m of the turn-on 1/(1 + (F_a/F)^m).")
    press_repeatability: float = _nn(0.02, "-", "[R] FSR 402 datasheet: single-part force repeatability +/-2 %, "
                                     "one standard deviation/mean at 1000 g; drawn per press as a resistance "
                                     "factor exp(sigma z)",
                                     doc="Part-to-part scatter of a press's reading, a fraction.")
    mechanical_lag_s: float = _pos(1.5e-3, "s", "[R] Interlink integration guide: 1-2 ms mechanical rise",
                                   doc="Mechanical rise time of the film.")
    noise_v_rms: float = _nn(2e-3, "V", "[E] divider + ADC input noise, about 0.4 LSB of a 10-bit 5 V ADC",
                             doc="RMS noise at the divider's output.")
    temperature_coeff_per_k: float = _p(
        -0.15 / 60.0, "1/K", "[D] warm side: datasheet -15 % resistance at +85 C after 1 h [R], linear from 25 C",
        doc="Relative change of resistance per kelvin on the warm side.")
    temperature_coeff_cold_per_k: float = _p(
        0.05 / 65.0, "1/K", "[D] cold side: datasheet -5 % resistance at -40 C after 1 h [R], linear from 25 C "
        "(the resistance falls on both sides)", doc="Relative change of resistance per kelvin on the cold side.")

    def __post_init__(self):
        super().__post_init__()
        if not self.creep_tau_max_s > self.creep_tau_min_s:
            raise ValueError(f"FSRParams.creep_tau_max_s ({self.creep_tau_max_s:g} s) must be above "
                             f"creep_tau_min_s ({self.creep_tau_min_s:g} s)")
        if not self.hysteresis_fraction < 1.0:
            raise ValueError(f"FSRParams.hysteresis_fraction = {self.hysteresis_fraction:g} must be below 1: "
                             f"it is the relative resistance difference between loading and unloading "
                             f"(0.10 for +10 %), and 1 would mean a zero resistance on one branch")

    @property
    def hysteresis_log_halfwidth(self) -> float:
        """Total half-width in ln(force) of the play operators: ``-ln(1-h_play)/(2 n)`` with
        ``h_play`` the loop left to them (:func:`ebraille_sim.physics.fsr.play_loop_fraction`)."""
        return -math.log(1.0 - _fsr.play_loop_fraction(self)) / (2.0 * self.exponent)

    def resistance_ohm(self, force_n: float) -> float:
        """Static resistance without hysteresis or creep (turn-on region included)."""
        return 1.0 / _fsr.conductance_s(float(force_n), self.resistance_at_1n_ohm, self.exponent,
                                        1.0 / self.standoff_resistance_ohm, 1.0, self.actuation_force_n,
                                        self.turn_on_steepness)


FSRS: dict[str, FSRParams] = {
    "nominal": FSRParams(),
    "low_k": FSRParams(name="fsr402_low_k", resistance_at_1n_ohm=6.9e3, exponent=0.86, sources=(
        ("resistance_at_1n_ohm", "[D] power-law fit over 0.2-10 N of the Interlink/Adafruit points"),
        ("exponent", "[D] same fit"))),
    "high_k": FSRParams(name="fsr402_high_k", resistance_at_1n_ohm=14e3, exponent=0.95, sources=(
        ("resistance_at_1n_ohm", "[E] upper part of the 6-27 kOhm part-to-part spread [R] Interlink guide"),
        ("exponent", "[D] 0.2-1 N fit gives 1.0, full range 0.77"))),
}


@dataclass(frozen=True)
class CircuitParams(_Checked):
    """Voltage divider (FSR to the supply, R2 to ground) and ADC; paper eq. 1."""
    supply_v: float = _pos(5.0, "V", "[R] Arduino Uno 5 V rail (Carambat 2016)",
                           doc="Supply of the FSR's voltage divider.")
    r2_ohm: float = _pos(1140.0, "ohm", "[D] the bench calibration of the nominal FSR unit for the paper's "
                         "Wiener estimator (calibration.bench_calibrate_device: presses to 0.5-2 N held 5-60 s, "
                         "set to 10 ohm; docs/model.md, 'Calibration'); paper: adjustable 1-20 kOhm",
                         doc="Fixed resistor R2 of the divider (the bench calibration sets it).")
    adc_bits: int = _pos(10, "bit", "[R] ATmega328 10-bit ADC", doc="Resolution of the FSR's ADC.")
    adc_ref_v: float = _pos(5.0, "V", "[R] ATmega328 AVcc reference", doc="Reference voltage of the FSR's ADC.")

    def __post_init__(self):
        super().__post_init__()
        try:
            bits = check_number("CircuitParams.adc_bits", self.adc_bits, lo=1, hi=ADC_BITS_MAX, integer=True)
        except ValueError as exc:
            raise ValueError(f"{exc} (an ADC converts to a whole number of bits; converters are made "
                             f"with 1 to {ADC_BITS_MAX} bits)") from None
        object.__setattr__(self, "adc_bits", bits)

    def divider_v(self, resistance_ohm: float) -> float:
        """Paper eq. 1: V_o = V_in R2/(R2 + R_FSR), through :func:`ebraille_sim.physics.fsr.divider_voltage`."""
        return _fsr.divider_voltage(1.0 / resistance_ohm, self.r2_ohm, self.supply_v)

    @property
    def adc_lsb_v(self) -> float:
        """Voltage of one ADC step, V_ref / 2^bits (V)."""
        return _adc_step_v(self.adc_ref_v, self.adc_bits)

    @property
    def adc_max_code(self) -> float:
        """Largest ADC code, 2^bits - 1."""
        return _adc_top_code(self.adc_bits)


INA240 = "[R] TI INA240 datasheet (SBOS662), electrical characteristics"


@functools.lru_cache(maxsize=None)
def _bounded_fields(cls) -> tuple:
    """``(name, lo, hi)`` of the unit errors and tolerances :class:`CurrentSenseParams` checks
    against their declared bounds (read once per class)."""
    names = ("shunt_tolerance", "gain_error_max", "offset_max_v", "adc_noise_lsb", "shunt_error", "gain_error",
             "offset_v")
    meta = {f.name: f.metadata for f in dataclasses.fields(cls)}
    return tuple((name, meta[name]["lo"], meta[name]["hi"]) for name in names)


@dataclass(frozen=True)
class CurrentSenseParams(_Checked):
    """The board's motor-current sensing chain (:mod:`ebraille_sim.physics.current_sense`):
    low-side shunt, bidirectional current-sense amplifier, RC anti-alias filter, the
    microcontroller's ADC, and the firmware's zeroing at rest.

    ``gain_error``, ``shunt_error`` and ``offset_v`` are the unit's own (0 for the nominal
    board; a population draws them within the ``*_max`` and ``shunt_tolerance`` bounds); the
    firmware knows only the nominal ``gain_v_per_v`` and ``shunt_ohm``."""
    shunt_ohm: float = _pos(0.05, "ohm", "[D] +/-0.5 A into the amplifier's +/-2.5 V half range at 100 V/V "
                            "(stall current 0.28 A of the Faulhaber drive)", doc="Motor current shunt resistance.")
    shunt_tolerance: float = sourced(0.01, "-", "[R] 1 % current-sense resistor (e.g. Vishay WSL2512 series)",
                                     lo=0.0, hi=0.05, doc="Tolerance of the shunt, a fraction (the firmware's bound).")
    shunt_error: float = sourced(0.0, "-", "[E] this unit's shunt deviation; nominal board 0", lo=-0.05, hi=0.05,
                                 doc="This unit's shunt deviation, a fraction.")
    gain_v_per_v: float = _pos(100.0, "V/V", INA240 + ": INA240A3 gain", doc="Gain of the current-sense amplifier.")
    gain_error_max: float = sourced(0.002, "-", INA240 + ": gain error +/-0.20 % max", lo=0.0, hi=0.05,
                                    doc="Largest gain error of the amplifier, a fraction (the firmware's bound).")
    gain_error: float = sourced(0.0, "-", "[E] this unit's gain error; nominal board 0", lo=-0.05, hi=0.05,
                                doc="This unit's gain error, a fraction.")
    offset_max_v: float = sourced(25e-6, "V", INA240 + ": input offset +/-25 uV max", lo=0.0, hi=1e-3,
                                  doc="Largest input offset of the amplifier.")
    offset_v: float = sourced(0.0, "V", "[E] this unit's input offset; nominal board 0", lo=-1e-3, hi=1e-3,
                              doc="This unit's input offset.")
    reference_v: float = _pos(2.5, "V", INA240 + ": output midpoint from REF1/REF2 at mid-supply of 5 V",
                              doc="Output reference of the amplifier (the zero-current level).")
    filter_tau_s: float = _pos(159e-6, "s", "[D] each RC anti-alias section 1.6 kOhm x 100 nF (corner 1.0 kHz)",
                               doc="Time constant of each RC anti-alias section.")
    filter_stages: int = _pos(2, "-", "[D] two buffered RC sections: the 20 kHz PWM ripple under one LSB "
                              "(ebraille_sim.physics.current_sense)", doc="Number of RC anti-alias sections.")
    adc_bits: int = _pos(10, "bit", "[R] ATmega328 10-bit ADC (the FSR's converter)",
                         doc="Resolution of the current's ADC.")
    adc_ref_v: float = _pos(5.0, "V", "[R] ATmega328 AVcc reference", doc="Reference voltage of the current's ADC.")
    adc_noise_lsb: float = sourced(0.5, "LSB", "[E] within the ATmega328's +/-2 LSB absolute accuracy [R]",
                                   lo=0.0, hi=4.0, doc="RMS noise of one conversion, in codes.")
    zero_samples: int = _pos(64, "-", "[E] conversions averaged by the start-up zeroing at rest",
                             doc="Conversions averaged by the start-up zeroing at rest.")
    pwm_hz: float = _pos(20000.0, "Hz", "[E] H-bridge PWM frequency above hearing",
                         doc="PWM frequency of the H-bridge.")

    def __post_init__(self):
        super().__post_init__()
        d = self.__dict__
        for name, lo, hi in (("adc_bits", 1, ADC_BITS_MAX), ("zero_samples", 1, 1_000_000), ("filter_stages", 1, 2)):
            v = d[name]
            if not (type(v) is int and lo <= v <= hi):          # an int within its bounds is what the check returns
                object.__setattr__(self, name, check_number(f"CurrentSenseParams.{name}", v, lo=lo, hi=hi,
                                                            integer=True))
        for name, lo, hi in _bounded_fields(type(self)):
            v = d[name]
            if not (type(v) is float and lo <= v <= hi):        # a float within its bounds passes the check
                check_number(f"CurrentSenseParams.{name}", v, lo=lo, hi=hi)
        if abs(self.gain_error) > self.gain_error_max or abs(self.shunt_error) > self.shunt_tolerance \
                or abs(self.offset_v) > self.offset_max_v:
            raise ValueError("CurrentSenseParams: the unit's gain_error, shunt_error and offset_v must lie within "
                             "gain_error_max, shunt_tolerance and offset_max_v")
        if not self.reference_v < self.adc_ref_v:
            raise ValueError(f"CurrentSenseParams.reference_v = {self.reference_v:g} V must lie inside the ADC range "
                             f"0-{self.adc_ref_v:g} V")
        if self.gain_v_per_v * self.offset_max_v >= min(self.reference_v, self.adc_ref_v - self.reference_v):
            raise ValueError("CurrentSenseParams.offset_max_v: the amplified offset would leave the ADC range")

    @property
    def nominal_v_per_a(self) -> float:
        """The transfer the firmware assumes, ``G_nom R_sh,nom`` (V/A)."""
        return self.gain_v_per_v * self.shunt_ohm

    @property
    def adc_lsb_v(self) -> float:
        """Voltage of one step of the chain's ADC (V)."""
        return _adc_step_v(self.adc_ref_v, self.adc_bits)

    @property
    def adc_max_code(self) -> float:
        """Largest code of the chain's ADC."""
        return _adc_top_code(self.adc_bits)

    @property
    def lsb_a(self) -> float:
        """Current of one ADC step through the nominal transfer, A."""
        return self.adc_lsb_v / self.nominal_v_per_a

    @property
    def range_a(self) -> float:
        """Largest current of either sign the chain reads before its output leaves the ADC range, A."""
        return min(self.reference_v, self.adc_ref_v - self.reference_v) / self.nominal_v_per_a


CALIBRATION_TABLE_MAX_POINTS = 6
"""Most points of a unit's calibration table (:class:`EstimatorParams`)."""

UNIT_ESTIMATOR_FIELDS = ("hysteresis_fraction", "creep_per_decade", "calibration_loads_n", "calibration_readings_n")
"""The :class:`EstimatorParams` fields a unit's bench measures and stores: they belong to the
unit, and a firmware preset loaded onto it keeps them."""


def unit_estimator(firmware: "EstimatorParams", unit: "EstimatorParams | None" = None) -> "EstimatorParams":
    """The estimator settings of ``firmware`` with the bench fields (:data:`UNIT_ESTIMATOR_FIELDS`)
    of ``unit``: another unit's estimator, or None for a unit its bench has not measured (the
    fields at their defaults)."""
    src = _NO_BENCH if unit is None else unit
    fields = {k: getattr(src, k) for k in UNIT_ESTIMATOR_FIELDS}
    if all(getattr(firmware, k) == v for k, v in fields.items()):
        return firmware                                   # already so (an env's every reset)
    return replace_checked(firmware, **fields)


@dataclass(frozen=True)
class EstimatorParams(_Checked):
    """In-loop force estimator: anti-alias filter, decimation, block-oriented model.

    The estimator runs at its model's own sample rate, ``1/dt_s`` of the block model (the
    paper's models: 100 Hz, the rate they were identified at); there is no separate rate
    setting.  The sensor rate must be a whole multiple of it
    (:func:`ebraille_sim.plant.lumped.pack_params` raises otherwise).
    """
    model: str = _p("paper:wiener:5", "-", "seed paper, Appendix 2-3, fifth-order Wiener")
    antialias_cutoff_hz: float = _pos(20.0, "Hz", "[E] the paper band-limited its data below 40 Hz; "
                                      "the model gain grows 9x at 40 Hz and 300x at 50 Hz")
    tare_at_start: bool = _p(True, "-", "[E] the no-load voltage is subtracted (the paper detrends)")
    clamp_nonnegative: bool = _p(True, "-", "[E] a contact force estimate is never negative")
    nyquist_average: bool = _p(True, "-", "[E] two-sample mean of the estimate: cancels the 50 Hz "
                               "ringing of the paper model's pole at z = -0.967")
    creep_compensation: bool = _p(True, "-", "[E] firmware runs the nominal FSR's hereditary creep law "
                                  "on its own estimate and divides the predicted creep gain out of the "
                                  "film conductance before the model (docs/model.md)")
    creep_reference_hold_s: float = _pos(20.0, "s", "[D] hold of the divider's calibration "
                                         "(estimation.calibration.calibrate_device; centre of calibrate_r2's "
                                         "5-60 s holds): the compensated voltage is the one read after it")
    hysteresis_compensation: bool = _p(False, "-", "[E] firmware inverts the nominal FSR's play-operator "
                                       "hysteresis and reads every voltage on the calibrated loading branch "
                                       "(docs/model.md); off by default")
    hysteresis_fraction: float | None = _p(None, "-", "[D] the loop the hysteresis compensation inverts: "
                                           "None measures the unit's at assembly (a press to 2 N and a "
                                           "let-down to 1 N, estimation.calibration."
                                           "measured_hysteresis_fraction, its rate-independent part); 0.10 is "
                                           "the datasheet's nominal, creep included (the part left to the "
                                           "play operators by the nominal creep law, with creep_per_decade when "
                                           "set, is inverted); a drawn unit's bench stores its own "
                                           "(estimation.calibration.bench_hysteresis_fraction)")
    hysteresis_deadband_lsb: float = _nn(1.5, "LSB", "[E] after a 5-sample running median, changes of the "
                                         "ADC voltage up to this many counts are taken as noise by the "
                                         "hysteresis compensation (the median removes single noisy samples; "
                                         "the creep compensation's transient after a fast press moves its "
                                         "voltage back by more than one count; docs/model.md)")
    hysteresis_turn_lsb: float = _nn(0.0, "LSB", "[E] turn test of the hysteresis compensation: a slow reversal "
                                     "is read once the voltage's exponential average is this many counts back "
                                     "from the median's extreme since the last turn; 0 is off (the plain "
                                     "deadband).  1.75 on the fast_1khz firmware preset, chosen on a training "
                                     "population (the benchmark study's hold-damping search; "
                                     "estimation.firmware.turn_tested_v)")
    hysteresis_follow_lsb: float = _nn(0.5, "LSB", "[E] with the turn test, the deadband a move on in the "
                                       "followed direction passes (at most hysteresis_deadband_lsb; a fast "
                                       "reversal still needs the plain deadband's swing of twice that)")
    hysteresis_centre_time_s: float = _nn(0.0, "s", "[E] time constant over which the hysteresis compensation's "
                                          "input, while the film shows no move, relaxes to the middle of the "
                                          "inputs its plays allow (estimation.firmware.centred_x); 0 is off")
    hysteresis_turn_time_s: float = _pos(0.008, "s", "[E] time constant of the turn test's exponential "
                                         "average: at 1 kHz and 0.4 LSB of noise its noise is about 0.1 LSB")
    creep_per_decade: float | None = _p(None, "-", "[D] the creep per decade the creep compensation runs: None "
                                        "the nominal film's (FSRParams.creep_per_decade); a drawn unit's bench "
                                        "measures its own from the conductance at 2 s and 20 s of the calibration "
                                        "table's 1 N holds (estimation.calibration.bench_creep_per_decade)")
    calibration_loads_n: tuple = _p((), "N", "[D] known loads of the unit's calibration table, ascending (each "
                                    "pressed from no load and held on the bench, estimation.calibration."
                                    "calibration_table); empty: no table, the model's estimate is the firmware's")
    calibration_readings_n: tuple = _p((), "N", "[D] the model's steady estimate the bench read at each of "
                                       "calibration_loads_n (the mean of the unit's presses through its ADC); "
                                       "ascending, > 0; the firmware maps its estimate onto the loads through "
                                       "them (estimation.firmware.table_calibrated_n)")

    def __post_init__(self):
        super().__post_init__()
        h = self.hysteresis_fraction
        if h is not None and not (isinstance(h, (int, float)) and 0.0 <= h < 1.0):
            raise ValueError(f"EstimatorParams.hysteresis_fraction = {h!r} must be None or in [0, 1)")
        c = self.creep_per_decade
        if c is not None and not (isinstance(c, (int, float)) and not isinstance(c, bool) and 0.0 <= c < 0.5):
            raise ValueError(f"EstimatorParams.creep_per_decade = {c!r} must be None or in [0, 0.5)")
        loads, reads = self.calibration_loads_n, self.calibration_readings_n
        for name, v in (("calibration_loads_n", loads), ("calibration_readings_n", reads)):
            if not (isinstance(v, tuple) and len(v) <= CALIBRATION_TABLE_MAX_POINTS
                    and all(isinstance(x, (int, float)) and not isinstance(x, bool) and 0.0 < x < math.inf for x in v)
                    and all(a < b for a, b in zip(v, v[1:]))):
                raise ValueError(f"EstimatorParams.{name} = {v!r} must be a tuple of at most "
                                 f"{CALIBRATION_TABLE_MAX_POINTS} ascending positive forces, N")
        if len(loads) != len(reads):
            raise ValueError(f"EstimatorParams.calibration_loads_n has {len(loads)} points and "
                             f"calibration_readings_n {len(reads)}: one reading per load")
        if self.hysteresis_turn_lsb > 0.0 and self.hysteresis_follow_lsb > self.hysteresis_deadband_lsb:
            raise ValueError(f"EstimatorParams.hysteresis_follow_lsb = {self.hysteresis_follow_lsb!r} must not exceed "
                             f"hysteresis_deadband_lsb = {self.hysteresis_deadband_lsb!r} with the turn test on")


@dataclass(frozen=True)
class RateParams(_Checked):
    """Control, sensor and physics rates; each a whole multiple of the next slower one."""
    control_rate_hz: float = _pos(1000.0, "Hz", "[E] microcontroller loop")
    sensor_rate_hz: float = _pos(1000.0, "Hz", "[E] ADC sampling")
    physics_rate_hz: float = _pos(10000.0, "Hz", "[E] integrator step; stable to ~40 kN/m at 6 g")

    def __post_init__(self):
        super().__post_init__()
        for slow_name, slow in (("control_rate_hz", self.control_rate_hz),
                                ("sensor_rate_hz", self.sensor_rate_hz)):
            ratio = self.physics_rate_hz / slow
            if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
                raise ValueError(f"physics_rate_hz ({self.physics_rate_hz:g}) must be a whole multiple "
                                 f"of {slow_name} ({slow:g})")

    @property
    def substeps_per_control(self) -> int:
        return int(round(self.physics_rate_hz / self.control_rate_hz))

    @property
    def substeps_per_sensor(self) -> int:
        return int(round(self.physics_rate_hz / self.sensor_rate_hz))


@dataclass(frozen=True)
class DeviceParams:
    """Everything physical about one device worn by one reader."""
    motor: MotorParams = MotorParams()
    drivetrain: DriveTrainParams = DriveTrainParams()
    finger: FingerParams = FingerParams()
    fsr: FSRParams = FSRParams()
    circuit: CircuitParams = CircuitParams()
    current_sense: CurrentSenseParams = CurrentSenseParams()
    estimator: EstimatorParams = EstimatorParams()
    rates: RateParams = RateParams()
    driver_supply_v: float = 6.0
    """H-bridge supply, V: the command saturates at +/- this value [E] (motor nominal voltage)."""
    gravity_m_per_s2: float = STANDARD_GRAVITY_M_PER_S2

    def __post_init__(self):
        for name in ("driver_supply_v", "gravity_m_per_s2"):
            v = getattr(self, name)
            if not math.isfinite(v):
                raise ValueError(f"DeviceParams.{name} must be finite, got {v}")
        if not self.driver_supply_v > 0:
            raise ValueError(f"DeviceParams.driver_supply_v must be > 0, got {self.driver_supply_v}")


_NO_BENCH = EstimatorParams()
"""An estimator whose unit's bench measured nothing (:func:`unit_estimator`)."""


def source_of(obj, name: str) -> str:
    """Source tag of field ``name`` of a parameter dataclass (preset-specific if given)."""
    f = _field(obj, name)
    for key, src in getattr(obj, "sources", ()):
        if key == name:
            return src
    return f.metadata.get("source", "")


def unit_of(obj, name: str) -> str:
    """Unit of field ``name`` of a parameter dataclass."""
    return _field(obj, name).metadata.get("unit", "")


def _field(obj, name):
    for f in dataclasses.fields(obj):
        if f.name == name:
            return f
    allowed = ", ".join(f.name for f in dataclasses.fields(obj))
    raise KeyError(f"{type(obj).__name__} has no field {name!r}; allowed: {allowed}")


def describe(obj) -> list[tuple[str, Any, str, str]]:
    """Rows (name, value, unit, source) of a parameter dataclass, for reports and docs."""
    return [(f.name, getattr(obj, f.name), f.metadata.get("unit", ""), source_of(obj, f.name))
            for f in dataclasses.fields(obj) if f.name != "sources"]
