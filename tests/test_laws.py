"""Every law of the plant and the sensor, through the very function the compiled kernel calls.

Each test drives one law function (a Numba dispatcher, called here from Python) against an
analytic case, with tolerances far below 5 %: a 5 % change of any law fails its own test
(``tests/law_perturbation.py`` checks that).  The last tests check that the kernel is
nothing but the composition of these functions, and that the static helpers use them too.
"""
import dataclasses
import math
import subprocess
import sys

import numpy as np
import pytest
import scipy.signal

from ebraille_sim.estimation import blockmodels, firmware
from ebraille_sim.estimation.blockmodels import (BlockModel, LinearBF, PiecewiseLinear, df2t_step, estimator_step,
                                                 pwl_eval)
from ebraille_sim.estimation.firmware import biquad_step, creep_compensated_v, tared_v
from ebraille_sim.estimation.calibration import loading_branch_factor, loading_voltage
from ebraille_sim.estimation.paper_models import paper_model
from ebraille_sim.physics import drivetrain, fingertip, fsr, motor, noise
from ebraille_sim.physics.current_sense import NOISE_INDEX_OFFSET, amplifier_v, firmware_current_a, rc_step
from ebraille_sim.physics.drivetrain import (end_stop, friction_velocity_update, gear_loss_n, loaded_friction_n,
                                             mesh_force, reflected, shaft_speed_rad_per_s, shaft_to_rack_per_m,
                                             stribeck, viscous_force_n, weight_along_n)
from ebraille_sim.physics.fingertip import (compression_m, contact_force, elastic_force, prony_coefficients,
                                            prony_rate_n_per_s, prony_step, tangent_stiffness_n_per_m)
from ebraille_sim.physics.fsr import (F_EPS_N, FAULT_NONE, FAULT_OPEN, FAULT_SHORT, FAULT_STUCK, FAULT_VALUE,
                                      N_PLAYS, adc_code, adc_sample, adc_voltage, conductance_s, creep_force,
                                      creep_state_step, divider_voltage, hysteresis, lag_step, log_force, play_widths,
                                      sensor_voltage, static_conductance, static_voltage, temperature_factor)
from ebraille_sim.physics.motor import (current_decay, current_rate_a_per_s, current_step, driver_voltage,
                                       electrical_power_w, rack_force_n)
from ebraille_sim.physics.noise import noise_v, normal_at
from ebraille_sim.physics.params import (FINGERS, FSRS, MOTORS, CircuitParams, DeviceParams, DriveTrainParams,
                                         EstimatorParams, FSRParams)
from ebraille_sim.plant import kernel, layout
from ebraille_sim.plant.layout import N_INPUT, P, S, U
from ebraille_sim.plant.lumped import Plant, check_step, initial_state, pack_params

FAULHABER = MOTORS["faulhaber_0816_006sr"]
NOMINAL = FINGERS["nominal"]


# ---------------------------------------------------------------------------- motor
def test_motor_current_step_follows_the_closed_form_exponential():
    r, l_h, ke = FAULHABER.resistance_ohm, FAULHABER.inductance_h, FAULHABER.back_emf_v_s_per_rad
    h = 2e-6
    decay = current_decay(h, r, l_h)
    v, w, i0 = 6.0, 400.0, 0.05
    i_ss = (v - ke * w) / r
    i = i0
    for k in range(1, 31):
        i = current_step(i, v, w, 1.0 / r, ke, decay)
        t = k * h
        assert i == pytest.approx(i_ss + (i0 - i_ss) * math.exp(-t * r / l_h), rel=1e-12)
    # far past L/R the current is the quasi-static (V - kE w)/R
    for _ in range(1000):
        i = current_step(i, v, w, 1.0 / r, ke, decay)
    assert i == pytest.approx(i_ss, rel=1e-12)


def test_armature_ode_is_the_rate_of_the_exact_current_step():
    """``di/dt = (V - R i - kE w)/L``: the slope at t = 0 of the exact solution
    ``i_ss + (i0 - i_ss) exp(-t R/L)``, and the rate of :func:`current_step` over a short step."""
    r, l_h, ke = FAULHABER.resistance_ohm, FAULHABER.inductance_h, FAULHABER.back_emf_v_s_per_rad
    v, w, i0 = 6.0, 400.0, 0.05
    i_ss = (v - ke * w) / r
    rate = current_rate_a_per_s(i0, v, w, r, l_h, ke)
    assert rate == pytest.approx((i_ss - i0) * r / l_h, rel=1e-12)
    h = 1e-4 * l_h / r
    stepped = (current_step(i0, v, w, 1.0 / r, ke, current_decay(h, r, l_h)) - i0) / h
    assert stepped == pytest.approx(rate, rel=1e-4)
    assert current_rate_a_per_s(i_ss, v, w, r, l_h, ke) == pytest.approx(0.0, abs=1e-9 * abs(rate))
    # linear: its values on unit inputs are its partial derivatives
    assert current_rate_a_per_s(1.0, 0.0, 0.0, r, l_h, ke) == pytest.approx(-r / l_h, rel=1e-12)
    assert current_rate_a_per_s(0.0, 0.0, 1.0, r, l_h, ke) == pytest.approx(-ke / l_h, rel=1e-12)


def test_motor_force_driver_clip_and_power():
    g = shaft_to_rack_per_m(64.0, 2.5e-3)
    assert g == pytest.approx(25600.0, rel=1e-15)
    assert rack_force_n(0.1, FAULHABER.torque_constant_nm_per_a, g) == pytest.approx(0.1 * 4.12e-3 * 25600.0,
                                                                                     rel=1e-15)
    assert driver_voltage(7.5, 6.0) == 6.0
    assert driver_voltage(-9.0, 6.0) == -6.0
    assert driver_voltage(2.5, 6.0) == 2.5
    assert electrical_power_w(6.0, 0.25) == 1.5
    assert shaft_speed_rad_per_s(0.01, g) == pytest.approx(256.0, rel=1e-15)


# ---------------------------------------------------------------------------- drive train
def test_mesh_force_in_and_out_of_the_backlash_gap():
    b, k, c = 5e-5, 3e4, 8.0
    for dx in (0.0, 3e-5, -5e-5, 5e-5):
        assert mesh_force(dx, 0.01, b, k, c) == 0.0                   # inside the gap: no force
    assert mesh_force(1.5e-4, 0.0, b, k, c) == pytest.approx(k * 1e-4, rel=1e-12)
    assert mesh_force(1.5e-4, 0.02, b, k, c) == pytest.approx(k * 1e-4 + c * 0.02, rel=1e-12)
    assert mesh_force(-1.5e-4, -0.02, b, k, c) == pytest.approx(-(k * 1e-4 + c * 0.02), rel=1e-12)
    # contact can push but never pull: a fast separation leaves zero, not a negative force
    assert mesh_force(1.5e-4, -1.0, b, k, c) == 0.0
    assert mesh_force(-1.5e-4, 1.0, b, k, c) == 0.0


def test_stribeck_curve_at_rest_at_vs_and_far_above():
    fc, fs, vs = 0.1, 0.125, 0.5e-3
    assert stribeck(0.0, fc, fs, vs) == pytest.approx(fs, rel=1e-12)
    assert stribeck(vs, fc, fs, vs) == pytest.approx(fc + (fs - fc) / math.e, rel=1e-12)
    assert stribeck(100 * vs, fc, fs, vs) == pytest.approx(fc, rel=1e-12)


def test_gear_loss_reproduces_the_forward_efficiency():
    dt = DriveTrainParams()
    mu = dt.gear_loss_coefficient
    # steady forward drive: F_in = F_out + mu |F_out|  ->  F_out = eta F_in
    f_out = 0.9
    f_in = f_out + gear_loss_n(mu, f_out)
    assert f_out / f_in == pytest.approx(dt.gear_efficiency, rel=1e-12)
    assert gear_loss_n(mu, -f_out) == gear_loss_n(mu, f_out)
    fk, fs_ = loaded_friction_n(0.0, 0.8, 1.0, 1e-3, 0.5)
    assert (fk, fs_) == (pytest.approx(1.5, rel=1e-12), pytest.approx(1.5, rel=1e-12))


def test_friction_sticks_below_breakaway_and_slips_above():
    m, h, fk, fs_ = 0.01, 1e-4, 0.1, 0.125
    hm = h / m
    assert friction_velocity_update(0.0, 0.12, hm, fk, fs_) == 0.0           # stuck
    assert friction_velocity_update(0.0, -0.12, hm, fk, fs_) == 0.0
    assert friction_velocity_update(0.0, 0.2, hm, fk, fs_) == pytest.approx(h * (0.2 - fk) / m, rel=1e-12)
    assert friction_velocity_update(0.0, -0.2, hm, fk, fs_) == pytest.approx(-h * (0.2 - fk) / m, rel=1e-12)
    # sliding: friction removes h fk/m of speed and never reverses the motion
    assert friction_velocity_update(0.01, 0.0, hm, fk, fs_) == pytest.approx(0.01 - h * fk / m, rel=1e-12)
    assert friction_velocity_update(1e-4, 0.0, hm, fk, fs_) == 0.0
    assert friction_velocity_update(-0.01, 0.05, hm, fk, fs_) == pytest.approx(-0.01 + h * (0.05 + fk) / m,
                                                                                rel=1e-12)


def test_end_stops_viscous_and_weight():
    assert end_stop(-1e-4, -0.01, 0.0, 6e-3) == (0.0, 0.0)
    assert end_stop(-1e-4, 0.01, 0.0, 6e-3) == (0.0, 0.01)
    assert end_stop(7e-3, 0.01, 0.0, 6e-3) == (6e-3, 0.0)
    assert end_stop(3e-3, 0.01, 0.0, 6e-3) == (3e-3, 0.01)
    assert viscous_force_n(2.0, 0.5) == 1.0
    assert weight_along_n(6e-3, -9.81) == pytest.approx(-0.05886, rel=1e-12)


