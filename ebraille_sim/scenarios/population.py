"""Populations of readers, FSR units and drive trains: stated distributions, seeded draws.

Each device is drawn from a :class:`PopulationSpec` by one compiled call
(:mod:`ebraille_sim.scenarios.draws`): every component (reader, sensor, motor, drive train,
board) has its own random stream of the seed's key (:func:`device_variates`), and each
parameter is a fixed function of its own variate
(:func:`device_from_variates`), so that changing one distribution does not change the draws
of another.  Distributions and their
sources:

==========================  ==========================  =========================================
parameter                   distribution                source
==========================  ==========================  =========================================
pulp b (stiffness)          log-uniform x[0.5, 2]        [E] sweep range of parameters table 1.4
pulp m (exponent)           uniform x[0.85, 1.15]        [E] same
relaxation c0               uniform [0.1, 0.2]           [E] around the tap-dissipation fit; c1..c3 rescaled
FSR k (R at 1 N)            log-normal, sigma 0.2        [R] part-to-part 15-25 % (Interlink guide)
FSR exponent n              uniform [0.8, 1.0]           [D] fits 0.77-1.0
FSR hysteresis              uniform [0.05, 0.15]         [R] datasheet +10 % average
FSR creep per decade        uniform [0.01, 0.05]         [R] datasheet < 5 %/decade (conductance)
motor R, kM                 normal, 5 % / 3 % (1 sigma)  [E] winding and magnet tolerances
gear efficiency             uniform [0.5, 0.7]           [R] 0.53 (3 stages) - 0.7 (Faulhaber)
guide Coulomb friction      log-uniform [0.05, 0.3] N    [E] parameters table 3
backlash                    uniform [0.03, 0.2] mm       [E] parameters table 3
current-sense shunt error   uniform +/- shunt_tolerance  [R] 1 % resistor; uniform [E]
current-sense gain error    uniform +/- gain_error_max   [R] INA240 +/-0.20 % max; uniform [E]
current-sense offset        uniform +/- offset_max_v     [R] INA240 +/-25 uV max; uniform [E]
divider calibration load    uniform +/- 2 %              [E] the 1 N load as the fixture applies it
table loads 0.5, 1.5, 2 N   uniform +/- 2 % each         [E] the same fixture, each load placed anew
==========================  ==========================  =========================================

With ``calibrate=True`` (default) each drawn device's divider is re-calibrated for its own
FSR unit at assembly (:func:`calibrate_device`, one press to 1 N held 20 s, the load off by
its drawn error), and with ``calibration_table=True`` (default) the bench then stores the
unit's calibration table (:func:`~ebraille_sim.estimation.calibration.with_calibration_table`:
0.5, 1, 1.5 and 2 N, each pressed three times and held 20 s, each load off by its own drawn
error); the spread of hysteresis and creep remains an uncalibrated error.

Examples
--------
>>> import numpy as np
>>> a = sample_devices(7, 3)
>>> b = sample_devices(7, 3)
>>> a == b
True
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from numpy.random.bit_generator import ISpawnableSeedSequence

from ebraille_sim.base.seeds import SeedNode
from ebraille_sim.base.validation import check_bool, check_number, check_pair, replace_fields
from ebraille_sim.estimation.calibration import TABLE_LOADS_N, calibrate_device, with_calibration_table
from ebraille_sim.physics.params import DeviceParams, replace_checked, unit_estimator
from ebraille_sim.scenarios.draws import device_numbers


@dataclass(frozen=True)
class PopulationSpec:
    """Spreads of a device population (see the module table for sources)."""
    finger_b_scale: tuple[float, float] = (0.5, 2.0)
    finger_m_scale: tuple[float, float] = (0.85, 1.15)
    relax_c0: tuple[float, float] = (0.1, 0.2)
    fsr_k_sigma_ln: float = 0.2
    fsr_exponent: tuple[float, float] = (0.8, 1.0)
    fsr_hysteresis: tuple[float, float] = (0.05, 0.15)
    fsr_creep_per_decade: tuple[float, float] = (0.01, 0.05)
    motor_r_sigma: float = 0.05
    motor_k_sigma: float = 0.03
    gear_efficiency: tuple[float, float] = (0.5, 0.7)
    guide_coulomb_n: tuple[float, float] = (0.05, 0.3)
    backlash_m: tuple[float, float] = (0.03e-3, 0.2e-3)
    calibrate: bool = True
    calibration_table: bool = True

    def __post_init__(self):
        for f in dataclasses.fields(self):
            v, name = getattr(self, f.name), f"PopulationSpec.{f.name}"
            if f.name in ("calibrate", "calibration_table"):
                check_bool(name, v)
            elif isinstance(f.default, tuple):
                check_pair(name, v, lo=0.0)
            else:
                check_number(name, v, lo=0.0)

    @classmethod
    def from_dict(cls, d, *, base: PopulationSpec | None = None) -> PopulationSpec:
        """A spec from field values (pairs as lists or tuples); omitted fields from ``base``.

        Raises
        ------
        ValueError
            On an unknown key (named, with the allowed ones) or an invalid value.
        """
        d = {k: tuple(v) if isinstance(v, list) else v for k, v in d.items()}
        return replace_checked(cls() if base is None else base, **d)


_DRAWN = "drawn from PopulationSpec (ebraille_sim/scenarios/population.py)"
_FINGER_SOURCES = tuple((k, _DRAWN) for k in ("stiffness_b_n_per_m", "exponent_m_per_m", "relax_weight_inf",
                                              "relax_weight_1", "relax_weight_2", "relax_weight_3"))
"""The ``sources`` of a drawn pulp: the fields the draw sets."""
_FSR_SOURCES = tuple((f, _DRAWN) for f in ("resistance_at_1n_ohm", "exponent", "hysteresis_fraction",
                                           "creep_per_decade"))
"""The ``sources`` of a drawn FSR unit."""


DEVICE_UNIFORMS = ("finger_b_scale", "finger_m_scale", "relax_c0", "fsr_exponent", "fsr_hysteresis",
                   "fsr_creep_per_decade", "gear_efficiency", "guide_coulomb_n", "backlash_m")
"""The :class:`PopulationSpec` ranges a device draws from, in the order of its uniform variates
(``finger_b_scale`` and ``guide_coulomb_n`` log-uniform, the others uniform)."""
DEVICE_NORMALS = ("fsr_k_sigma_ln", "motor_r_sigma", "motor_k_sigma")
"""The :class:`PopulationSpec` spreads of a device's standard normal variates, in their order."""
BOARD_UNIFORMS = ("shunt_error", "gain_error", "offset_v", "calibration_load_error", "table_load_error_0",
                  "table_load_error_2", "table_load_error_3")
