"""The contact plant in continuous time (ebraille_sim.analysis.plant_model): equilibrium, nlsys, Jacobian."""
import control
import numpy as np
import pytest

from ebraille_sim.analysis.plant_model import CONTINUOUS_STATES, contact_plant_system, continuous_model, operating_point
from ebraille_sim.physics.drivetrain import mesh_force
from ebraille_sim.physics.fingertip import elastic_force
from ebraille_sim.physics.params import DeviceParams
from ebraille_sim.plant.layout import P
from ebraille_sim.plant.lumped import pack_params


@pytest.mark.parametrize("force", [0.5, 1.0, 2.0])
def test_operating_point_closed_form_and_solver_agree(force):
    dev = DeviceParams()
    op = operating_point(dev, force)
    f = dev.finger
    assert op.elastic_force_n == pytest.approx(force / f.relax_weight_inf)
    assert op.compression_m == pytest.approx(f.compression_at_m(force, relaxed=True))
    assert op.tangent_stiffness_n_per_m == pytest.approx(
        f.stiffness_b_n_per_m + f.exponent_m_per_m * force / f.relax_weight_inf)
    # pressing edge of the friction band: (1 + mu) Fm + Fc at the motor
    g = dev.drivetrain.gear_ratio / dev.drivetrain.pinion_radius_m
    mu = dev.drivetrain.gear_loss_coefficient
    fm = force + dev.drivetrain.moving_mass_kg * dev.gravity_m_per_s2 + dev.drivetrain.guide_coulomb_n
    v0 = dev.motor.resistance_ohm * ((1 + mu) * fm + dev.motor.friction_torque_nm * g) / (
        dev.motor.torque_constant_nm_per_a * g)
    assert op.command_v == pytest.approx(v0, rel=1e-12)
    assert op.solver_residual < 1e-6


def test_find_operating_point_from_out_of_contact_guess_is_not_trusted():
    # the pitfall: from a guess outside contact the solver sees no force gradient
    sys = contact_plant_system()
    op = control.find_operating_point(sys, np.zeros(9), [0.5], y0=[1.0, 0.0], iy=[0], return_result=True)
    ok = op.result.success and abs(float(np.asarray(op.outputs)[0]) - 1.0) < 1e-6
    assert not ok


def test_analytic_jacobian_matches_control_linearize():
    dev = DeviceParams()
    op = operating_point(dev, 1.0)
    x_eq = np.array([op.current_a, op.pinion_pos_m, 0.0, op.board_pos_m, 0.0, 0.0, 0.0, 0.0, op.force_n])
    num = control.linearize(contact_plant_system(dev), x_eq, [op.command_v], eps=1e-9)
    ana = continuous_model(dev, op)
    assert ana.state_labels == CONTINUOUS_STATES
    scale = np.maximum(np.abs(ana.A), 1e-9 * np.max(np.abs(ana.A)))
    assert np.max(np.abs(num.A - ana.A) / scale) < 1e-3
    assert np.allclose(num.B, ana.B, rtol=1e-6)
    assert np.allclose(num.C[0], ana.C[0], rtol=1e-4, atol=1e-6)


def _law_mismatch(dev, op, elastic, mesh) -> dict:
    """Relative differences between the gains of the linear model at ``op`` and central
    differences of the nonlinear laws ``elastic(d, b, m)`` and ``mesh(dx, dv, b, k, c)``,
    evaluated with the parameters the kernel simulates (``pack_params``)."""
    p = pack_params(dev, 1.0)
    ct = continuous_model(dev, op)
    A, C = ct.A, ct.C
    f = dev.finger
    b, m = p[P.finger_b_n_per_m], p[P.finger_m_per_m]
    d0 = op.compression_m
    hd = 1e-6 * d0
    k_pulp = (elastic(d0 + hd, b, m) - elastic(d0 - hd, b, m)) / (2 * hd)
    hb, km, cm = p[P.half_backlash_m], p[P.mesh_k_n_per_m], p[P.mesh_c_n_s_per_m]
    dx0 = op.pinion_pos_m - op.board_pos_m
    hx, hv = 1e-6 * (dx0 - hb), 1e-6
    k_mesh = (mesh(dx0 + hx, 0.0, hb, km, cm) - mesh(dx0 - hx, 0.0, hb, km, cm)) / (2 * hx)
    c_mesh = (mesh(dx0, hv, hb, km, cm) - mesh(dx0, -hv, hb, km, cm)) / (2 * hv)
    mb, mp, g = p[P.board_mass_kg], p[P.pinion_mass_kg], p[P.n_over_r_per_m]
    rel = lambda lin, law: abs(lin - law) / abs(law)  # noqa: E731
    return {
        "pulp_relaxed": rel(C[0, 3], f.relax_weight_inf * k_pulp),
        **{f"pulp_prony_{j}": rel(A[5 + j, 4], cj * k_pulp)
           for j, cj in enumerate((f.relax_weight_1, f.relax_weight_2, f.relax_weight_3))},
        "mesh_stiffness": rel(A[4, 1] * mb, k_mesh),
        "mesh_damping": rel(A[4, 2] * mb, c_mesh),
        "mesh_force_at_op": rel(op.mesh_force_n, mesh(dx0, 0.0, hb, km, cm)),
        "pulp_force_at_op": rel(op.force_n, f.relax_weight_inf * elastic(d0, b, m)),
        "motor_force_per_a": rel(A[2, 0] * mp, p[P.motor_kt] * g),
        "back_emf_per_m_per_s": rel(-A[0, 2] * dev.motor.inductance_h, p[P.motor_ke] * g),
    }


@pytest.mark.parametrize("force", [0.3, 1.0, 2.5])
def test_linear_gains_are_finite_differences_of_the_law_functions(force):
    """The linear model's pulp, mesh and motor gains are the slopes of the nonlinear law
    functions (physics.fingertip.elastic_force, physics.drivetrain.mesh_force) at the
    operating point, with the parameters the kernel runs; a 5 % change of either law
    moves its finite difference by 5 %, which this comparison sees."""
    dev = DeviceParams()
    op = operating_point(dev, force)
    elastic, mesh = elastic_force.py_func, mesh_force.py_func
    mismatch = _law_mismatch(dev, op, elastic, mesh)
    assert max(mismatch.values()) < 1e-5, mismatch
    scaled = _law_mismatch(dev, op, lambda d, b, m: 1.05 * elastic(d, b, m), mesh)
    assert scaled["pulp_relaxed"] == pytest.approx(0.05 / 1.05, rel=1e-3)
    scaled = _law_mismatch(dev, op, elastic, lambda dx, dv, b, k, c: 1.05 * mesh(dx, dv, b, k, c))
    assert scaled["mesh_stiffness"] == pytest.approx(0.05 / 1.05, rel=1e-3)
    assert scaled["mesh_damping"] == pytest.approx(0.05 / 1.05, rel=1e-3)
