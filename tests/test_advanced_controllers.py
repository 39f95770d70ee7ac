"""Gain-scheduled PID, feedforward, LQG: registry, laws, loop robustness and closed-loop comparison."""
import dataclasses
import math
import subprocess
import sys

import control
import numpy as np
import pytest

import controllers
from ebraille_sim.analysis.design import make_lqg
from controllers.pid import DEFAULT_PID, PID, PIDConfig
from ebraille_sim.analysis.robust import evaluate, linearisation_points, population_ms, summarise, tuning_population
from controllers.pid import stiffness_ratio
from controllers.schedule import ScheduleConfig, ScheduledPID
from ebraille_sim.physics.params import DeviceParams
from ebraille_sim.scenarios.spec import load_scenario, with_firmware


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
    with pytest.raises(ValueError, match="unknown key 'kp' in the gains of a scheduled PID; allowed: kp_v_per_n"):
        controllers.make("pid_scheduled", kp=1.0)
    with pytest.raises(ValueError, match="unknown key 'q' in LQGConfig"):
        controllers.make("lqg", q=1.0)


def test_schedule_follows_the_pulp_stiffness():
    c = ScheduledPID(ScheduleConfig())
    f = DeviceParams().finger
    k = lambda x: f.stiffness_b_n_per_m + f.exponent_m_per_m * x / f.relax_weight_inf  # noqa: E731
    kp2 = c.gains_at(2.0)[0]
    assert kp2 == pytest.approx(ScheduleConfig().kp_v_per_n * k(1.0) / k(2.0))
    assert c.gains_at(5.0) == c.gains_at(3.0)                     # clipped to the reading range
    assert stiffness_ratio(1.0, 1.0) == 1.0


# Commands of the shipped factories (reset from 0.4 N / 0.5 N / 0.3 V, then the inputs of
# _reference_inputs), recorded by running exactly this protocol on controllers.make(name).
# Recorded first before the PID recursion was shared with controllers.pid (they agreed to
# the last bits: the pulp stiffness is now the law's b + m (F/c0) instead of b + (m F)/c0,
# and the tracking gain h (1/Tt) instead of h/Tt, as in the plain PID); re-recorded with the
# tap-dissipation pulp weights, the hereditary creep and R2 = 1150 ohm (the schedule is built
# on the default device); re-recorded when RECOMMENDED became the Ms <= 2.0 design (kp 0.859,
# ki 1.72, kd 0.00348; no physics law changed, the gains of both factories did: with kp 0.81,
# ki 1.8, kd 0.011 the same protocol gives the previous record to the last bit); re-recorded
# with the FSR's creep to days, turn-on and 10 %-with-creep hysteresis (the schedule's sensor
# slopes are the default device's; commands moved by up to 0.2 %).
_RECORDED = {
    "pid_scheduled": [
        0.3, 0.1469387630116856, 0.023644739989330643, 0.07498420416312339,
        -0.023073855500695656, 0.019629994483953223, -0.04650357630970106, -0.1129013516107068,
        -0.05454372389178125, -0.08834369435256684, -0.03723471857632582, -0.08186922509763779,
        -0.10632183627563256, -0.014967754109789025, -0.019961158695083595, 0.06508365356021564,
        0.048495189139097665, 0.03054088209416044, 0.10586262126467864, 0.07997734530594597,
        0.15306568356353534, 0.11895626286657335, 0.08787471398725544, 0.1625481583818409],
    "pid_feedforward": [
        0.3, 1.253869578725694, 1.0610473812790915, 0.7454204993210409,
        0.9106429342022342, 0.9146647625434421, 0.5623412991085694, 0.7236285044021957,
        0.7601392557123421, 0.49308489098261926, 0.7449769336963974, 0.6886805742081147,
        0.4682774485121758, -0.7284027520745202, -0.7389163276509312, -0.5806451603870486,
        -0.6819772454299715, -0.7059471364201068, -0.5532442672789564, -0.6691075594435232,
        -0.6026238092959513, -0.5547085569960817, -0.6817019568187956, -0.6143408462981933],
}


def _reference_inputs():
    for k in range(24):
        r = 0.5 + 0.05 * k if k < 12 else 1.1 - 0.02 * (k - 12)
        yield r - 0.1 + 0.013 * ((k * 7) % 5), r, (1e-3 if k % 3 else 1.5e-3)


