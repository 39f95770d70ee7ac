"""Flat state and parameter vectors shared by the compiled loop kernel.

The loop kernel (:mod:`ebraille_sim.plant.lumped`) works on one float64 state vector ``S`` and
one float64 parameter vector ``P`` per device, so that a single device and a batch of
``n`` devices (arrays of shape ``(n, N_STATE)`` and ``(n, N_PARAM)``) run the same
compiled code.  This module names every slot once; nothing else hard-codes an index.

Inputs that may change every control period (the motor command, the finger position,
gravity along the travel, the FSR temperature offset, the driver supply and an injected
sensor fault) travel in a third vector ``U`` of length ``N_INPUT``.

State slots are declared by the module whose law advances them (``STATE_SLOTS`` and
friends in :mod:`~ebraille_sim.physics.motor`, :mod:`~ebraille_sim.physics.drivetrain`,
:mod:`~ebraille_sim.physics.fingertip`, :mod:`~ebraille_sim.physics.fsr`,
:mod:`~ebraille_sim.physics.noise`, :mod:`~ebraille_sim.estimation.firmware` and
:mod:`~ebraille_sim.estimation.blockmodels`);
the loop itself owns only its clock and sample phases (:data:`LOOP_STATE_SLOTS`).
:data:`STATE_BLOCKS` puts those declarations in their order in the state vector.

The FSR fault codes ``FAULT_*`` for the ``fsr_fault`` input are those of
:mod:`ebraille_sim.physics.fsr`: open circuit (divider reads 0 V), short (reads the supply),
stuck (the ADC repeats its last code), forced value (reads ``fsr_fault_value`` volts).
``motor_jammed`` > 0 locks the pinion (a stalled gearmotor).
"""
from __future__ import annotations

import collections

from ebraille_sim.estimation import blockmodels as _est
from ebraille_sim.estimation import firmware as _fw
from ebraille_sim.estimation.blockmodels import MAX_BREAKPOINTS, MAX_TF_LEN
from ebraille_sim.physics import current_sense as _isense
from ebraille_sim.physics import drivetrain as _drivetrain
from ebraille_sim.physics import fingertip as _fingertip
from ebraille_sim.physics import fsr as _fsr
from ebraille_sim.physics import motor as _motor
from ebraille_sim.physics import noise as _noise
from ebraille_sim.physics.fsr import N_CREEP, N_PLAYS


class _Slots(tuple):
    """Read-only record of slot indices: ``S.current_a``, ``S["current_a"]``, ``"x" in S``.

    Built by :func:`slots`; compiled kernels read the attributes as constants.
    """
    __slots__ = ()

    def __getitem__(self, key):
        if isinstance(key, str):
            try:
                return getattr(self, key)
            except AttributeError:
                raise KeyError(f"unknown slot {key!r}") from None
        return tuple.__getitem__(self, key)

    def __contains__(self, key):
        return key in self._fields

    def keys(self):
        return self._fields

    def items(self):
        return zip(self._fields, tuple.__iter__(self))

    def values(self):
        return tuple(tuple.__iter__(self))


def slots(kind: str, names) -> _Slots:
    """A record type named ``kind`` with one field per name, instantiated with the indices."""
    names = list(names)
    if len(set(names)) != len(names):
        raise ValueError(f"{kind}: duplicate slot names")
    base = collections.namedtuple(kind, names)
    cls = type(kind, (_Slots, base), {"__slots__": ()})
    cls.__getitem__ = _Slots.__getitem__
    cls.__contains__ = _Slots.__contains__
    return cls(*range(len(names)))


LOOP_STATE_SLOTS = ("sensor_phase", "estimator_phase", "time_s")
"""State slots of the loop itself: physics steps since the last sensor sample, sensor
samples since the last estimate, and the simulated time."""

STATE_BLOCKS = (
    _motor.STATE_SLOTS, _drivetrain.STATE_SLOTS, _fingertip.STATE_SLOTS, _fsr.STATE_SLOTS,
    _fw.ANTIALIAS_SLOTS, LOOP_STATE_SLOTS[:2], _noise.STATE_SLOTS, _est.OUTPUT_SLOTS,
    _motor.ENERGY_SLOTS, LOOP_STATE_SLOTS[2:], _fw.TARE_SLOTS, _fsr.HYSTERESIS_SLOTS, _fsr.CREEP_SLOTS, _est.FILTER_SLOTS,
    _fw.CREEP_COMP_SLOTS, _fw.HYSTERESIS_COMP_SLOTS, _isense.STATE_SLOTS,
)
"""The modules' slot declarations in state-vector order."""

STATE_OWNERS = {"motor": _motor.OWNED_STATE_SLOTS, "drivetrain": _drivetrain.OWNED_STATE_SLOTS,
                "fingertip": _fingertip.OWNED_STATE_SLOTS, "fsr": _fsr.OWNED_STATE_SLOTS,
                "noise": _noise.OWNED_STATE_SLOTS, "firmware": _fw.OWNED_STATE_SLOTS,
                "estimator": _est.OWNED_STATE_SLOTS, "current_sense": _isense.OWNED_STATE_SLOTS,
                "loop": LOOP_STATE_SLOTS}
