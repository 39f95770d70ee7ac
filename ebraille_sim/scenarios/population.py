"""Populations of readers, FSR units and drive trains: stated distributions, seeded draws.

Each device is drawn from a :class:`PopulationSpec` with a NumPy ``Generator``; every
component (reader, sensor, motor, drive train) has its own child ``SeedSequence`` so that
changing one distribution does not change the draws of another.  Distributions and their
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
==========================  ==========================  =========================================

With ``calibrate=True`` (default) each drawn device's divider is re-calibrated for its own
FSR unit at assembly (:func:`calibrate_device`, one press to 1 N held 20 s); the spread of
hysteresis and creep remains an uncalibrated error.

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
from ebraille_sim.estimation.calibration import calibrate_device
from ebraille_sim.physics.params import FINGERS, DeviceParams, replace_checked


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

    def __post_init__(self):
        for f in dataclasses.fields(self):
            v, name = getattr(self, f.name), f"PopulationSpec.{f.name}"
            if f.name == "calibrate":
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


def _log_uniform(rng, lo, hi):
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def sample_finger(rng: np.random.Generator, spec: PopulationSpec, base=FINGERS["nominal"]):
    """A reader's pulp drawn around ``base``."""
    b = base.stiffness_b_n_per_m * _log_uniform(rng, *spec.finger_b_scale)
    m = base.exponent_m_per_m * float(rng.uniform(*spec.finger_m_scale))
    c0 = float(rng.uniform(*spec.relax_c0))
    rest = base.relax_weight_1 + base.relax_weight_2 + base.relax_weight_3
    k = (1.0 - c0) / rest
    return replace_checked(base, name="drawn", sources=_FINGER_SOURCES, stiffness_b_n_per_m=b, exponent_m_per_m=m, relax_weight_inf=c0,
                           relax_weight_1=base.relax_weight_1 * k, relax_weight_2=base.relax_weight_2 * k,
                           relax_weight_3=1.0 - c0 - base.relax_weight_1 * k - base.relax_weight_2 * k)


def sample_fsr(rng: np.random.Generator, spec: PopulationSpec, base):
    """An FSR unit drawn around ``base``."""
    k = base.resistance_at_1n_ohm * float(math.exp(rng.normal(0.0, spec.fsr_k_sigma_ln)))
    return replace_checked(base, name="drawn", sources=_FSR_SOURCES, resistance_at_1n_ohm=k,
                           exponent=float(rng.uniform(*spec.fsr_exponent)),
                           hysteresis_fraction=float(rng.uniform(*spec.fsr_hysteresis)),
                           creep_per_decade=float(rng.uniform(*spec.fsr_creep_per_decade)))


def sample_motor(rng: np.random.Generator, spec: PopulationSpec, base):
    """A motor drawn around ``base`` (winding resistance and the motor constant)."""
    r = base.resistance_ohm * max(0.5, 1.0 + spec.motor_r_sigma * float(rng.normal()))
    kscale = max(0.5, 1.0 + spec.motor_k_sigma * float(rng.normal()))
    return replace_checked(base, name=base.name, resistance_ohm=r,
                           torque_constant_nm_per_a=base.torque_constant_nm_per_a * kscale,
                           back_emf_v_s_per_rad=base.back_emf_v_s_per_rad * kscale)


def sample_drivetrain(rng: np.random.Generator, spec: PopulationSpec, base):
    """A drive train drawn around ``base`` (gear efficiency, guide friction, backlash)."""
    return replace_checked(base, name=base.name, gear_efficiency=float(rng.uniform(*spec.gear_efficiency)),
                           guide_coulomb_n=_log_uniform(rng, *spec.guide_coulomb_n),
                           backlash_m=float(rng.uniform(*spec.backlash_m)))


def sample_device(rng_or_seed, spec: PopulationSpec = PopulationSpec(), base: DeviceParams = DeviceParams()
                  ) -> DeviceParams:
    """One device (reader + FSR unit + motor + drive train) drawn from ``spec``.

    ``rng_or_seed`` is an int, a ``SeedSequence`` (NumPy's or a
    :class:`~ebraille_sim.base.seeds.SeedNode`) or a ``Generator``; components draw from
    child seeds so that each component's draw is independent of the others' distributions.
    """
    if isinstance(rng_or_seed, np.random.Generator):
        ss = SeedNode(int(rng_or_seed.integers(0, 2**63)))
    elif isinstance(rng_or_seed, ISpawnableSeedSequence):
        ss = rng_or_seed
    else:
        ss = SeedNode(int(rng_or_seed))
    r_f, r_s, r_m, r_d = (np.random.default_rng(c) for c in ss.spawn(4))
    dev = replace_fields(base, finger=sample_finger(r_f, spec, base.finger),
                              fsr=sample_fsr(r_s, spec, base.fsr), motor=sample_motor(r_m, spec, base.motor),
                              drivetrain=sample_drivetrain(r_d, spec, base.drivetrain))
    return calibrate_device(dev) if spec.calibrate else dev


def sample_devices(seed: int, n: int, spec: PopulationSpec = PopulationSpec(),
                   base: DeviceParams = DeviceParams()) -> list[DeviceParams]:
    """``n`` devices from one master seed (child ``k`` of ``SeedSequence(seed)`` for device k)."""
    check_number("n", n, lo=0, integer=True)
    return [sample_device(c, spec, base) for c in SeedNode(seed).spawn(n)]
