"""The compiled closed-loop kernel: one control period of the lumped plant and the sensor.

Everything physical that happens between two controller updates runs here, written once
and compiled with Numba.  A single device and a batch of devices call the same
:func:`advance`, so a scenario, the Gymnasium env and its vectorised form see identical
physics.  State, parameter and input slots are named in :mod:`ebraille_sim.plant.layout`.

Per physics step ``h`` (default 0.1 ms), with the command held over the control period:

1. driver: command clipped to +/- the driver supply;
2. armature current advanced exactly (:func:`ebraille_sim.physics.motor.current_step`);
3. mesh force through the backlash dead zone (:func:`ebraille_sim.physics.drivetrain.mesh_force`);
4. pinion side (reflected rotor inertia) and board (racks + board mass) velocities
   updated with dry friction at the velocity level, then positions (semi-implicit
   Euler), then the end stops (inelastic projection);
5. fingertip QLV contact force from the new board position;
6. FSR mechanical lag; at every sensor sample the hysteresis, creep, conduction,
   divider, noise, ADC and faults, then the anti-alias filter; at every estimator sample
   the block-oriented estimator.

Stability: the semi-implicit step is stable while ``w h < 2`` for the stiffest
oscillation, the board on the mesh and the pulp; :func:`ebraille_sim.plant.loop.check_step`
rejects physics rates that give ``w h > 1``.
"""
from __future__ import annotations

import math

from ebraille_sim.base.compiled import njit

from ebraille_sim.physics.drivetrain import friction_velocity_update, mesh_force, stribeck
from ebraille_sim.physics.fingertip import elastic_force
from ebraille_sim.physics.fsr import F_EPS_N, adc_code, conductance_s, divider_voltage, play
from ebraille_sim.plant.layout import (FAULT_OPEN, FAULT_SHORT, FAULT_STUCK, FAULT_VALUE, MAX_BREAKPOINTS, MAX_TF_LEN,
                     N_PLAYS, P, S, U)
from ebraille_sim.physics.motor import current_step
from ebraille_sim.physics.noise import normal_at

# state slots
_I = S["current_a"]; _XP = S["pinion_pos_m"]; _VP = S["pinion_vel_m_per_s"]
_XB = S["board_pos_m"]; _VB = S["board_vel_m_per_s"]
_H1 = S["prony_1_n"]; _H2 = S["prony_2_n"]; _H3 = S["prony_3_n"]
_FE = S["elastic_force_n"]; _FC = S["contact_force_n"]
_FL = S["fsr_force_lagged_n"]; _TL = S["fsr_load_time_s"]; _VF = S["fsr_voltage_v"]; _CODE = S["fsr_code"]
_AZ1 = S["aa_z1"]; _AZ2 = S["aa_z2"]; _SPH = S["sensor_phase"]; _EPH = S["estimator_phase"]
_SCOUNT = S["sensor_count"]; _FEST = S["force_est_n"]; _EN = S["energy_j"]; _T = S["time_s"]
_TARE = S["tare_v"]; _PLAY0 = S["play_0"]; _EZ0 = S["est_z0"]

# parameter slots
_H = P["h_s"]; _SPS = P["substeps_per_sensor"]; _SPE = P["sensors_per_estimate"]
_R = P["motor_r_ohm"]; _DEC = P["motor_current_decay"]; _KT = P["motor_kt"]; _KE = P["motor_ke"]
_G = P["n_over_r_per_m"]
_MP = P["pinion_mass_kg"]; _PFC = P["pinion_coulomb_n"]; _PFS = P["pinion_static_n"]
_PFV = P["pinion_viscous_n_s_per_m"]; _MU = P["gear_mu"]
_HB = P["half_backlash_m"]; _KM = P["mesh_k_n_per_m"]; _CM = P["mesh_c_n_s_per_m"]; _MB = P["board_mass_kg"]
_GFC = P["guide_coulomb_n"]; _GFS = P["guide_static_n"]; _GFV = P["guide_viscous_n_s_per_m"]
_VS = P["stribeck_v_m_per_s"]; _XMIN = P["travel_min_m"]; _XMAX = P["travel_max_m"]
_FB = P["finger_b_n_per_m"]; _FM = P["finger_m_per_m"]
_C0 = P["relax_c0"]; _C1 = P["relax_c1"]; _C2 = P["relax_c2"]; _C3 = P["relax_c3"]
_A1 = P["relax_a1"]; _A2 = P["relax_a2"]; _A3 = P["relax_a3"]
_B1 = P["relax_beta1"]; _B2 = P["relax_beta2"]; _B3 = P["relax_beta3"]
_LAG = P["fsr_lag_alpha"]; _FK = P["fsr_k_ohm"]; _FN = P["fsr_n"]; _GSO = P["fsr_g_standoff_s"]
_CRD = P["fsr_creep_per_decade"]; _CT0 = P["fsr_creep_t0_s"]; _REC = P["fsr_recovery_decay"]
_LTH = P["fsr_load_threshold_n"]; _TCO = P["fsr_tempco_per_k"]; _NV = P["fsr_noise_v"]; _FDT = P["fsr_dt_s"]
_R2 = P["r2_ohm"]; _VSUP = P["divider_supply_v"]; _LSB = P["adc_lsb_v"]; _MAXC = P["adc_max_code"]
_AB0 = P["aa_b0"]; _AB1 = P["aa_b1"]; _AB2 = P["aa_b2"]; _AA1 = P["aa_a1"]; _AA2 = P["aa_a2"]
_ELEN = P["est_len"]; _ENIN = P["est_n_in"]; _ENOUT = P["est_n_out"]; _ECL = P["est_clamp"]
_EAVG = P["est_nyquist_average"]; _FRAW = S["est_raw_prev_n"]
_SEED = P["seed"]
_PW0 = P["play_w0"]; _PWT0 = P["play_weight0"]
_NUM0 = P["est_num0"]; _DEN0 = P["est_den0"]
_INX0 = P["est_in_x0"]; _INY0 = P["est_in_y0"]; _OUTX0 = P["est_out_x0"]; _OUTY0 = P["est_out_y0"]