def test_reflected_quantities_use_the_gear_reflection():
    d = DriveTrainParams()
    g = d.gear_ratio / d.pinion_radius_m
    r = reflected(FAULHABER, d)
    assert r["mass_kg"] == pytest.approx(FAULHABER.rotor_inertia_kg_m2 * g ** 2, rel=1e-12)
    assert r["coulomb_n"] == pytest.approx(FAULHABER.friction_torque_nm * g, rel=1e-12)
    p = pack_params(DeviceParams(), 0.0)
    assert p[P.pinion_mass_kg] == r["mass_kg"]
    assert p[P.pinion_coulomb_n] == r["coulomb_n"]
    assert p[P.n_over_r_per_m] == shaft_to_rack_per_m(d.gear_ratio, d.pinion_radius_m)


# ---------------------------------------------------------------------------- fingertip
def test_pulp_elastic_force_at_the_paper_derived_compressions():
    b, m = NOMINAL.stiffness_b_n_per_m, NOMINAL.exponent_m_per_m
    d1 = math.log1p(m * 1.0 / b) / m                       # exact compression at 1 N
    assert elastic_force(d1, b, m) == pytest.approx(1.0, rel=1e-12)
    assert elastic_force(d1, b, m) == pytest.approx(b / m * (math.exp(m * d1) - 1.0), rel=1e-12)
    # the parameters were solved through 1.4 mm at 1 N and 2.4 mm at 4 N
    assert elastic_force(1.4e-3, b, m) == pytest.approx(1.0, rel=0.01)
    assert elastic_force(2.4e-3, b, m) == pytest.approx(4.0, rel=0.01)
    assert elastic_force(0.0, b, m) == 0.0 and elastic_force(-1e-3, b, m) == 0.0
    # tangent stiffness b + m Fe is the derivative of the law
    dd = 1e-9
    slope = (elastic_force(d1 + dd, b, m) - elastic_force(d1 - dd, b, m)) / (2 * dd)
    assert tangent_stiffness_n_per_m(1.0, b, m) == pytest.approx(slope, rel=1e-5)
    assert compression_m(2.0e-3, 0.6e-3) == pytest.approx(1.4e-3, rel=1e-12)


def test_the_pulp_laws_exp_minus_one_is_expm1_within_two_ulp():
    """The kernel's ``exp(x) - 1`` (``exp`` above ln 2, ``expm1`` below) against ``math.expm1``
    over the pulp's range of ``m d`` (0 to well past the travel's end), and exactly ``expm1``
    near zero, where the subtraction would cancel."""
    xs = np.concatenate([np.linspace(-1.0, 60.0, 20001), np.geomspace(1e-12, 0.69, 2000)])
    got = np.array([fingertip.exp_minus_one(float(x)) for x in xs])
    want = np.array([math.expm1(float(x)) for x in xs])
    assert np.all(np.abs(got - want) <= 2.0 * np.spacing(np.abs(want)))
    small = xs < math.log(2.0)
    assert np.array_equal(got[small], want[small])


def test_ramp_compression_follows_the_qlv_law_between_its_relaxed_and_instant_limits():
    from ebraille_sim.physics.fingertip import ramp_compression_at_force_m
    f = NOMINAL
    # a ramp far slower than the 1.4 s term meets the relaxed law, a near-instant one the elastic law
    assert ramp_compression_at_force_m(f, 1.0, 1e-8, 2e-6) == pytest.approx(f.compression_at_m(1.0, relaxed=True),
                                                                           rel=1e-4)
    assert ramp_compression_at_force_m(f, 1.0, 100.0, 2e-6) == pytest.approx(f.compression_at_m(1.0), rel=1e-3)
    # between them, the shipped nominal reader on flat-plate ramps: 1 N at 2.61 mm at 1 mm/s,
    # at 2.15 mm at 32 mm/s; 4 N at 3.38 mm at 16 mm/s
    assert ramp_compression_at_force_m(f, 1.0, 1e-3, 2e-6) * 1e3 == pytest.approx(2.606, rel=0.005)
    assert ramp_compression_at_force_m(f, 1.0, 32e-3, 2e-6) * 1e3 == pytest.approx(2.148, rel=0.005)
    assert ramp_compression_at_force_m(f, 4.0, 16e-3, 2e-6) * 1e3 == pytest.approx(3.380, rel=0.005)
    # an elastic pulp reaches the force at the instantaneous law's compression at any speed
    import dataclasses
    elastic = dataclasses.replace(f, relax_weight_inf=1.0, relax_weight_1=0.0, relax_weight_2=0.0, relax_weight_3=0.0)
    for v in (1e-3, 0.1):
        assert ramp_compression_at_force_m(elastic, 1.0, v, 1e-7) == pytest.approx(f.compression_at_m(1.0), rel=1e-4)
    with pytest.raises(ValueError, match="needs force_n"):
        ramp_compression_at_force_m(f, 1.0, 0.0)


def test_dynamic_stiffness_is_the_tangent_stiffness_times_the_relaxation_modulus():
    from ebraille_sim.physics.fingertip import complex_relaxation, dynamic_stiffness_n_per_m
    f = NOMINAL
    k_inst = f.stiffness_b_n_per_m + f.exponent_m_per_m * 1.0 / f.relax_weight_inf
    assert dynamic_stiffness_n_per_m(f, 1.0, 0.0) == pytest.approx(f.relax_weight_inf * k_inst, rel=1e-12)
    assert dynamic_stiffness_n_per_m(f, 1.0, 1e9) == pytest.approx(k_inst, rel=1e-6)
    w = 2 * math.pi * 6.5
    g = f.relax_weight_inf + sum(c * 1j * w * t / (1 + 1j * w * t) for c, t in (
        (f.relax_weight_1, 0.004), (f.relax_weight_2, 0.070), (f.relax_weight_3, 1.4)))
    assert complex_relaxation(f, 6.5) == pytest.approx(g, rel=1e-12)
    assert complex_relaxation(f, 0.0) == pytest.approx(f.relax_weight_inf, rel=1e-12)
    assert complex_relaxation(f, 1e9) == pytest.approx(1.0, rel=1e-6)
    # the shipped nominal reader at 1 N: 2.55 N/mm at the default loop's 6.5 Hz crossover, a
    # third of the instantaneous 8.57 N/mm, twice the relaxed 1.29 N/mm
    assert dynamic_stiffness_n_per_m(f, 1.0, 6.5) == pytest.approx(abs(g) * k_inst, rel=1e-12)
    assert dynamic_stiffness_n_per_m(f, 1.0, 6.5) == pytest.approx(2545.0, rel=2e-3)


def test_qlv_step_response_relaxes_to_c0_fe_with_the_three_time_constants():
    f = NOMINAL
    taus = (f.relax_tau_1_s, f.relax_tau_2_s, f.relax_tau_3_s)
    cs = (f.relax_weight_1, f.relax_weight_2, f.relax_weight_3)
    h = 1e-4
    a, beta = prony_coefficients(h, taus)
    fe, d = 1.0, 1.4e-3
    hs = [0.0, 0.0, 0.0]
    fe_old = 0.0
    for k in range(1, 40001):                               # 4 s held step
        hs = [prony_step(hs[j], a[j], cs[j], beta[j], fe - fe_old) for j in range(3)]
        fe_old = fe
        fc = contact_force(d, fe, f.relax_weight_inf, *hs)
        t = k * h
        if k in (1, 40, 700, 3000, 14000, 40000):
            # exact for the ramp-invariant step: the step enters over the first interval
            expected = fe * (f.relax_weight_inf + sum(c * b_ * math.exp(-(t - h) / tau)
                                                      for c, b_, tau in zip(cs, beta, taus)))
            assert fc == pytest.approx(expected, rel=1e-10)
            # and the continuous relaxation function G(t) to within the step's smearing
            g_t = f.relax_weight_inf + sum(c * math.exp(-t / tau) for c, tau in zip(cs, taus))
            assert fc == pytest.approx(fe * g_t, rel=0.03)
    assert fc == pytest.approx(f.relax_weight_inf * fe + f.relax_weight_3 * math.exp(-4.0 / 1.4), rel=1e-3)


def test_qlv_ramp_is_exact_and_contact_only_pushes():
    """Fe rising at r: h_i(t) = c_i tau_i r (1 - exp(-t/tau_i)) exactly, for any step."""
    f = NOMINAL
    taus = (f.relax_tau_1_s, f.relax_tau_2_s, f.relax_tau_3_s)
    cs = (f.relax_weight_1, f.relax_weight_2, f.relax_weight_3)
    h, rate = 1e-3, 2.0
    a, beta = prony_coefficients(h, taus)
    hs = [0.0, 0.0, 0.0]
    for k in range(1, 301):
        hs = [prony_step(hs[j], a[j], cs[j], beta[j], rate * h) for j in range(3)]
    t = 300 * h
    for j in range(3):
        assert hs[j] == pytest.approx(cs[j] * taus[j] * rate * (1 - math.exp(-t / taus[j])), rel=1e-9)
    assert contact_force(1e-3, 1.0, 0.4, 0.1, 0.1, 0.1) == pytest.approx(0.7, rel=1e-12)
    assert contact_force(-1e-6, 1.0, 0.4, 0.1, 0.1, 0.1) == 0.0          # board below the pulp
    assert contact_force(1e-3, 0.1, 0.4, -0.3, 0.0, 0.0) == 0.0          # would pull


def test_prony_ode_is_the_rate_of_the_exact_prony_step():
    """``dh/dt = -h/tau + c dFe/dt``: the closed form, and the rate of :func:`prony_step` over a
    step short against tau with Fe rising at ``dFe/dt``."""
    f = NOMINAL
    tau, c = f.relax_tau_2_s, f.relax_weight_2
    h0, fe_rate = 0.05, 3.0
    rate = prony_rate_n_per_s(h0, tau, c, fe_rate)
    assert rate == pytest.approx(-h0 / tau + c * fe_rate, rel=1e-12)
    h = 1e-6 * tau
    (a,), (beta,) = prony_coefficients(h, (tau,))
    assert (prony_step(h0, a, c, beta, fe_rate * h) - h0) / h == pytest.approx(rate, rel=1e-5)
    # relaxation alone decays at 1/tau; a held state is in equilibrium with a steady ramp c tau dFe/dt
    assert prony_rate_n_per_s(1.0, tau, c, 0.0) == pytest.approx(-1.0 / tau, rel=1e-12)
    assert prony_rate_n_per_s(c * tau * fe_rate, tau, c, fe_rate) == pytest.approx(0.0, abs=1e-12)


