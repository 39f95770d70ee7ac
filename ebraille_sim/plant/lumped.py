"""The lumped plant: the packed state, parameters and inputs of ``n`` devices.

:class:`Plant` holds the packed rows of ``n`` devices (``n = 1`` for a scenario), packs a
device's parameters for the compiled kernel (:mod:`ebraille_sim.plant.kernel`) and exposes the
microcontroller's view.  The closed loop around it is the loop engine's
(:mod:`ebraille_sim.plant.engine`); :meth:`Plant.advance` advances the devices by one control
period with a given command (the plant alone, open loop).

Array-shape convention: per-device quantities are arrays of shape ``(n,)``; the packed
state is ``(n, N_STATE)``, the parameters ``(n, N_PARAM)``, the inputs ``(n, N_INPUT)``.

Examples
--------
>>> from ebraille_sim.physics.params import FSRS, DeviceParams
>>> plant = Plant.from_devices([DeviceParams()], seeds=[1])
>>> plant.set_finger(1.0e-3)
>>> for _ in range(200):
...     plant.advance(3.0)             # 3 V up for 0.2 s
>>> bool(plant.contact_force_n[0] > 0.0)
True
"""
from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass

import numpy as np

from ebraille_sim.estimation.blockmodels import pwl_eval
from ebraille_sim.estimation.firmware import (CALIBRATION_TABLE_POINTS, FIRMWARE_FSR, HYSTERESIS_MEDIAN, firmware_fsr,
                                              table_calibrated_n)
from ebraille_sim.estimation.calibration import measured_hysteresis_fraction
from ebraille_sim.estimation.registry import plant_model
from ebraille_sim.physics.drivetrain import (mesh_damping_n_s_per_m, reflected_force_n, reflected_inertia_kg,
                                             shaft_to_rack_per_m)
from ebraille_sim.physics.fingertip import prony_coefficients, tangent_stiffness_n_per_m
from ebraille_sim.physics.fsr import (N_CREEP, adc_code, adc_voltage, creep_decay, creep_gain, creep_taus_s,
                                      creep_term_weight, lag_alpha, log_force, play_loop_fraction, play_loop_widths,
                                      play_widths, static_voltage)
from ebraille_sim.physics.motor import current_decay
from ebraille_sim.base.validation import replace_fields
from ebraille_sim.physics.params import DeviceParams
from ebraille_sim.plant import kernel
from ebraille_sim.plant.layout import (MAX_BREAKPOINTS, MAX_TF_LEN, N_INPUT, N_PARAM, N_PLAYS, N_STATE, P, S, U)

__all__ = ["Plant", "pack_params", "pack_devices", "initial_state", "reseed", "check_step", "check_sensor_rates"]


def check_step(device: DeviceParams, max_force_n: float = 10.0) -> float:
    """Largest ``w h`` of the explicit mechanics; raise if the physics rate is too low.

    The stiffest oscillation is the board (``moving_mass_kg``) between the mesh and the
    pulp loaded to ``max_force_n``; the semi-implicit step is stable for ``w h < 2`` and
    accurate for ``w h < 1``.
    """
    dt = device.drivetrain
    k_pulp = tangent_stiffness_n_per_m(float(max_force_n), device.finger.stiffness_b_n_per_m,
                                       device.finger.exponent_m_per_m)
    w = math.sqrt((dt.mesh_stiffness_n_per_m + k_pulp) / dt.moving_mass_kg)
    wh = w / device.rates.physics_rate_hz
    if wh > 1.0:
        need = w
        raise ValueError(f"physics_rate_hz {device.rates.physics_rate_hz:g} is too low for the stiff "
                         f"mesh/pulp contact (w = {w:.0f} rad/s); use at least {need:.0f} Hz")
    return wh


def check_sensor_rates(device: DeviceParams, model) -> int:
    """Sensor samples per force estimate; raise if the sensor rate does not suit the estimator.

    The estimator runs at its model's own rate ``1/model.dt_s`` (the rate it was identified
    at) and decimates the anti-aliased sensor samples by a whole factor, so the sensor rate
    must be a whole multiple of it; the anti-alias cutoff must lie below the sensor's
    Nyquist frequency.

    Raises
    ------
    ValueError
        One line naming the rates and the reason.
    """
    r, e = device.rates, device.estimator
    est_rate = 1.0 / model.dt_s
    ratio = r.sensor_rate_hz / est_rate
    if abs(ratio - round(ratio)) > 1e-6 or round(ratio) < 1:
        raise ValueError(f"sensor_rate_hz ({r.sensor_rate_hz:g}) must be a whole multiple of the "
                         f"estimator model's rate ({est_rate:g} Hz): the estimator takes every "
                         f"n-th sensor sample, n a whole number (sensor/estimator = {ratio:.6g})")
    nyq = 0.5 * r.sensor_rate_hz
    if not 0 < e.antialias_cutoff_hz < nyq:
        raise ValueError(f"antialias_cutoff_hz {e.antialias_cutoff_hz:g} must lie in (0, {nyq:g}) Hz, "
                         f"below the Nyquist frequency of the {r.sensor_rate_hz:g} Hz sensor rate")
    return int(round(ratio))