# input slots
_UCMD = U["command_v"]; _UXF = U["finger_pos_m"]; _UG = U["gravity_along_m_per_s2"]
_UTEMP = U["fsr_temp_offset_k"]; _USUP = U["driver_supply_v"]; _UFLT = U["fsr_fault"]
_UFV = U["fsr_fault_value"]; _UJAM = U["motor_jammed"]

assert MAX_TF_LEN >= 2 and MAX_BREAKPOINTS >= 2


@njit(cache=True, inline="always")
def pwl_eval(x, p, x0, y0, n):
    """Piecewise-linear map with breakpoints ``p[x0:x0+n]``, ``p[y0:y0+n]``.

    Beyond the end breakpoints the end segments are continued (linear extrapolation).
    """
    j = 0
    while j < n - 2 and x > p[x0 + j + 1]:
        j += 1
    xa = p[x0 + j]
    xb = p[x0 + j + 1]
    ya = p[y0 + j]
    yb = p[y0 + j + 1]
    return ya + (yb - ya) * (x - xa) / (xb - xa)


@njit(cache=True, inline="always")
def estimator_update(s, p, u):
    """One sample of the block-oriented estimator (input map, IIR in DF2T, output map).

    With ``est_nyquist_average`` set, the output is the mean of the last two model outputs:
    a zero at z = -1 that removes the sample-to-sample ringing of a model pole near -1
    (the paper's fifth-order Wiener has one at -0.967), at the price of half a sample of delay.
    """
    x = pwl_eval(u, p, _INX0, _INY0, int(p[_ENIN]))
    n = int(p[_ELEN])
    y = p[_NUM0] * x + s[_EZ0]
    for j in range(n - 2):
        s[_EZ0 + j] = p[_NUM0 + j + 1] * x + s[_EZ0 + j + 1] - p[_DEN0 + j + 1] * y
    if n >= 2:
        s[_EZ0 + n - 2] = p[_NUM0 + n - 1] * x - p[_DEN0 + n - 1] * y
    f = pwl_eval(y, p, _OUTX0, _OUTY0, int(p[_ENOUT]))
    if p[_EAVG] > 0.0:
        f_raw = f
        f = 0.5 * (f + s[_FRAW])
        s[_FRAW] = f_raw
    if p[_ECL] > 0.0 and f < 0.0:
        f = 0.0
    return f


@njit(cache=True, inline="always")
def sensor_sample(s, p, u):
    """One ADC sample of the FSR divider, then the anti-alias filter and the estimator."""
    f_lag = s[_FL]
    # creep clock
    if f_lag > p[_LTH]:
        s[_TL] += p[_FDT]
    else:
        s[_TL] *= p[_REC]
    # hysteresis on ln(F + eps)
    lf = math.log(f_lag + F_EPS_N)
    leff = 0.0
    for j in range(N_PLAYS):
        yj = play(lf, s[_PLAY0 + j], p[_PW0 + j])
        s[_PLAY0 + j] = yj
        leff += p[_PWT0 + j] * yj
    f_eff = math.exp(leff) - F_EPS_N
    scale = (1.0 + p[_CRD] * math.log10(1.0 + s[_TL] / p[_CT0])) * (1.0 + p[_TCO] * u[_UTEMP])
    g = conductance_s(f_eff, p[_FK], p[_FN], p[_GSO], scale)
    fault = int(u[_UFLT])
    if fault == FAULT_OPEN:
        v = 0.0
    elif fault == FAULT_SHORT:
        v = p[_VSUP]
    elif fault == FAULT_VALUE:
        v = u[_UFV]
    else:
        v = divider_voltage(g, p[_R2], p[_VSUP])
    v += p[_NV] * normal_at(p[_SEED], s[_SCOUNT])
    s[_SCOUNT] += 1.0
    if fault != FAULT_STUCK:
        s[_CODE] = adc_code(v, p[_LSB], p[_MAXC])
    vq = s[_CODE] * p[_LSB]
    s[_VF] = vq
    # anti-alias biquad (DF2T) on the tared voltage
    x = vq - s[_TARE]
    y = p[_AB0] * x + s[_AZ1]
    s[_AZ1] = p[_AB1] * x - p[_AA1] * y + s[_AZ2]
    s[_AZ2] = p[_AB2] * x - p[_AA2] * y
    s[_EPH] += 1.0
    if s[_EPH] >= p[_SPE]:
        s[_EPH] = 0.0
        s[_FEST] = estimator_update(s, p, y)