# ---------------------------------------------------------------------------- FSR
def test_fsr_conductance_power_law():
    k, n, gso = 10e3, 0.9, 1e-7
    for force in (0.2, 1.0, 2.0, 3.0):          # actuation force 0: no turn-on
        assert conductance_s(force, k, n, gso, 1.0, 0.0, 4.0) - gso == pytest.approx(force ** n / k, rel=1e-9)
    # doubling the force multiplies the conduction path by 2^n; the scale divides it
    g1 = conductance_s(1.0, k, n, 0.0, 1.0, 0.0, 4.0)
    assert conductance_s(2.0, k, n, 0.0, 1.0, 0.0, 4.0) / g1 == pytest.approx(2 ** n, rel=1e-12)
    assert conductance_s(1.0, k, n, 0.0, 1.25, 0.0, 4.0) == pytest.approx(g1 / 1.25, rel=1e-12)
    assert conductance_s(0.0, k, n, gso, 1.0, 0.1, 4.0) == gso and conductance_s(-1.0, k, n, gso, 1.0, 0.1, 4.0) == gso
    # the turn-on scales the power-law path only
    f = 0.15
    assert conductance_s(f, k, n, gso, 1.0, 0.1, 4.0) - gso == pytest.approx(
        f ** n / k * fsr.turn_on_factor(f, 0.1, 4.0), rel=1e-12)
    # the nominal FSR 402 reads 10 kOhm at 1 N (the turn-on costs 1e-4 there)
    assert 1.0 / conductance_s(1.0, k, n, 0.0, 1.0, 0.0, 4.0) == pytest.approx(10e3, rel=1e-12)
    assert FSRS["nominal"].resistance_ohm(1.0) == pytest.approx(10e3, rel=2e-3)


def test_fsr_turn_on_region_has_the_datasheet_actuation():
    """Half the power law at the actuation force (0.1 N, FSR 402 sheet), > 100 kOhm there (guide:
    the resistance swings down from > 100 kOhm at turn-on), the power law from about 2 F_a."""
    assert fsr.turn_on_factor(0.1, 0.1, 4.0) == 0.5
    assert fsr.turn_on_factor(0.2, 0.1, 4.0) == pytest.approx(1.0 / (1.0 + 0.5 ** 4), rel=1e-15)
    assert fsr.turn_on_factor(0.0, 0.1, 4.0) == 0.0 and fsr.turn_on_factor(5.0, 0.0, 4.0) == 1.0
    s = FSRS["nominal"]
    assert s.resistance_ohm(0.1) == pytest.approx(156.4e3, rel=1e-3)          # 78 kOhm of the law, doubled
    assert s.resistance_ohm(0.05) > 1e6                                       # below actuation: barely touching
    assert s.resistance_ohm(0.2) == pytest.approx(45.0e3, rel=1e-3)           # law 42.4 kOhm, 6 % above
    law = lambda f: s.resistance_at_1n_ohm * f ** -s.exponent
    assert abs(s.resistance_ohm(0.5) / law(0.5) - 1.0) < 3e-3             # turn-on +0.16 %, stand-off -0.19 %


def test_fsr_temperature_law_has_the_datasheet_points():
    """Datasheet, after 1 h: -15 % at +85 C and -5 % at -40 C (both falls), from 25 C."""
    s = FSRParams()
    assert temperature_factor(60.0, s.temperature_coeff_per_k, s.temperature_coeff_cold_per_k) == pytest.approx(
        0.85, rel=1e-12)
    assert temperature_factor(-65.0, s.temperature_coeff_per_k, s.temperature_coeff_cold_per_k) == pytest.approx(
        0.95, rel=1e-12)
    assert temperature_factor(0.0, s.temperature_coeff_per_k, s.temperature_coeff_cold_per_k) == 1.0
    # the inverse used to fold a session's creep into the temperature input returns the warm offset
    assert fsr.temperature_offset_k(0.85, s.temperature_coeff_per_k, s.temperature_coeff_cold_per_k) == \
        pytest.approx(60.0, rel=1e-12)
    np.testing.assert_allclose(fsr.temperature_scale(np.array([-65.0, 0.0, 60.0]), s), [0.95, 1.0, 0.85], rtol=1e-12)
    with pytest.raises(ValueError, match="at most 1"):
        fsr.temperature_offset_k(1.01, s.temperature_coeff_per_k, s.temperature_coeff_cold_per_k)


def test_press_scatter_draws_once_per_press_with_the_datasheet_repeatability():
    """A new resistance factor exp(sigma z) at each press (lagged force rising through the
    threshold), kept through the press; over many presses the spread is the datasheet's 2 %."""
    s = np.zeros(3)
    sigma, seed, thr = 0.02, 12345.0, 0.02
    assert fsr.press_scatter(0.0, thr, s, 0, 1, 2, seed, sigma) == 1.0            # before any press
    first = fsr.press_scatter(0.5, thr, s, 0, 1, 2, seed, sigma)
    assert first == pytest.approx(math.exp(sigma * fsr.normal_at(seed, fsr.PRESS_INDEX_OFFSET + 1.0)), rel=1e-15)
    assert fsr.press_scatter(1.5, thr, s, 0, 1, 2, seed, sigma) == first          # same press
    assert fsr.press_scatter(0.01, thr, s, 0, 1, 2, seed, sigma) == first         # released: kept until the next
    second = fsr.press_scatter(0.3, thr, s, 0, 1, 2, seed, sigma)
    assert second != first and s[1] == 2.0
    factors = []
    for _ in range(4000):
        fsr.press_scatter(0.0, thr, s, 0, 1, 2, seed, sigma)
        factors.append(fsr.press_scatter(1.0, thr, s, 0, 1, 2, seed, sigma))
    assert np.std(np.log(factors)) == pytest.approx(0.02, rel=0.05)
    assert np.mean(np.log(factors)) == pytest.approx(0.0, abs=0.002)


def test_creep_terms_follow_the_force_and_add_only_while_loaded():
    s = FSRParams()
    # one exact sample of a first-order term under a held force
    assert creep_state_step(0.2, 1.5, 0.9) == pytest.approx(0.9 * 0.2 + 0.1 * 1.5, rel=1e-15)
    assert creep_state_step(0.7, 0.0, 0.5) == pytest.approx(0.35, rel=1e-15)       # recovery
    # the crept force: F + w sum z while loaded, F alone once the film is off the electrodes
    st = np.array([0.0, 1.0, 2.0, 3.0])
    pp = np.array([0.5, 0.25, 0.0])
    f_c = creep_force(1.0, 1.0, st, 1, pp, 0, 0.1, 0.02, 3)
    z = [0.5 * 1.0 + 0.5 * 1.0, 0.25 * 2.0 + 0.75 * 1.0, 1.0]
    np.testing.assert_allclose(st[1:], z, rtol=1e-15)
    assert f_c == pytest.approx(1.0 + 0.1 * sum(z), rel=1e-15)
    assert creep_force(0.01, 0.01, st.copy(), 1, pp, 0, 0.1, 0.02, 3) == 0.01
    # held gain: one term per decade rises by the per-decade weight per decade (+/- 10 %)
    w = fsr.creep_term_weight(s.creep_per_decade, s.creep_tau_min_s, s.creep_tau_max_s)
    assert w == pytest.approx(s.creep_per_decade, rel=1e-12)
    g = [fsr.held_creep_gain(t, w, s.creep_tau_min_s, s.creep_tau_max_s, fsr.N_CREEP) for t in (0.1, 1.0, 10.0)]
    assert fsr.held_creep_gain(0.0, w, s.creep_tau_min_s, s.creep_tau_max_s, fsr.N_CREEP) == 1.0
    assert fsr.held_creep_gain(1e6, w, 0.01, 100.0, 5) == pytest.approx(1.0 + 5 * w, rel=1e-12)
    assert (g[1] - g[0]) / w == pytest.approx(0.983, abs=0.03) and (g[2] - g[1]) / w == pytest.approx(0.99, abs=0.03)


def test_creep_continues_to_days_at_the_sources_rate():
    """Standard FSR ink: conductance +12 % over 48 h under a held load, log-time from 1 s
    (Sensitronics); FSR 402: < 5 % per decade (datasheet).  The creep does not stop after
    minutes: every decade from 0.1 s to 10^5 s adds 1.8-2.4 %."""
    s = FSRS["nominal"]
    g = lambda t: float(fsr.creep_gain(float(t), s)) ** s.exponent
    assert g(48 * 3600.0) / g(1.0) - 1.0 == pytest.approx(0.12, abs=0.002)
    for t in (0.1, 1.0, 10.0, 100.0, 1e3, 1e4, 1e5):
        assert 0.018 < g(10 * t) / g(t) - 1.0 < 0.025
    # a two-hour session, from 100 s into it to its end: 4 % (the old 10 ms-100 s law: 0.5 %)
    assert g(7200.0) / g(100.0) - 1.0 == pytest.approx(0.040, abs=0.002)


def test_datasheet_hysteresis_at_1kg_with_the_creep_is_10_percent():
    """The datasheet's +10 % average (R_F+ - R_F-)/R_F+ is taken at 1000 g with whatever the film
    creeps during the cycle: measured that way (0 -> 2 kg -> 0, 0.3-30 s a leg) through the plant's
    laws, the nominal film gives 9.9 % (creep 3.2 %, plays 7.1 %); the creep's share is about the
    same at every rate (log-time creep between two passes a fixed ratio of time apart)."""
    s = FSRS["nominal"]
    assert fsr.creep_loop_fraction(s) == pytest.approx(0.0317, abs=5e-4)
    assert fsr.play_loop_fraction(s) == pytest.approx(0.0705, abs=5e-4)
    assert fsr.datasheet_hysteresis(s) == pytest.approx(0.099, abs=0.001)
    for ramp in (0.3, 3.0, 30.0):
        assert 0.09 <= fsr.datasheet_hysteresis(s, ramp_s=ramp, dt_s=ramp / 1000) <= 0.11


def test_mechanical_lag_is_a_first_order_step():
    tau, h = 1.5e-3, 1e-4
    alpha = fsr.lag_alpha(h, tau)
    f = 0.0
    for k in range(1, 51):
        f = lag_step(f, 2.0, alpha)
    assert f == pytest.approx(2.0 * (1 - math.exp(-50 * h / tau)), rel=1e-12)