"""Every state slot by the module that declares it."""

STATE_NAMES = [name for block in STATE_BLOCKS for name in block]
S = slots("StateSlots", STATE_NAMES)
N_STATE = len(STATE_NAMES)

PARAM_NAMES = [
    # time steps
    "h_s", "substeps_per_sensor", "sensors_per_estimate",
    # motor (at the motor shaft) and the drive ratio
    "motor_r_ohm", "motor_current_decay", "motor_kt", "motor_ke", "n_over_r_per_m",
    # pinion side, expressed at the rack line
    "pinion_mass_kg", "pinion_coulomb_n", "pinion_static_n", "pinion_viscous_n_s_per_m", "gear_mu",
    # mesh and board
    "half_backlash_m", "mesh_k_n_per_m", "mesh_c_n_s_per_m", "board_mass_kg",
    "guide_coulomb_n", "guide_static_n", "guide_viscous_n_s_per_m", "stribeck_v_m_per_s",
    "travel_min_m", "travel_max_m",
    # finger (QLV)
    "finger_b_n_per_m", "finger_m_per_m", "relax_c0", "relax_c1", "relax_c2", "relax_c3",
    "relax_a1", "relax_a2", "relax_a3", "relax_beta1", "relax_beta2", "relax_beta3",
    # FSR and circuit
    "fsr_lag_alpha", "fsr_k_ohm", "fsr_n", "fsr_g_standoff_s", "fsr_creep_weight",
    "fsr_load_threshold_n", "fsr_tempco_per_k", "fsr_tempco_cold_per_k", "fsr_noise_v", "fsr_actuation_n",
    "fsr_turn_on_m", "fsr_press_sigma",
    "r2_ohm", "divider_supply_v", "adc_lsb_v", "adc_max_code",
    "aa_b0", "aa_b1", "aa_b2", "aa_a1", "aa_a2",
    "est_len", "est_n_in", "est_n_out", "est_clamp", "est_nyquist_average",
    # the estimator's creep compensation (the device's nominal FSR)
    "est_creep_comp", "comp_creep_weight", "comp_fsr_n", "comp_g_standoff_s", "comp_load_threshold_n",
    "comp_reference_gain",
    # the estimator's hysteresis compensation (the device's nominal FSR)
    "est_hyst_comp", "comp_fsr_k_ohm", "comp_hyst_halfwidth", "comp_hyst_deadband_v",
    "comp_hyst_follow_v", "comp_hyst_turn_v", "comp_turn_alpha", "comp_centre_alpha",
    # the motor-current sensing chain: the unit's transfer, the filter, the ADC, the firmware's constants
    "isense_shunt_ohm", "isense_gain", "isense_offset_v", "isense_ref_v", "isense_decay", "isense_decay2",
    "isense_lsb_v", "isense_max_code", "isense_noise_v", "isense_zero_code", "isense_nominal_v_per_a",
    "seed",
] + [f"creep_a{j}" for j in range(N_CREEP)] + [f"comp_creep_a{j}" for j in range(N_CREEP)] \
  + [f"play_w{j}" for j in range(N_PLAYS)] + [f"play_weight{j}" for j in range(N_PLAYS)] \
  + [f"comp_play_w{j}" for j in range(N_PLAYS)] + [f"comp_play_weight{j}" for j in range(N_PLAYS)] \
  + [f"est_num{j}" for j in range(MAX_TF_LEN)] + [f"est_den{j}" for j in range(MAX_TF_LEN)] \
  + [f"est_in_x{j}" for j in range(MAX_BREAKPOINTS)] + [f"est_in_y{j}" for j in range(MAX_BREAKPOINTS)] \
  + [f"est_out_x{j}" for j in range(MAX_BREAKPOINTS)] + [f"est_out_y{j}" for j in range(MAX_BREAKPOINTS)] \
  + ["est_cal_n"] + [f"est_cal_x{j}" for j in range(_fw.CALIBRATION_TABLE_POINTS)] \
  + [f"est_cal_y{j}" for j in range(_fw.CALIBRATION_TABLE_POINTS)]
P = slots("ParamSlots", PARAM_NAMES)
N_PARAM = len(PARAM_NAMES)

INPUT_NAMES = ["command_v", "finger_pos_m", "gravity_along_m_per_s2", "fsr_temp_offset_k",
               "driver_supply_v", "fsr_fault", "fsr_fault_value", "motor_jammed",
               "press_offset_m", "finger_tilt_rad", "gravity_lateral_m_per_s2", "est_creep_preload"]
U = slots("InputSlots", INPUT_NAMES)
N_INPUT = len(INPUT_NAMES)
