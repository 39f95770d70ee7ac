"""The compiled closed-loop kernel: one control period of the lumped plant and the sensor.

Everything physical that happens between two controller updates runs here, compiled with
Numba.  A single device and a batch of devices call the same :func:`advance`, so a
scenario, the Gymnasium env and its vectorised form see identical physics.  State,
parameter and input slots are named in :mod:`ebraille_sim.plant.layout`.

The kernel holds no law of its own: every force, flow and conversion is a function of the
module that states the law (:mod:`~ebraille_sim.physics.motor`,
:mod:`~ebraille_sim.physics.drivetrain`, :mod:`~ebraille_sim.physics.fingertip`,
:mod:`~ebraille_sim.physics.fsr`, :mod:`~ebraille_sim.physics.noise`,
:mod:`~ebraille_sim.estimation.firmware`, :mod:`~ebraille_sim.estimation.blockmodels`), inlined at compile time.  The kernel only
orders those calls, sums the forces on each body, integrates positions (semi-implicit
Euler), time and energy, and schedules the sensor and estimator samples.

Per physics step ``h`` (default 0.1 ms), with the command held over the control period:

1. driver: command clipped to +/- the driver supply (:func:`~ebraille_sim.physics.motor.driver_voltage`);
2. armature current advanced exactly (:func:`~ebraille_sim.physics.motor.current_step`);
3. mesh force through the backlash dead zone (:func:`~ebraille_sim.physics.drivetrain.mesh_force`);
4. pinion side (reflected rotor inertia, gear loss) and board (racks + board mass)
   velocities updated with dry friction at the velocity level, then positions, then the
   end stops (:func:`~ebraille_sim.physics.drivetrain.end_stop`);
5. fingertip QLV contact force from the new board position
   (:func:`~ebraille_sim.physics.fingertip.prony_step`, :func:`~ebraille_sim.physics.fingertip.contact_force`);
6. FSR mechanical lag; at every sensor sample the hysteresis, hereditary creep, temperature
   and press-to-press factors, conduction with its turn-on, divider (or fault), noise and ADC, then the estimator's creep compensation
   (:func:`~ebraille_sim.estimation.firmware.creep_compensated_v`, when on), the
   hysteresis compensation (:func:`~ebraille_sim.estimation.firmware.hysteresis_compensated_v`,
   when on) and the anti-alias filter; at every estimator
   sample the block-oriented estimator (:func:`~ebraille_sim.estimation.blockmodels.estimator_step`).

Speed: :func:`advance` keeps the per-step states in local variables over its steps and forms
``h/m`` and ``1/R`` once per call; it and its batch and sensor-only forms allocate nothing and
are compiled without Numba's reference counting (``_nrt=False``): with it, every inlined call
that takes an array counted that array up and down atomically, which cost more than the laws.

Stability: the semi-implicit step is stable while ``w h < 2`` for the stiffest
oscillation, the board on the mesh and the pulp; :func:`ebraille_sim.plant.lumped.check_step`
rejects physics rates that give ``w h > 1``.
"""
from __future__ import annotations

from ebraille_sim.base.compiled import njit

from ebraille_sim.estimation.blockmodels import estimator_step
from ebraille_sim.estimation.firmware import (biquad_step, creep_compensated_v, hysteresis_compensated_v,
                                              table_calibrated_n, tared_v)
from ebraille_sim.physics.current_sense import NOISE_INDEX_OFFSET, amplifier_v, rc_step, sample_current_a
from ebraille_sim.physics.drivetrain import (end_stop, friction_velocity_update, gear_loss_n, loaded_friction_n,
                                             mesh_force, shaft_speed_rad_per_s, stribeck, viscous_force_n,
                                             weight_along_n)
from ebraille_sim.physics.fingertip import compression_m, contact_force, elastic_force, prony_step
from ebraille_sim.physics.fsr import (adc_sample, adc_voltage, conductance_s, creep_force, hysteresis, lag_step,
                                      press_scatter, sensor_voltage, temperature_factor)
from ebraille_sim.physics.motor import current_step, driver_voltage, electrical_power_w, rack_force_n
from ebraille_sim.physics.noise import noise_v
from ebraille_sim.plant.layout import MAX_BREAKPOINTS, MAX_TF_LEN, N_CREEP, N_PLAYS, P, S, U

assert MAX_TF_LEN >= 2 and MAX_BREAKPOINTS >= 2