def pack_params(device: DeviceParams, seed: float, model=None) -> np.ndarray:
    """Flat parameter vector ``(N_PARAM,)`` of one device for the kernel.

    The estimator runs at its model's own rate, ``1/model.dt_s`` (the rate it was
    identified at); the sensor rate must be a whole multiple of it.
    """
    p = _unseeded_params(device, model)
    reseed(p, device, seed)
    return p


def _unseeded_params(device: DeviceParams, model=None) -> np.ndarray:
    """:func:`pack_params` but the seed and what was measured with the device's noise (:func:`reseed`)."""
    m, d, f, s, c, e, r = (device.motor, device.drivetrain, device.finger, device.fsr, device.circuit,
                           device.estimator, device.rates)
    check_step(device)
    if model is None:
        model = plant_model(e.model)
    ratio = check_sensor_rates(device, model)
    p = np.zeros(N_PARAM)
    h = 1.0 / r.physics_rate_hz
    g = shaft_to_rack_per_m(d.gear_ratio, d.pinion_radius_m)
    dt_sensor = 1.0 / r.sensor_rate_hz
    bb, aa = _antialias_filter(float(e.antialias_cutoff_hz), float(r.sensor_rate_hz))
    p[_DEVICE_SLOTS] = (
        h, r.substeps_per_sensor, ratio,
        m.resistance_ohm, current_decay(h, m.resistance_ohm, m.inductance_h), m.torque_constant_nm_per_a,
        m.back_emf_v_s_per_rad, g, reflected_inertia_kg(m.rotor_inertia_kg_m2, g),
        reflected_force_n(m.friction_torque_nm, g), reflected_force_n(m.friction_torque_nm, g) * m.breakaway_ratio,
        reflected_inertia_kg(m.viscous_friction_nm_s_per_rad, g),
        d.gear_loss_coefficient, 0.5 * d.backlash_m, d.mesh_stiffness_n_per_m,
        mesh_damping_n_s_per_m(d.mesh_damping_ratio, d.mesh_stiffness_n_per_m, d.moving_mass_kg),
        d.moving_mass_kg, d.guide_coulomb_n, d.guide_coulomb_n * d.guide_breakaway_ratio, d.guide_viscous_n_s_per_m,
        d.stribeck_velocity_m_per_s, d.travel_min_m, d.travel_max_m,
        f.stiffness_b_n_per_m, f.exponent_m_per_m, f.relax_weight_inf, f.relax_weight_1, f.relax_weight_2,
        f.relax_weight_3,
        lag_alpha(h, s.mechanical_lag_s), s.resistance_at_1n_ohm, s.exponent, 1.0 / s.standoff_resistance_ohm,
        creep_term_weight(s.creep_per_decade, s.creep_tau_min_s, s.creep_tau_max_s), s.load_threshold_n,
        s.temperature_coeff_per_k, s.temperature_coeff_cold_per_k, s.actuation_force_n, s.turn_on_steepness,
        s.press_repeatability, s.noise_v_rms,
        c.r2_ohm, c.supply_v, c.adc_lsb_v, c.adc_max_code,
        bb[0], bb[1], bb[2], aa[1], aa[2])
    p[_RELAX_SLOTS] = _prony_row(h, f.relax_tau_1_s, f.relax_tau_2_s, f.relax_tau_3_s)
    p[_CREEP_SLOTS] = _creep_decays(dt_sensor, s.creep_tau_min_s, s.creep_tau_max_s)
    widths, weights = play_widths(s)
    p[_PLAY_W_SLOTS] = widths
    p[_PLAY_WEIGHT_SLOTS] = weights
    _pack_model(p, model)
    p[P.est_clamp] = 1.0 if e.clamp_nonnegative else 0.0
    p[P.est_nyquist_average] = 1.0 if e.nyquist_average else 0.0
    _pack_calibration_table(p, e)
    _pack_creep_compensation(p, e, dt_sensor)
    _pack_hysteresis_compensation(p, e, c, s, float(r.sensor_rate_hz))
    _pack_current_sense(p, device.current_sense, h)
    return p