def _press(forces, s_fsr=FSRParams()):
    widths, weights = play_widths(s_fsr)
    p = np.array(widths + weights)
    s = np.full(N_PLAYS, log_force(0.0))
    out = 0.0
    for force in forces:
        out = hysteresis(float(force), s, 0, p, 0, N_PLAYS, N_PLAYS)
    return out


def test_hysteresis_loading_branch_and_loop_width():
    s_fsr = FSRParams()
    w_total = s_fsr.hysteresis_log_halfwidth
    # monotone press from zero: every play at its lower edge, ln(F_eff + eps) = ln(F + eps) - W
    up = _press(np.linspace(0.0, 1.0, 21), s_fsr)
    assert up + F_EPS_N == pytest.approx((1.0 + F_EPS_N) * math.exp(-w_total), rel=1e-12)
    assert up == pytest.approx(loading_branch_factor(s_fsr), rel=1e-4)
    # up to 3 N and back to 1 N: every play at its upper edge
    down = _press(np.concatenate([np.linspace(0.0, 3.0, 61), np.linspace(3.0, 1.0, 41)]), s_fsr)
    assert down + F_EPS_N == pytest.approx((1.0 + F_EPS_N) * math.exp(w_total), rel=1e-12)
    # loop width in resistance: (R_up - R_down)/R_up = 1 - (F_up/F_down)^n = h
    width = 1.0 - ((up + F_EPS_N) / (down + F_EPS_N)) ** s_fsr.exponent
    assert width == pytest.approx(fsr.play_loop_fraction(s_fsr), rel=1e-12)


def test_divider_is_paper_eq_1():
    for r_fsr, r2, vs in ((10e3, 10e3, 5.0), (30e3, 10e3, 5.0), (6.0e3, 1310.0, 5.0), (1e7, 1310.0, 3.3)):
        assert divider_voltage(1.0 / r_fsr, r2, vs) == pytest.approx(vs * r2 / (r2 + r_fsr), rel=1e-12)
    assert divider_voltage(0.0, 1310.0, 5.0) == 0.0
    assert CircuitParams(r2_ohm=10e3).divider_v(10e3) == pytest.approx(2.5, rel=1e-12)


def test_divider_conductance_inverts_the_divider():
    for g, r2, vs in ((1e-4, 1150.0, 5.0), (1.0 / 30e3, 10e3, 5.0), (1e-7, 1310.0, 3.3)):
        v = divider_voltage(g, r2, vs)
        assert fsr.divider_conductance_s(v, r2, vs) == pytest.approx(g, rel=1e-12)
    # 1 V on 1150 ohm from 5 V: the film carries 1/1150 A... at 4 V across it
    assert fsr.divider_conductance_s(1.0, 1150.0, 5.0) == pytest.approx(1.0 / (1150.0 * 4.0), rel=1e-15)
    assert fsr.divider_conductance_s(0.0, 1150.0, 5.0) == 0.0


def test_creep_compensation_scales_the_conduction_path_by_the_gain_ratio():
    """The firmware's creep prediction is the plant's law on its estimate; the power-law part of
    the conductance is scaled by (c_ref / c)^n, the stand-off path kept; no load: c = 1."""
    r2, vs, n, gso, w, thr, c_ref = 1150.0, 5.0, 0.9, 1e-7, 0.1, 0.02, 1.12
    pp = np.array([0.5, 0.25, 0.0])
    st = np.array([0.0, 1.0, 2.0, 3.0])
    st_law = st.copy()
    g = 1.0 / 9000.0
    v = divider_voltage(g, r2, vs)
    f_c = creep_force(1.0, 1.0, st_law, 1, pp, 0, w, thr, 3)
    out = creep_compensated_v(v, 1.0, st, 1, pp, 0, w, thr, 3, n, gso, c_ref, r2, vs, 0.0)
    np.testing.assert_array_equal(st, st_law)                    # same states as the law advances
    g_u = gso + (g - gso) * (c_ref / f_c) ** n
    assert out == pytest.approx(divider_voltage(g_u, r2, vs), rel=1e-13)
    assert f_c == pytest.approx(1.0 + w * (1.0 + 1.25 + 1.0), rel=1e-15)
    # below the load threshold the predicted gain is 1; only the calibration's gain is applied
    st2 = np.array([0.0, 1.0, 2.0, 3.0])
    out_low = creep_compensated_v(v, 0.01, st2, 1, pp, 0, w, thr, 3, n, gso, c_ref, r2, vs, 0.0)
    assert out_low == pytest.approx(divider_voltage(gso + (g - gso) * c_ref ** n, r2, vs), rel=1e-13)
    # a railed or faulted divider passes unchanged (the states still advance)
    st3 = np.array([0.0, 1.0, 2.0, 3.0])
    assert creep_compensated_v(vs, 1.0, st3, 1, pp, 0, w, thr, 3, n, gso, c_ref, r2, vs, 0.0) == vs
    assert creep_compensated_v(0.0, 1.0, st3, 1, pp, 0, w, thr, 3, n, gso, c_ref, r2, vs, 0.0) == 0.0
    # the predicted gain equal to the reference leaves the voltage alone
    st4 = np.zeros(4)
    assert creep_compensated_v(v, 1.0, st4, 1, np.ones(3), 0, w, thr, 3, n, gso, 1.0, r2, vs, 0.0) == pytest.approx(
        v, rel=1e-13)
    # a session's preload scales the conduction path by (1 + preload) as well
    st5 = np.array([0.0, 1.0, 2.0, 3.0])
    out_pre = creep_compensated_v(v, 1.0, st5, 1, pp, 0, w, thr, 3, n, gso, c_ref, r2, vs, -0.06)
    assert out_pre == pytest.approx(divider_voltage(gso + (g - gso) * (c_ref / f_c) ** n * 0.94, r2, vs), rel=1e-13)


def test_adc_rounds_down_and_clips_at_the_rails():
    c = CircuitParams()
    lsb, top = c.adc_lsb_v, c.adc_max_code
    assert lsb == 5.0 / 1024 and top == 1023.0
    assert adc_code(100.5 * lsb, lsb, top) == 100.0
    assert adc_code(100.0 * lsb + 1e-9, lsb, top) == 100.0
    assert adc_code(99.999 * lsb, lsb, top) == 99.0
    assert adc_code(-0.2, lsb, top) == 0.0
    assert adc_code(5.5, lsb, top) == top
    assert adc_voltage(512.0, lsb) == 2.5
    assert adc_sample(77.0, 1.0, lsb, top, FAULT_STUCK) == 77.0
    assert adc_sample(77.0, 1.0, lsb, top, FAULT_NONE) == 204.0


def test_fault_switch_replaces_the_divider():
    g, r2, vs = 1e-4, 1310.0, 5.0
    assert sensor_voltage(FAULT_NONE, g, r2, vs, 9.0) == divider_voltage(g, r2, vs)
    assert sensor_voltage(FAULT_STUCK, g, r2, vs, 9.0) == divider_voltage(g, r2, vs)
    assert sensor_voltage(FAULT_OPEN, g, r2, vs, 9.0) == 0.0
    assert sensor_voltage(FAULT_SHORT, g, r2, vs, 9.0) == vs
    assert sensor_voltage(FAULT_VALUE, g, r2, vs, 1.25) == 1.25


def test_noise_is_scaled_counter_based_gaussian():
    assert noise_v(2e-3, 7.0, 12.0) == 2e-3 * normal_at(7.0, 12.0)
    x = np.array([noise_v(1.0, 3.0, float(k)) for k in range(20000)])
    assert abs(x.mean()) < 0.03 and x.std() == pytest.approx(1.0, rel=0.03)


# ---------------------------------------------------------------------------- estimator
def _pwl_ref(x, xs, ys):
    """np.interp inside the breakpoints, end-segment slopes outside."""
    y = np.interp(x, xs, ys)
    y = np.where(x < xs[0], ys[0] + (ys[1] - ys[0]) / (xs[1] - xs[0]) * (x - xs[0]), y)
    return np.where(x > xs[-1], ys[-1] + (ys[-1] - ys[-2]) / (xs[-1] - xs[-2]) * (x - xs[-1]), y)


def _packed(model):
    arr = model.kernel_arrays()
    n = len(arr["num"])
    parts = [arr["num"], arr["den"], arr["in_x"], arr["in_y"], arr["out_x"], arr["out_y"]]
    offs = np.cumsum([0] + [len(a) for a in parts])
    return np.concatenate(parts), offs, n, len(arr["in_x"]), len(arr["out_x"])


def _run_estimator(model, u, average=False, clamp=False):
    p, o, n, n_in, n_out = _packed(model)
    s = np.zeros(n)                                 # z0..z(n-2), then the previous raw output
    out = []
    for x in u:
        out.append(estimator_step(float(x), s, 0, n - 1, p, o[2], o[3], n_in, o[0], o[1], n, o[4], o[5], n_out,
                                  average, clamp))
    return np.array(out)


def test_estimator_step_equals_lfilter_and_interp_on_a_random_input():
    rng = np.random.default_rng(3)
    lin = LinearBF(b=(0.2, -0.1, 0.05), f=(-0.9, 0.2), nk=1)
    model = BlockModel(lin, PiecewiseLinear((-1.0, 0.0, 0.5, 1.0), (-0.5, 0.0, 0.8, 1.1)),
                       PiecewiseLinear((-2.0, 0.0, 0.3, 1.0, 2.0), (-1.0, 0.0, 0.5, 2.0, 2.2)), dt_s=0.01)
    u = rng.uniform(-1.3, 1.3, 400)
    w = _pwl_ref(u, np.array(model.input_nl.x_bp), np.array(model.input_nl.y_bp))
    x = scipy.signal.lfilter(lin.numerator(), lin.denominator(), w)
    ref = _pwl_ref(x, np.array(model.output_nl.x_bp), np.array(model.output_nl.y_bp))
    got = _run_estimator(model, u)
    np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-12)
    # the paper's fifth-order Wiener, with the two-sample mean and the clamp
    paper = paper_model("wiener", 5)
    u = 0.3 + 0.2 * rng.standard_normal(300)
    raw, _ = paper.simulate(u)
    avg = np.maximum(0.5 * (raw + np.concatenate([[0.0], raw[:-1]])), 0.0)
    np.testing.assert_allclose(_run_estimator(paper, u, True, True), avg, rtol=1e-12, atol=1e-12)