@njit(cache=True, inline="always")
def estimator_update(s, p, u):
    """One sample of the in-loop estimator on the filtered voltage ``u``, through the unit's
    calibration table; returns the estimate."""
    f = estimator_step(u, s, S.est_z0, S.est_raw_prev_n, p,
                       P.est_in_x0, P.est_in_y0, int(p[P.est_n_in]),
                       P.est_num0, P.est_den0, int(p[P.est_len]),
                       P.est_out_x0, P.est_out_y0, int(p[P.est_n_out]),
                       p[P.est_nyquist_average] > 0.0, p[P.est_clamp] > 0.0)
    return table_calibrated_n(f, p, P.est_cal_x0, P.est_cal_y0, int(p[P.est_cal_n]))


@njit(cache=True, inline="always")
def sensor_sample(s, p, u):
    """One ADC sample of the FSR divider, then the estimator's creep and hysteresis
    compensations (when on), the anti-alias filter and the estimator."""
    f_lag = s[S.fsr_force_lagged_n]
    f_eff = hysteresis(f_lag, s, S.play_0, p, P.play_w0, P.play_weight0, N_PLAYS)
    f_c = creep_force(f_eff, f_lag, s, S.creep_0_n, p, P.creep_a0, p[P.fsr_creep_weight], p[P.fsr_load_threshold_n],
                      N_CREEP)
    scale = temperature_factor(u[U.fsr_temp_offset_k], p[P.fsr_tempco_per_k], p[P.fsr_tempco_cold_per_k])
    scale *= press_scatter(f_lag, p[P.fsr_load_threshold_n], s, S.fsr_pressed, S.fsr_press_count, S.fsr_press_z,
                           p[P.seed], p[P.fsr_press_sigma])
    g = conductance_s(f_c, p[P.fsr_k_ohm], p[P.fsr_n], p[P.fsr_g_standoff_s], scale, p[P.fsr_actuation_n],
                      p[P.fsr_turn_on_m])
    fault = int(u[U.fsr_fault])
    v = sensor_voltage(fault, g, p[P.r2_ohm], p[P.divider_supply_v], u[U.fsr_fault_value])
    v += noise_v(p[P.fsr_noise_v], p[P.seed], s[S.sensor_count])
    s[S.sensor_count] += 1.0
    s[S.fsr_code] = adc_sample(s[S.fsr_code], v, p[P.adc_lsb_v], p[P.adc_max_code], fault)
    vq = adc_voltage(s[S.fsr_code], p[P.adc_lsb_v])
    s[S.fsr_voltage_v] = vq
    if p[P.est_creep_comp] > 0.0:
        vq = creep_compensated_v(vq, s[S.force_est_n], s, S.comp_creep_0_n, p, P.comp_creep_a0,
                                 p[P.comp_creep_weight], p[P.comp_load_threshold_n], N_CREEP, p[P.comp_fsr_n],
                                 p[P.comp_g_standoff_s], p[P.comp_reference_gain], p[P.r2_ohm],
                                 p[P.divider_supply_v], u[U.est_creep_preload])
    if p[P.est_hyst_comp] > 0.0:
        vq = hysteresis_compensated_v(vq, s, S.comp_hyst_v, S.comp_hyst_x, S.comp_play_0, S.comp_med_0,
                                      S.comp_turn_dir, S.comp_centre_x, p, P.comp_play_w0, P.comp_play_weight0, N_PLAYS,
                                      p[P.comp_hyst_halfwidth], p[P.comp_hyst_deadband_v], p[P.comp_hyst_follow_v],
                                      p[P.comp_hyst_turn_v], p[P.comp_turn_alpha], p[P.comp_centre_alpha],
                                      p[P.comp_fsr_k_ohm], p[P.comp_fsr_n],
                                      p[P.comp_g_standoff_s], p[P.r2_ohm], p[P.divider_supply_v])
    y = biquad_step(tared_v(vq, s[S.tare_v]), s, S.aa_z1, S.aa_z2,
                    p[P.aa_b0], p[P.aa_b1], p[P.aa_b2], p[P.aa_a1], p[P.aa_a2])
    s[S.estimator_phase] += 1.0
    if s[S.estimator_phase] >= p[P.sensors_per_estimate]:
        s[S.estimator_phase] = 0.0
        s[S.force_est_n] = estimator_update(s, p, y)