def reseed(p: np.ndarray, device: DeviceParams, seed: float) -> None:
    """Give a packed parameter row the sensor seed ``seed``: the seed of the device's noise and
    what was measured with that noise (the current chain's zero, :func:`ebraille_sim.physics.current_sense.zero_code`)."""
    from ebraille_sim.physics.current_sense import zero_code
    cs = device.current_sense
    p[P.seed] = float(seed)
    p[P.isense_zero_code] = zero_code(cs, float(seed), cs.adc_lsb_v, cs.adc_max_code)


def _pack_current_sense(p: np.ndarray, cs, h_s: float) -> None:
    """The motor-current chain (:mod:`ebraille_sim.physics.current_sense`): the unit's true
    transfer (shunt and gain with their errors, input offset), the RC sections' decay per physics
    step, the ADC, and what the firmware knows: the nominal transfer (its zero, measured with
    the device's noise, is written by :func:`reseed`)."""
    p[P.isense_shunt_ohm] = cs.shunt_ohm * (1.0 + cs.shunt_error)
    p[P.isense_gain] = cs.gain_v_per_v * (1.0 + cs.gain_error)
    p[P.isense_offset_v] = cs.offset_v
    p[P.isense_ref_v] = cs.reference_v
    p[P.isense_decay] = math.exp(-h_s / cs.filter_tau_s)
    p[P.isense_decay2] = p[P.isense_decay] if cs.filter_stages == 2 else 0.0    # 0: the second passes the first
    p[P.isense_lsb_v] = cs.adc_lsb_v
    p[P.isense_max_code] = cs.adc_max_code
    p[P.isense_noise_v] = cs.adc_noise_lsb * cs.adc_lsb_v
    p[P.isense_nominal_v_per_a] = cs.nominal_v_per_a


def _slots(*names) -> np.ndarray:
    """The parameter slots of ``names`` (read-only; each slot once)."""
    slots = np.array([P[name] for name in names], dtype=np.intp)
    if np.unique(slots).size != slots.size:
        raise ImportError(f"parameter slots written twice: {names}")
    slots.flags.writeable = False
    return slots


_DEVICE_SLOTS = _slots(
    "h_s", "substeps_per_sensor", "sensors_per_estimate",
    "motor_r_ohm", "motor_current_decay", "motor_kt", "motor_ke", "n_over_r_per_m", "pinion_mass_kg",
    "pinion_coulomb_n", "pinion_static_n", "pinion_viscous_n_s_per_m",
    "gear_mu", "half_backlash_m", "mesh_k_n_per_m", "mesh_c_n_s_per_m",
    "board_mass_kg", "guide_coulomb_n", "guide_static_n", "guide_viscous_n_s_per_m",
    "stribeck_v_m_per_s", "travel_min_m", "travel_max_m",
    "finger_b_n_per_m", "finger_m_per_m", "relax_c0", "relax_c1", "relax_c2", "relax_c3",
    "fsr_lag_alpha", "fsr_k_ohm", "fsr_n", "fsr_g_standoff_s", "fsr_creep_weight", "fsr_load_threshold_n",
    "fsr_tempco_per_k", "fsr_tempco_cold_per_k", "fsr_actuation_n", "fsr_turn_on_m", "fsr_press_sigma", "fsr_noise_v",
    "r2_ohm", "divider_supply_v", "adc_lsb_v", "adc_max_code",
    "aa_b0", "aa_b1", "aa_b2", "aa_a1", "aa_a2")
"""The parameter slots :func:`pack_params` fills with one number each of the device's parts (in its order)."""
_PLAY_STATE_SLOTS = np.array([S[f"play_{j}"] for j in range(N_PLAYS)], dtype=np.intp)
_COMP_PLAY_STATE_SLOTS = np.array([S[f"comp_play_{j}"] for j in range(N_PLAYS)], dtype=np.intp)
_COMP_MEDIAN_SLOTS = np.array([S[f"comp_med_{j}"] for j in range(HYSTERESIS_MEDIAN - 1)], dtype=np.intp)
_RELAX_SLOTS = np.array([P[f"relax_{k}{j}"] for k in ("a", "beta") for j in (1, 2, 3)])
_CREEP_SLOTS = np.array([P[f"creep_a{j}"] for j in range(N_CREEP)])
_PLAY_W_SLOTS = np.array([P[f"play_w{j}"] for j in range(N_PLAYS)])
_PLAY_WEIGHT_SLOTS = np.array([P[f"play_weight{j}"] for j in range(N_PLAYS)])


