r"""Small-signal model of the contact-force loop and its frequency analysis.

The plant seen by a controller runs from the motor command (V) to the *estimated* force
(N).  :func:`linearize` returns it as a ``control.StateSpace`` at an operating force in
contact; :func:`analyse_loop` closes it with a controller and reports gain and phase
margins (:func:`loop_margins`, from the loop's frequency response), the sensitivity peak
``Ms``, the bandwidth and the closed-loop step.

The model, block by block (symbols at the rack line, ``g = N/r``)
-----------------------------------------------------------------

Armature, pinion side (reflected rotor mass ``Mp = J g^2``), mesh, board and pulp::

    L di/dt    = V - R i - kE g vp
    Mp dvp/dt  = kM g i - (1 + s mu) Fm - cp vp              Fm = km (xp - xb) + cm (vp - vb)
    Mb dvb/dt  = Fm - F - cg vb
    dh_j/dt    = -h_j / tau_j + c_j K vb                     (j = 1, 2, 3: QLV Prony states)
    F          = c0 K (xb - xb0) + h1 + h2 + h3              K = b + m Fe0 (tangent stiffness)
    dFl/dt     = (F - Fl) / tau_fsr                          (FSR mechanical lag)
    v          = (dV/dF) Fl                                  (divider slope on the loading branch)

*Friction rule.*  Coulomb friction has no derivative at zero speed, and the drive sticks
whenever the command change is inside the break-away band.  The model describes the
**sliding regime**: the pinion and the board keep moving in one direction (``s = +1``
while pressing, the default; ``s = -1`` while releasing).  The constant Coulomb levels
then only shift the operating point, and the load-dependent gear loss ``mu |Fm|``
(``mu = 1/eta - 1``) keeps a small-signal part ``s mu dFm``.  ``friction="none"`` drops
all friction (``s = 0``).  The Stribeck rise below 0.5 mm/s is neglected.

*Backlash* is closed under load: the mesh is a spring-damper around the loaded flank.

*Pulp.*  At a relaxed equilibrium the Prony states are zero and the contact force is
``F0 = c0 Fe0``, so the tangent stiffness of the instantaneous law is ``K = b + m F0/c0``
(the long-time stiffness is ``c0 K``).

*FSR.*  After a monotone press every play operator of the hysteresis sits on its edge and
moves with the input (``dF_eff = c_h dF_l``, ``c_h`` the loading-branch factor of
:func:`ebraille_sim.estimation.calibration.loading_branch_factor`).  The hereditary creep
(:func:`ebraille_sim.physics.fsr.creep_force`) stays dynamic: the operating point is the
force held for ``load_time_s`` on a recovered film (creep states ``z_i = F_eff (1 -
exp(-t/tau_i))``, the voltage of
:func:`ebraille_sim.estimation.calibration.loading_voltage`), and a small change sees
``dF_c = dF_eff + w sum_i dz_i`` with ``dz_i`` advanced by
:func:`ebraille_sim.physics.fsr.creep_state_step` at every sensor sample, i.e. the
frequency response ``1 + w sum_i (1 - a_i)/(1 - a_i z^-1)`` of the creep terms
(:func:`ebraille_sim.physics.fsr.creep_frequency_response` in continuous time): about 1 at
the loop's crossover, the fully crept ``1 + N w`` only at DC.  The divider slope
``dV/dF_c`` is taken at the crept force ``F_c``.  ADC quantisation and noise are left
out.

Sampled-data form (the method)
------------------------------
The controller runs at the control rate (1 kHz) and holds its command over each
control period; the ADC samples the divider once per period and the digital anti-alias
biquad runs at that rate; the estimator (the paper's Wiener model, linear block and the
slope of its output map at the operating point, then the two-sample mean) runs every
``N = rate_ctrl / rate_est`` samples (10).  Nothing here is approximated by a continuous
equivalent:

1. the continuous part above is discretised exactly at the control period (zero-order
   hold, which is what the kernel does: the command is held over the period);
2. it is put in series with the creep terms (:func:`creep_model`, at the sensor rate, as the
   kernel advances them), the estimator's creep compensation (:func:`compensation_model`:
   the partial derivatives of the kernel's own compensation, its creep terms driven by the
   estimate the firmware holds) and the anti-alias biquad at the same rate;
3. for the open-loop plant, the command is held over ``N`` control periods and the
   sampled model is lifted to the estimator rate (``A^N``, ``sum A^j B``) and put in series
   with the estimator: :func:`linearize` returns this model with ``dt`` = 0.01 s.  With the
   compensation the estimate is fed back into the front: the sample the estimator reads
   still holds the previous estimate, the ``N - 1`` after it the new one (:func:`_lift`);
4. for a loop with a controller that runs at the control rate (:func:`pid_statespace`),
   the controller and the plant are lifted together over ``N`` periods with the estimate
   held, which gives the exact loop transfer at the estimator rate (the only rate at which
   the measured signal changes).

Operating point
---------------
:func:`operating_point` derives the equilibrium in closed form and checks it with
``control.find_operating_point`` (``return_result=True``; the result's ``success`` flag
is checked, and the two answers must agree) on :func:`contact_plant_system`, a
``NonlinearIOSystem`` of the contact plant that keeps the contact and backlash kinks.

Examples
--------
>>> from ebraille_sim.analysis.tuning import linearize, analyse_loop
>>> from controllers.pid import DEFAULT_PID
>>> P = linearize(force_n=1.0)
>>> P.dt
0.01
>>> a = analyse_loop(DEFAULT_PID, force_n=0.6)
>>> a.stable, round(a.ms, 2)
(True, 1.7)
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import control
import numpy as np
import scipy.linalg
import scipy.optimize
import scipy.signal

from ebraille_sim.physics import fsr as _fsr
from ebraille_sim.physics.drivetrain import mesh_damping_n_s_per_m, mesh_force, reflected, shaft_to_rack_per_m
from ebraille_sim.physics.fingertip import elastic_force, tangent_stiffness_n_per_m
from ebraille_sim.physics.params import DeviceParams

__all__ = [
    "OperatingPoint", "LoopAnalysis", "FRICTION_RULES", "CONTINUOUS_STATES",
    "operating_point", "contact_plant_system", "continuous_model", "sensor_models", "creep_model", "CREEP_STATES",
    "compensation_model", "COMP_STATES", "ESTIMATE_HELD_STATE",
    "linearize", "pid_statespace", "lift", "loop_models", "analyse_loop", "sensitivity_peak",
    "LoopMargins", "loop_margins",
    "simc_pid", "foptd_fit", "plot_bode", "plot_nyquist",
]

FRICTION_RULES = {"press": 1.0, "release": -1.0, "none": 0.0}
"""Sliding direction used to linearise the friction (see the module docstring)."""

CONTINUOUS_STATES = ["current_a", "pinion_pos_m", "pinion_vel_m_per_s", "board_pos_m",
                     "board_vel_m_per_s", "prony_1_n", "prony_2_n", "prony_3_n",
                     "fsr_force_lagged_n"]
"""State names of the continuous part (the same names as :data:`ebraille_sim.plant.layout.S`)."""


@dataclass(frozen=True)
class OperatingPoint:
    """A relaxed equilibrium of the device pressing the pulp.

    All quantities are absolute values of the nonlinear model.
    """
    force_n: float
    """Contact force (relaxed), N."""
    elastic_force_n: float
    """Instantaneous elastic force ``Fe0 = F0/c0``, N."""
    compression_m: float
    tangent_stiffness_n_per_m: float
    """``K = b + m Fe0``, N/m."""
    finger_pos_m: float
    board_pos_m: float
    pinion_pos_m: float
    mesh_force_n: float
    current_a: float
    command_v: float
    """Command at the edge of the friction band in the sliding direction, V."""
    fsr_voltage_v: float
    """Noise-free divider voltage on the loading branch, V."""
    fsr_slope_v_per_n: float
    """Instantaneous slope of the divider voltage in the contact force on the loading branch,
    V/N (creep states held: the high-frequency gain of the sensor)."""
    estimator_input_v: float
    """Tared voltage seen by the estimator, V."""
    estimator_linear_output: float
    estimator_output_slope_n: float
    """Slope of the estimator's output map at its operating input, N per unit."""
    estimate_n: float
    """Steady estimate at the operating point, N (differs from ``force_n`` by the
    estimator's static error)."""
    friction: str
    solver_residual: float
    """Largest state-derivative residual of ``find_operating_point``'s answer."""
    load_time_s: float = 20.0
    """Time the force has been held on a recovered film (the creep states' age), s."""


# the scalar laws of the plant, evaluated in Python (the code the kernel compiles)
_mesh_force = mesh_force.py_func
_elastic_force = elastic_force.py_func
_tangent_stiffness = tangent_stiffness_n_per_m.py_func
_shaft_to_rack = shaft_to_rack_per_m.py_func