@njit(cache=True, inline="always")
def current_sample(s, p):
    """The firmware's one conversion of the motor current at the end of a control period (its noise
    indexed by the physics steps so far: the reading at a time is the same at any control rate)."""
    noise = noise_v(p[P.isense_noise_v], p[P.seed], NOISE_INDEX_OFFSET + s[S.isense_count])
    s[S.current_meas_a] = sample_current_a(s[S.isense_filter2_v], noise, p[P.isense_zero_code], p[P.isense_lsb_v],
                                           p[P.isense_max_code], p[P.isense_nominal_v_per_a])


@njit(cache=True, inline="always")
def sensor_substep(s, p, u, lagged_n, filter1_v, filter2_v, phase, current_a, contact_force_n):
    """The sensors at the physics rate: the motor-current chain's RC sections on the amplifier's
    image of the armature current (:mod:`ebraille_sim.physics.current_sense`), the FSR mechanical
    lag, and an FSR ADC sample when one is due.  Takes and returns the per-step sensor states
    ``(lagged force, filter 1, filter 2, sample phase)``, which the loop keeps in registers; a
    sample reads the lagged force from ``s``."""
    v = amplifier_v(current_a, p[P.isense_shunt_ohm], p[P.isense_gain], 0.0, p[P.isense_offset_v],
                    p[P.isense_ref_v])
    filter1_v = rc_step(filter1_v, v, p[P.isense_decay])
    filter2_v = rc_step(filter2_v, filter1_v, p[P.isense_decay2])       # decay2 = 0: one section
    lagged_n = lag_step(lagged_n, contact_force_n, p[P.fsr_lag_alpha])
    phase += 1.0
    if phase >= p[P.substeps_per_sensor]:
        phase = 0.0
        s[S.fsr_force_lagged_n] = lagged_n
        sensor_sample(s, p, u)
    return lagged_n, filter1_v, filter2_v, phase


@njit(cache=True, inline="always")
def mechanics_substep(p, u, h, h_per_pinion_mass, h_per_board_mass, g_armature_s,
                      xp, vp, xb, vb, i, fe, h1, h2, h3, fc):
    """One physics step of the lumped drive train, board and fingertip, on the mechanical state
    ``(pinion position and velocity, board position and velocity, current, elastic force, Prony
    states, contact force)``; returns the new state and the electrical energy of the step (J)."""
    v_cmd = driver_voltage(u[U.command_v], u[U.driver_supply_v])
    g = p[P.n_over_r_per_m]
    i = current_step(i, v_cmd, shaft_speed_rad_per_s(vp, g), g_armature_s, p[P.motor_ke], p[P.motor_current_decay])
    f_motor = rack_force_n(i, p[P.motor_kt], g)
    f_mesh = mesh_force(xp - xb, vp - vb, p[P.half_backlash_m], p[P.mesh_k_n_per_m], p[P.mesh_c_n_s_per_m])
    # pinion side: reflected rotor inertia, brush/bearing friction grown by the gear loss
    fk_p, fs_p = loaded_friction_n(abs(vp), p[P.pinion_coulomb_n], p[P.pinion_static_n], p[P.stribeck_v_m_per_s],
                                   gear_loss_n(p[P.gear_mu], f_mesh))
    if u[U.motor_jammed] > 0.0:
        vp_new = 0.0
    else:
        vp_new = friction_velocity_update(vp, f_motor - f_mesh - viscous_force_n(p[P.pinion_viscous_n_s_per_m], vp),
                                          h_per_pinion_mass, fk_p, fs_p)
    # board: mesh, contact, gravity, guide friction
    f_b = (f_mesh - fc + weight_along_n(p[P.board_mass_kg], u[U.gravity_along_m_per_s2])
           - viscous_force_n(p[P.guide_viscous_n_s_per_m], vb))
    fk_b = stribeck(abs(vb), p[P.guide_coulomb_n], p[P.guide_static_n], p[P.stribeck_v_m_per_s])
    vb_new = friction_velocity_update(vb, f_b, h_per_board_mass, fk_b, p[P.guide_static_n])
    # positions (semi-implicit Euler), then the end stops
    xp = xp + h * vp_new
    xb, vb_new = end_stop(xb + h * vb_new, vb_new, p[P.travel_min_m], p[P.travel_max_m])
    # fingertip (QLV)
    d = compression_m(xb, u[U.finger_pos_m])
    fe_new = elastic_force(d, p[P.finger_b_n_per_m], p[P.finger_m_per_m])
    dfe = fe_new - fe
    h1 = prony_step(h1, p[P.relax_a1], p[P.relax_c1], p[P.relax_beta1], dfe)
    h2 = prony_step(h2, p[P.relax_a2], p[P.relax_c2], p[P.relax_beta2], dfe)
    h3 = prony_step(h3, p[P.relax_a3], p[P.relax_c3], p[P.relax_beta3], dfe)
    fc = contact_force(d, fe_new, p[P.relax_c0], h1, h2, h3)
    return xp, vp_new, xb, vb_new, i, fe_new, h1, h2, h3, fc, electrical_power_w(v_cmd, i) * h