@functools.lru_cache(maxsize=64)
def _prony_row(h_s: float, tau_1_s: float, tau_2_s: float, tau_3_s: float) -> np.ndarray:
    """:func:`~ebraille_sim.physics.fingertip.prony_coefficients` as the values of ``_RELAX_SLOTS``
    (``a1..a3``, then ``beta1..beta3``; computed once per step and time constants, read-only)."""
    a, beta = prony_coefficients(h_s, (tau_1_s, tau_2_s, tau_3_s))
    row = np.array(list(a) + list(beta), dtype=float)
    row.flags.writeable = False
    return row


@functools.lru_cache(maxsize=64)
def _creep_decays(dt_sensor_s: float, tau_min_s: float, tau_max_s: float) -> np.ndarray:
    """Per-sample decays of the creep terms, the values of ``_CREEP_SLOTS`` (computed once per
    sensor period and time-constant range, read-only)."""
    row = np.array([creep_decay(dt_sensor_s, tau) for tau in creep_taus_s(tau_min_s, tau_max_s)], dtype=float)
    row.flags.writeable = False
    return row


def _pack_calibration_table(p: np.ndarray, e) -> None:
    """The unit's calibration table (:func:`ebraille_sim.estimation.firmware.table_calibrated_n`):
    its size, the readings and the loads (unused slots 0)."""
    n = len(e.calibration_loads_n)
    p[P.est_cal_n] = n
    p[P.est_cal_x0:P.est_cal_x0 + CALIBRATION_TABLE_POINTS] = 0.0
    p[P.est_cal_y0:P.est_cal_y0 + CALIBRATION_TABLE_POINTS] = 0.0
    p[P.est_cal_x0:P.est_cal_x0 + n] = e.calibration_readings_n
    p[P.est_cal_y0:P.est_cal_y0 + n] = e.calibration_loads_n


CREEP_COMPENSATION_SLOTS = _slots("est_creep_comp", "comp_creep_weight", *(f"comp_creep_a{j}" for j in range(N_CREEP)),
                                  "comp_fsr_n", "comp_g_standoff_s", "comp_load_threshold_n", "comp_reference_gain")
"""The parameter slots of the creep compensation, in the order of :func:`creep_compensation_values`."""


def _pack_creep_compensation(p: np.ndarray, e, dt_sensor_s: float) -> None:
    """The estimator's creep compensation: on/off, and the creep law of the nominal FSR
    (:data:`~ebraille_sim.estimation.firmware.FIRMWARE_FSR`, the nominal unit: the firmware does not know the individual sensor's parameters)
    with the creep per decade the bench measured when the estimator carries one
    (:func:`~ebraille_sim.estimation.firmware.firmware_fsr`), at the sensor rate, with the creep gain of the calibration hold as its reference.
    Depends only on the estimator and the sensor period: the values are computed once per pair."""
    p[CREEP_COMPENSATION_SLOTS] = creep_compensation_values(e, float(dt_sensor_s))


@functools.lru_cache(maxsize=64)
def creep_compensation_values(e, dt_sensor_s: float) -> np.ndarray:
    """The values of :data:`CREEP_COMPENSATION_SLOTS` for the estimator ``e`` at the sensor period
    ``dt_sensor_s`` (read-only)."""
    nominal = firmware_fsr(e)
    values = np.array([1.0 if e.creep_compensation else 0.0,
                       creep_term_weight(nominal.creep_per_decade, nominal.creep_tau_min_s, nominal.creep_tau_max_s)]
                      + _creep_decays(dt_sensor_s, nominal.creep_tau_min_s, nominal.creep_tau_max_s).tolist()
                      + [nominal.exponent, 1.0 / nominal.standoff_resistance_ohm, nominal.load_threshold_n,
                         creep_gain(e.creep_reference_hold_s, nominal)], dtype=float)
    values.flags.writeable = False
    return values


HYSTERESIS_COMPENSATION_SLOTS = _slots(
    "est_hyst_comp", *(f"comp_play_w{j}" for j in range(N_PLAYS)), *(f"comp_play_weight{j}" for j in range(N_PLAYS)),
    "comp_hyst_halfwidth", "comp_fsr_k_ohm", "comp_hyst_deadband_v", "comp_hyst_turn_v", "comp_hyst_follow_v",
    "comp_centre_alpha", "comp_turn_alpha")
"""The parameter slots of the hysteresis compensation, in the order of :func:`hysteresis_compensation_values`."""