@njit(cache=True, inline="always")
def sensor_substep(s, p, u, contact_force_n):
    """FSR mechanical lag at the physics rate; an ADC sample when one is due."""
    s[_FL] += (contact_force_n - s[_FL]) * p[_LAG]
    s[_SPH] += 1.0
    if s[_SPH] >= p[_SPS]:
        s[_SPH] = 0.0
        sensor_sample(s, p, u)


@njit(cache=True, inline="always")
def mechanics_substep(s, p, u):
    """One physics step of the lumped drive train, board and fingertip."""
    h = p[_H]
    sup = u[_USUP]
    v_cmd = u[_UCMD]
    if v_cmd > sup:
        v_cmd = sup
    elif v_cmd < -sup:
        v_cmd = -sup
    vp = s[_VP]
    vb = s[_VB]
    g = p[_G]
    i = current_step(s[_I], v_cmd, vp * g, p[_R], p[_KE], p[_DEC])
    s[_I] = i
    f_motor = p[_KT] * i * g
    f_mesh = mesh_force(s[_XP] - s[_XB], vp - vb, p[_HB], p[_KM], p[_CM])
    # pinion side: reflected rotor inertia, brush/bearing friction, load-dependent gear loss
    load = p[_MU] * abs(f_mesh)
    fs_p = p[_PFS] + load
    fk_p = stribeck(abs(vp), p[_PFC] + load, fs_p, p[_VS])
    if u[_UJAM] > 0.0:
        vp_new = 0.0
    else:
        vp_new = friction_velocity_update(vp, f_motor - f_mesh - p[_PFV] * vp, p[_MP], h, fk_p, fs_p)
    # board: mesh, contact, gravity, guide friction
    f_b = f_mesh - s[_FC] + p[_MB] * u[_UG] - p[_GFV] * vb
    fk_b = stribeck(abs(vb), p[_GFC], p[_GFS], p[_VS])
    vb_new = friction_velocity_update(vb, f_b, p[_MB], h, fk_b, p[_GFS])
    xp = s[_XP] + h * vp_new
    xb = s[_XB] + h * vb_new
    if xb < p[_XMIN]:
        xb = p[_XMIN]
        if vb_new < 0.0:
            vb_new = 0.0
    elif xb > p[_XMAX]:
        xb = p[_XMAX]
        if vb_new > 0.0:
            vb_new = 0.0
    s[_XP] = xp
    s[_VP] = vp_new
    s[_XB] = xb
    s[_VB] = vb_new
    # fingertip (QLV)
    d = xb - u[_UXF]
    fe_new = elastic_force(d, p[_FB], p[_FM])
    dfe = fe_new - s[_FE]
    s[_H1] = p[_A1] * s[_H1] + p[_C1] * p[_B1] * dfe
    s[_H2] = p[_A2] * s[_H2] + p[_C2] * p[_B2] * dfe
    s[_H3] = p[_A3] * s[_H3] + p[_C3] * p[_B3] * dfe
    s[_FE] = fe_new
    fc = p[_C0] * fe_new + s[_H1] + s[_H2] + s[_H3]
    if d <= 0.0 or fc < 0.0:
        fc = 0.0
    s[_FC] = fc
    s[_EN] += v_cmd * i * h
    s[_T] += h


@njit(cache=True)
def advance(s, p, u, n_sub):
    """Advance one device by ``n_sub`` physics steps with the inputs ``u`` held."""
    for _ in range(n_sub):
        mechanics_substep(s, p, u)
        sensor_substep(s, p, u, s[_FC])


@njit(cache=True)
def advance_batch(s2, p2, u2, n_sub):
    """Advance ``n`` devices (rows of ``s2``, ``p2``, ``u2``) by ``n_sub`` physics steps."""
    for e in range(s2.shape[0]):
        advance(s2[e], p2[e], u2[e], n_sub)


@njit(cache=True)
def advance_sensor_only(s, p, u, contact_force_n, n_sub):
    """Sensor chain only, for plants simulated elsewhere (the pymunk mechanism)."""
    for _ in range(n_sub):
        s[_FC] = contact_force_n
        sensor_substep(s, p, u, contact_force_n)