def test_antialias_biquad_and_pwl_and_df2t_pieces():
    b, a = scipy.signal.butter(2, 20.0, fs=1000.0)
    rng = np.random.default_rng(4)
    x = rng.standard_normal(500)
    s = np.zeros(2)
    y = [biquad_step(float(v), s, 0, 1, b[0], b[1], b[2], a[1], a[2]) for v in x]
    np.testing.assert_allclose(y, scipy.signal.lfilter(b, a, x), rtol=1e-12, atol=1e-14)
    p = np.array([0.0, 1.0, 3.0, 0.0, 2.0, 3.0])
    assert [pwl_eval(v, p, 0, 3, 3) for v in (0.5, 2.0, -1.0, 5.0)] == pytest.approx([1.0, 2.5, -2.0, 4.0],
                                                                                      rel=1e-15)
    num, den = np.array([0.5, 0.25]), np.array([1.0, -0.5])
    p = np.concatenate([num, den])
    s = np.zeros(1)
    y = [df2t_step(float(v), s, 0, p, 0, 2, 2) for v in x]
    np.testing.assert_allclose(y, scipy.signal.lfilter(num, den, x), rtol=1e-12, atol=1e-14)
    assert tared_v(1.25, 0.25) == 1.0


# ---------------------------------------------------------------------------- legibility
def test_legibility_contact_area_law_against_the_measured_finger_pad():
    from ebraille_sim.scenarios import legibility as L
    c = L._contact(L.DEFAULT)
    area = L._contact_area_m2
    assert area(1.0, c.contact_area_1n_m2, c.contact_area_exponent) == pytest.approx(100e-6, rel=1e-12)
    assert area(4.0, c.contact_area_1n_m2, c.contact_area_exponent) == pytest.approx(100e-6 * 4 ** (1 / 3), rel=1e-12)
    assert area(0.0, 1e-4, 0.5) == 0.0 and area(-1.0, 1e-4, 0.5) == 0.0
    # the measured ranges [M]: 60-150 mm2 near 1 N, 100-250 mm2 near 4 N; over twice the
    # 40 mm2 of the Hertz sphere (R = 8 mm, E = 0.1 MPa) at 1 N
    a1, a4 = area(1.0, c.contact_area_1n_m2, c.contact_area_exponent), area(4.0, c.contact_area_1n_m2,
                                                                          c.contact_area_exponent)
    assert 60e-6 <= a1 <= 150e-6 and 100e-6 <= a4 <= 250e-6
    hertz_1n = math.pi * (3 * 1.0 * 8e-3 / (4 * 0.1e6 / 0.75)) ** (2 / 3)
    assert hertz_1n == pytest.approx(39.7e-6, rel=0.01) and a1 > 2 * hertz_1n
    # the radius is that of the disc of the same area
    assert L._contact_radius(1.0, c) == pytest.approx(math.sqrt(100e-6 / math.pi), rel=1e-12)
    assert L._contact_radius(0.0, c) == 0.0


def test_legibility_lens_area_of_two_discs():
    from ebraille_sim.scenarios.legibility import _lens_area
    r = 0.6e-3
    assert _lens_area(0.0, r, 2e-3) == pytest.approx(math.pi * r * r, rel=1e-12)      # electrode inside
    assert _lens_area(0.2e-3, r, 0.3e-3) == pytest.approx(math.pi * 0.09e-6, rel=1e-12)   # patch inside
    assert _lens_area(1.3e-3, r, 0.6e-3) == 0.0                                        # apart
    for d in (0.3e-3, 0.6e-3, 1.0e-3):                                                 # equal discs
        exact = 2 * r * r * math.acos(d / (2 * r)) - 0.5 * d * math.sqrt(4 * r * r - d * d)
        assert _lens_area(d, r, r) == pytest.approx(exact, rel=1e-12)


def test_legibility_impedance_falls_with_the_patch_pressure():
    from ebraille_sim.scenarios import legibility as L
    s = L._stimulator(L.DEFAULT)
    assert L._impedance(1.0, s) == pytest.approx(80e3, rel=1e-12)                     # p(1 N) = p_ref = 10 kPa
    assert L._impedance(0.2, s) == pytest.approx(30e3 + 50e3 * 0.2 ** (-2 / 3), rel=1e-12)
    assert L._impedance(3.0, s) == pytest.approx(30e3 + 50e3 * 3.0 ** (-2 / 3), rel=1e-12)
    assert L._impedance(0.0, s) == L._impedance(1e-3, s) == pytest.approx(5.03e6, rel=1e-12)


def test_legibility_stimulator_current_constant_current_and_voltage():
    from ebraille_sim.scenarios import legibility as L
    cc, cv = L._stimulator(L.DEFAULT), L._stimulator(L.CONSTANT_VOLTAGE)
    assert L._current_a(1.0, 80e3, 80e3, cc) == 2e-3                                   # 160 V < 300 V compliance
    assert L._current_a(1.0, 200e3, 80e3, cc) == pytest.approx(1.5e-3, rel=1e-12)      # 300 V / 200 kOhm
    assert L._current_a(0.5, 100e3, 80e3, cc) == pytest.approx(1.5e-3, rel=1e-12)      # 300 V * 0.5 / 100 kOhm
    assert L._current_a(1.0, 100e3, 80e3, cv) == pytest.approx(1.6e-3, rel=1e-12)      # 160 V / 100 kOhm
    assert L._current_a(0.5, 80e3, 80e3, cv) == pytest.approx(1e-3, rel=1e-12)


# ---------------------------------------------------------------------------- composition
def test_state_layout_is_composed_from_the_module_declarations():
    declared = [n for names in layout.STATE_OWNERS.values() for n in names]
    assert len(declared) == len(set(declared)), "a state slot is declared twice"
    assert sorted(declared) == sorted(layout.STATE_NAMES)
    assert len(layout.STATE_NAMES) == len(set(layout.STATE_NAMES)) == layout.N_STATE
    assert [n for block in layout.STATE_BLOCKS for n in block] == layout.STATE_NAMES
    assert layout.STATE_OWNERS["motor"] == motor.OWNED_STATE_SLOTS
    assert layout.STATE_OWNERS["drivetrain"] == drivetrain.OWNED_STATE_SLOTS
    assert layout.STATE_OWNERS["fingertip"] == fingertip.OWNED_STATE_SLOTS
    assert layout.STATE_OWNERS["fsr"] == fsr.OWNED_STATE_SLOTS
    assert layout.STATE_OWNERS["noise"] == noise.OWNED_STATE_SLOTS
    assert layout.STATE_OWNERS["firmware"] == firmware.OWNED_STATE_SLOTS
    assert layout.STATE_OWNERS["estimator"] == blockmodels.OWNED_STATE_SLOTS
    # the order the state vector always had
    assert layout.STATE_NAMES[:5] == ["current_a", "pinion_pos_m", "pinion_vel_m_per_s", "board_pos_m",
                                      "board_vel_m_per_s"]
    assert S.tare_v == 25 and S.play_0 == 26 and S.creep_0_n == 30 and S.est_z0 == 39


def _device_mid_press():
    """A device pressing the pulp, with the next physics step due to sample and estimate."""
    dev = DeviceParams()
    plant = Plant.from_devices([dev], seeds=[5])
    plant.set_finger(1.0e-3)
    plant.set_input("fsr_temp_offset_k", 4.0)
    for _ in range(150):
        plant.advance(2.5)
    s, p, u = plant.state[0].copy(), plant.params[0].copy(), plant.inputs[0].copy()
    u[U.command_v] = 3.0
    s[S.sensor_phase] = p[P.substeps_per_sensor] - 1.0
    s[S.estimator_phase] = p[P.sensors_per_estimate] - 1.0
    assert s[S.contact_force_n] > 0.3 and s[S.pinion_vel_m_per_s] != 0.0
    return s, p, u