def _pack_hysteresis_compensation(p: np.ndarray, e, circuit, fsr, sensor_rate_hz: float) -> None:
    """The estimator's hysteresis compensation: on/off; play operators of the nominal FSR's
    exponent (:data:`~ebraille_sim.estimation.firmware.FIRMWARE_FSR`, whose resistance at 1 N is packed too and whose exponent and
    stand-off are packed with the creep compensation) with the rate-independent part of the loop
    the estimator was given (a datasheet or bench loop, creep included: its play part by the nominal creep
    law with the bench's creep per decade when the estimator carries one,
    :func:`~ebraille_sim.physics.fsr.play_loop_fraction`), or, when it was given none, the
    unit's rate-independent loop as measured at assembly
    (:func:`ebraille_sim.estimation.calibration.measured_hysteresis_fraction`); the noise
    deadband, the turn test's threshold and following deadband in volts and its average's weight
    per sensor sample.  Given the loop, the values depend only on the estimator, the ADC's LSB and
    the sensor rate: they are computed once per combination."""
    if e.hysteresis_fraction is not None:
        h = play_loop_fraction(replace_fields(firmware_fsr(e), hysteresis_fraction=e.hysteresis_fraction))
    else:
        h = measured_hysteresis_fraction(fsr) if e.hysteresis_compensation else play_loop_fraction(FIRMWARE_FSR)
    p[HYSTERESIS_COMPENSATION_SLOTS] = hysteresis_compensation_values(e, float(circuit.adc_lsb_v), h, sensor_rate_hz)


@functools.lru_cache(maxsize=256)
def hysteresis_compensation_values(e, adc_lsb_v: float, h, sensor_rate_hz: float) -> np.ndarray:
    """The values of :data:`HYSTERESIS_COMPENSATION_SLOTS` for the estimator ``e``, the ADC's LSB,
    the play part ``h`` of the loop and the sensor rate (read-only)."""
    nominal = firmware_fsr(e)
    widths, weights = play_loop_widths(h, nominal.exponent)
    centre = (-math.expm1(-1.0 / (e.hysteresis_centre_time_s * sensor_rate_hz))
              if e.hysteresis_centre_time_s > 0.0 else 0.0)
    values = np.array([1.0 if e.hysteresis_compensation else 0.0] + list(widths) + list(weights)
                      + [sum(w * x for w, x in zip(weights, widths)), nominal.resistance_at_1n_ohm,
                         e.hysteresis_deadband_lsb * adc_lsb_v, e.hysteresis_turn_lsb * adc_lsb_v,
                         e.hysteresis_follow_lsb * adc_lsb_v, centre,
                         -math.expm1(-1.0 / (e.hysteresis_turn_time_s * sensor_rate_hz))], dtype=float)
    values.flags.writeable = False
    return values


@functools.lru_cache(maxsize=64)
def _antialias_filter(cutoff_hz: float, sensor_rate_hz: float) -> tuple:
    """Second-order Butterworth anti-alias coefficients ``(b, a)`` (designed once per pair).

    The analogue prototype's poles ``-exp(+-j pi/4)`` scaled to the pre-warped cutoff
    ``4 tan(pi Wn / 2)`` (``Wn`` = cutoff / Nyquist), mapped by the bilinear transform with
    two zeros at ``z = -1``, expanded into polynomials: the steps of
    ``scipy.signal.butter(2, cutoff_hz, fs=sensor_rate_hz)`` in its order, so the
    coefficients are SciPy's to the last bit (tested) without importing its signal package.
    """
    wn = np.float64(cutoff_hz) / (sensor_rate_hz / 2)
    warped = 4.0 * np.tan(np.pi * wn / 2.0)
    poles = warped * -np.exp(1j * np.pi * np.array([-1.0, 1.0]) / 4.0)
    gain = warped ** 2 * np.real(1.0 / np.prod(4.0 - poles))
    bb = gain * np.poly(-np.ones(2))
    aa = np.real(np.poly((4.0 + poles) / (4.0 - poles)))
    return tuple(float(x) for x in bb), tuple(float(x) for x in aa)


@functools.lru_cache(maxsize=256)
def _unit_step_state(num: tuple, den: tuple) -> np.ndarray:
    """The direct-form-II-transposed filter state of a unit step's steady state (read-only;
    the computation of ``scipy.signal.lfilter_zi``: ``zi = A zi + B`` solved with
    ``numpy.linalg.solve``, ``A`` the companion matrix of ``den``)."""
    b, a = np.asarray(num, dtype=float), np.asarray(den, dtype=float)
    while len(a) > 1 and a[0] == 0.0:
        a = a[1:]
    if a[0] != 1.0:
        b, a = b / a[0], a / a[0]
    n = max(len(a), len(b))
    a = np.concatenate((a, np.zeros(n - len(a))))
    b = np.concatenate((b, np.zeros(n - len(b))))
    companion = np.zeros((n - 1, n - 1))
    companion[0] = -a[1:] / a[0]
    companion[np.arange(1, n - 1), np.arange(n - 2)] = 1.0
    zi = np.linalg.solve(np.eye(n - 1) - companion.T, b[1:] - a[1:] * b[0])
    zi.setflags(write=False)
    return zi