def _constants(device: DeviceParams) -> dict:
    """Coefficients of the contact plant at the rack line, from the physics law functions.

    The gear reflection is :func:`~ebraille_sim.physics.drivetrain.shaft_to_rack_per_m`, the
    reflected rotor mass and brush friction come from
    :func:`~ebraille_sim.physics.drivetrain.reflected` and the mesh damping from
    :func:`~ebraille_sim.physics.drivetrain.mesh_damping_n_s_per_m`, as the kernel's packed
    parameters do.
    """
    m, d, f = device.motor, device.drivetrain, device.finger
    g = _shaft_to_rack(d.gear_ratio, d.pinion_radius_m)
    refl = reflected(m, d)
    return dict(
        g=g, R=m.resistance_ohm, L=m.inductance_h, kt=m.torque_constant_nm_per_a,
        ke=m.back_emf_v_s_per_rad, Mp=refl["mass_kg"],
        Fpc=refl["coulomb_n"], cp=m.viscous_friction_nm_s_per_rad * g * g,
        mu=d.gear_loss_coefficient, hb=0.5 * d.backlash_m, km=d.mesh_stiffness_n_per_m,
        cm=mesh_damping_n_s_per_m(d.mesh_damping_ratio, d.mesh_stiffness_n_per_m, d.moving_mass_kg),
        Mb=d.moving_mass_kg, Fgc=d.guide_coulomb_n, cg=d.guide_viscous_n_s_per_m,
        b=f.stiffness_b_n_per_m, m=f.exponent_m_per_m,
        c=(f.relax_weight_inf, f.relax_weight_1, f.relax_weight_2, f.relax_weight_3),
        tau=(f.relax_tau_1_s, f.relax_tau_2_s, f.relax_tau_3_s),
        tau_fsr=device.fsr.mechanical_lag_s, grav=-device.gravity_m_per_s2,
    )


def _friction_sign(friction: str) -> float:
    if friction not in FRICTION_RULES:
        raise ValueError(f"friction must be one of {', '.join(FRICTION_RULES)}, got {friction!r}")
    return FRICTION_RULES[friction]


def contact_plant_system(device: DeviceParams = DeviceParams(), friction: str = "press",
                         finger_pos_m: float = 1e-3) -> control.NonlinearIOSystem:
    """The continuous contact plant as a ``control.NonlinearIOSystem``.

    States :data:`CONTINUOUS_STATES` (SI units), input ``command_v``, outputs
    ``contact_force_n`` and ``mesh_force_n``.  Friction follows the sliding rule of the
    module docstring (constant Coulomb levels in the direction ``friction``); the contact
    (no force for ``d <= 0``, force never negative) and the backlash dead zone are kept, so
    the system has the kinks that make a blind equilibrium search fail.
    """
    k = _constants(device)
    sgn = _friction_sign(friction)
    c0, c1, c2, c3 = k["c"]
    t1, t2, t3 = k["tau"]

    def mesh(x):
        return _mesh_force(x[1] - x[3], x[2] - x[4], k["hb"], k["km"], k["cm"])

    def elastic(xb):
        return _elastic_force(xb - finger_pos_m, k["b"], k["m"])

    def stiffness(xb):
        # out of contact the elastic force does not change with the board position
        d = xb - finger_pos_m
        return 0.0 if d <= 0.0 else _tangent_stiffness(elastic(xb), k["b"], k["m"])

    def contact(x):
        d = x[3] - finger_pos_m
        f = c0 * elastic(x[3]) + x[5] + x[6] + x[7]
        return 0.0 if (d <= 0.0 or f < 0.0) else f

    def updfcn(t, x, u, params):
        v = float(u[0])
        fm = mesh(x)
        f = contact(x)
        kk = stiffness(x[3])
        di = (v - k["R"] * x[0] - k["ke"] * k["g"] * x[2]) / k["L"]
        fric_p = sgn * (k["Fpc"] + k["mu"] * abs(fm))
        dvp = (k["kt"] * k["g"] * x[0] - fm - fric_p - k["cp"] * x[2]) / k["Mp"]
        dvb = (fm - f + k["Mb"] * k["grav"] - sgn * k["Fgc"] - k["cg"] * x[4]) / k["Mb"]
        dfe = kk * x[4]
        return np.array([di, x[2], dvp, x[4], dvb,
                         -x[5] / t1 + c1 * dfe, -x[6] / t2 + c2 * dfe, -x[7] / t3 + c3 * dfe,
                         (f - x[8]) / k["tau_fsr"]])

    def outfcn(t, x, u, params):
        return np.array([contact(x), mesh(x)])

    return control.nlsys(updfcn, outfcn, inputs=["command_v"], outputs=["contact_force_n", "mesh_force_n"],
                         states=list(CONTINUOUS_STATES), name="contact_plant")


def _sensor_point(device: DeviceParams, force_n: float, load_time_s: float, model=None, direction: float = 1.0):
    """Loading-branch voltage, its instantaneous slope and the estimator's operating values.

    The slope is ``c_h dV/dF_c`` at the crept force of a press held ``load_time_s``: the creep
    states are held (their small-signal dynamics are :func:`creep_model`).  At a breakpoint of
    a piecewise-linear map the slope of the segment the signal enters when the force moves in
    ``direction`` (+1 rising, -1 falling) is used.
    """
    from ebraille_sim.estimation.calibration import _tare, loading_branch_factor, loading_voltage
    from ebraille_sim.estimation.models import load_estimator
    model = model if model is not None else load_estimator(device.estimator.model)
    fsr, circ = device.fsr, device.circuit
    v0 = loading_voltage(force_n, fsr, circ, load_time_s)
    c_h = loading_branch_factor(fsr)
    f_c = force_n * c_h * (_fsr.creep_gain(load_time_s, fsr) if force_n * c_h > fsr.load_threshold_n else 1.0)

    def v_of_crept(f):
        # the divider voltage of a crept force (no further creep: load time 0)
        return _fsr.divider_voltage(_fsr.static_conductance(f, fsr, 0.0), circ.r2_ohm, circ.supply_v)
    h = 1e-4 * max(f_c, 1e-2)
    slope = c_h * (v_of_crept(f_c + h) - v_of_crept(f_c - h)) / (2 * h)
    tare = _tare(fsr, circ) if device.estimator.tare_at_start else 0.0
    # the estimator reads the compensated voltage (the same whatever the estimate: the
    # firmware's creep gain does not depend on the force it has followed)
    u0 = (_compensation_point(device, v0, force_n, load_time_s)[0] if device.estimator.creep_compensation
          else v0) - tare
    w0 = model._in(u0)
    side = 1.0 if direction >= 0 else -1.0
    du = side * 1e-9 * max(1.0, abs(u0))
    in_slope = 1.0 if model.input_nl is None else float(model.input_nl.slope_at(u0 + du))
    gain = model.linear.steady_state_gain()
    y0 = gain * w0
    dy = side * math.copysign(1.0, gain * in_slope) * 1e-9 * max(1.0, abs(y0))
    out_slope = 1.0 if model.output_nl is None else float(model.output_nl.slope_at(y0 + dy))
    est = float(model.steady_state(u0))
    return model, v0, slope, u0, in_slope, y0, out_slope, est


CREEP_STATES = [f"fsr_creep_{j}_v" for j in range(_fsr.N_CREEP)]
"""States of :func:`creep_model`: the creep terms as divider-voltage deviations."""


def creep_model(device: DeviceParams = DeviceParams()) -> control.StateSpace:
    """Small-signal hereditary creep at the sensor rate, instantaneous voltage in, voltage out.

    The kernel advances every creep term once per sensor sample with
    :func:`ebraille_sim.physics.fsr.creep_state_step` (``z <- a z + (1 - a) F_eff``) and adds
    ``w sum_i z_i`` of the *new* states to the force (:func:`ebraille_sim.physics.fsr.creep_force`).
    Linear in its arguments, the law gives ``a`` and ``1 - a`` as its values on unit inputs;
    with the input ``x`` the instantaneous voltage deviation (slope times ``dF_l``, which
    scales the force deviation the terms follow by a constant), the model is
    ``zeta+ = a zeta + (1-a) x``, ``y = x + w sum_i (a_i zeta_i + (1-a_i) x)``, with the
    weight ``w`` and decays ``a_i`` that :func:`ebraille_sim.plant.loop.pack_params` packs.
    Its gain is ``1 + w sum_i (1 - a_i)`` at the Nyquist frequency and ``1 + N w`` at DC.
    """
    fsr = device.fsr
    dt = 1.0 / device.rates.sensor_rate_hz
    w = _fsr.creep_term_weight(fsr.creep_per_decade, fsr.creep_tau_min_s, fsr.creep_tau_max_s)
    step = _fsr.creep_state_step.py_func
    a = np.array([step(1.0, 0.0, _fsr.creep_decay(dt, tau)) for tau in _fsr.creep_taus_s(fsr.creep_tau_min_s,
                                                                                            fsr.creep_tau_max_s)])
    b = np.array([step(0.0, 1.0, _fsr.creep_decay(dt, tau)) for tau in _fsr.creep_taus_s(fsr.creep_tau_min_s,
                                                                                            fsr.creep_tau_max_s)])
    return control.ss(np.diag(a), b.reshape(-1, 1), (w * a).reshape(1, -1), [[1.0 + w * float(np.sum(b))]],
                      dt=dt, inputs=["fsr_voltage_inst_v"], outputs=["fsr_voltage_v"], states=list(CREEP_STATES),
                      name="creep")