def _substep_by_hand(s, p, u):
    """One physics step composed from the law functions alone (the kernel's order)."""
    s = s.copy()
    h = p[P.h_s]
    g = p[P.n_over_r_per_m]
    v_cmd = driver_voltage(u[U.command_v], u[U.driver_supply_v])
    vp, vb = s[S.pinion_vel_m_per_s], s[S.board_vel_m_per_s]
    i = current_step(s[S.current_a], v_cmd, shaft_speed_rad_per_s(vp, g), 1.0 / p[P.motor_r_ohm], p[P.motor_ke],
                     p[P.motor_current_decay])
    f_motor = rack_force_n(i, p[P.motor_kt], g)
    f_mesh = mesh_force(s[S.pinion_pos_m] - s[S.board_pos_m], vp - vb, p[P.half_backlash_m], p[P.mesh_k_n_per_m],
                        p[P.mesh_c_n_s_per_m])
    fk_p, fs_p = loaded_friction_n(abs(vp), p[P.pinion_coulomb_n], p[P.pinion_static_n], p[P.stribeck_v_m_per_s],
                                   gear_loss_n(p[P.gear_mu], f_mesh))
    vp_new = friction_velocity_update(vp, f_motor - f_mesh - viscous_force_n(p[P.pinion_viscous_n_s_per_m], vp),
                                      h / p[P.pinion_mass_kg], fk_p, fs_p)
    f_b = (f_mesh - s[S.contact_force_n] + weight_along_n(p[P.board_mass_kg], u[U.gravity_along_m_per_s2])
           - viscous_force_n(p[P.guide_viscous_n_s_per_m], vb))
    fk_b = stribeck(abs(vb), p[P.guide_coulomb_n], p[P.guide_static_n], p[P.stribeck_v_m_per_s])
    vb_new = friction_velocity_update(vb, f_b, h / p[P.board_mass_kg], fk_b, p[P.guide_static_n])
    xp = s[S.pinion_pos_m] + h * vp_new
    xb, vb_new = end_stop(s[S.board_pos_m] + h * vb_new, vb_new, p[P.travel_min_m], p[P.travel_max_m])
    d = compression_m(xb, u[U.finger_pos_m])
    fe = elastic_force(d, p[P.finger_b_n_per_m], p[P.finger_m_per_m])
    dfe = fe - s[S.elastic_force_n]
    h1 = prony_step(s[S.prony_1_n], p[P.relax_a1], p[P.relax_c1], p[P.relax_beta1], dfe)
    h2 = prony_step(s[S.prony_2_n], p[P.relax_a2], p[P.relax_c2], p[P.relax_beta2], dfe)
    h3 = prony_step(s[S.prony_3_n], p[P.relax_a3], p[P.relax_c3], p[P.relax_beta3], dfe)
    fc = contact_force(d, fe, p[P.relax_c0], h1, h2, h3)
    s[S.current_a], s[S.pinion_pos_m], s[S.pinion_vel_m_per_s] = i, xp, vp_new
    s[S.board_pos_m], s[S.board_vel_m_per_s] = xb, vb_new
    s[S.prony_1_n], s[S.prony_2_n], s[S.prony_3_n], s[S.elastic_force_n], s[S.contact_force_n] = h1, h2, h3, fe, fc
    s[S.energy_j] += electrical_power_w(v_cmd, i) * h
    s[S.time_s] += h
    # the motor-current chain's two RC sections on the amplifier's image of the new current
    va = amplifier_v(i, p[P.isense_shunt_ohm], p[P.isense_gain], 0.0, p[P.isense_offset_v], p[P.isense_ref_v])
    s[S.isense_filter1_v] = rc_step(s[S.isense_filter1_v], va, p[P.isense_decay])
    s[S.isense_filter2_v] = rc_step(s[S.isense_filter2_v], s[S.isense_filter1_v], p[P.isense_decay2])
    # sensor: lag, then (due) a sample and (due) an estimate
    s[S.fsr_force_lagged_n] = lag_step(s[S.fsr_force_lagged_n], fc, p[P.fsr_lag_alpha])
    s[S.sensor_phase] = 0.0
    f_lag = s[S.fsr_force_lagged_n]
    f_eff = hysteresis(f_lag, s, S.play_0, p, P.play_w0, P.play_weight0, N_PLAYS)
    f_c = creep_force(f_eff, f_lag, s, S.creep_0_n, p, P.creep_a0, p[P.fsr_creep_weight], p[P.fsr_load_threshold_n],
                      fsr.N_CREEP)
    scale = temperature_factor(u[U.fsr_temp_offset_k], p[P.fsr_tempco_per_k], p[P.fsr_tempco_cold_per_k])
    scale *= fsr.press_scatter(f_lag, p[P.fsr_load_threshold_n], s, S.fsr_pressed, S.fsr_press_count, S.fsr_press_z,
                               p[P.seed], p[P.fsr_press_sigma])
    gs = conductance_s(f_c, p[P.fsr_k_ohm], p[P.fsr_n], p[P.fsr_g_standoff_s], scale, p[P.fsr_actuation_n],
                       p[P.fsr_turn_on_m])
    fault = int(u[U.fsr_fault])
    v = sensor_voltage(fault, gs, p[P.r2_ohm], p[P.divider_supply_v], u[U.fsr_fault_value])
    v += noise_v(p[P.fsr_noise_v], p[P.seed], s[S.sensor_count])
    s[S.sensor_count] += 1.0
    s[S.fsr_code] = adc_sample(s[S.fsr_code], v, p[P.adc_lsb_v], p[P.adc_max_code], fault)
    s[S.fsr_voltage_v] = adc_voltage(s[S.fsr_code], p[P.adc_lsb_v])
    vq = s[S.fsr_voltage_v]
    if p[P.est_creep_comp] > 0.0:
        vq = creep_compensated_v(vq, s[S.force_est_n], s, S.comp_creep_0_n, p, P.comp_creep_a0,
                                 p[P.comp_creep_weight], p[P.comp_load_threshold_n], fsr.N_CREEP, p[P.comp_fsr_n],
                                 p[P.comp_g_standoff_s], p[P.comp_reference_gain], p[P.r2_ohm],
                                 p[P.divider_supply_v], u[U.est_creep_preload])
    y = biquad_step(tared_v(vq, s[S.tare_v]), s, S.aa_z1, S.aa_z2,
                    p[P.aa_b0], p[P.aa_b1], p[P.aa_b2], p[P.aa_a1], p[P.aa_a2])
    s[S.estimator_phase] = 0.0
    s[S.force_est_n] = estimator_step(y, s, S.est_z0, S.est_raw_prev_n, p, P.est_in_x0, P.est_in_y0,
                                      int(p[P.est_n_in]), P.est_num0, P.est_den0, int(p[P.est_len]),
                                      P.est_out_x0, P.est_out_y0, int(p[P.est_n_out]),
                                      p[P.est_nyquist_average] > 0.0, p[P.est_clamp] > 0.0)
    # the end of the control period: the firmware reads the current once
    s[S.isense_count] += 1.0
    noise = noise_v(p[P.isense_noise_v], p[P.seed], NOISE_INDEX_OFFSET + s[S.isense_count])
    s[S.current_meas_a] = firmware_current_a(adc_code(s[S.isense_filter2_v] + noise, p[P.isense_lsb_v],
                                                      p[P.isense_max_code]),
                                             p[P.isense_zero_code], p[P.isense_lsb_v], p[P.isense_nominal_v_per_a])
    return s


def test_current_sense_amplifier_is_the_ina240_transfer():
    """V_ref + G (1 + e_G)(R_sh i + V_os): INA240A3 (100 V/V), 50 mOhm, mid-supply 2.5 V; clipped
    to the 0-5 V swing."""
    assert amplifier_v(0.1, 0.05, 100.0, 0.0, 0.0, 2.5) == pytest.approx(3.0, abs=1e-12)   # 0.1 A -> +0.5 V
    assert amplifier_v(-0.2, 0.05, 100.0, 0.0, 0.0, 2.5) == pytest.approx(1.5, abs=1e-12)
    assert amplifier_v(0.1, 0.05, 100.0, 0.002, 25e-6, 2.5) == pytest.approx(2.5 + 100.2 * (0.005 + 25e-6))
    assert amplifier_v(0.0, 0.05, 100.0, 0.0, 0.0, 2.5) == 2.5
    assert amplifier_v(1.0, 0.05, 100.0, 0.0, 0.0, 2.5) == 5.0 and amplifier_v(-1.0, 0.05, 100.0, 0.0, 0.0, 2.5) == 0.0


def test_current_sense_rc_section_is_the_exact_first_order_step():
    """One held-input step of tau dv/dt = v_in - v: v_in + (v - v_in) exp(-h/tau)."""
    import math
    h, tau = 1e-4, 159e-6
    d = math.exp(-h / tau)
    assert rc_step(2.5, 3.0, d) == pytest.approx(3.0 - 0.5 * d, abs=1e-15)
    v = 2.5
    for _ in range(int(round(tau / h * 10))):          # ten time constants: settled to 5e-5
        v = rc_step(v, 3.0, d)
    assert abs(v - 3.0) < 0.5 * math.exp(-9.5)


def test_firmware_current_reading_uses_the_nominal_transfer_and_its_zero():
    """(code - zero) LSB / (G_nom R_sh,nom): 5 V/A nominal, 10-bit 5 V ADC (0.977 mA per code)."""
    lsb = 5.0 / 1024
    assert firmware_current_a(612.0, 512.0, lsb, 5.0) == pytest.approx(100 * lsb / 5.0, abs=1e-15)
    assert firmware_current_a(511.5, 511.5, lsb, 5.0) == 0.0
    assert firmware_current_a(412.0, 512.0, lsb, 5.0) == pytest.approx(-0.09765625, abs=1e-15)


def test_the_current_chain_reads_a_held_current_within_its_worst_case():
    """A nominal plant held at a steady current: the firmware's reading lies within the chain's
    worst-case error of the true current, and a unit with a 1 % high shunt and +0.2 % gain reads
    about 1.2 % high (the firmware knows only the nominal transfer)."""
    import dataclasses
    from ebraille_sim.physics.current_sense import worst_case_error_a
    from ebraille_sim.physics.params import CurrentSenseParams, DeviceParams
    from ebraille_sim.plant.backends import make_plant
    for cs in (CurrentSenseParams(), CurrentSenseParams(shunt_error=0.01, gain_error=0.002, offset_v=25e-6)):
        dev = dataclasses.replace(DeviceParams(), current_sense=cs)
        plant = make_plant([dev], seeds=[7])
        plant.set_finger(-1e-3)                         # pressed into the pulp at the end stop: stalled
        reads, trues = [], []
        for _ in range(300):
            plant.advance(1.5)
            reads.append(plant.state[0, S.current_meas_a])
            trues.append(plant.state[0, S.current_a])
        i_true, i_read = float(np.mean(trues[-100:])), float(np.mean(reads[-100:]))
        assert i_true > 0.02
        assert abs(i_read - i_true) <= worst_case_error_a(cs, i_true)
        if cs.shunt_error:
            assert i_read / i_true - 1.0 == pytest.approx(0.012, abs=0.006)


def test_one_kernel_step_is_exactly_the_composition_of_the_law_functions():
    s, p, u = _device_mid_press()
    expected = _substep_by_hand(s, p, u)
    kernel.advance(s, p, u, 1)
    np.testing.assert_array_equal(s, expected)
    # reversing into the gap, with a forced sensor voltage in place of the divider
    s2, p2, u2 = _device_mid_press()
    u2[U.command_v], u2[U.fsr_fault], u2[U.fsr_fault_value] = -4.0, FAULT_VALUE, 0.7
    expected = _substep_by_hand(s2, p2, u2)
    kernel.advance(s2, p2, u2, 1)
    np.testing.assert_array_equal(s2, expected)


