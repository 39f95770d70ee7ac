"""Linearisation, sampled-data loop analysis and robust tuning (ebraille_sim.analysis.tuning, ebraille_sim.analysis.robust)."""
import dataclasses
import math

import control
import numpy as np
import pytest

from controllers.pid import DEFAULT_PID, PID, PIDConfig
from ebraille_sim.analysis.tuning import (CONTINUOUS_STATES, analyse_loop, contact_plant_system, continuous_model,
                                linearize, operating_point, pid_statespace, simc_pid)
from ebraille_sim.physics.drivetrain import mesh_force
from ebraille_sim.physics.fingertip import elastic_force
from ebraille_sim.physics.params import DeviceParams
from ebraille_sim.plant.layout import P
from ebraille_sim.plant.loop import Plant, pack_params

COULOMB = dataclasses.replace(
    DeviceParams(), motor=dataclasses.replace(DeviceParams().motor, breakaway_ratio=1.0),
    drivetrain=dataclasses.replace(DeviceParams().drivetrain, guide_breakaway_ratio=1.0))
"""The default device with the static-friction excess removed (pure Coulomb friction)."""


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


def test_sampled_model_shape_and_gain():
    P, op = linearize(force_n=1.0, return_point=True)
    assert P.dt == pytest.approx(0.01)
    assert P.state_labels[:9] == CONTINUOUS_STATES
    assert P.state_labels[-2:] == ["est_raw_prev_n", "est_held_n"]     # the compensation holds it
    assert np.all(np.abs(P.poles()) < 1.0)
    # DC gain: stall force per volt through the gear loss, times the sensor chain's slope
    dev = DeviceParams()
    g = dev.drivetrain.gear_ratio / dev.drivetrain.pinion_radius_m
    stall = dev.motor.torque_constant_nm_per_a * g / (dev.motor.resistance_ohm * (1 + dev.drivetrain.gear_loss_coefficient))
    assert float(np.real(control.dcgain(P))) == pytest.approx(stall * 0.955, rel=0.03)