COMP_STATES = [f"comp_creep_{j}_n" for j in range(_fsr.N_CREEP)]
"""States of :func:`compensation_model`: the firmware's creep terms (deviations, N)."""

ESTIMATE_HELD_STATE = "est_held_n"
"""State of the lifted model with compensation: the estimate the compensation holds."""


def _compensation_point(device: DeviceParams, raw_v: float, estimate_n: float, load_time_s: float):
    """The kernel's creep compensation at an operating point, and its partial derivatives.

    Evaluates :func:`ebraille_sim.estimation.blockmodels.creep_compensated_v` itself with the
    parameters :func:`ebraille_sim.plant.loop.pack_params` packs, its creep terms having
    followed ``estimate_n`` for ``load_time_s`` (``z_i = F (1 - a_i^k)``).  Returns
    ``(v_out, d/dv, d/dF_est, d/dz_i, a_i)``; the derivatives are central differences of
    that function (it is smooth away from the load threshold and the rails).
    """
    from ebraille_sim.estimation.blockmodels import creep_compensated_v
    from ebraille_sim.plant.layout import N_CREEP, P
    from ebraille_sim.plant.loop import pack_params
    p = pack_params(device, 0.0)
    a = np.array([p[P[f"comp_creep_a{j}"]] for j in range(N_CREEP)])
    k = int(round(load_time_s * device.rates.sensor_rate_hz))
    z = estimate_n * (1.0 - a ** k)
    fn = creep_compensated_v.py_func

    def out(v, f, zz):
        st = np.zeros(N_CREEP)
        st[:] = zz
        return fn(v, f, st, 0, p, P.comp_creep_a0, p[P.comp_creep_weight], p[P.comp_load_threshold_n], N_CREEP,
                  p[P.comp_fsr_n], p[P.comp_g_standoff_s], p[P.comp_reference_gain], p[P.r2_ohm],
                  p[P.divider_supply_v], 0.0)
    v0 = out(raw_v, estimate_n, z)
    hv = 1e-6 * max(abs(raw_v), 1e-3)
    hf = 1e-6 * max(abs(estimate_n), 1e-3)
    d_v = (out(raw_v + hv, estimate_n, z) - out(raw_v - hv, estimate_n, z)) / (2 * hv)
    d_f = (out(raw_v, estimate_n + hf, z) - out(raw_v, estimate_n - hf, z)) / (2 * hf)
    d_z = np.empty(N_CREEP)
    for j in range(N_CREEP):
        e = np.zeros(N_CREEP)
        e[j] = hf
        d_z[j] = (out(raw_v, estimate_n, z + e) - out(raw_v, estimate_n, z - e)) / (2 * hf)
    return v0, d_v, d_f, d_z, a


def compensation_model(device: DeviceParams, op: OperatingPoint) -> control.StateSpace:
    """Small-signal creep compensation at the sensor rate.

    Inputs: the divider voltage (V) and the estimate the firmware holds (N); output: the
    voltage the anti-alias filter receives (V); states :data:`COMP_STATES`, the firmware's
    creep terms, advanced by :func:`ebraille_sim.physics.fsr.creep_state_step` on the held
    estimate (``zeta+ = a zeta + (1 - a) dF_est``).  The output is
    ``dv_out = d_v dv + d_F dF_est + sum_i d_zi zeta_i`` with the partial derivatives of
    the kernel's own compensation (:func:`_compensation_point`, old states as arguments).
    Without compensation the model passes the voltage through.
    """
    dt = 1.0 / device.rates.sensor_rate_hz
    if not device.estimator.creep_compensation:
        return control.ss(np.zeros((0, 0)), np.zeros((0, 2)), np.zeros((1, 0)), [[1.0, 0.0]], dt=dt,
                          inputs=["fsr_voltage_v", "force_est_held_n"], outputs=["fsr_voltage_comp_v"],
                          name="compensation")
    _, d_v, d_f, d_z, a = _compensation_point(device, op.fsr_voltage_v, op.estimate_n, op.load_time_s)
    n = len(a)
    B = np.zeros((n, 2))
    B[:, 1] = 1.0 - a
    return control.ss(np.diag(a), B, d_z.reshape(1, -1), [[d_v, d_f]], dt=dt,
                      inputs=["fsr_voltage_v", "force_est_held_n"], outputs=["fsr_voltage_comp_v"],
                      states=list(COMP_STATES), name="compensation")


def operating_point(device: DeviceParams = DeviceParams(), force_n: float = 1.0, *,
                    friction: str = "press", finger_pos_m: float = 1e-3,
                    load_time_s: float = 20.0, check: bool = True) -> OperatingPoint:
    """Relaxed equilibrium at the contact force ``force_n``.

    Derived in closed form (Prony states zero, ``Fe0 = F0/c0``, mesh and friction
    balances in the sliding direction) and, with ``check`` (default), verified with
    ``control.find_operating_point(..., return_result=True)`` on
    :func:`contact_plant_system` started from a guess 20 % off in compression: the
    solver must report success and agree with the closed form to 1e-6 relative.

    Raises
    ------
    ValueError
        If ``force_n`` is not in (0, 10] N.
    RuntimeError
        If the solver fails or disagrees with the closed form.
    """
    if not (isinstance(force_n, (int, float)) and math.isfinite(force_n) and 0.0 < force_n <= 10.0):
        raise ValueError(f"force_n must be in (0, 10] N, got {force_n!r}")
    sgn = _friction_sign(friction)
    k = _constants(device)
    c0 = k["c"][0]
    fe0 = force_n / c0
    d0 = math.log1p(k["m"] * fe0 / k["b"]) / k["m"]        # the elastic law solved for Fe0
    kk = _tangent_stiffness(fe0, k["b"], k["m"])
    xb0 = finger_pos_m + d0
    fm0 = force_n - k["Mb"] * k["grav"] + sgn * k["Fgc"]
    xp0 = xb0 + k["hb"] + fm0 / k["km"]
    i0 = (fm0 + sgn * (k["Fpc"] + k["mu"] * abs(fm0))) / (k["kt"] * k["g"])
    v0 = k["R"] * i0
    x_eq = np.array([i0, xp0, 0.0, xb0, 0.0, 0.0, 0.0, 0.0, force_n])
    residual = 0.0
    if check:
        sys = contact_plant_system(device, friction, finger_pos_m)
        guess = x_eq.copy()
        guess[3] = finger_pos_m + 0.8 * d0
        guess[1] = guess[3] + k["hb"] + 0.8 * fm0 / k["km"]
        guess[0] *= 0.8
        guess[8] *= 0.5
        op = control.find_operating_point(sys, guess, [0.8 * v0], y0=[force_n, 0.0], iy=[0],
                                          return_result=True)
        res = op.result
        if not res.success:
            raise RuntimeError(f"find_operating_point failed at {force_n:g} N: {res.message}")
        x_s, u_s = np.asarray(op.states, float), float(np.asarray(op.inputs, float)[0])
        scale = np.array([1e-2, 1e-3, 1e-3, 1e-3, 1e-3, 1.0, 1.0, 1.0, 1.0])
        dev = np.max(np.abs(x_s - x_eq) / scale)
        if dev > 1e-6 or abs(u_s - v0) > 1e-6 * max(1.0, abs(v0)):
            raise RuntimeError(f"find_operating_point disagrees with the closed-form equilibrium at "
                               f"{force_n:g} N (state deviation {dev:.3g}, input {u_s:.6g} vs {v0:.6g} V)")
        residual = float(np.max(np.abs(sys._rhs(0.0, x_s, np.array([u_s])) * scale)))
    _, vf, slope, u_est, _, y_lin, out_slope, est = _sensor_point(device, force_n, load_time_s,
                                                                  direction=-1.0 if friction == "release" else 1.0)
    return OperatingPoint(force_n=float(force_n), elastic_force_n=fe0, compression_m=d0,
                          tangent_stiffness_n_per_m=kk, finger_pos_m=finger_pos_m, board_pos_m=xb0,
                          pinion_pos_m=xp0, mesh_force_n=fm0, current_a=i0, command_v=v0,
                          fsr_voltage_v=vf, fsr_slope_v_per_n=slope, estimator_input_v=u_est,
                          estimator_linear_output=y_lin, estimator_output_slope_n=out_slope,
                          estimate_n=est, friction=friction, solver_residual=residual,
                          load_time_s=float(load_time_s))