def test_static_helpers_call_the_same_law_functions():
    f = NOMINAL
    for d in (0.0, 3e-4, 1.4e-3, 2.4e-3):
        assert f.elastic_force_n(d) == elastic_force(d, f.stiffness_b_n_per_m, f.exponent_m_per_m)
    assert f.elastic_force_n(f.compression_at_m(2.0)) == pytest.approx(2.0, rel=1e-12)
    assert f.relax_weight_inf * f.elastic_force_n(f.compression_at_m(1.0, relaxed=True)) == pytest.approx(1.0,
                                                                                                          rel=1e-12)
    s_fsr, c = FSRParams(), CircuitParams()
    for force in (0.0, 0.3, 1.0, 2.5):
        gs = conductance_s(force, s_fsr.resistance_at_1n_ohm, s_fsr.exponent, 1 / s_fsr.standoff_resistance_ohm, 1.0,
                           s_fsr.actuation_force_n, s_fsr.turn_on_steepness)
        assert s_fsr.resistance_ohm(force) == 1.0 / gs
        assert static_conductance(force, s_fsr) == gs
        assert static_voltage(force, s_fsr, c) == divider_voltage(gs, c.r2_ohm, c.supply_v)
    w = fsr.creep_term_weight(s_fsr.creep_per_decade, s_fsr.creep_tau_min_s, s_fsr.creep_tau_max_s)
    gain = fsr.held_creep_gain(20.0, w, s_fsr.creep_tau_min_s, s_fsr.creep_tau_max_s, fsr.N_CREEP)
    f_eff = 1.0 * loading_branch_factor(s_fsr)
    g20 = conductance_s(f_eff * gain, s_fsr.resistance_at_1n_ohm, s_fsr.exponent, 1 / s_fsr.standoff_resistance_ohm,
                        1.0, s_fsr.actuation_force_n, s_fsr.turn_on_steepness)
    assert loading_voltage(1.0, s_fsr, c, 20.0) == divider_voltage(g20, c.r2_ohm, c.supply_v)
    dev = DeviceParams()
    k_pulp = tangent_stiffness_n_per_m(10.0, f.stiffness_b_n_per_m, f.exponent_m_per_m)
    w = math.sqrt((dev.drivetrain.mesh_stiffness_n_per_m + k_pulp) / dev.drivetrain.moving_mass_kg)
    assert check_step(dev) == pytest.approx(w / dev.rates.physics_rate_hz, rel=1e-15)


def test_kernel_adc_reads_the_static_voltage_exactly_without_memory_or_noise():
    s_fsr = FSRParams(noise_v_rms=0.0, hysteresis_fraction=0.0, creep_per_decade=0.0, press_repeatability=0.0)
    c = CircuitParams(adc_bits=24)
    dev = DeviceParams(fsr=s_fsr, circuit=c)
    p = pack_params(dev, 0.0)
    s = initial_state(dev, p)
    u = np.zeros(N_INPUT)
    kernel.advance_sensor_only(s, p, u, 1.2, 2000)
    v = static_voltage(1.2, s_fsr, c)
    assert s[S.fsr_voltage_v] == adc_voltage(adc_code(v, c.adc_lsb_v, c.adc_max_code), c.adc_lsb_v)


def test_estimator_rate_is_the_models_own():
    assert not hasattr(EstimatorParams(), "rate_hz")
    from ebraille_sim.physics.params import RateParams
    dev = DeviceParams(rates=RateParams(control_rate_hz=150.0, sensor_rate_hz=150.0, physics_rate_hz=10500.0))
    with pytest.raises(ValueError, match="whole multiple of the estimator model's rate"):
        pack_params(dev, 0.0)


def test_importing_the_plant_does_not_import_scipy_signal():
    code = "import sys, ebraille_sim.plant.lumped, ebraille_sim.plant.kernel; print('scipy.signal' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_inverse_hysteresis_retraces_the_input_wherever_the_output_moves():
    """Forward play operators on a random walk in ln F, then the inverse on their outputs: where
    the output changed the inverse returns the input (to rounding) and advances the same plays;
    where it did not (the stretch after a reversal) it holds its last input."""
    widths, weights = fsr.play_widths(FSRS["nominal"])
    pp = np.array(widths + weights)
    n = len(widths)
    fwd = np.full(n, math.log(F_EPS_N))
    inv = fwd.copy()
    rng = np.random.default_rng(3)
    f = np.abs(1.0 + np.cumsum(rng.normal(0.0, 0.01, 4000)))
    x_prev, l_prev, moved, held = math.log(F_EPS_N), None, 0, 0
    for fk in f:
        x = fsr.log_force(fk)
        l_out = math.log(fsr.hysteresis(fk, fwd, 0, pp, 0, n, n) + F_EPS_N)
        xi = fsr.inverse_hysteresis(l_out, x_prev, inv, 0, pp, 0, n, n)
        if l_prev is None or l_out != l_prev:
            assert xi == pytest.approx(x, abs=1e-12)
            np.testing.assert_allclose(inv, fwd, rtol=0, atol=1e-12)
            moved += 1
        else:
            assert xi == x_prev
            held += 1
        x_prev, l_prev = xi, l_out
    assert moved > 500 and held > 1000
    # on the loading branch (plays at their lower edges) a rise is seen at once, a fall of less
    # than twice the narrowest width not at all
    st = np.array([-w for w in widths])
    assert fsr.inverse_hysteresis(sum(wt * y for wt, y in zip(weights, st)) + 1e-3, 0.0, st.copy(), 0, pp, 0, n,
                                  n) == pytest.approx(1e-3, abs=1e-12)
    below = fsr.inverse_hysteresis(sum(wt * y for wt, y in zip(weights, st)) - 1e-3, 0.0, st.copy(), 0, pp, 0, n, n)
    assert below == pytest.approx(-2.0 * widths[0] - 1e-3 / weights[0], abs=1e-12)


def test_hysteresis_compensation_reads_the_loading_branch():
    """The film's conductance on its loading branch passes unchanged; on the unloading branch
    (plays at their upper edges, 2 H higher in ln F_eff) it is brought back to the loading
    branch's value at the same force; a change within the deadband is ignored."""
    nominal = FSRS["nominal"]
    widths, weights = fsr.play_widths(nominal)
    n = len(widths)
    pp = np.array(widths + weights)
    h = sum(w * x for w, x in zip(weights, widths))
    r2, vs, k, ex, gso, db = 1150.0, 5.0, nominal.resistance_at_1n_ohm, nominal.exponent, 1e-7, 0.002

    def volts(f_eff):
        return divider_voltage(gso + f_eff ** ex / k, r2, vs)

    nm = firmware.HYSTERESIS_MEDIAN - 1
    M0 = 2 + n
    T0 = M0 + nm

    def state(x, side, v):
        return np.array([v, x] + [x + side * w for w in widths] + [v] * nm + [0.0, v, v])

    x = math.log(1.2 + F_EPS_N)
    v_load = volts(math.exp(x - h) - F_EPS_N)
    st = state(x, -1.0, v_load)
    out = firmware.hysteresis_compensated_v(v_load, st, 0, 1, 2, M0, T0, T0 + 4, pp, 0, n, n, h, db, db, 0.0, 0.1, 0.0, k, ex, gso, r2, vs)
    assert out == pytest.approx(v_load, rel=1e-12)
    assert st[1] == pytest.approx(x, abs=1e-12)
    v_unload = volts(math.exp(x + h) - F_EPS_N)
    st = state(x, +1.0, v_unload)
    out = firmware.hysteresis_compensated_v(v_unload, st, 0, 1, 2, M0, T0, T0 + 4, pp, 0, n, n, h, db, db, 0.0, 0.1, 0.0, k, ex, gso, r2, vs)
    assert out == pytest.approx(v_load, rel=1e-12)
    assert v_unload > 1.05 * v_load
    # the film further down its unloading branch: the inversion moves the input with the output
    # (slope 1 on that branch) and the result is the loading branch 2 H lower
    v_down = v_unload - 3.0 * db
    st[M0:M0 + nm] = v_down                          # a sustained change: the median passes it
    out3 = firmware.hysteresis_compensated_v(v_down, st, 0, 1, 2, M0, T0, T0 + 4, pp, 0, n, n, h, db, db, 0.0, 0.1, 0.0, k, ex, gso, r2, vs)
    vf = v_unload - 2.0 * db
    assert st[0] == vf
    f_down = (k * (fsr.divider_conductance_s(vf, r2, vs) - gso)) ** (1.0 / ex)
    assert st[1] == pytest.approx(math.log(f_down + F_EPS_N) - h, abs=1e-12)
    assert out3 == pytest.approx(volts(math.exp(math.log(f_down + F_EPS_N) - 2.0 * h) - F_EPS_N), rel=1e-12)
    st = state(x, +1.0, v_unload)
    out = firmware.hysteresis_compensated_v(v_unload, st, 0, 1, 2, M0, T0, T0 + 4, pp, 0, n, n, h, db, db, 0.0, 0.1, 0.0, k, ex, gso, r2, vs)
    # within the deadband the held voltage is used: the output does not move
    out2 = firmware.hysteresis_compensated_v(v_unload + 0.9 * db, st, 0, 1, 2, M0, T0, T0 + 4, pp, 0, n, n, h, db, db, 0.0, 0.1, 0.0, k, ex, gso,
                                                r2, vs)
    assert out2 == out and st[0] == v_unload
    # a railed or faulted divider passes unchanged
    assert firmware.hysteresis_compensated_v(vs, st, 0, 1, 2, M0, T0, T0 + 4, pp, 0, n, n, h, db, db, 0.0, 0.1, 0.0, k, ex, gso, r2, vs) == vs
    assert firmware.hysteresis_compensated_v(0.0, st, 0, 1, 2, M0, T0, T0 + 4, pp, 0, n, n, h, db, db, 0.0, 0.1, 0.0, k, ex, gso, r2, vs) == 0.0