"""The board's uniform variates, after :data:`DEVICE_UNIFORMS`: the current chain's unit errors
within their datasheet bounds (``shunt_tolerance``, ``gain_error_max``, ``offset_max_v`` of
the base device's :class:`~ebraille_sim.physics.params.CurrentSenseParams`), the error of
the divider calibration's known load within :data:`CALIBRATION_LOAD_TOLERANCE`, and those of
the calibration table's other loads (:data:`~ebraille_sim.estimation.calibration.TABLE_LOADS_N`
but the 1 N one, which is the divider's load and keeps its error) within the same tolerance.
Drawn after the first four, so adding them changed none of those."""
CALIBRATION_LOAD_TOLERANCE = 0.02
"""Relative error of the 1 N load the divider calibration applies through the board [E]: a
102 g weight is exact to far better, its alignment on the fixture is not."""


def device_variates(seed_sequence) -> tuple[list, list]:
    """The random numbers of one device: the uniforms on [0, 1) of :data:`DEVICE_UNIFORMS` and
    the standard normals of :data:`DEVICE_NORMALS`, in their orders, the uniforms followed by
    the board's :data:`BOARD_UNIFORMS`.  Each component (reader, FSR unit, motor, drive train,
    board) draws from its own stream of the seed's key (:func:`ebraille_sim.scenarios.draws.device_numbers`,
    the compiled call an episode's draw makes too), so that a component's draws do not depend
    on another's."""
    return device_numbers(seed_sequence)