def continuous_model(device: DeviceParams = DeviceParams(), op: OperatingPoint | None = None, *,
                     force_n: float = 1.0, friction: str = "press") -> control.StateSpace:
    """Continuous small-signal model of the drive train, pulp and FSR lag.

    Input ``command_v``; outputs ``contact_force_n`` (deviation, N) and ``fsr_voltage_v``
    (deviation of the divider voltage, V); states :data:`CONTINUOUS_STATES` (deviations
    from ``op``).
    """
    if op is None:
        op = operating_point(device, force_n, friction=friction)
    k = _constants(device)
    sgn = FRICTION_RULES[op.friction]
    kk = op.tangent_stiffness_n_per_m
    c0, c1, c2, c3 = k["c"]
    t1, t2, t3 = k["tau"]
    A = np.zeros((9, 9))
    B = np.zeros((9, 1))
    # armature
    A[0, 0] = -k["R"] / k["L"]
    A[0, 2] = -k["ke"] * k["g"] / k["L"]
    B[0, 0] = 1.0 / k["L"]
    # pinion: Fm = km (xp - xb) + cm (vp - vb), loaded by (1 + s mu) Fm
    A[1, 2] = 1.0
    gl = 1.0 + sgn * k["mu"]
    A[2, 0] = k["kt"] * k["g"] / k["Mp"]
    A[2, 1] = -gl * k["km"] / k["Mp"]
    A[2, 3] = gl * k["km"] / k["Mp"]
    A[2, 2] = -(gl * k["cm"] + k["cp"]) / k["Mp"]
    A[2, 4] = gl * k["cm"] / k["Mp"]
    # board
    A[3, 4] = 1.0
    A[4, 1] = k["km"] / k["Mb"]
    A[4, 3] = -(k["km"] + c0 * kk) / k["Mb"]
    A[4, 2] = k["cm"] / k["Mb"]
    A[4, 4] = -(k["cm"] + k["cg"]) / k["Mb"]
    A[4, 5:8] = -1.0 / k["Mb"]
    # Prony states
    for j, (cj, tj) in enumerate(((c1, t1), (c2, t2), (c3, t3))):
        A[5 + j, 5 + j] = -1.0 / tj
        A[5 + j, 4] = cj * kk
    # FSR lag, driven by F = c0 K xb + h1 + h2 + h3
    tf = k["tau_fsr"]
    A[8, 3] = c0 * kk / tf
    A[8, 5:8] = 1.0 / tf
    A[8, 8] = -1.0 / tf
    C = np.zeros((2, 9))
    C[0, 3] = c0 * kk
    C[0, 5:8] = 1.0
    C[1, 8] = op.fsr_slope_v_per_n
    return control.ss(A, B, C, np.zeros((2, 1)), inputs=["command_v"],
                      outputs=["contact_force_n", "fsr_voltage_v"], states=list(CONTINUOUS_STATES),
                      name="plant_ct")


def sensor_models(device: DeviceParams = DeviceParams(), op: OperatingPoint | None = None, *,
                  force_n: float = 1.0, model=None) -> tuple[control.StateSpace, control.StateSpace]:
    """The digital anti-alias filter (at the sensor rate) and the linearised estimator.

    Returns
    -------
    aa : StateSpace, dt = 1/sensor_rate
        Tared divider voltage (V) to filtered voltage (V); states ``aa_z1``, ``aa_z2``.
    est : StateSpace, dt = the estimator model's period
        Filtered voltage (V) to estimated force (N): input-map slope, the linear block,
        the output-map slope at the operating point and (when enabled) the two-sample mean;
        states ``est_z0...`` and ``est_raw_prev_n``.
    """
    if op is None:
        op = operating_point(device, force_n)
    r = device.rates
    bb, aa = scipy.signal.butter(2, device.estimator.antialias_cutoff_hz, fs=r.sensor_rate_hz)
    # DF2T realisation exactly as the kernel runs it
    b0, b1, b2 = bb
    a1, a2 = aa[1], aa[2]
    Aaa = np.array([[-a1, 1.0], [-a2, 0.0]])
    Baa = np.array([[b1 - a1 * b0], [b2 - a2 * b0]])
    aa_sys = control.ss(Aaa, Baa, [[1.0, 0.0]], [[b0]], dt=1.0 / r.sensor_rate_hz,
                        inputs=["fsr_voltage_v"], outputs=["aa_out_v"], states=["aa_z1", "aa_z2"],
                        name="antialias")
    from ebraille_sim.estimation.models import load_estimator
    model, _, _, _, in_slope, _, out_slope, _ = _sensor_point(
        device, op.force_n, op.load_time_s, model, direction=-1.0 if op.friction == "release" else 1.0)
    model = model if model is not None else load_estimator(device.estimator.model)
    num = np.asarray(model.linear.numerator(), float)
    den = np.asarray(model.linear.denominator(), float)
    n = max(len(num), len(den))
    num = np.pad(num, (0, n - len(num))) / den[0]
    den = np.pad(den, (0, n - len(den))) / den[0]
    gain = in_slope * out_slope
    # DF2T: y = num0 x + z0 ; z_j <- num_{j+1} x + z_{j+1} - den_{j+1} y
    m = n - 1
    Ae = np.zeros((m, m))
    Be = np.zeros((m, 1))
    for j in range(m):
        Ae[j, 0] = -den[j + 1]
        if j + 1 < m:
            Ae[j, j + 1] = 1.0
        Be[j, 0] = num[j + 1] - den[j + 1] * num[0]
    Ce = np.zeros((1, m))
    Ce[0, 0] = gain
    De = np.array([[gain * num[0]]])
    names = [f"est_z{j}" for j in range(m)]
    if device.estimator.nyquist_average:
        # f = (f_raw + f_raw_prev)/2 with f_raw_prev a state
        A2 = np.zeros((m + 1, m + 1))
        A2[:m, :m] = Ae
        A2[m, :m] = Ce[0]
        B2 = np.vstack([Be, De])
        C2 = np.hstack([0.5 * Ce, [[0.5]]])
        D2 = 0.5 * De
        Ae, Be, Ce, De = A2, B2, C2, D2
        names.append("est_raw_prev_n")
    est_sys = control.ss(Ae, Be, Ce, De, dt=model.dt_s, inputs=["aa_out_v"], outputs=["force_est_n"],
                         states=names, name="estimator")
    return aa_sys, est_sys


def _ratio(device: DeviceParams, est_dt: float) -> int:
    n = device.rates.control_rate_hz * est_dt
    if abs(n - round(n)) > 1e-9 or round(n) < 1:
        raise ValueError(f"the estimator period {est_dt:g} s must be a whole number of control periods")
    if device.rates.sensor_rate_hz != device.rates.control_rate_hz:
        raise ValueError("the sampled-data model assumes the sensor rate equals the control rate")
    return int(round(n))