@njit(cache=True, _nrt=False)
def advance(s, p, u, n_sub):
    """Advance one device by ``n_sub`` physics steps with the inputs ``u`` held.

    The per-step states live in local variables over the steps (read from ``s`` once, written
    back once), and ``h/m`` and ``1/R`` are formed once per call (for ``n_sub`` > 0)."""
    if n_sub <= 0:
        s[S.isense_count] += n_sub
        return
    h = p[P.h_s]
    h_per_pinion_mass = h / p[P.pinion_mass_kg]
    h_per_board_mass = h / p[P.board_mass_kg]
    g_armature_s = 1.0 / p[P.motor_r_ohm]
    xp, vp = s[S.pinion_pos_m], s[S.pinion_vel_m_per_s]
    xb, vb = s[S.board_pos_m], s[S.board_vel_m_per_s]
    i, fe, fc = s[S.current_a], s[S.elastic_force_n], s[S.contact_force_n]
    h1, h2, h3 = s[S.prony_1_n], s[S.prony_2_n], s[S.prony_3_n]
    energy, t = s[S.energy_j], s[S.time_s]
    lag, f1, f2, phase = s[S.fsr_force_lagged_n], s[S.isense_filter1_v], s[S.isense_filter2_v], s[S.sensor_phase]
    for _ in range(n_sub):
        xp, vp, xb, vb, i, fe, h1, h2, h3, fc, e = mechanics_substep(
            p, u, h, h_per_pinion_mass, h_per_board_mass, g_armature_s, xp, vp, xb, vb, i, fe, h1, h2, h3, fc)
        energy += e
        t += h
        lag, f1, f2, phase = sensor_substep(s, p, u, lag, f1, f2, phase, i, fc)
    s[S.pinion_pos_m], s[S.pinion_vel_m_per_s] = xp, vp
    s[S.board_pos_m], s[S.board_vel_m_per_s] = xb, vb
    s[S.current_a], s[S.elastic_force_n], s[S.contact_force_n] = i, fe, fc
    s[S.prony_1_n], s[S.prony_2_n], s[S.prony_3_n] = h1, h2, h3
    s[S.energy_j], s[S.time_s] = energy, t
    s[S.fsr_force_lagged_n], s[S.isense_filter1_v], s[S.isense_filter2_v], s[S.sensor_phase] = lag, f1, f2, phase
    s[S.isense_count] += n_sub
    current_sample(s, p)


@njit(cache=True, _nrt=False)
def advance_batch(s2, p2, u2, n_sub):
    """Advance ``n`` devices (rows of ``s2``, ``p2``, ``u2``) by ``n_sub`` physics steps."""
    for e in range(s2.shape[0]):
        advance(s2[e], p2[e], u2[e], n_sub)


@njit(cache=True, _nrt=False)
def advance_sensor_only(s, p, u, contact_force_n, n_sub):
    """Sensor chain only, for plants simulated elsewhere (the pymunk mechanism)."""
    s[S.contact_force_n] = contact_force_n
    i = s[S.current_a]
    lag, f1, f2, phase = s[S.fsr_force_lagged_n], s[S.isense_filter1_v], s[S.isense_filter2_v], s[S.sensor_phase]
    for _ in range(n_sub):
        lag, f1, f2, phase = sensor_substep(s, p, u, lag, f1, f2, phase, i, contact_force_n)
    s[S.fsr_force_lagged_n], s[S.isense_filter1_v], s[S.isense_filter2_v], s[S.sensor_phase] = lag, f1, f2, phase
    s[S.isense_count] += n_sub