def device_from_variates(u, z, spec: PopulationSpec = PopulationSpec(),
                         base: DeviceParams = DeviceParams()) -> DeviceParams:
    """The device of the variates ``u`` and ``z`` (:func:`device_variates`) under ``spec``, around
    ``base``: every drawn value is a fixed function of its own variate, so changing one
    distribution changes no other component's value (recalibrated when ``spec.calibrate``)."""
    x = []
    for name, v in zip(DEVICE_UNIFORMS, u):
        lo, hi = getattr(spec, name)
        if name in ("finger_b_scale", "guide_coulomb_n"):        # log-uniform
            lo, hi = math.log(lo), math.log(hi)
            x.append(math.exp(lo + (hi - lo) * v))
        else:
            x.append(lo + (hi - lo) * v)                          # Generator.uniform's formula
    (b_scale, m_scale, c0, fsr_n, fsr_hyst, fsr_creep, gear_eff, guide_n, backlash) = x
    z_k, z_r, z_km = z
    f, s, m, d = base.finger, base.fsr, base.motor, base.drivetrain
    rest = f.relax_weight_1 + f.relax_weight_2 + f.relax_weight_3
    k = (1.0 - c0) / rest
    finger = replace_checked(f, name="drawn", sources=_FINGER_SOURCES, stiffness_b_n_per_m=f.stiffness_b_n_per_m * b_scale,
                             exponent_m_per_m=f.exponent_m_per_m * m_scale, relax_weight_inf=c0,
                             relax_weight_1=f.relax_weight_1 * k, relax_weight_2=f.relax_weight_2 * k,
                             relax_weight_3=1.0 - c0 - f.relax_weight_1 * k - f.relax_weight_2 * k)
    fsr = replace_checked(s, name="drawn", sources=_FSR_SOURCES,
                          resistance_at_1n_ohm=s.resistance_at_1n_ohm * math.exp(spec.fsr_k_sigma_ln * z_k),
                          exponent=fsr_n, hysteresis_fraction=fsr_hyst, creep_per_decade=fsr_creep)
    kscale = max(0.5, 1.0 + spec.motor_k_sigma * z_km)
    motor = replace_checked(m, name=m.name, resistance_ohm=m.resistance_ohm * max(0.5, 1.0 + spec.motor_r_sigma * z_r),
                            torque_constant_nm_per_a=m.torque_constant_nm_per_a * kscale,
                            back_emf_v_s_per_rad=m.back_emf_v_s_per_rad * kscale)
    drivetrain = replace_checked(d, name=d.name, gear_efficiency=gear_eff, guide_coulomb_n=guide_n, backlash_m=backlash)
    cs = base.current_sense
    e_shunt, e_gain, e_offset, e_load, e_t0, e_t2, e_t3 = (2.0 * v - 1.0 for v in u[len(DEVICE_UNIFORMS):])
    board = replace_checked(cs, shunt_error=cs.shunt_tolerance * e_shunt, gain_error=cs.gain_error_max * e_gain,
                            offset_v=cs.offset_max_v * e_offset)
    dev = replace_fields(base, finger=finger, fsr=fsr, motor=motor, drivetrain=drivetrain, current_sense=board,
                         estimator=unit_estimator(base.estimator))     # a new unit: nothing of the base's bench
    if not spec.calibrate:
        return dev
    dev = calibrate_device(dev, load_error=CALIBRATION_LOAD_TOLERANCE * e_load)
    if not spec.calibration_table:
        return dev
    return with_calibration_table(dev, TABLE_LOADS_N, tuple(CALIBRATION_LOAD_TOLERANCE * e
                                                            for e in (e_t0, e_load, e_t2, e_t3)))


def sample_device(rng_or_seed, spec: PopulationSpec = PopulationSpec(), base: DeviceParams = DeviceParams()
                  ) -> DeviceParams:
    """One device (reader + FSR unit + motor + drive train) drawn from ``spec``.

    ``rng_or_seed`` is an int, a ``SeedSequence`` (NumPy's or a
    :class:`~ebraille_sim.base.seeds.SeedNode`) or a ``Generator`` (which draws the seed);
    :func:`device_variates` of that seed, :func:`device_from_variates` of those.
    """
    if isinstance(rng_or_seed, np.random.Generator):
        ss = SeedNode(int(rng_or_seed.integers(0, 2**63)))
    elif isinstance(rng_or_seed, ISpawnableSeedSequence):
        ss = rng_or_seed
    else:
        ss = SeedNode(int(rng_or_seed))
    return device_from_variates(*device_variates(ss), spec, base)


def sample_devices(seed: int, n: int, spec: PopulationSpec = PopulationSpec(),
                   base: DeviceParams = DeviceParams()) -> list[DeviceParams]:
    """``n`` devices from one master seed (child ``k`` of ``SeedSequence(seed)`` for device k)."""
    check_number("n", n, lo=0, integer=True)
    return [sample_device(c, spec, base) for c in SeedNode(seed).spawn(n)]