def _sampled_front(device: DeviceParams, op: OperatingPoint) -> tuple[control.StateSpace, control.StateSpace]:
    """Control-rate model from the command to the anti-alias output, and the estimator.

    With the estimator's creep compensation the front has a second input, the estimate the
    firmware holds (:func:`compensation_model`); :func:`_lift` closes that path."""
    ct = continuous_model(device, op)
    h = 1.0 / device.rates.control_rate_hz
    dt_sys = control.c2d(ct[1, 0], h, method="zoh")
    dt_sys = control.ss(dt_sys.A, dt_sys.B, dt_sys.C, dt_sys.D, dt=h, inputs=["command_v"],
                        outputs=["fsr_voltage_inst_v"], states=list(CONTINUOUS_STATES))
    aa, est = sensor_models(device, op)
    if not device.estimator.creep_compensation:
        front = control.series(control.series(dt_sys, creep_model(device)), aa)
        front = control.ss(front.A, front.B, front.C, front.D, dt=h, inputs=["command_v"], outputs=["aa_out_v"],
                           states=list(CONTINUOUS_STATES) + CREEP_STATES + ["aa_z1", "aa_z2"], name="front")
        return front, est
    g1 = control.series(dt_sys, creep_model(device))
    comp = compensation_model(device, op)
    A1, B1, C1, D1 = (np.atleast_2d(np.asarray(m, float)) for m in (g1.A, g1.B, g1.C, g1.D))
    Ac, Bc, Cc, Dc = (np.atleast_2d(np.asarray(m, float)) for m in (comp.A, comp.B, comp.C, comp.D))
    Aa, Ba, Ca, Da = (np.atleast_2d(np.asarray(m, float)) for m in (aa.A, aa.B, aa.C, aa.D))
    n1, nc, na = A1.shape[0], Ac.shape[0], Aa.shape[0]
    bcv, bce, dcv, dce = Bc[:, [0]], Bc[:, [1]], Dc[0, 0], Dc[0, 1]
    A = np.block([[A1, np.zeros((n1, nc)), np.zeros((n1, na))],
                  [bcv @ C1, Ac, np.zeros((nc, na))],
                  [dcv * (Ba @ C1), Ba @ Cc, Aa]])
    B = np.block([[B1, np.zeros((n1, 1))],
                  [bcv @ D1, bce],
                  [dcv * (Ba @ D1), dce * Ba]])
    C = np.hstack([dcv * (Da @ C1), Da @ Cc, Ca])
    D = np.hstack([dcv * (Da @ D1), dce * Da])
    front = control.ss(A, B, C, D, dt=h, inputs=["command_v", "force_est_held_n"], outputs=["aa_out_v"],
                       states=list(CONTINUOUS_STATES) + CREEP_STATES + COMP_STATES + ["aa_z1", "aa_z2"],
                       name="front")
    return front, est


def _compensated(front: control.StateSpace) -> bool:
    return front.ninputs == 2


def _lift(A, Bu, Be, C, De, est: control.StateSpace, n: int):
    """Lift a sensor-rate model with the compensation's held-estimate input to the estimator rate.

    ``x+ = A x + Bu u + Be e``, ``y = C x + De e`` (``u`` held over the ``n`` samples, ``e``
    the estimate the compensation holds).  The sample that feeds the estimator still holds
    the previous estimate; the ``n - 1`` samples after it hold the new one.  Returns
    ``(A_L, B_L, C_L)``: states ``[x, estimator states, est_held]``, inputs ``u``, output the
    new estimate (no direct term).
    """
    Ae, Bes, Ce, Des = (np.atleast_2d(np.asarray(m, float)) for m in (est.A, est.B, est.C, est.D))
    nx, ne = A.shape[0], Ae.shape[0]
    An, Bn = lift(A, Bu, n)
    An1 = np.linalg.matrix_power(A, n - 1)
    S = np.zeros_like(A)
    Ak = np.eye(nx)
    for _ in range(n - 1):
        S += Ak
        Ak = A @ Ak
    # est_k = Des C x + Ce xe + Des De e_prev
    ex = Des @ C
    ee = Des @ De
    AL = np.zeros((nx + ne + 1, nx + ne + 1))
    AL[:nx, :nx] = An + S @ Be @ ex
    AL[:nx, nx:nx + ne] = S @ Be @ Ce
    AL[:nx, [-1]] = An1 @ Be + S @ Be @ ee
    AL[nx:nx + ne, :nx] = Bes @ C
    AL[nx:nx + ne, nx:nx + ne] = Ae
    AL[nx:nx + ne, [-1]] = Bes @ De
    AL[[-1], :nx] = ex
    AL[[-1], nx:nx + ne] = Ce
    AL[-1, -1] = ee[0, 0]
    BL = np.vstack([Bn, np.zeros((ne + 1, Bu.shape[1]))])
    CL = np.hstack([ex, Ce, ee])
    return AL, BL, CL