_MODEL_ROWS: dict = {}
_MODEL_SLOTS = [P[name] for name in P.keys() if name in ("est_len", "est_n_in", "est_n_out")
                or name.startswith(("est_num", "est_den", "est_in_", "est_out_"))]


def _pack_model(p: np.ndarray, model) -> None:
    """Write the estimator model's slots of ``p`` (packed once per model object)."""
    hit = _MODEL_ROWS.get(id(model))
    if hit is None or hit[0] is not model:
        row = np.zeros(N_PARAM)
        _pack_model_rows(row, model)
        mask = np.zeros(N_PARAM, dtype=bool)
        mask[_MODEL_SLOTS] = True
        hit = (model, row[mask], mask)
        if len(_MODEL_ROWS) > 64:
            _MODEL_ROWS.clear()
        _MODEL_ROWS[id(model)] = hit
    p[hit[2]] = hit[1]


def _pack_model_rows(p: np.ndarray, model) -> None:
    arr = model.kernel_arrays()
    num, den = np.asarray(arr["num"], float), np.asarray(arr["den"], float)
    n = max(len(num), len(den))
    if n > MAX_TF_LEN:
        raise ValueError(f"estimator linear block has {n} coefficients; at most {MAX_TF_LEN} are supported")
    num = np.pad(num, (0, n - len(num)))
    den = np.pad(den, (0, n - len(den)))
    if den[0] != 1.0:
        num, den = num / den[0], den / den[0]
    p[P.est_len] = n
    p[P.est_num0:P.est_num0 + n] = num
    p[P.est_den0:P.est_den0 + n] = den
    for side in ("in", "out"):
        xs, ys = np.asarray(arr[f"{side}_x"], float), np.asarray(arr[f"{side}_y"], float)
        if len(xs) > MAX_BREAKPOINTS or len(xs) < 2:
            raise ValueError(f"estimator {side}put nonlinearity needs 2..{MAX_BREAKPOINTS} breakpoints, got {len(xs)}")
        p[P[f"est_n_{side}"]] = len(xs)
        p[P[f"est_{side}_x0"]:P[f"est_{side}_x0"] + len(xs)] = xs
        p[P[f"est_{side}_y0"]:P[f"est_{side}_y0"] + len(ys)] = ys


def initial_state(device: DeviceParams, p: np.ndarray, board_pos_m: float | None = None) -> np.ndarray:
    """State ``(N_STATE,)`` at rest: board at ``board_pos_m`` (default fully retracted),
    pinion centred in the backlash, no contact, estimator at its steady state for the
    tared no-load voltage."""
    s = np.zeros(N_STATE)
    xb = device.drivetrain.travel_min_m if board_pos_m is None else float(board_pos_m)
    s[S.board_pos_m] = xb
    s[S.pinion_pos_m] = xb
    lf = log_force(0.0)
    s[_PLAY_STATE_SLOTS] = lf
    v0 = static_voltage(0.0, device.fsr, device.circuit)
    lsb = device.circuit.adc_lsb_v
    code0 = adc_code(v0, lsb, float(device.circuit.adc_max_code))
    v_read = adc_voltage(code0, lsb)
    s[S.fsr_code] = code0
    s[S.fsr_voltage_v] = v_read
    s[S.tare_v] = v_read if device.estimator.tare_at_start else 0.0
    s[S.comp_hyst_v] = v_read
    s[S.comp_turn_avg_v] = v_read
    s[S.comp_turn_ext_v] = v_read
    s[S.comp_turn_at_v] = v_read
    s[_COMP_MEDIAN_SLOTS] = v_read
    s[S.comp_hyst_x] = lf
    s[S.comp_centre_x] = lf
    s[_COMP_PLAY_STATE_SLOTS] = lf
    _estimator_steady_state(s, p, v_read - s[S.tare_v])
    s[S.force_est_n] = table_calibrated_n(s[S.force_est_n], p, P.est_cal_x0, P.est_cal_y0, int(p[P.est_cal_n]))
    v_rest = p[P.isense_ref_v] + p[P.isense_gain] * p[P.isense_offset_v]       # no current: the filters settled
    s[S.isense_filter1_v] = v_rest
    s[S.isense_filter2_v] = v_rest
    s[S.current_meas_a] = 0.0
    return s