def test_turn_test_reads_slow_and_fast_reversals_and_not_noise():
    """The hysteresis compensation's turn test (voltages in counts).  A fast rise is followed
    within ``follow`` and, the 8-sample average lagging it by more than ``turn``, taken to end
    in a turn on the next sample (output unchanged).  A slow fall of two counts, which the plain
    deadband never reads, is then followed down along the average, ``max(v, a) + follow``; a
    step fall of two counts outruns the average and is itself taken to end in a turn (not
    read).  A code toggling does not ratchet the output below the toggle's mean, and a fall
    beyond the plain swing from the turn is followed at once."""
    db, fo, turn = 1.5, 0.5, 1.75
    alpha = -math.expm1(-1.0 / 8.0)

    def step(s, v):
        y = firmware.turn_tested_v(v, v, s, 0, 1, db, fo, turn, alpha)
        s[0] = y
        return y

    s = np.array([100.0, 0.0, 100.0, 100.0, 100.0])      # output, direction, average, extreme, turn
    assert step(s, 110.0) == 109.5 and s[1] == 1.0 and s[3] == 110.0 and s[2] == 100.0 + 10.0 * alpha
    assert step(s, 110.0) == 109.5 and s[1] == -1.0 and s[4] == 110.0
    for _ in range(60):
        assert step(s, 110.0) == 109.5 and s[1] == -1.0
    plain = 110.0 - db
    assert fsr.play(108.0, plain, db) == plain                  # the plain deadband never reads the fall
    stepped = s.copy()
    assert [step(stepped, 108.0) for _ in range(40)] == [109.5] * 40 and stepped[1] == 1.0
    ramp = 110.0 - 2.0 * np.arange(1, 61) / 60.0
    outs, avgs = [], []
    for v in np.concatenate([ramp, np.full(60, 108.0)]):
        outs.append(step(s, v))
        avgs.append(s[2])
    m = np.minimum.accumulate(np.maximum(np.concatenate([ramp, np.full(60, 108.0)]), avgs))
    want = np.where(m < 109.5 - fo, m + fo, 109.5)
    assert np.array(outs) == pytest.approx(want, abs=1e-12)
    assert outs[0] == 109.5 and outs[-1] == pytest.approx(108.5, abs=1e-3) and s[1] == -1.0
    lo = [step(s, 107.0 + (k % 2)) for k in range(1000)]
    assert s[1] == -1.0 and min(lo) >= 107.5 + fo - 0.05
    assert step(s, 104.0) == 104.5                              # beyond the plain swing from the turn


def test_centring_relaxes_the_input_to_the_middle_of_the_blind_stretch_and_snaps_on_a_move():
    """While the film shows no move the input read relaxes by ``alpha`` of its distance to the
    middle of the inputs the plays admit (``max(y - w) .. min(y + w)``); on a move it is the
    inverse's own.  After a rise (plays at ``x - w``) the middle is the narrowest width below
    ``x``, after a fall the same above it."""
    widths = [0.02, 0.04, 0.06, 0.08]
    n = len(widths)
    pp = np.array(widths)
    x = 0.3
    s = np.array([x] + [x - w for w in widths])           # the input given, the plays after a rise
    alpha = 0.1
    assert firmware.centred_x(x, True, s, 0, 1, pp, 0, n, alpha) == x
    want = x
    for _ in range(5):
        want += alpha * (x - widths[0] - want)
        assert firmware.centred_x(x, False, s, 0, 1, pp, 0, n, alpha) == pytest.approx(want, abs=1e-12)
    for _ in range(400):
        firmware.centred_x(x, False, s, 0, 1, pp, 0, n, alpha)
    assert s[0] == pytest.approx(x - widths[0], abs=1e-12)
    # a move: the inverse's input at once; after a fall the middle lies above it
    s[1:] = [x + w for w in widths]
    assert firmware.centred_x(x, True, s, 0, 1, pp, 0, n, alpha) == x
    assert firmware.centred_x(x, False, s, 0, 1, pp, 0, n, alpha) == pytest.approx(x + alpha * widths[0], abs=1e-12)
    # plays left inside their bands by a minor loop: the middle of the narrowest admitted interval
    s[1:] = [x - 0.01, x + 0.03, x - 0.05, x + 0.02]
    lo, hi = max(y - w for y, w in zip(s[1:], widths)), min(y + w for y, w in zip(s[1:], widths))
    s[0] = x
    assert firmware.centred_x(x, False, s, 0, 1, pp, 0, n, 1.0) == pytest.approx(0.5 * (lo + hi), abs=1e-12)


def test_running_median_passes_a_ramp_delayed_and_removes_a_spike():
    nm = firmware.HYSTERESIS_MEDIAN - 1
    st = np.zeros(nm)
    out = [firmware.running_median_v(float(k), st, 0) for k in range(1, 12)]
    assert out[nm // 2:] == [float(k) for k in range(1, 12 - nm // 2)]
    st = np.full(nm, 1.0)
    seq = [1.0, 1.0, 5.0, 1.0, 1.0, 1.0, -3.0, -3.0, 1.0, 1.0]
    assert [firmware.running_median_v(v, st, 0) for v in seq] == [1.0] * len(seq)
    # the selection is the median of the last five samples, whatever their order
    rng = np.random.default_rng(4)
    x = rng.integers(0, 4, 3000).astype(float)           # many ties, as quantised codes have
    st = x[3::-1].copy()
    got = [firmware.running_median_v(x[k], st, 0) for k in range(4, len(x))]
    np.testing.assert_array_equal(got, [np.median(x[k - 4:k + 1]) for k in range(4, len(x))])
    np.testing.assert_array_equal(st, x[:-5:-1])


def test_assembly_measures_the_units_hysteresis_and_the_firmware_packs_it():
    """A press to 1 N, on to 2 N and back to 1 N through the plant's laws reads the unit's loop
    (R_F+ - R_F-)/R_F+; with the compensation on and no loop given, the packed play widths are
    those of that loop with the nominal exponent; a loop given explicitly is used as given."""
    import dataclasses as dc
    from ebraille_sim.estimation.calibration import measured_hysteresis_fraction
    nominal = FSRS["nominal"]
    for h in (0.05, 0.10, 0.15):
        drawn = dc.replace(nominal, hysteresis_fraction=h)
        assert measured_hysteresis_fraction(drawn) == pytest.approx(fsr.play_loop_fraction(drawn), abs=3e-4)
    unit = dc.replace(nominal, hysteresis_fraction=0.14, exponent=0.95)
    # a given loop is the datasheet's (creep included): the firmware inverts its play part by the nominal creep law
    for given, expect in ((None, measured_hysteresis_fraction(unit)), (0.10, fsr.play_loop_fraction(nominal))):
        dev = DeviceParams(fsr=unit, estimator=EstimatorParams(hysteresis_compensation=True, hysteresis_fraction=given))
        p = pack_params(dev, 0)
        widths, _ = fsr.play_loop_widths(expect, nominal.exponent)
        np.testing.assert_allclose([p[P[f"comp_play_w{j}"]] for j in range(N_PLAYS)], widths, rtol=1e-12)
        assert p[P.comp_hyst_halfwidth] == pytest.approx(-math.log(1.0 - expect) / (2.0 * nominal.exponent), rel=1e-12)
    with pytest.raises(ValueError, match="hysteresis_fraction"):
        EstimatorParams(hysteresis_fraction=1.0)


def test_calibration_table_maps_each_bench_reading_onto_its_load():
    """The unit's table (readings 0.57, 1.0, 1.44, 1.94 N at 0.5, 1, 1.5, 2 N): each reading gives
    its load; between two points the map is linear, below the first and above the last the
    proportional one of that point (zero stays zero, a negative estimate keeps its sign); an
    empty table passes the estimate unchanged."""
    reads, loads = [0.57, 1.0, 1.44, 1.94], [0.5, 1.0, 1.5, 2.0]
    p = np.array(reads + loads)
    n = 4

    def t(f):
        return firmware.table_calibrated_n(f, p, 0, n, n)

    for r, f in zip(reads, loads):
        assert t(r) == pytest.approx(f, rel=1e-15)
    assert t(1.22) == pytest.approx(1.0 + 0.5 * (1.22 - 1.0) / 0.44, rel=1e-14)
    assert t(0.75) == pytest.approx(0.5 + 0.5 * (0.75 - 0.57) / 0.43, rel=1e-14)
    assert t(0.2) == pytest.approx(0.2 * 0.5 / 0.57, rel=1e-14)
    assert t(0.0) == 0.0 and t(-0.1) == pytest.approx(-0.1 * 0.5 / 0.57, rel=1e-14)
    assert t(3.0) == pytest.approx(3.0 * 2.0 / 1.94, rel=1e-14)
    assert firmware.table_calibrated_n(1.3, p, 0, n, 0) == 1.3


def test_bench_creep_per_decade_recovers_the_units_creep_law():
    """The bench's reading of a unit's creep from its 1 N holds (2 s and 20 s): with the nominal
    exponent, no press scatter and no conversion noise it is the unit's creep per decade to 0.1 %
    (the creep law inverted over the decade of the nominal retardation times; the film's turn-on
    factor moves with the crept force by a few 1e-4); the noise of 256 conversions (0.125 mV on
    the 2 s and 20 s readings) and a 2 % load error move it by less than 0.001 per decade."""
    from ebraille_sim.estimation.calibration import bench_creep_per_decade
    for per_decade in (0.01, 0.0275, 0.05):
        quiet = DeviceParams(fsr=dataclasses.replace(FSRS["nominal"], creep_per_decade=per_decade,
                                                     noise_v_rms=0.0, press_repeatability=0.0))
        assert bench_creep_per_decade(quiet) == pytest.approx(per_decade, rel=1e-3)
        noisy = DeviceParams(fsr=dataclasses.replace(FSRS["nominal"], creep_per_decade=per_decade))
        assert bench_creep_per_decade(noisy, load_error=0.02) == pytest.approx(per_decade, abs=1e-3)


def test_bench_loop_less_the_bench_creep_is_the_units_play_loop():
    """The bench's loop of a unit (1 N up and down a 0-2-0 N cycle in 1 s legs, creep included)
    less the share its own creep law gives in that cycle is the unit's rate-independent loop
    (``measured_hysteresis_fraction``, the creep-free check) to 3 %, for units with little and
    much creep and loop; the loop with the creep in it is larger than the play part by the
    creep's share."""
    from ebraille_sim.estimation.calibration import bench_hysteresis_fraction, measured_hysteresis_fraction
    for h, c in ((0.05, 0.01), (0.10, 0.0275), (0.15, 0.05), (0.15, 0.01)):
        unit = dataclasses.replace(FSRS["nominal"], hysteresis_fraction=h, creep_per_decade=c)
        bench = bench_hysteresis_fraction(DeviceParams(fsr=unit))
        play = fsr.play_loop_fraction(dataclasses.replace(FSRS["nominal"], hysteresis_fraction=bench,
                                                          creep_per_decade=c))
        truth = measured_hysteresis_fraction(unit)
        assert play == pytest.approx(truth, rel=0.03)
        assert bench > truth + 0.5 * fsr.creep_loop_fraction(unit)

