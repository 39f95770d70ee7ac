"""Gain-scheduled PID, feedforward, LQG: registry, laws, loop robustness and closed-loop comparison."""
import math
import subprocess
import sys

import control
import numpy as np
import pytest

import controllers
from ebraille_sim.analysis.tuning import make_lqg
from controllers.pid import DEFAULT_PID, PID
from ebraille_sim.analysis.robust import evaluate, linearisation_points, population_ms, summarise, tuning_population
from controllers.schedule import ScheduleConfig, ScheduledPID, stiffness_ratio
from ebraille_sim.physics.params import DeviceParams
from ebraille_sim.scenarios.spec import load_scenario


def test_registered_and_listed():
    for name in ("pid_scheduled", "pid_feedforward", "lqg"):
        assert name in controllers.available()
        c = controllers.make(name)
        c.reset(force_est_n=0.5, setpoint_n=1.0)
        assert math.isfinite(c.update(0.5, 1.0, 1e-3))
    out = subprocess.run([sys.executable, "-m", "ebraille_sim", "list"], capture_output=True, text=True, check=True)
    for name in ("pid_scheduled", "pid_feedforward", "lqg"):
        assert name in out.stdout


def test_unknown_gain_is_rejected():
    with pytest.raises(ValueError, match="unknown gain key 'kp'"):
        controllers.make("pid_scheduled", kp=1.0)
    with pytest.raises(ValueError, match="unknown gain key"):
        controllers.make("lqg", q=1.0)


def test_schedule_follows_the_pulp_stiffness():
    c = ScheduledPID(ScheduleConfig())
    f = DeviceParams().finger
    k = lambda x: f.stiffness_b_n_per_m + f.exponent_m_per_m * x / f.relax_weight_inf  # noqa: E731
    kp2 = c.gains_at(2.0)[0]
    assert kp2 == pytest.approx(ScheduleConfig().kp_v_per_n * k(1.0) / k(2.0))
    assert c.gains_at(5.0) == c.gains_at(3.0)                     # clipped to the reading range
    assert stiffness_ratio(1.0, 1.0) == 1.0


def test_feedforward_static_and_rate_terms():
    dev = DeviceParams()
    c = ScheduledPID(ScheduleConfig(feedforward=True))
    g = dev.drivetrain.gear_ratio / dev.drivetrain.pinion_radius_m
    v_per_n = dev.motor.resistance_ohm / (dev.motor.torque_constant_nm_per_a * g)
    assert c.feedforward_v(1.5, 0.0, direction=0.0) == pytest.approx(1.5 * v_per_n)
    mu = dev.drivetrain.gear_loss_coefficient
    fc = dev.motor.friction_torque_nm * g + dev.drivetrain.guide_coulomb_n
    assert c.feedforward_v(1.5, 0.0, direction=1.0) == pytest.approx(v_per_n * ((1 + mu) * 1.5 + fc))
    up, down = c.feedforward_v(1.5, 2.0), c.feedforward_v(1.5, -2.0)
    assert up > c.feedforward_v(1.5, 0.0, direction=1.0) > c.feedforward_v(1.5, 0.0, direction=-1.0) > down


def test_reference_map_targets_the_sensor_reading_of_the_true_force():
    c = ScheduledPID(ScheduleConfig(reference_map=True))
    assert c.reference(1.0) == pytest.approx(1.0, abs=1e-3)     # calibrated at 1 N
    assert c.reference(0.5) > 0.5                               # the paper's model reads high at low force


def test_ms_of_the_shipped_schedules_on_presets():
    from controllers.schedule import HAND, MS_1_6, RECOMMENDED
    pop = tuning_population(0, seed=0)
    pts = linearisation_points(pop, [0.6, 1.0, 2.0])
    ms16 = population_ms(ScheduledPID(MS_1_6).pid_config_at, pts)
    rec = population_ms(ScheduledPID(RECOMMENDED).pid_config_at, pts)
    assert np.max(ms16) <= 1.6                                     # the bound, sliding model
    assert np.max(rec) <= 2.0 and np.max(population_ms(ScheduledPID(RECOMMENDED).pid_config_at, pts, 0.5)) <= 1.6
    assert np.max(population_ms(ScheduledPID(HAND).pid_config_at, pts)) > 2.0
    assert np.max(population_ms(DEFAULT_PID, pts)) == math.inf     # the default PID: unstable at 2 N


def test_pid_scheduled_defaults_are_the_recommended_design():
    from controllers.schedule import RECOMMENDED
    c = controllers.make("pid_scheduled")
    assert c.config == RECOMMENDED and c.config.reference_map and not c.config.feedforward


def test_lqg_statespace_matches_the_controller_in_the_linear_range():
    c = make_lqg()
    ss = c.statespace()
    c.reset(force_est_n=c._y0, setpoint_n=c._y0, command_v=c._u0)
    rng = np.random.default_rng(1)
    r = c._y0 + 0.05 * rng.normal(size=50)
    y = c._y0 + 0.05 * rng.normal(size=50)
    u = []
    for k in range(50):
        u.append(c.update(float(y[k]), float(r[k]), 0.01))
    u_ss = np.asarray(control.forced_response(ss, U=np.vstack([r - c._y0, y - c._y0])).outputs).ravel() + c._u0
    assert np.allclose(u, u_ss, atol=1e-9)


def test_lqg_acts_at_its_sample_period():
    c = make_lqg()
    c.reset(force_est_n=0.5, setpoint_n=1.0, command_v=0.0)
    u = [c.update(0.5, 1.0, 1e-3) for _ in range(25)]
    changes = [k for k in range(1, 25) if u[k] != u[k - 1]]
    assert changes == [10, 20]


def test_scheduled_pid_beats_default_on_setpoint_steps_presets():
    spec = load_scenario("setpoint_steps")
    pop = tuning_population(0, seed=0)[:3]
    d = summarise(evaluate(lambda: PID(DEFAULT_PID), pop, spec))
    s = summarise(evaluate(lambda: controllers.make("pid_scheduled"), pop, spec))
    assert s["in_band_fraction"]["worst"] > d["in_band_fraction"]["worst"]