_STEADY_HEAD = slice(P.aa_b0, P.est_clamp + 1)
_STEADY_MODEL = slice(P.est_num0, max(P.est_out_y0, P.est_in_y0, P.est_den0) + MAX_BREAKPOINTS)
"""The parameter slots :func:`_estimator_steady_state` reads: the anti-alias filter, the model's
sizes and clamp flag; the model's coefficients and breakpoints."""


def _estimator_steady_state(s: np.ndarray, p: np.ndarray, u0: float) -> None:
    """Fill the anti-alias and estimator states for a constant input ``u0``.

    The states depend only on the slots of ``p`` it reads and on ``u0``, which for a tared
    start is 0 in every episode: they are computed once per combination
    (:func:`_steady_state_slots`) and written as slots."""
    slots, values = _steady_state_slots(p[_STEADY_HEAD].tobytes(), p[_STEADY_MODEL].tobytes(), float(u0).hex())
    s[slots] = values


@functools.lru_cache(maxsize=256)
def _steady_state_slots(head: bytes, model: bytes, u0_hex: str) -> tuple[np.ndarray, np.ndarray]:
    """``(slots, values)`` of the states :func:`_fill_estimator_steady_state` writes for the
    parameter slots ``head`` and ``model`` (their bytes) and the input ``u0`` (its hex form, so
    that -0.0 and 0.0 are told apart); both read-only."""
    p = np.zeros(N_PARAM)
    p[_STEADY_HEAD] = np.frombuffer(head)
    p[_STEADY_MODEL] = np.frombuffer(model)
    s = np.zeros(N_STATE)
    _fill_estimator_steady_state(s, p, float.fromhex(u0_hex))
    n = int(p[P.est_len])
    slots = np.array([S.aa_z1, S.aa_z2] + list(range(S.est_z0, S.est_z0 + max(n - 1, 0)))
                     + [S.est_raw_prev_n, S.force_est_n], dtype=np.intp)
    values = s[slots]
    slots.flags.writeable = values.flags.writeable = False
    return slots, values


def _fill_estimator_steady_state(s: np.ndarray, p: np.ndarray, u0: float) -> None:
    bb = (float(p[P.aa_b0]), float(p[P.aa_b1]), float(p[P.aa_b2]))
    aa = (1.0, float(p[P.aa_a1]), float(p[P.aa_a2]))
    zi = _unit_step_state(bb, aa) * u0
    s[S.aa_z1], s[S.aa_z2] = zi
    n = int(p[P.est_len])
    num = p[P.est_num0:P.est_num0 + n]
    den = p[P.est_den0:P.est_den0 + n]
    x0 = pwl_eval(u0, p, P.est_in_x0, P.est_in_y0, int(p[P.est_n_in]))
    if n >= 2:
        zi = _unit_step_state(tuple(num.tolist()), tuple(den.tolist())) * x0
        s[S.est_z0:S.est_z0 + n - 1] = zi
    y0 = num.sum() / den.sum() * x0 if abs(den.sum()) > 1e-12 else 0.0
    f0 = pwl_eval(y0, p, P.est_out_x0, P.est_out_y0, int(p[P.est_n_out]))
    s[S.est_raw_prev_n] = f0
    s[S.force_est_n] = max(f0, 0.0) if p[P.est_clamp] > 0 else f0


_LAST_ROWS: list = []
"""The parts (objects), estimator model and board position of the device packed last, its
parameter row (its seed slots 0; :func:`reseed` gives it each device's seed) and its initial state
(:func:`_device_rows`)."""


def _device_rows(device: DeviceParams, seed: float, model, board_pos_m) -> tuple[np.ndarray, np.ndarray]:
    """:func:`pack_params` and :func:`initial_state` of ``device``, copied from the last device
    packed when ``device`` shares every part with it (the same objects of its motor, drive
    train, finger, FSR, circuit, estimator and rates, the same model object and board
    position): the nominal device of every episode, with its supply sagged or not (neither row
    reads the supply or the gravity), packs once.  Only the seed and what was measured with the
    device's noise differ (:func:`reseed`)."""
    key = (device.motor, device.drivetrain, device.finger, device.fsr, device.circuit, device.current_sense,
           device.estimator, device.rates, model, board_pos_m)
    last = _LAST_ROWS
    if last and all(a is b for a, b in zip(last[0], key)):
        p, st = last[1].copy(), last[2].copy()
    else:
        p = _unseeded_params(device, model)
        st = initial_state(device, p, board_pos_m)
        last[:] = [key, p.copy(), st.copy()]
    reseed(p, device, seed)
    return p, st