@pytest.mark.parametrize("force,dv", [(1.0, 0.1), (2.0, 0.1)])
def test_small_step_matches_nonlinear_plant(force, dv):
    """Tolerance: estimated force within 10 % and true force within 5 % of the final change.

    The plant is the default device with pure Coulomb friction (the linearisation rule);
    it is brought to its pressing equilibrium with the operating command held 15 s.
    """
    P, op = linearize(COULOMB, force, return_point=True)
    pl = Plant.from_devices([COULOMB], seeds=[1])
    pl.set_finger(1e-3)
    for _ in range(15000):
        pl.advance(op.command_v)
    assert pl.contact_force_n[0] == pytest.approx(force, rel=1e-3)
    f0, e0 = pl.contact_force_n[0], pl.force_est_n[0]
    n = 1500
    fe, ft = np.zeros(n), np.zeros(n)
    for k in range(n):
        pl.advance(op.command_v + dv)
        fe[k], ft[k] = pl.force_est_n[0], pl.contact_force_n[0]
    t = np.arange(n // 10) * 0.01
    y_lin = np.asarray(control.forced_response(P, T=t, U=np.full(len(t), dv)).outputs).ravel()
    y_nl = np.concatenate([[0.0], fe[9::10][:len(t) - 1] - e0])
    assert np.max(np.abs(y_nl - y_lin)) <= 0.10 * abs(y_lin[-1])
    ct = continuous_model(COULOMB, op)
    tt = np.arange(n + 1) * 1e-3
    y_ct = np.asarray(control.forced_response(ct[0, 0], T=tt, U=np.full(n + 1, dv)).outputs).ravel()[1:]
    assert np.max(np.abs(ft - f0 - y_ct)) <= 0.05 * abs(y_ct[-1])


def _sensor_chain_after_a_hold(dev, force_n: float, hold: int, after: int, slot: str) -> np.ndarray:
    """The compiled sensor chain alone: 1 N held for ``hold`` sensor samples on a recovered
    film, then ``force_n`` for ``after`` samples; the state ``slot`` at each of those."""
    from ebraille_sim.plant import kernel
    from ebraille_sim.plant.layout import N_INPUT, S
    from ebraille_sim.plant.loop import initial_state
    n_sub = int(round(dev.rates.physics_rate_hz / dev.rates.sensor_rate_hz))
    p = pack_params(dev, 0.0)
    s = initial_state(dev, p)
    u = np.zeros(N_INPUT)
    for _ in range(hold):
        kernel.advance_sensor_only(s, p, u, 1.0, n_sub)
    out = np.zeros(after)
    for k in range(after):
        kernel.advance_sensor_only(s, p, u, force_n, n_sub)
        out[k] = s[S[slot]]
    return out


def _sensor_chain_to_estimate(dev, op):
    """Linear model from the contact force to the estimate at the estimator rate: the FSR's
    mechanical lag over a sensor period, slope and creep terms, the compensation, the
    anti-alias filter and the estimator, lifted as :func:`linearize` lifts the plant."""
    from ebraille_sim.analysis.tuning import _lift, compensation_model, creep_model, sensor_models
    p = pack_params(dev, 0.0)
    n_sub = int(round(dev.rates.physics_rate_hz / dev.rates.sensor_rate_hz))
    al = 1.0 - (1.0 - p[P.fsr_lag_alpha]) ** n_sub
    dt = 1.0 / dev.rates.sensor_rate_hz
    k = op.fsr_slope_v_per_n
    lag = control.ss([[1 - al]], [[al]], [[k * (1 - al)]], [[k * al]], dt=dt)
    g1 = control.series(lag, creep_model(dev))
    aa, est = sensor_models(dev, op)
    comp = compensation_model(dev, op)
    m = [[np.atleast_2d(np.asarray(x, float)) for x in (g.A, g.B, g.C, g.D)] for g in (g1, comp, aa)]
    (A1, B1, C1, D1), (Ac, Bc, Cc, Dc), (Aa, Ba, Ca, Da) = m
    n1, nc, na = A1.shape[0], Ac.shape[0], Aa.shape[0]
    bcv, bce = Bc.reshape(nc, 2)[:, [0]], Bc.reshape(nc, 2)[:, [1]]
    dcv, dce = Dc[0, 0], Dc[0, 1]
    A = np.block([[A1, np.zeros((n1, nc)), np.zeros((n1, na))], [bcv @ C1, Ac, np.zeros((nc, na))],
                  [dcv * (Ba @ C1), Ba @ Cc, Aa]])
    Bu = np.vstack([B1, bcv @ D1, dcv * (Ba @ D1)])
    Be = np.vstack([np.zeros((n1, 1)), bce, dce * Ba])
    C = np.hstack([dcv * (Da @ C1), Da @ Cc, Ca])
    AL, BL, CL = _lift(A, Bu, Be, C, np.array([[dce * Da[0, 0]]]), est, int(round(est.dt / dt)))
    return control.ss(AL, BL, CL, [[0.0]], dt=est.dt)


def test_linear_estimate_with_creep_compensation_is_the_finite_difference_of_the_kernel():
    """The sensor chain of the linearisation with the estimator's creep compensation (the
    firmware's creep terms on the held estimate, the compensated voltage, the lifted
    estimator with the estimate fed back) against differences of the compiled chain: 1 N
    held 20 s, then 1 or 2 mN more for 3 s (noise off, 24-bit ADC, Richardson-extrapolated).
    From 80 ms on, the linear estimate agrees within 1 % with and without the compensation
    (measured 0.57 % and 0.54 %), and it reproduces what the compensation changes: after
    3 s the compensated estimate has risen 2.2 % more (kernel 0.0205, model 0.0201)."""
    base = DeviceParams()
    hold, after, df = 20000, 3000, 1e-3
    last = {}
    for comp in (True, False):
        dev = dataclasses.replace(base, fsr=dataclasses.replace(base.fsr, noise_v_rms=0.0),
                                  circuit=dataclasses.replace(base.circuit, adc_bits=24),
                                  estimator=dataclasses.replace(base.estimator, creep_compensation=comp))
        op = operating_point(dev, 1.0, check=False)
        e0, e1, e2 = (_sensor_chain_after_a_hold(dev, f1, hold, after, "force_est_n")
                      for f1 in (1.0, 1.0 + df, 1.0 + 2 * df))
        sim = (2 * (e1 - e0) / df - (e2 - e0) / (2 * df))[::10]
        lin = np.asarray(control.step_response(_sensor_chain_to_estimate(dev, op),
                                               T=np.arange(len(sim)) * 0.01).outputs).ravel()
        assert np.max(np.abs(sim[8:] - lin[8:]) / np.abs(lin[8:])) < 0.01, comp
        last[comp] = (sim[-1], lin[-1])
    d_sim = last[True][0] - last[False][0]
    d_lin = last[True][1] - last[False][1]
    assert d_sim > 0.015 and d_lin == pytest.approx(d_sim, rel=0.05)


def test_linear_sensor_creep_is_the_finite_difference_of_the_kernel():
    """The FSR part of the linearisation (instantaneous slope, then the creep terms of
    ``creep_model``) against central differences of the compiled sensor chain: from a
    recovered film, 1 N held 20 s, then 1 N plus 1 or 2 mN for 5 s (noise off, 24-bit ADC;
    one-sided in the pressing direction, as the linearisation: a small decrease stays inside
    the hysteresis plays; Richardson-extrapolated).
    A creep frozen at its 20-s value (the slope of the 20-s loading voltage) reads 8.7 % high
    20 ms after the step; the dynamic terms match to 0.3 % at every sample after the 1.5 ms
    mechanical lag has settled."""
    from ebraille_sim.analysis.tuning import creep_model
    from ebraille_sim.estimation.calibration import loading_voltage
    base = DeviceParams()
    dev = dataclasses.replace(base, fsr=dataclasses.replace(base.fsr, noise_v_rms=0.0),
                              circuit=dataclasses.replace(base.circuit, adc_bits=24))
    op = operating_point(dev, 1.0, check=False)
    hold, after, df = 20000, 5000, 1e-3
    v0, v1, v2 = (_sensor_chain_after_a_hold(dev, f1, hold, after, "fsr_voltage_v")
                  for f1 in (1.0, 1.0 + df, 1.0 + 2 * df))
    sim = 2 * (v1 - v0) / df - (v2 - v0) / (2 * df)
    lin = op.fsr_slope_v_per_n * np.asarray(control.step_response(creep_model(dev), T=np.arange(after) * 1e-3)
                                            .outputs).ravel()
    k0 = 20
    assert np.max(np.abs(sim[k0:] - lin[k0:]) / lin[k0:]) < 3e-3
    frozen = (loading_voltage(1.0 + df, dev.fsr, dev.circuit, 20.0)
              - loading_voltage(1.0 - df, dev.fsr, dev.circuit, 20.0)) / (2 * df)
    assert frozen / sim[k0] == pytest.approx(1.087, abs=0.005)
    # the fast terms have crept within 5 s; the 10 s and 100 s terms give the rest at DC (1 + N w)
    assert sim[-1] / sim[k0] == pytest.approx(1.068, abs=0.005)


def test_pid_statespace_reproduces_pid_recursions():
    cfg = PIDConfig(kp_v_per_n=1.3, ki_v_per_ns=7.0, kd_vs_per_n=0.01, derivative_filter_s=0.004,
                    setpoint_weight_p=0.7, setpoint_weight_d=0.2, u_min_v=-1e6, u_max_v=1e6,
                    tracking_time_s=math.inf)
    pid = PID(cfg)
    pid.reset(force_est_n=0.0, setpoint_n=0.0, command_v=0.0)
    rng = np.random.default_rng(0)
    r, y = rng.normal(size=200), rng.normal(size=200)
    u_pid = [pid.update(float(y[k]), float(r[k]), 1e-3) for k in range(200)]
    ss = pid_statespace(cfg, 1e-3)
    u_ss = np.asarray(control.forced_response(ss, U=np.vstack([r, y])).outputs).ravel()
    assert np.allclose(u_pid, u_ss, atol=1e-12)


def test_default_gains_fixed_lose_stability_at_2n_and_scaling_keeps_the_loop():
    fixed = dataclasses.replace(DEFAULT_PID, schedule_above_n=None)
    a06 = analyse_loop(fixed, force_n=0.6)
    a2 = analyse_loop(fixed, force_n=2.0)
    assert a06.stable and 1.0 < a06.ms < 3.0
    assert not a2.stable and a2.ms == math.inf
    # the default scales its gains above 1 N with the pulp's stiffness: the loop at 2 and 3 N
    # has about the margins of the loop at 1 N
    a1 = analyse_loop(DEFAULT_PID, force_n=1.0)
    assert analyse_loop(DEFAULT_PID, force_n=0.6).ms == a06.ms
    for f in (2.0, 3.0):
        a = analyse_loop(DEFAULT_PID, force_n=f)
        assert a.stable and a.ms < 1.5 * a1.ms


def test_simc_gains_are_robust_on_the_nominal_plant():
    cfg = simc_pid(force_n=1.0)
    assert cfg.kp_v_per_n > 0 and cfg.ki_v_per_ns > 0
    a = analyse_loop(dataclasses.replace(cfg, kp_v_per_n=0.5 * cfg.kp_v_per_n, ki_v_per_ns=0.5 * cfg.ki_v_per_ns),
                     force_n=1.0)
    assert a.stable and a.step["SettlingTime"] < 2.0


def test_bad_arguments():
    with pytest.raises(ValueError, match="force_n"):
        linearize(force_n=-1.0)
    with pytest.raises(ValueError, match="friction"):
        linearize(force_n=1.0, friction="sticky")


def test_describing_function_gain_equals_scaled_controller():
    # kappa L is the loop of the controller with every gain scaled by kappa
    from ebraille_sim.analysis.robust import linearisation_points, population_ms, tuning_population
    pts = linearisation_points(tuning_population(0, seed=0)[:2], [0.6, 2.0])
    cfg = dataclasses.replace(DEFAULT_PID, kp_v_per_n=1.0, ki_v_per_ns=6.0, kd_vs_per_n=0.002)
    half = dataclasses.replace(cfg, kp_v_per_n=0.5, ki_v_per_ns=3.0, kd_vs_per_n=0.001)
    assert np.allclose(population_ms(cfg, pts, 0.5), population_ms(half, pts), rtol=1e-9)
    with pytest.raises(ValueError, match="gain"):
        population_ms(cfg, pts, 0.0)


def test_friction_band_is_the_press_release_command_gap():
    from ebraille_sim.analysis.robust import friction_band_v
    dev = DeviceParams()
    g = dev.drivetrain.gear_ratio / dev.drivetrain.pinion_radius_m
    v_per_n = dev.motor.resistance_ohm / (dev.motor.torque_constant_nm_per_a * g)
    mu = dev.drivetrain.gear_loss_coefficient
    fw = 1.0 + dev.drivetrain.moving_mass_kg * dev.gravity_m_per_s2
    # mesh force pressing F + W + Fg, releasing F + W - Fg; motor command (1 +- mu) Fm +- Fc
    fg, fc = dev.drivetrain.guide_coulomb_n, dev.motor.friction_torque_nm * g
    expect = v_per_n * ((1 + mu) * (fw + fg) + fc - (1 - mu) * (fw - fg) + fc)
    assert friction_band_v(dev, 1.0) == pytest.approx(expect, rel=1e-6)
    assert 0.5 < friction_band_v(dev, 1.0) < friction_band_v(dev, 2.0)


def test_scenario_cost_rewards_in_band_and_penalises_overshoot():
    from ebraille_sim.analysis.robust import cvar, scenario_cost
    good = [{"force_rmse_n": 0.02, "in_band_fraction": 1.0, "peak_force_n": 1.1}] * 4
    worse = good[:3] + [{"force_rmse_n": 0.02, "in_band_fraction": 0.5, "peak_force_n": 1.1}]
    over = good[:3] + [{"force_rmse_n": 0.02, "in_band_fraction": 1.0, "peak_force_n": 1.5}]
    c0 = scenario_cost(good, 1.0, 1.0)
    assert c0 == pytest.approx(0.02)
    assert scenario_cost(worse, 1.0, 1.0) == pytest.approx(c0 + 2 * 0.5 + 0.5)   # worst case and CVaR25
    assert scenario_cost(over, 1.0, 1.0) == pytest.approx(c0 + 2 * (1.5 - 1.15))
    assert cvar([1.0, 0.2, 0.9, 0.8, 0.7]) == pytest.approx(0.45)                  # worst 2 of 5


def test_gains_file_of_a_schedule_round_trips_through_make(tmp_path):
    import controllers
    from ebraille_sim.analysis.robust import family_config, gains_document
    from ebraille_sim.commands.tune import _toml
    cfg = family_config("pid_scheduled", 1.5, 6.0, 0.002)
    doc = gains_document(cfg, "pid_scheduled")
    assert doc["controller"] == "pid_scheduled" and doc["gains"]["reference_map"] is True
    path = tmp_path / "gains.toml"
    path.write_text(_toml(doc))
    c = controllers.make(str(path))
    assert c.name == "pid_scheduled" and c.config == cfg
    ff = controllers.make(str(path), feedforward=True)
    assert ff.config.feedforward


def test_recommended_design_beats_default_on_worst_case_in_band():
    """The design docs/tuning.md recommends, against the hand-tuned default PID, on the
    setpoint steps (with and without the ramp) for the three reader presets."""
    from ebraille_sim.analysis.robust import evaluate, summarise, tuning_population, unramped
    from controllers.schedule import RECOMMENDED, ScheduledPID
    from ebraille_sim.scenarios.spec import load_scenario
    pop = tuning_population(0, seed=0)[:3]
    steps = load_scenario("setpoint_steps")
    for spec in (steps, unramped(steps)):
        d = summarise(evaluate(lambda: PID(DEFAULT_PID), pop, spec))["in_band_fraction"]
        r = summarise(evaluate(lambda: ScheduledPID(RECOMMENDED), pop, spec))["in_band_fraction"]
        assert r["worst"] > d["worst"] + 0.05, spec.name
        assert r["median"] > d["median"], spec.name


def test_recommended_design_holds_steady_reading_and_onset():
    """Steady reading on the three reader presets.  On the soft reader the contact onset leaves
    the FSR on its unloading hysteresis branch, where it reads 8-10 % above the true force for
    the rest of the run (the default PID holds the estimate at 1.000 N with 0.915 N on the
    finger): the true-force band there is the sensor's limit, so the controller is held to its
    estimate (what it can see) and the true force to the hysteresis-limited 0.85."""
    import dataclasses
    from ebraille_sim.analysis.robust import evaluate, summarise, tuning_population
    from ebraille_sim.scenarios.metrics import in_band
    from ebraille_sim.scenarios.runner import run_scenario
    from controllers.schedule import RECOMMENDED, ScheduledPID
    from ebraille_sim.scenarios.spec import load_scenario
    pop = tuning_population(0, seed=0)[:3]
    spec = load_scenario("steady_90wpm")
    for label, dev in pop:
        d = dataclasses.replace(dev, rates=spec.device.rates, estimator=spec.device.estimator)
        res = run_scenario(dataclasses.replace(spec, device=d), controller=ScheduledPID(RECOMMENDED),
                           duration_s=8.0)
        tr = res.trace
        read = tr["t_s"] >= spec.reading.start_s
        est_ok = in_band(tr["force_est_n"][read], tr["setpoint_n"][read], spec.setpoint.band_fraction)
        assert est_ok.mean() >= 0.95, label
        assert res.metrics["in_band_fraction"] >= (0.85 if label == "soft" else 0.95), label
    o = summarise(evaluate(lambda: ScheduledPID(RECOMMENDED), pop, load_scenario("contact_onset")))
    assert o["peak_force_n"]["worst"] <= 1.15 * 1.5


@pytest.mark.slow
def test_robust_tuning_beats_default_on_worst_case_in_band():
    """Multi-scenario tuning under Ms <= 1.6 (sliding model) on a small population."""
    from ebraille_sim.analysis.robust import TuneScenario, robust_tune, tuning_population, unramped
    from ebraille_sim.scenarios.spec import load_scenario
    spec = load_scenario("setpoint_steps")
    pop = tuning_population(0, seed=0)[:3]
    scen = [TuneScenario(spec.name, spec), TuneScenario("unramped", unramped(spec)),
            TuneScenario("steady_90wpm", load_scenario("steady_90wpm"), 6.0)]
    res = robust_tune(spec, pop, family="pid_scheduled", max_evaluations=8, scenarios=scen)
    rep = res.report()
    assert res.tuned.ms_max <= 1.6
    assert res.tuned.cost <= min(h["cost"] for h in res.history if math.isfinite(h["cost"]))
    assert (res.selected == "shipped") == (res.named_cost("shipped") < res.named_cost("tuned"))
    for name in ("setpoint_steps", "unramped"):
        t = rep["tuned"]["scenarios"][name]["metrics"]["in_band_fraction"]["worst"]
        d = rep["default"]["scenarios"][name]["metrics"]["in_band_fraction"]["worst"]
        assert t > d, name
    assert res.gains_file()["controller"] == "pid_scheduled"


@pytest.mark.slow
def test_tune_command_writes_a_gains_file_that_run_accepts(tmp_path):
    import subprocess
    import sys
    out = tmp_path / "tune"
    r = subprocess.run([sys.executable, "-m", "ebraille_sim", "tune", "contact_onset", "--population", "0",
                        "--evaluations", "4", "--scenarios", "single", "--out", str(out)],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    for f in ("gains.toml", "gains_hand.toml", "report.md", "report.json", "bode.png", "nyquist.png",
              "population.png"):
        assert (out / f).is_file(), f
    assert 'controller = "pid_scheduled"' in (out / "gains.toml").read_text()
    assert "reference_map = true" in (out / "gains.toml").read_text()
    r = subprocess.run([sys.executable, "-m", "ebraille_sim", "run", "contact_onset", "--controller",
                        str(out / "gains.toml"), "--duration", "2", "--out", str(tmp_path / "run")],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr


def test_tune_report_gives_margins_only_for_a_stable_loop(tmp_path):
    from ebraille_sim.analysis.tuning import plot_bode
    from ebraille_sim.commands.tune import _loop_cells
    fixed = dataclasses.replace(DEFAULT_PID, schedule_above_n=None)
    a1, a2 = analyse_loop(DEFAULT_PID, force_n=1.0), analyse_loop(fixed, force_n=2.0)
    # the loop of test_margins.test_default_pid_margins_at_1n_and_0_6n
    assert _loop_cells(a1.summary()) == ["stable", "33.7 deg at 6.41 Hz", "1.46 at 9.30 Hz", "3.53"]
    assert _loop_cells(a2.summary()) == ["unstable", "-", "-", "unstable"]
    assert a1.margin_label() == "PM 33.7 deg at 6.41 Hz, GM 1.46"
    plot_bode([a1, a2], tmp_path / "bode.png")
    assert (tmp_path / "bode.png").stat().st_size > 10_000


def test_tune_keeps_the_shipped_controller_that_beats_the_optimum_and_counts_its_runs(tmp_path, capsys):
    """On steady reading the shipped pid_scheduled beats the Ms <= 1.5 optimum: it is kept, with the reason
    (its max Ms on the presets at 1 N is 1.56, above that bound and below the default 1.6)."""
    import json
    import tomllib

    from controllers.schedule import RECOMMENDED
    from ebraille_sim.analysis.robust import gains_document
    from ebraille_sim.cli import main as cli
    out = tmp_path / "t"
    assert cli(["tune", "steady_90wpm", "--population", "0", "--evaluations", "4", "--scenarios", "single",
                "--duration", "2.0", "--ms-max", "1.5", "--out", str(out), "--json"]) == 0
    cap = capsys.readouterr()
    doc = json.loads(cap.out)
    assert doc["ms_bound"] == 1.5 and doc["ms_max_tuned"] <= 1.5
    assert doc["selected"] == "shipped"
    assert doc["named_costs"]["shipped"] < doc["named_costs"]["tuned"]
    assert doc["gains"] == gains_document(RECOMMENDED, "pid_scheduled")["gains"]
    assert doc["ms_max"] == pytest.approx(doc["shipped"]["ms_max"]) and doc["ms_max"] > 1.5
    assert "exceeds the bound 1.5" in doc["selection_reason"]
    text = (out / "gains.toml").read_text()
    assert text.startswith("# kept the shipped pid_scheduled: on steady_90wpm its cost is")
    assert "kp_v_per_n = 0.859" in text
    rep = json.loads((out / "report.json").read_text())
    with open(out / "gains_tuned.toml", "rb") as fh:
        assert tomllib.load(fh)["gains"] == rep["tuned"]["gains"]
    assert rep["selected"] == "shipped" and "## Selection" in (out / "report.md").read_text()
    # progress: periodic lines on a non-terminal stderr, ending at the runs actually made (5 devices x
    # 1 scenario x (4 references + the candidates within the bound))
    runs = 5 * (4 + sum(h["ms_max"] <= 1.5 for h in rep["history"]))
    lines = cap.err.strip().splitlines()
    assert lines[-1] == f"tune steady_90wpm: runs {runs}/{runs}"
    assert all("\r" not in ln for ln in lines)


def test_run_with_a_gains_file_labels_the_run_and_records_the_gains(tmp_path, capsys):
    import json

    from controllers.schedule import ScheduleConfig
    from ebraille_sim.analysis.robust import gains_document
    from ebraille_sim.cli import main as cli
    from ebraille_sim.commands.tune import _toml
    cfg = ScheduleConfig(kp_v_per_n=0.6, ki_v_per_ns=1.5, kd_vs_per_n=0.0)
    gains = tmp_path / "gains.toml"
    gains.write_text(_toml(gains_document(cfg, "pid_scheduled"), "a comment line"))
    # 0.3 s ends before reading: the criteria fail (status 1); only the labelling is checked here
    assert cli(["run", "steady_90wpm", "--controller", str(gains), "--duration", "0.3", "--trace", "none",
                "--no-plot", "--out", str(tmp_path / "r")]) == 1
    assert f"controller pid_scheduled (gains {gains})" in capsys.readouterr().out
    doc = json.loads((tmp_path / "r" / "metrics.json").read_text())
    assert doc["controller"] == "pid_scheduled" and doc["controller_file"] == str(gains)
    assert doc["controller_gains"] == dataclasses.asdict(cfg)
    assert doc["controller_gains"]["kp_v_per_n"] == 0.6


def test_tune_scenarios_keep_the_named_scenarios_estimator():
    """Every scenario of the tuning set runs with the named scenario's [estimator] settings
    (the population and the Ms check are built on its device); a shipped primary changes nothing."""
    import pathlib

    from ebraille_sim.analysis.robust import standard_scenarios, with_estimator
    from ebraille_sim.commands.tune import _scenarios
    from ebraille_sim.scenarios.spec import load_scenario
    fast = load_scenario(str(pathlib.Path(__file__).resolve().parent.parent / "docs" / "figures" / "estimators"
                             / "setpoint_steps_fast.toml"))
    est = fast.device.estimator
    assert (est.model, est.antialias_cutoff_hz) == ("paper:wiener:5@1000", 50.0)
    for arg in ("standard", "steady_120wpm,contact_onset_unramped", "single"):
        scen = _scenarios(arg, fast, None)
        assert all(sc.spec.device.estimator == est for sc in scen), arg
    names = [sc.name for sc in standard_scenarios(fast)]
    assert names == ["setpoint_steps", "setpoint_steps_unramped", "steady_90wpm", "contact_onset", "strap_slip"]
    steady = [sc for sc in standard_scenarios(fast) if sc.name == "steady_90wpm"][0]
    assert steady.duration_s == 12.0
    assert steady.spec.reading == load_scenario("steady_90wpm").reading
    shipped = load_scenario("setpoint_steps")
    for sc in standard_scenarios(shipped)[2:]:
        assert sc.spec == load_scenario(sc.name), sc.name
    assert with_estimator(shipped, shipped.device.estimator) is shipped