def lift(A: np.ndarray, B: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """``(A^n, sum_{j<n} A^j B)``: ``n`` steps of ``x+ = A x + B u`` with ``u`` held."""
    An = np.eye(A.shape[0])
    Bn = np.zeros_like(B)
    for _ in range(n):
        Bn = A @ Bn + B
        An = A @ An
    return An, Bn


def linearize(device: DeviceParams = DeviceParams(), force_n: float = 1.0, *, friction: str = "press",
              finger_pos_m: float = 1e-3, load_time_s: float = 20.0, return_point: bool = False):
    """Small-signal plant from the command (V) to the estimated force (N).

    A discrete-time ``control.StateSpace`` at the estimator's period (0.01 s): the input
    is the command held over one estimator period, the output the estimate produced at
    the end of it (see the module docstring for the sampled-data method).  States, in
    order: :data:`CONTINUOUS_STATES`, :data:`CREEP_STATES`, ``aa_z1``, ``aa_z2``, ``est_z0...``,
    ``est_raw_prev_n``; all are deviations from the operating point.

    Parameters
    ----------
    device : DeviceParams
    force_n : float
        Operating contact force, N (relaxed equilibrium).
    friction : {"press", "release", "none"}
        Sliding direction for the friction linearisation.
    finger_pos_m : float
        Pulp surface position (the scenario's gap), m; it only shifts positions.
    load_time_s : float
        Time the operating force has been held on a recovered FSR film, s: it sets the creep
        states and the divider slope at the operating point; the creep's small-signal
        dynamics are in the model (:func:`creep_model`).
    return_point : bool
        Also return the :class:`OperatingPoint`.

    Returns
    -------
    StateSpace or (StateSpace, OperatingPoint)
    """
    op = operating_point(device, force_n, friction=friction, finger_pos_m=finger_pos_m,
                         load_time_s=load_time_s)
    front, est = _sampled_front(device, op)
    n = _ratio(device, est.dt)
    if _compensated(front):
        A, B, C, D = (np.atleast_2d(np.asarray(m, float)) for m in (front.A, front.B, front.C, front.D))
        AL, BL, CL = _lift(A, B[:, [0]], B[:, [1]], C, D[:, [1]], est, n)
        plant = control.ss(AL, BL, CL, np.zeros((1, 1)), dt=est.dt, inputs=["command_v"], outputs=["force_est_n"],
                           states=front.state_labels + est.state_labels + [ESTIMATE_HELD_STATE], name="plant")
        return (plant, op) if return_point else plant
    An, Bn = lift(front.A, front.B, n)
    lifted = control.ss(An, Bn, front.C, np.zeros((1, 1)), dt=est.dt, inputs=["command_v"],
                        outputs=["aa_out_v"], states=front.state_labels)
    plant = control.series(lifted, est)
    plant = control.ss(plant.A, plant.B, plant.C, plant.D, dt=est.dt, inputs=["command_v"],
                       outputs=["force_est_n"], states=front.state_labels + est.state_labels,
                       name="plant")
    return (plant, op) if return_point else plant


def pid_statespace(config, dt_s: float) -> control.StateSpace:
    """The linear part of :class:`controllers.pid.PID` (no saturation) at the step ``dt_s``.

    Inputs ``setpoint_n`` and ``force_est_n``; output ``command_v``; states
    ``integrator_v`` and ``derivative_v``.  Exactly the recursions of :mod:`controllers.pid`:
    forward-Euler integral on ``r - y``, backward-difference filtered derivative on
    ``c r - y``, proportional on ``b r - y``.
    """
    kp, ki, kd = config.kp_v_per_n, config.ki_v_per_ns, config.kd_vs_per_n
    tf, b, c, h = config.derivative_filter_s, config.setpoint_weight_p, config.setpoint_weight_d, dt_s
    alpha = tf / (tf + h)
    beta = kd / (tf + h)
    A = np.diag([1.0, alpha])
    B = np.array([[ki * h, -ki * h], [(alpha - 1.0) * beta * c, -(alpha - 1.0) * beta]])
    C = np.array([[1.0, 1.0]])
    D = np.array([[kp * b + beta * c, -(kp + beta)]])
    return control.ss(A, B, C, D, dt=h, inputs=["setpoint_n", "force_est_n"], outputs=["command_v"],
                      states=["integrator_v", "derivative_v"], name="pid")


def loop_models(device: DeviceParams, force_n: float, controller, *, friction: str = "press",
                op: OperatingPoint | None = None, front=None):
    """Exact sampled-data loop at the estimator rate.

    ``controller`` is a two-input (setpoint, estimate) ``StateSpace`` at the control rate
    (e.g. :func:`pid_statespace`), a :class:`~controllers.pid.PIDConfig`, a controller
    object: a :class:`~controllers.pid.PID` (its config at ``force_n``, :meth:`~controllers.pid.PIDConfig.at`), a scheduled PID (its
    fixed equivalent at ``force_n``, ``pid_config_at``) or one with a ``statespace()``
    method (:mod:`controllers.lqg`), or a two-input ``StateSpace`` already at the
    estimator rate.  Anything else is a one-line ``TypeError``.

    Returns
    -------
    loop : StateSpace
        Loop transfer ``L`` (estimate in, estimate out, negative feedback), at the
        estimator rate.
    closed : StateSpace
        Setpoint to estimated force, closed loop.
    """
    from controllers.pid import PIDConfig
    if front is None:
        if op is None:
            op = operating_point(device, force_n, friction=friction)
        front = _sampled_front(device, op)
    fr, est = front
    n = _ratio(device, est.dt)
    h = fr.dt
    if isinstance(getattr(controller, "config", None), PIDConfig):
        controller = controller.config
    elif hasattr(controller, "pid_config_at"):
        controller = controller.pid_config_at(force_n)
    elif hasattr(controller, "statespace") and callable(controller.statespace):
        controller = controller.statespace()
    if isinstance(controller, PIDConfig):
        controller = controller.at(force_n)
    if not isinstance(controller, PIDConfig) and not all(hasattr(controller, m) for m in "ABCD"):
        raise TypeError(f"cannot analyse a controller of type {type(controller).__name__}: give a PIDConfig, "
                        "a PID, a scheduled PID, an object with statespace() or a two-input StateSpace")
    if isinstance(controller, PIDConfig):
        controller = pid_statespace(controller, h)
    Ac, Bc, Cc, Dc = (np.atleast_2d(np.asarray(m, float)) for m in
                      (controller.A, controller.B, controller.C, controller.D))
    nx, nc = fr.A.shape[0], Ac.shape[0]
    if _compensated(fr):
        Af, Bf, Cf, Df = (np.atleast_2d(np.asarray(m, float)) for m in (fr.A, fr.B, fr.C, fr.D))
        bu, be = Bf[:, [0]], Bf[:, [1]]
        if math.isclose(controller.dt, h):
            AJ = np.block([[Af, bu @ Cc], [np.zeros((nc, nx)), Ac]])
            BJ = np.vstack([bu @ Dc, Bc])
            BE = np.vstack([be, np.zeros((nc, 1))])
            CJ = np.hstack([Cf, np.zeros((1, nc))])
            A, B, C = _lift(AJ, BJ, BE, CJ, Df[:, [1]], est, n)
        elif math.isclose(controller.dt, est.dt):
            AL, BL, CL = _lift(Af, bu, be, Cf, Df[:, [1]], est, n)
            q = control.series(control.ss(Ac, Bc, Cc, Dc, dt=est.dt), control.ss(AL, BL, CL, [[0.0]], dt=est.dt))
            A, B, C = q.A, q.B, q.C
            if np.any(np.abs(q.D) > 0):
                raise ValueError("the sampled loop must be strictly proper")
        else:
            raise ValueError(f"controller dt {controller.dt} must equal the control period {h} or the "
                             f"estimator period {est.dt}")
        loop = control.ss(A, -B[:, [1]], C, np.zeros((1, 1)), dt=est.dt, inputs=["e"], outputs=["force_est_n"])
        closed = control.ss(A + B[:, [1]] @ C, B[:, [0]], C, np.zeros((1, 1)), dt=est.dt,
                            inputs=["setpoint_n"], outputs=["force_est_n"])
        return loop, closed
    if math.isclose(controller.dt, h):
        # controller and plant lifted together over n control periods
        AJ = np.block([[fr.A, fr.B @ Cc], [np.zeros((nc, nx)), Ac]])
        BJ = np.vstack([fr.B @ Dc, Bc])
        An, Bn = lift(AJ, BJ, n)
        CJ = np.hstack([fr.C, np.zeros((1, nc))])
        q = control.ss(An, Bn, CJ, np.zeros((1, 2)), dt=est.dt)
        q = control.series(q, est)
    elif math.isclose(controller.dt, est.dt):
        An, Bn = lift(fr.A, fr.B, n)
        p = control.series(control.ss(An, Bn, fr.C, np.zeros((1, 1)), dt=est.dt), est)
        # controller then plant
        q = control.series(control.ss(Ac, Bc, Cc, Dc, dt=est.dt), p)
    else:
        raise ValueError(f"controller dt {controller.dt} must equal the control period {h} or the "
                         f"estimator period {est.dt}")
    A, B, C, D = q.A, q.B, q.C, q.D
    if np.any(np.abs(D) > 0):
        raise ValueError("the sampled loop must be strictly proper")
    loop = control.ss(A, -B[:, [1]], C, np.zeros((1, 1)), dt=est.dt, inputs=["e"], outputs=["force_est_n"])
    closed = control.ss(A + B[:, [1]] @ C, B[:, [0]], C, np.zeros((1, 1)), dt=est.dt,
                        inputs=["setpoint_n"], outputs=["force_est_n"])
    return loop, closed


def _freq_grid(dt: float, n: int = 400) -> np.ndarray:
    return np.logspace(-1.5, math.log10(0.999 * math.pi / dt), n)


def _response_function(sys: control.StateSpace):
    """Evaluator ``w -> L(e^{j w dt})`` of a SISO discrete system (Hessenberg form computed once)."""
    A, B, C, D = (np.atleast_2d(np.asarray(m, float)) for m in (sys.A, sys.B, sys.C, sys.D))
    d, dt = complex(D[0, 0]), sys.dt
    if A.size == 0:
        return lambda w: np.full(np.size(w), d)
    H, Q = scipy.linalg.hessenberg(A, calc_q=True)
    Bq = Q.T @ B
    Cq = C @ Q
    I = np.eye(A.shape[0])

    def response(w) -> np.ndarray:
        z = np.exp(1j * np.atleast_1d(np.asarray(w, float)) * dt)
        out = np.empty(len(z), complex)
        for k, zk in enumerate(z):
            out[k] = (Cq @ np.linalg.solve(zk * I - H, Bq))[0, 0] + d
        return out
    return response


def _freq_response(sys: control.StateSpace, w: np.ndarray) -> np.ndarray:
    """Frequency response of a SISO discrete system on ``w`` (rad/s), by a Hessenberg solve."""
    return _response_function(sys)(w)


def _closed_loop_stable(loop: control.StateSpace) -> bool:
    """Whether ``L/(1 + L)`` (unity negative feedback) has every pole inside the unit circle."""
    A, B, C, D = (np.atleast_2d(np.asarray(m, float)) for m in (loop.A, loop.B, loop.C, loop.D))
    if abs(1.0 + D[0, 0]) < 1e-12:
        return False
    if A.size == 0:
        return True
    acl = A - B @ C / (1.0 + D[0, 0])
    return bool(np.max(np.abs(np.linalg.eigvals(acl))) < 1.0)


def sensitivity_peak(loop: control.StateSpace, w: np.ndarray | None = None) -> float:
    """``Ms = max |1/(1 + L)|`` on the unit circle (``inf`` if the closed loop is unstable)."""
    acl = loop.A - loop.B @ loop.C
    if np.max(np.abs(np.linalg.eigvals(acl))) >= 1.0:
        return math.inf
    w = _freq_grid(loop.dt) if w is None else w
    return float(np.max(np.abs(1.0 / (1.0 + _freq_response(loop, w)))))


@dataclass(frozen=True)
class LoopMargins:
    """Gain and phase margins of a loop transfer ``L`` (unity negative feedback).

    Every crossing of the unit circle (gain crossover) and of the negative real axis (phase
    crossover) between 0 and the Nyquist frequency is listed; the reported margins are the
    smallest ones.  The margins describe the distance of the Nyquist curve from -1; they
    say how far a *stable* closed loop is from instability only when
    ``closed_loop_stable`` is true.
    """
    gain_margin: float
    """Gain margin (absolute): ``1/|L|`` at the phase crossover whose value is nearest to 1
    on a log scale (a factor below 1 is a gain-reduction margin); ``inf`` without a phase
    crossover."""
    phase_margin_deg: float
    """``180 deg + arg L``, wrapped to (-180, 180], at the gain crossover where its magnitude
    is smallest; ``inf`` without a gain crossover."""
    gain_crossover_rad_s: float
    """Frequency of the reported phase margin (``nan`` without a gain crossover)."""
    phase_crossover_rad_s: float
    """Frequency of the reported gain margin (``nan`` without a phase crossover)."""
    closed_loop_stable: bool
    """Every pole of ``L/(1 + L)`` inside the unit circle."""
    gain_crossovers_rad_s: tuple = ()
    """All frequencies with ``|L| = 1``, ascending."""
    phase_margins_deg: tuple = ()
    """Phase margin at each gain crossover."""
    phase_crossovers_rad_s: tuple = ()
    """All frequencies with ``arg L = -180 deg (mod 360)``, ascending."""
    gain_margins: tuple = ()
    """Gain margin at each phase crossover."""


def _margin_grid(loop: control.StateSpace, response, w: np.ndarray | None, integrating: bool) -> np.ndarray:
    """Search grid for the crossings: the ``Ms`` grid (or ``w``), the Nyquist frequency, a
    low-frequency extension below the slowest pole or zero, and dense points around every
    lightly damped pole or zero (so that a narrow resonance cannot hide a pair of crossings)."""
    dt = loop.dt
    w_nyq = math.pi / dt
    base = _freq_grid(dt) if w is None else np.asarray(w, float)
    roots = np.concatenate([np.asarray(loop.poles(), complex), np.asarray(loop.zeros(), complex)])
    roots = roots[np.isfinite(roots) & (np.abs(roots) > 1e-9)]
    s = np.log(roots) / dt                    # continuous-time equivalents
    corner = np.abs(s)
    slow = corner[corner > 1e-8 * w_nyq]
    lo = max(1e-8 * w_nyq, 0.01 * float(np.min(slow))) if slow.size else 1e-8 * w_nyq
    lo = min(lo, float(base[0]))
    parts = [base, [w_nyq], np.logspace(math.log10(lo), math.log10(base[0]), 1 + int(100 * math.log10(base[0] / lo)))]
    for wd, sigma in zip(np.abs(s.imag), np.abs(s.real)):
        if lo < wd < w_nyq and sigma < 0.5 * wd:
            parts.append(wd + sigma * np.linspace(-4.0, 4.0, 33))
    if not integrating:
        parts.append([0.0])
    elif abs(response(lo)[0]) < 1.0:
        # below lo the integrators dominate: extend down until |L| > 1
        w_low = lo
        while abs(response(w_low)[0]) < 1.0 and w_low > 1e-12 * w_nyq:
            w_low /= 10.0
        parts.append(np.logspace(math.log10(w_low), math.log10(lo), 1 + 10 * round(math.log10(lo / w_low))))
    grid = np.unique(np.concatenate([np.asarray(p, float) for p in parts]))
    return grid[(grid >= 0.0) & (grid <= w_nyq)]


def _crossings(fun, grid: np.ndarray, values: np.ndarray) -> list[float]:
    """Roots of ``fun`` on the grid: exact zeros and every sign change refined by ``brentq``."""
    out = [float(w) for w, v in zip(grid, values) if v == 0.0]
    ok = np.isfinite(values)
    for i in np.nonzero(ok[:-1] & ok[1:] & (values[:-1] * values[1:] < 0.0))[0]:
        out.append(float(scipy.optimize.brentq(fun, grid[i], grid[i + 1], xtol=1e-13, rtol=4 * np.finfo(float).eps)))
    return sorted(out)


def loop_margins(loop: control.StateSpace, w: np.ndarray | None = None) -> LoopMargins:
    """Gain and phase margins of a discrete SISO loop transfer from its frequency response.

    ``L(e^{j w dt})`` is evaluated on the ``Ms`` grid of :func:`sensitivity_peak` (or on
    ``w``, rad/s) extended as described in :func:`_margin_grid`, up to the Nyquist
    frequency ``pi/dt``.  A gain crossover is a sign change of ``ln|L|``, a phase crossover
    a sign change of ``Im L/|L| = sin(arg L)`` where ``Re L < 0``; each is refined by
    ``scipy.optimize.brentq`` on that continuous function of ``w``.  The phase margin at a
    gain crossover is ``arg(-L)`` in (-180, 180] deg, so no phase unwrapping (and no
    multiple of 360 deg) enters.  ``L`` is real at 0 and at the Nyquist frequency; there a
    negative value is a phase crossover, except at a zero of ``L`` on the unit circle.

    Parameters
    ----------
    loop : StateSpace
        Loop transfer (negative feedback), discrete time, one input and one output.
    w : ndarray, optional
        Base search grid (rad/s, positive, at most the Nyquist frequency).

    Returns
    -------
    LoopMargins
        The smallest margins, their frequencies, every crossing, and whether the closed
        loop is stable.
    """
    if not isinstance(loop, control.StateSpace):
        loop = control.ss(loop)
    if loop.ninputs != 1 or loop.noutputs != 1:
        raise ValueError(f"loop must have one input and one output, got {loop.ninputs} x {loop.noutputs}")
    if loop.dt is None or loop.dt is True or not loop.dt > 0:
        raise ValueError(f"loop must be discrete-time with a numeric sampling period, got dt={loop.dt}")
    w_nyq = math.pi / loop.dt
    if w is not None:
        w = np.asarray(w, float)
        if w.ndim != 1 or w.size < 2 or not np.all(np.isfinite(w)) or np.any(w <= 0) or np.any(w > w_nyq * (1 + 1e-12)):
            raise ValueError(f"w must be a 1-D grid of at least two frequencies in (0, {w_nyq:g}] rad/s")
        w = np.sort(w)
    response = _response_function(loop)
    # a pole this close to z = 1 acts as an integrator on the whole grid (and makes L(1) meaningless)
    poles = np.asarray(loop.poles(), complex)
    integrating = bool(np.any(np.abs(np.log(poles[np.abs(poles) > 1e-9])) < 1e-8 * math.pi))
    grid = _margin_grid(loop, response, w, integrating)
    ell = response(grid)
    real_end = (grid == 0.0) | (grid == w_nyq)
    ell[real_end] = ell[real_end].real          # L is real at z = 1 and z = -1
    with np.errstate(divide="ignore", invalid="ignore"):
        log_mag = np.log(np.abs(ell))
        sin_arg = ell.imag / np.abs(ell)

    def f_mag(x):
        return float(np.log(abs(response(x)[0])))

    def f_arg(x):
        v = response(x)[0]
        return 0.0 if x in (0.0, w_nyq) else float(v.imag / abs(v))

    wgc = _crossings(f_mag, grid, log_mag)
    pms = [math.degrees(np.angle(-response(x)[0])) for x in wgc]
    wpc, gms = [], []
    for x in _crossings(f_arg, grid, sin_arg):
        v = response(x)[0]
        if x in (0.0, w_nyq):
            v = complex(v.real, 0.0)
            # a zero of L at z = +-1 is the curve passing through the origin, not a crossing
            k = int(np.searchsorted(grid, x))
            neighbour = ell[k + 1] if x == 0.0 else ell[k - 1]
            if abs(v) <= 1e-6 * abs(neighbour):
                continue
        # a sign change of sin(arg L) across a zero of L on the unit circle is a jump, not a root
        if v.real < 0.0 and abs(v.imag) <= 1e-3 * abs(v):
            wpc.append(x)
            gms.append(1.0 / abs(v))
    if pms:
        i = int(np.argmin(np.abs(pms)))
        pm, w_pm = pms[i], wgc[i]
    else:
        pm, w_pm = math.inf, math.nan
    if gms:
        j = int(np.argmin(np.abs(np.log(gms))))
        gm, w_gm = gms[j], wpc[j]
    else:
        gm, w_gm = math.inf, math.nan
    return LoopMargins(gain_margin=gm, phase_margin_deg=pm, gain_crossover_rad_s=w_pm, phase_crossover_rad_s=w_gm,
                       closed_loop_stable=_closed_loop_stable(loop), gain_crossovers_rad_s=tuple(wgc),
                       phase_margins_deg=tuple(pms), phase_crossovers_rad_s=tuple(wpc), gain_margins=tuple(gms))


@dataclass
class LoopAnalysis:
    """Frequency and step analysis of one loop at one operating force.

    The margins are those of :func:`loop_margins`; on an unstable closed loop they are
    ``nan`` here (the crossings themselves stay in ``margins``).
    """
    force_n: float
    gain_margin: float
    """Gain margin (absolute, ``inf`` if the phase never crosses -180 deg, ``nan`` if the
    closed loop is unstable)."""
    phase_margin_deg: float
    """Phase margin (``inf`` if ``|L|`` never crosses 1, ``nan`` if the closed loop is unstable)."""
    gain_crossover_hz: float
    """Frequency of the phase margin (``nan`` if none or unstable)."""
    phase_crossover_hz: float
    """Frequency of the gain margin (``nan`` if none or unstable)."""
    ms: float
    """Sensitivity peak max |S|."""
    bandwidth_hz: float
    """First frequency where |T| falls 3 dB below its DC value."""
    step: dict
    """``control.step_info`` of the setpoint-to-estimate step (a unit step)."""
    stable: bool
    loop: control.StateSpace
    closed: control.StateSpace
    op: OperatingPoint
    margins: LoopMargins
    """Every crossing of ``L`` (:func:`loop_margins`), stable or not."""

    def summary(self) -> dict:
        keys = ("RiseTime", "SettlingTime", "Overshoot", "Peak")
        return {"force_n": self.force_n, "gain_margin": self.gain_margin, "phase_margin_deg": self.phase_margin_deg,
                "gain_crossover_hz": self.gain_crossover_hz, "phase_crossover_hz": self.phase_crossover_hz,
                "ms": self.ms, "bandwidth_hz": self.bandwidth_hz,
                "stable": self.stable, **{f"step_{k}": float(self.step.get(k, math.nan)) for k in keys}}

    def margin_label(self) -> str:
        """``PM .. deg at .. Hz, GM ..`` for a stable loop, ``closed loop unstable`` otherwise."""
        if not self.stable:
            return "closed loop unstable"
        pm = "PM none" if math.isinf(self.phase_margin_deg) else \
            f"PM {self.phase_margin_deg:.1f} deg at {self.gain_crossover_hz:.2f} Hz"
        gm = "GM inf" if math.isinf(self.gain_margin) else f"GM {self.gain_margin:.2f}"
        return f"{pm}, {gm}"


def analyse_loop(controller, device: DeviceParams = DeviceParams(), force_n: float = 1.0, *,
                 friction: str = "press", step_time_s: float = 3.0) -> LoopAnalysis:
    """Margins, Ms, bandwidth and closed-loop step of ``controller`` at ``force_n``.

    ``controller`` as in :func:`loop_models`.  Margins from :func:`loop_margins` (the
    loop's frequency response, crossings refined by a root finder); the step from
    ``control.step_info`` on a ``step_time_s`` response.
    """
    op = operating_point(device, force_n, friction=friction)
    loop, closed = loop_models(device, force_n, controller, op=op)
    margins = loop_margins(loop)
    stable = margins.closed_loop_stable
    hz = 1.0 / (2 * math.pi)
    gm, pm, wgc, wpc = ((margins.gain_margin, margins.phase_margin_deg, margins.gain_crossover_rad_s * hz,
                         margins.phase_crossover_rad_s * hz) if stable else (math.nan,) * 4)
    ms = sensitivity_peak(loop)
    w = _freq_grid(loop.dt, 800)
    t_mag = np.abs(_freq_response(closed, w))
    t0 = abs(float(np.real(control.dcgain(closed)))) if stable else math.nan
    below = np.nonzero(t_mag < t0 / math.sqrt(2.0))[0] if stable else []
    bw = float(w[below[0]] / (2 * math.pi)) if len(below) else math.nan
    if stable:
        t = np.arange(0.0, step_time_s, closed.dt)
        resp = control.step_response(closed, T=t)
        info = control.step_info(resp.outputs, T=resp.time, yfinal=t0)
    else:
        info = {}
    return LoopAnalysis(force_n=float(force_n), gain_margin=gm, phase_margin_deg=pm, gain_crossover_hz=wgc,
                        phase_crossover_hz=wpc, ms=ms, bandwidth_hz=bw, step=dict(info), stable=stable, loop=loop,
                        closed=closed, op=op, margins=margins)


def foptd_fit(plant: control.StateSpace, t_end_s: float = 6.0) -> tuple[float, float, float]:
    """First-order-plus-delay fit ``k e^{-theta s}/(tau s + 1)`` of a stable plant's step.

    Uses the 28 % / 63 % two-point method on the step response of ``plant`` (Smith's
    method), with the crossing times interpolated between samples; returns
    ``(k, tau_s, theta_s)``.  ``k`` is the response reached at ``t_end_s``: the FSR creep's
    10-100 s terms raise the DC gain by a few per cent more over minutes, which the
    controller's integral action takes up and a fit of the loop's time scale must not
    stretch over.  The delay is at least one sample period of the plant: the estimate is
    held over it, and a shorter delay cannot be read from the samples (with the pulp's
    tap-dissipation weights the two-point delay of the estimator-rate step is 5 ms).
    """
    t = np.arange(0.0, t_end_s, plant.dt)
    r = control.step_response(plant, T=t)
    y = np.asarray(r.outputs).ravel()
    k = float(y[-1])

    def crossing(level):
        j = int(np.argmax(y >= level))
        return float(r.time[j - 1] + (level - y[j - 1]) / (y[j] - y[j - 1]) * (r.time[j] - r.time[j - 1]))
    t28, t63 = crossing(0.283 * k), crossing(0.632 * k)
    tau = 1.5 * (t63 - t28)
    theta = max(t63 - tau, plant.dt)
    return k, tau, theta


def simc_pid(device: DeviceParams = DeviceParams(), force_n: float = 1.0, tau_c_s: float | None = None):
    """SIMC PI gains (Skogestad 2003) from a first-order-plus-delay fit of :func:`linearize`.

    ``kc = tau / (k (tau_c + theta))``, ``tau_I = min(tau, 4 (tau_c + theta))``, with the
    "tight" choice ``tau_c = theta`` unless given.  Returns a
    :class:`~controllers.pid.PIDConfig` with the default limits and derivative filter.
    """
    from controllers.pid import DEFAULT_PID
    plant = linearize(device, force_n)
    k, tau, theta = foptd_fit(plant)
    tc = theta if tau_c_s is None else tau_c_s
    kc = tau / (k * (tc + theta))
    ti = min(tau, 4.0 * (tc + theta))
    return dataclasses.replace(DEFAULT_PID, kp_v_per_n=kc, ki_v_per_ns=kc / ti, kd_vs_per_n=0.0)


def plot_bode(analyses, path, title: str = "") -> None:
    """Bode plot of the loop transfer of several :class:`LoopAnalysis` (one line each).

    The legend gives the margins of :func:`loop_margins` (or says that the closed loop is
    unstable); a circle marks the gain crossover of the phase margin, a square the phase
    crossover of the gain margin.
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    for an in analyses:
        w = _freq_grid(an.loop.dt, 600)
        l = _freq_response(an.loop, w)
        f = w / (2 * math.pi)
        ms = f"Ms {an.ms:.2f}" if math.isfinite(an.ms) else "Ms inf"
        lab = f"{an.force_n:g} N ({an.margin_label()}, {ms})"
        phase = np.degrees(np.unwrap(np.angle(l)))
        phase -= 360.0 * math.floor((phase[0] + 180.0) / 360.0)   # start within [-180, 180)
        line, = a1.semilogx(f, 20 * np.log10(np.abs(l)), label=lab)
        a2.semilogx(f, phase, color=line.get_color())
        if an.stable and math.isfinite(an.gain_crossover_hz):
            a1.plot(an.gain_crossover_hz, 0.0, "o", color=line.get_color(), ms=4)
        if an.stable and math.isfinite(an.phase_crossover_hz):
            p_gm = np.interp(an.phase_crossover_hz, f, phase)
            a2.plot(an.phase_crossover_hz, -180.0 + 360.0 * round((p_gm + 180.0) / 360.0), "s",
                    color=line.get_color(), ms=4)
    a1.axhline(0, color="0.5", lw=0.8)
    a2.axhline(-180, color="0.5", lw=0.8)
    a1.set_ylabel("|L| (dB)")
    a2.set_ylabel("phase L (deg)")
    a2.set_xlabel("frequency (Hz)")
    a1.legend(fontsize=8)
    a1.set_title(title or "loop transfer L = C P (sampled at the estimator rate)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_nyquist(analyses, path, title: str = "", ms_limit: float = 1.6) -> None:
    """Nyquist plot of the loop transfers with the ``1/ms_limit`` circle around -1."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6, 6))
    for an in analyses:
        w = _freq_grid(an.loop.dt, 800)
        l = _freq_response(an.loop, w)
        ax.plot(l.real, l.imag, label=f"{an.force_n:g} N (Ms {an.ms:.2f})")
        ax.plot(l.real, -l.imag, color=ax.lines[-1].get_color(), ls=":", lw=0.8)
    th = np.linspace(0, 2 * np.pi, 200)
    ax.plot(-1 + np.cos(th) / ms_limit, np.sin(th) / ms_limit, "k--", lw=0.8, label=f"|1+L| = 1/{ms_limit:g}")
    ax.plot([-1], [0], "r+", ms=12)
    ax.set_xlim(-3, 1.5)
    ax.set_ylim(-2.5, 2.5)
    ax.set_aspect("equal")
    ax.set_xlabel("Re L")
    ax.set_ylabel("Im L")
    ax.legend(fontsize=8, loc="lower right")
    ax.set_title(title or "Nyquist plot of L")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def make_lqg(device: DeviceParams = DeviceParams(), **gains):
    """The registered ``"lqg"`` controller: :class:`controllers.lqg.LQG` designed on
    :func:`linearize` of ``device`` at ``design_force_n``."""
    from controllers.lqg import LQG, config_from
    config = config_from(**gains)
    plant, op = linearize(device, config.design_force_n, return_point=True)
    return LQG(config, plant, op.command_v, op.estimate_n)
