"""Flat state and parameter vectors shared by the compiled loop kernel.

The loop kernel (:mod:`ebraille_sim.plant.loop`) works on one float64 state vector ``S`` and
one float64 parameter vector ``P`` per device, so that a single device and a batch of
``n`` devices (arrays of shape ``(n, N_STATE)`` and ``(n, N_PARAM)``) run the same
compiled code.  This module names every slot once; nothing else hard-codes an index.

Inputs that may change every control period (the motor command, the finger position,
gravity along the travel, the FSR temperature offset, the driver supply and an injected
sensor fault) travel in a third vector ``U`` of length ``N_INPUT``.
"""
from __future__ import annotations

import collections

from ebraille_sim.physics.fsr import N_PLAYS

MAX_TF_LEN = 10          # numerator/denominator length of the estimator's linear block
MAX_BREAKPOINTS = 12     # breakpoints of each estimator nonlinearity


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


STATE_NAMES = [
    "current_a", "pinion_pos_m", "pinion_vel_m_per_s", "board_pos_m", "board_vel_m_per_s",
    "prony_1_n", "prony_2_n", "prony_3_n", "elastic_force_n", "contact_force_n",
    "fsr_force_lagged_n", "fsr_load_time_s", "fsr_voltage_v", "fsr_code",
    "aa_z1", "aa_z2", "sensor_phase", "estimator_phase", "sensor_count",
    "force_est_n", "est_raw_prev_n", "energy_j", "time_s", "tare_v",
] + [f"play_{j}" for j in range(N_PLAYS)] + [f"est_z{j}" for j in range(MAX_TF_LEN - 1)]
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
    "fsr_lag_alpha", "fsr_k_ohm", "fsr_n", "fsr_g_standoff_s", "fsr_creep_per_decade", "fsr_creep_t0_s",
    "fsr_recovery_decay", "fsr_load_threshold_n", "fsr_tempco_per_k", "fsr_noise_v", "fsr_dt_s",
    "r2_ohm", "divider_supply_v", "adc_lsb_v", "adc_max_code",
    "aa_b0", "aa_b1", "aa_b2", "aa_a1", "aa_a2",
    "est_len", "est_n_in", "est_n_out", "est_clamp", "est_nyquist_average",
    "seed",
] + [f"play_w{j}" for j in range(N_PLAYS)] + [f"play_weight{j}" for j in range(N_PLAYS)] \
  + [f"est_num{j}" for j in range(MAX_TF_LEN)] + [f"est_den{j}" for j in range(MAX_TF_LEN)] \
  + [f"est_in_x{j}" for j in range(MAX_BREAKPOINTS)] + [f"est_in_y{j}" for j in range(MAX_BREAKPOINTS)] \
  + [f"est_out_x{j}" for j in range(MAX_BREAKPOINTS)] + [f"est_out_y{j}" for j in range(MAX_BREAKPOINTS)]
P = slots("ParamSlots", PARAM_NAMES)
N_PARAM = len(PARAM_NAMES)

INPUT_NAMES = ["command_v", "finger_pos_m", "gravity_along_m_per_s2", "fsr_temp_offset_k",
               "driver_supply_v", "fsr_fault", "fsr_fault_value", "motor_jammed",
               "press_offset_m", "finger_tilt_rad", "gravity_lateral_m_per_s2"]
U = slots("InputSlots", INPUT_NAMES)
N_INPUT = len(INPUT_NAMES)

FAULT_NONE, FAULT_OPEN, FAULT_SHORT, FAULT_STUCK, FAULT_VALUE = 0, 1, 2, 3, 4
"""FSR fault codes for the ``fsr_fault`` input: open circuit (divider reads 0 V), short
(reads the supply), stuck (the ADC repeats its last code), forced value (reads
``fsr_fault_value`` volts).  ``motor_jammed`` > 0 locks the pinion (a stalled gearmotor)."""
