r"""The contact plant in continuous time: its equations, equilibrium and Jacobian.

The plant a controller drives runs from the motor command (V) through the drive train and
the pulp to the FSR's mechanical lag.  :func:`contact_plant_system` is it as a
``control.NonlinearIOSystem`` (``nlsys``), :func:`operating_point` its relaxed equilibrium
in contact and :func:`continuous_model` its Jacobian there, a ``control.StateSpace``.  The
sampled-data plant a controller sees (:mod:`ebraille_sim.analysis.sampled`) starts from it.

The continuous-time laws are those of the physics layer, called by both the right-hand side
and the Jacobian: the armature ODE (:func:`ebraille_sim.physics.motor.current_rate_a_per_s`),
the gear loss (:func:`ebraille_sim.physics.drivetrain.gear_loss_n`), the mesh
(:func:`ebraille_sim.physics.drivetrain.mesh_force`), the pulp's elastic law and tangent
stiffness (:mod:`ebraille_sim.physics.fingertip`) and the Prony ODE
(:func:`ebraille_sim.physics.fingertip.prony_rate_n_per_s`).  The Jacobian takes the
partial derivatives of the linear laws as their values on unit inputs and the gear loss's
as its value at a unit load on the loaded flank, so it is exact (no finite difference).

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

Operating point
---------------
:func:`operating_point` derives the equilibrium in closed form and checks it with
``control.find_operating_point`` (``return_result=True``; the result's ``success`` flag
is checked, and the two answers must agree) on :func:`contact_plant_system`, a
``NonlinearIOSystem`` of the contact plant that keeps the contact and backlash kinks.

Examples
--------
>>> from ebraille_sim.analysis.plant_model import continuous_model, operating_point
>>> op = operating_point(force_n=1.0)
>>> round(op.compression_m * 1e3, 3), round(op.command_v, 3)
(2.793, 0.563)
>>> continuous_model(op=op).nstates
9
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import control
import numpy as np

from ebraille_sim.analysis.sensor_point import sensor_point
from ebraille_sim.physics.drivetrain import (gear_loss_n, mesh_damping_n_s_per_m, mesh_force, reflected,
                                             shaft_to_rack_per_m)
from ebraille_sim.physics.fingertip import elastic_force, prony_rate_n_per_s, tangent_stiffness_n_per_m
from ebraille_sim.physics.motor import current_rate_a_per_s
from ebraille_sim.physics.params import DeviceParams

__all__ = ["OperatingPoint", "FRICTION_RULES", "CONTINUOUS_STATES", "operating_point", "contact_plant_system",
           "continuous_model"]

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
# the scalar laws of the plant, evaluated in Python (the code the kernel compiles)
_mesh_force = mesh_force.py_func
_elastic_force = elastic_force.py_func
_tangent_stiffness = tangent_stiffness_n_per_m.py_func
_shaft_to_rack = shaft_to_rack_per_m.py_func
_gear_loss = gear_loss_n.py_func


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
        di = current_rate_a_per_s(x[0], v, x[2], k["R"], k["L"], k["ke"] * k["g"])
        fric_p = sgn * (k["Fpc"] + _gear_loss(k["mu"], fm))
        dvp = (k["kt"] * k["g"] * x[0] - fm - fric_p - k["cp"] * x[2]) / k["Mp"]
        dvb = (fm - f + k["Mb"] * k["grav"] - sgn * k["Fgc"] - k["cg"] * x[4]) / k["Mb"]
        dfe = kk * x[4]
        return np.array([di, x[2], dvp, x[4], dvb,
                         prony_rate_n_per_s(x[5], t1, c1, dfe), prony_rate_n_per_s(x[6], t2, c2, dfe),
                         prony_rate_n_per_s(x[7], t3, c3, dfe),
                         (f - x[8]) / k["tau_fsr"]])

    def outfcn(t, x, u, params):
        return np.array([contact(x), mesh(x)])

    return control.nlsys(updfcn, outfcn, inputs=["command_v"], outputs=["contact_force_n", "mesh_force_n"],
                         states=list(CONTINUOUS_STATES), name="contact_plant")


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
    i0 = (fm0 + sgn * (k["Fpc"] + _gear_loss(k["mu"], fm0))) / (k["kt"] * k["g"])
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
    _, vf, slope, u_est, _, y_lin, out_slope, est = sensor_point(device, force_n, load_time_s,
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
    # armature: the ODE is linear in (i, V, vp), so its partials are its values on unit inputs
    emf = k["ke"] * k["g"]
    A[0, 0] = current_rate_a_per_s(1.0, 0.0, 0.0, k["R"], k["L"], emf)
    A[0, 2] = current_rate_a_per_s(0.0, 0.0, 1.0, k["R"], k["L"], emf)
    B[0, 0] = current_rate_a_per_s(0.0, 1.0, 0.0, k["R"], k["L"], emf)
    # pinion: Fm = km (xp - xb) + cm (vp - vb), loaded by (1 + s mu) Fm
    A[1, 2] = 1.0
    # the gear loss mu |Fm| is homogeneous of degree one: its slope is its value at a unit
    # load on the flank the mesh force is on, times the sign of that force
    side = math.copysign(1.0, op.mesh_force_n)
    gl = 1.0 + sgn * (side * _gear_loss(k["mu"], side))
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
        A[5 + j, 5 + j] = prony_rate_n_per_s(1.0, tj, cj, 0.0)
        A[5 + j, 4] = prony_rate_n_per_s(0.0, tj, cj, kk)       # dFe/dt = K vb
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