def pack_devices(devices, seeds, board_pos_m=None, models=None):
    """Packed parameters, initial states and default inputs of several devices.

    All devices must share their rates.  Estimator models are loaded once per distinct
    ``estimator.model`` unless given in ``models``.

    Returns
    -------
    devices : list of DeviceParams
    params : list of ndarray, each (N_PARAM,)
    states : list of ndarray, each (N_STATE,)
    inputs : ndarray, shape (n, N_INPUT)
        Gravity along the travel and the driver supply filled in; everything else zero.
    """
    devices = list(devices)
    if not devices:
        raise ValueError("a plant needs at least one device")
    rates = devices[0].rates
    for dvc in devices[1:]:
        if dvc.rates != rates:
            raise ValueError("all devices of one plant must share control, sensor and physics rates")
    cache: dict[str, object] = {}
    params, states = [], []
    for k, (dvc, seed) in enumerate(zip(devices, seeds, strict=True)):
        model = models[k] if models is not None else None
        if model is None:
            key = dvc.estimator.model
            if key not in cache:
                cache[key] = plant_model(key)
            model = cache[key]
        p, st = _device_rows(dvc, seed, model, board_pos_m)
        params.append(p)
        states.append(st)
    inputs = np.zeros((len(devices), N_INPUT))
    inputs[:, U.gravity_along_m_per_s2] = [-d.gravity_m_per_s2 for d in devices]
    inputs[:, U.driver_supply_v] = [d.driver_supply_v for d in devices]
    return devices, params, states, inputs


@dataclass
class Plant:
    """Packed state of ``n`` devices and their per-period inputs.

    Attributes
    ----------
    state : ndarray, shape (n, N_STATE)
    params : ndarray, shape (n, N_PARAM)
    inputs : ndarray, shape (n, N_INPUT)
    substeps : int
        Physics steps per control period.
    control_dt_s : float
        Control period, s.
    devices : list of DeviceParams
    """
    state: np.ndarray
    params: np.ndarray
    inputs: np.ndarray
    substeps: int
    control_dt_s: float
    devices: list

    @classmethod
    def from_devices(cls, devices, seeds, board_pos_m=None, models=None) -> "Plant":
        """Build a plant of ``len(devices)`` devices; all must share the same rates."""
        devices, params, states, inputs = pack_devices(devices, seeds, board_pos_m, models)
        rates = devices[0].rates
        plant = cls(np.array(states), np.array(params), inputs, rates.substeps_per_control,
                    1.0 / rates.control_rate_hz, devices)
        # compile (or load from the cache) before any timed loop: zero substeps change nothing
        kernel.advance(plant.state[0], plant.params[0], plant.inputs[0], 0)
        return plant

    @property
    def n(self) -> int:
        return self.state.shape[0]

    def advance(self, command_v) -> None:
        """Advance every device by one control period with ``command_v`` held (V, finite; a
        float or one per device; clipped to the driver supply inside the kernel)."""
        inp = self.inputs
        if self.state.shape[0] == 1:
            c = float(command_v) if isinstance(command_v, (float, int)) else float(np.ravel(command_v)[0])
            if not math.isfinite(c):
                raise ValueError(f"command_v must be finite, got {c}")
            inp[0, U.command_v] = c
            kernel.advance(self.state[0], self.params[0], inp[0], self.substeps)
        else:
            cmd = np.broadcast_to(np.asarray(command_v, dtype=float), (self.n,))
            if not np.all(np.isfinite(cmd)):
                raise ValueError("command_v must be finite for every device")
            inp[:, U.command_v] = cmd
            kernel.advance_batch(self.state, self.params, inp, self.substeps)

    def set_input(self, name: str, value) -> None:
        """Set a per-period input (see :data:`ebraille_sim.plant.layout.INPUT_NAMES`) for all devices."""
        if name not in U:
            raise KeyError(f"unknown plant input {name!r}; allowed: {', '.join(U.keys())}")
        self.inputs[:, U[name]] = value

    def set_finger(self, finger_pos_m) -> None:
        """Pulp surface position(s) relative to the device frame, m (board travel axis)."""
        self.inputs[:, U.finger_pos_m] = finger_pos_m

    def _col(self, name):
        return self.state[:, S[name]]

    @property
    def contact_force_n(self):
        """True contact force on the pulp (what the finger feels), N, shape (n,)."""
        return self._col("contact_force_n")

    @property
    def force_est_n(self):
        """Estimated force (the microcontroller's view), N, shape (n,)."""
        return self._col("force_est_n")

    @property
    def fsr_voltage_v(self):
        return self._col("fsr_voltage_v")

    @property
    def motor_current_a(self):
        return self._col("current_a")

    @property
    def board_pos_m(self):
        return self._col("board_pos_m")

    @property
    def energy_j(self):
        return self._col("energy_j")

    @property
    def time_s(self):
        return self._col("time_s")