@pytest.mark.parametrize("name", sorted(_RECORDED))
def test_shipped_schedules_give_the_recorded_commands(name):
    c = controllers.make(name)
    c.reset(force_est_n=0.4, setpoint_n=0.5, command_v=0.3)
    got = [c.update(y, r, h) for y, r, h in _reference_inputs()]
    assert got == pytest.approx(_RECORDED[name], rel=0.0, abs=1e-14)


@pytest.mark.parametrize("extra", [
    {},
    {"setpoint_weight_p": 0.6, "setpoint_weight_d": 0.3},
    {"tracking_time_s": 0.05},
    {"tracking_time_s": math.inf},
    {"kd_vs_per_n": 0.0},
    {"ki_v_per_ns": 0.0},
])
def test_scheduled_pid_with_everything_off_is_the_plain_pid_bit_for_bit(extra):
    gains = {"kp_v_per_n": 1.7, "ki_v_per_ns": 9.0, "kd_vs_per_n": 0.02, "derivative_filter_s": 0.004,
             "u_min_v": -2.0, "u_max_v": 2.5, **extra}
    sched = ScheduledPID(ScheduleConfig(schedule=False, feedforward=False, reference_map=False, **gains))
    pid = PID(PIDConfig(**gains))
    rng = np.random.default_rng(11)
    for c in (sched, pid):
        c.reset(force_est_n=0.3, setpoint_n=0.8, command_v=0.7)
    a, b, saturated = [], [], 0
    for k in range(4000):
        r = float(rng.uniform(0.2, 3.0)) if k % 40 == 0 else r
        y = float(r + rng.normal(0.0, 0.8))
        h = float(rng.uniform(0.5e-3, 2e-3))
        a.append(sched.update(y, r, h))
        b.append(pid.update(y, r, h))
        saturated += b[-1] in (-2.0, 2.5)
    assert a == b
    assert 100 < saturated < 3900          # the anti-windup path is exercised


def test_schedule_and_supervisor_limits_come_from_the_laws():
    from ebraille_sim.physics.fingertip import tangent_stiffness_n_per_m
    from ebraille_sim.physics.params import TACTILE_FORCE_MAX_N, TACTILE_FORCE_MIN_N
    from controllers.pid import pulp_stiffness_n_per_m
    from controllers.schedule import F_MAX_N, F_MIN_N
    f = DeviceParams().finger
    assert (F_MIN_N, F_MAX_N) == (TACTILE_FORCE_MIN_N, TACTILE_FORCE_MAX_N)
    assert pulp_stiffness_n_per_m(1.5) == tangent_stiffness_n_per_m(1.5 / f.relax_weight_inf,
                                                                     f.stiffness_b_n_per_m, f.exponent_m_per_m)
    soft = DeviceParams(finger=dataclasses.replace(f, stiffness_b_n_per_m=2 * f.stiffness_b_n_per_m))
    assert stiffness_ratio(2.0, 1.0, soft) > stiffness_ratio(2.0, 1.0)   # a larger b flattens K(F)


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
    assert np.max(ms16) <= 1.6                                     # the robustness target, sliding model
    assert np.max(rec) <= 2.0 and np.max(population_ms(ScheduledPID(RECOMMENDED).pid_config_at, pts, 0.5)) <= 1.6
    assert np.max(population_ms(ScheduledPID(HAND).pid_config_at, pts)) > 2.0
    fixed = dataclasses.replace(DEFAULT_PID, schedule_above_n=None)
    assert np.max(population_ms(fixed, pts)) == math.inf           # the default gains, fixed: unstable at 2 N
    assert 2.0 < np.max(population_ms(DEFAULT_PID, pts)) < math.inf  # scaled above 1 N: stable, not robust


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
    spec = with_firmware(load_scenario("setpoint_steps"), "paper_100hz")     # the path both were tuned on
    pop = tuning_population(0, seed=0)[:3]
    d = summarise(evaluate(lambda: PID(DEFAULT_PID), pop, spec))
    s = summarise(evaluate(lambda: controllers.make("pid_scheduled"), pop, spec))
    assert s["in_band_fraction"]["worst"] > d["in_band_fraction"]["worst"]
