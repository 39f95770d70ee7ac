"""Tests of the discrete PID controller and the controller registry.

Closed forms used below (see the ``controllers.pid`` module docstring):

* P only: ``u = kp (b r - y)``.
* I only, forward Euler, constant error ``e`` after reset: ``u_k = ki e h k``
  (k = 0 at the first update; with varying steps ``u_k = ki e (h_1 + ... + h_k)``).
* D only, backward difference, unit step in ``y`` at the first update:
  ``u_k = -kd / (Tf + h) * (Tf / (Tf + h))**k``.
* Back-calculation with constant error ``e1`` while saturated at ``U``:
  ``I -> I* = U - kp e1 + ki Tt e1``; after the error switches to ``e2 < 0``
  the excess ``x_j = v_j - U`` obeys ``x_j = x_inf + (1 - a)**j (x_0 - x_inf)``
  with ``a = h/Tt``, ``x_0 = kp (e2 - e1) + ki Tt e1``, ``x_inf = ki Tt e2``.
"""

from __future__ import annotations

import json
import math
import random

import pytest

import controllers
from controllers import PID, Controller, PIDConfig, available, make, register
from controllers.pid import DEFAULT_PID, pid_from_dict

WIDE = {"u_min_v": -1e6, "u_max_v": 1e6}


def _pid(**kw) -> PID:
    fields = {"kp_v_per_n": 0.0, **WIDE, **kw}
    return PID(PIDConfig(**fields))


# --------------------------------------------------------------------- P only


def test_p_only_matches_closed_form_exactly():
    kp, b = 2.5, 0.7
    pid = _pid(kp_v_per_n=kp, setpoint_weight_p=b)
    pid.reset(force_est_n=0.0, setpoint_n=0.0)
    rng = random.Random(1)
    for _ in range(200):
        r = rng.uniform(0.2, 3.0)
        y = rng.uniform(0.0, 3.5)
        assert pid.update(y, r, 1e-3) == kp * (b * r - y)


def test_p_only_without_reset_is_plain_proportional():
    pid = _pid(kp_v_per_n=3.0)
    assert pid.update(1.0, 1.5, 1e-3) == 3.0 * (1.5 - 1.0)
    assert pid.update(2.0, 1.5, 1e-3) == 3.0 * (1.5 - 2.0)


# --------------------------------------------------------------------- I only


def test_i_only_constant_error_is_exact_ramp():
    ki, e, h = 4.0, 0.5, 0.25  # dyadic values: the sums are exact
    pid = _pid(ki_v_per_ns=ki)
    pid.reset(force_est_n=1.0, setpoint_n=1.0 + e)
    outs = [pid.update(1.0, 1.0 + e, h) for _ in range(40)]
    assert outs == [ki * e * h * k for k in range(40)]


def test_i_only_ramp_with_millisecond_step():
    ki, e, h = 40.0, 0.3, 1e-3
    pid = _pid(ki_v_per_ns=ki)
    pid.reset(force_est_n=0.7, setpoint_n=0.7 + e)
    for k in range(1000):
        u = pid.update(0.7, 0.7 + e, h)
        assert u == pytest.approx(ki * e * h * k, rel=1e-12, abs=1e-15)


def test_i_only_uses_the_given_dt_of_each_step():
    ki, e = 10.0, 0.5
    steps = [1e-3, 2e-3, 0.5e-3, 3e-3, 1e-3, 4e-3]
    pid = _pid(ki_v_per_ns=ki)
    pid.reset(force_est_n=1.0, setpoint_n=1.0 + e)
    elapsed = 0.0
    for k, h in enumerate(steps):
        u = pid.update(1.0, 1.0 + e, h)
        if k > 0:
            elapsed += h
        assert u == pytest.approx(ki * e * elapsed, rel=1e-12, abs=1e-15)


# --------------------------------------------------------------------- D only


@pytest.mark.parametrize("tf", [0.004, 0.0005, 0.0])
def test_d_only_measurement_step_matches_backward_difference(tf):
    kd, h = 0.02, 1e-3
    pid = _pid(kd_vs_per_n=kd, derivative_filter_s=tf)
    pid.reset(force_est_n=0.0, setpoint_n=1.0)
    a = tf / (tf + h)
    for k in range(60):
        u = pid.update(1.0, 1.0, h)
        assert u == pytest.approx(-kd / (tf + h) * a**k, rel=0.0, abs=1e-12)


def test_d_only_ramp_converges_to_minus_kd_times_slope():
    kd, tf, h, slope = 0.05, 0.004, 1e-3, 2.0
    pid = _pid(kd_vs_per_n=kd, derivative_filter_s=tf)
    pid.reset(force_est_n=0.0, setpoint_n=0.0)
    a = tf / (tf + h)
    for k in range(100):
        u = pid.update(slope * h * (k + 1), 0.0, h)
        assert u == pytest.approx(-kd * slope * (1.0 - a ** (k + 1)), rel=0.0, abs=1e-12)


def test_derivative_setpoint_weight():
    kd, tf, h = 0.02, 0.004, 1e-3
    for c in (0.0, 1.0, 0.5):
        pid = _pid(kd_vs_per_n=kd, derivative_filter_s=tf, setpoint_weight_d=c)
        pid.reset(force_est_n=1.0, setpoint_n=1.0)
        assert pid.update(1.0, 2.0, h) == pytest.approx(c * kd / (tf + h), abs=1e-12)


def test_no_derivative_kick_after_reset_or_on_first_update():
    pid = _pid(kd_vs_per_n=5.0, derivative_filter_s=0.0)
    pid.reset(force_est_n=2.0, setpoint_n=1.0)
    assert pid.update(2.0, 1.0, 1e-3) == 0.0
    fresh = _pid(kd_vs_per_n=5.0)
    assert fresh.update(2.0, 1.0, 1e-3) == 0.0


# ----------------------------------------------------------------- saturation


def test_output_is_clamped_to_limits():
    pid = PID(PIDConfig(kp_v_per_n=10.0, ki_v_per_ns=50.0, kd_vs_per_n=0.1, u_min_v=-1.5, u_max_v=2.0))
    pid.reset(force_est_n=0.0, setpoint_n=0.0)
    assert pid.update(0.0, 3.0, 1e-3) == 2.0
    assert pid.update(3.0, 0.0, 1e-3) == -1.5
    rng = random.Random(7)
    for _ in range(2000):
        u = pid.update(rng.uniform(0, 3), rng.uniform(0, 3), rng.uniform(1e-4, 2e-3))
        assert -1.5 <= u <= 2.0


# ---------------------------------------------------------------- anti-windup


def _saturate_then_reverse(tracking_time_s, *, m1=20000, m2=40000):
    """Error e1 = 3 for m1 steps, then e2 = -0.5; return integrators, outputs."""
    cfg = PIDConfig(kp_v_per_n=1.0, ki_v_per_ns=10.0, u_min_v=-2.0, u_max_v=2.0, tracking_time_s=tracking_time_s)
    pid = PID(cfg)
    pid.reset(force_est_n=0.0, setpoint_n=0.0)
    h = 1e-3
    i1, u2, i2 = [], [], []
    for _ in range(m1):
        pid.update(0.0, 3.0, h)
        i1.append(pid.state()["integrator_v"])
    for _ in range(m2):
        u2.append(pid.update(3.5, 3.0, h))
        i2.append(pid.state()["integrator_v"])
    return cfg, h, i1, u2, i2


def _first_unsaturated(outputs, limit):
    return next(j for j, u in enumerate(outputs) if u < limit)


def test_back_calculation_bounds_integrator_and_exit_time():
    tt = 0.5
    cfg, h, i1, u2, i2 = _saturate_then_reverse(tt)
    kp, ki, umax = cfg.kp_v_per_n, cfg.ki_v_per_ns, cfg.u_max_v
    e1, e2 = 3.0, -0.5
    i_star = umax - kp * e1 + ki * tt * e1
    assert max(i1) <= i_star + 1e-9
    assert i1[-1] == pytest.approx(i_star, abs=1e-9)

    a = h / tt
    x0 = kp * (e2 - e1) + ki * tt * e1
    x_inf = ki * tt * e2
    j_bound = math.ceil(math.log(-x_inf / (x0 - x_inf)) / math.log(1.0 - a))
    j_exit = _first_unsaturated(u2, umax)
    assert j_exit == j_bound
    assert all(u == umax for u in u2[:j_exit])


def test_tracking_time_equal_to_ti_leaves_saturation_immediately():
    cfg, _h, i1, u2, _i2 = _saturate_then_reverse(None)
    assert cfg.effective_tracking_time_s == pytest.approx(cfg.kp_v_per_n / cfg.ki_v_per_ns)
    assert _first_unsaturated(u2, cfg.u_max_v) == 0
    assert u2[0] == pytest.approx(cfg.kp_v_per_n * -0.5 + cfg.u_max_v, abs=1e-9)


def test_without_back_calculation_integrator_winds_up_and_exit_is_late():
    _cfg, _h, i1_aw, u2_aw, _ = _saturate_then_reverse(0.5, m1=5000)
    cfg, h, i1, u2, _ = _saturate_then_reverse(math.inf, m1=5000)
    ki, kp, umax = cfg.ki_v_per_ns, cfg.kp_v_per_n, cfg.u_max_v
    assert i1[-1] == pytest.approx(ki * h * 3.0 * (len(i1) - 1), rel=1e-9)
    assert i1[-1] > 10 * max(i1_aw)
    i_start = i1[-1] + ki * h * 3.0
    j_expected = (i_start + kp * -0.5 - umax) / (ki * h * 0.5)
    j_exit = _first_unsaturated(u2, umax)
    assert abs(j_exit - j_expected) <= 1.0
    assert j_exit > 20 * _first_unsaturated(u2_aw, umax)


def _closed_loop_overshoot(tracking_time_s):
    cfg = PIDConfig(kp_v_per_n=3.0, ki_v_per_ns=60.0, u_min_v=0.0, u_max_v=1.5, tracking_time_s=tracking_time_s)
    pid = PID(cfg)
    pid.reset(force_est_n=0.0, setpoint_n=0.0)
    h, tau, r, y = 1e-3, 0.1, 1.2, 0.0
    peak = saturated = 0
    for _ in range(3000):
        u = pid.update(y, r, h)
        saturated += u == cfg.u_max_v
        y += h / tau * (u - y)
        peak = max(peak, y)
    return peak - r, saturated, y


def test_back_calculation_reduces_closed_loop_overshoot():
    over_aw, sat_aw, y_aw = _closed_loop_overshoot(None)
    over_raw, sat_raw, y_raw = _closed_loop_overshoot(math.inf)
    assert sat_aw > 50 and sat_raw > 50
    assert over_aw < 0.5 * over_raw
    assert y_aw == pytest.approx(1.2, abs=1e-6)
    assert y_raw == pytest.approx(1.2, abs=1e-6)


# ------------------------------------------------------------------- bumpless


def test_bumpless_reset_zero_error():
    pid = PID(DEFAULT_PID)
    pid.reset(force_est_n=1.0, setpoint_n=1.0, command_v=1.3)
    assert pid.update(1.0, 1.0, 1e-3) == 1.3
    assert pid.update(1.0, 1.0, 1e-3) == 1.3


def test_bumpless_reset_absorbs_weighted_p_and_feedforward():
    pid = PID(PIDConfig(kp_v_per_n=2.0, ki_v_per_ns=20.0, setpoint_weight_p=0.5, feedforward_v=0.4))
    pid.reset(force_est_n=1.0, setpoint_n=1.0, command_v=1.3)
    assert pid.update(1.0, 1.0, 1e-3) == pytest.approx(1.3, abs=1e-12)


def test_bumpless_reset_then_error_adds_p_term():
    pid = PID(PIDConfig(kp_v_per_n=2.0, ki_v_per_ns=20.0, kd_vs_per_n=0.0))
    pid.reset(force_est_n=1.0, setpoint_n=1.0, command_v=1.3)
    assert pid.update(0.9, 1.0, 1e-3) == pytest.approx(1.3 + 2.0 * 0.1, abs=1e-12)


def test_bumpless_reset_clamps_command_to_limits():
    pid = PID(PIDConfig(kp_v_per_n=1.0, ki_v_per_ns=1.0, u_min_v=-1.0, u_max_v=1.0))
    pid.reset(force_est_n=0.0, setpoint_n=0.0, command_v=5.0)
    assert pid.update(0.0, 0.0, 1e-3) == 1.0
    assert pid.state()["integrator_v"] == 1.0


# ------------------------------------------------------------ setpoint weight


@pytest.mark.parametrize("b", [0.0, 1.0])
def test_setpoint_weight_b_controls_proportional_kick(b):
    kp = 2.0
    cfg = PIDConfig(kp_v_per_n=kp, ki_v_per_ns=40.0, kd_vs_per_n=0.02, derivative_filter_s=0.004, setpoint_weight_p=b)
    pid = PID(cfg)
    pid.reset(force_est_n=1.0, setpoint_n=1.0, command_v=0.8)
    before = pid.update(1.0, 1.0, 1e-3)
    after = pid.update(1.0, 2.0, 1e-3)
    assert after - before == pytest.approx(b * kp * 1.0, abs=1e-12)


# ----------------------------------------------------------- input validation


@pytest.mark.parametrize("dt", [0.0, -1e-3, math.nan, math.inf, -math.inf])
def test_dt_must_be_finite_and_positive(dt):
    pid = PID(DEFAULT_PID)
    with pytest.raises(ValueError, match="dt_s") as info:
        pid.update(1.0, 1.0, dt)
    msg = str(info.value)
    assert repr(dt) in msg and "\n" not in msg


@pytest.mark.parametrize("arg", ["force_est_n", "setpoint_n"])
@pytest.mark.parametrize("bad", [math.nan, math.inf])
def test_non_finite_force_or_setpoint_rejected_without_state_change(arg, bad):
    pid = PID(DEFAULT_PID)
    pid.reset(force_est_n=1.0, setpoint_n=1.0, command_v=0.5)
    pid.update(0.9, 1.0, 1e-3)
    before = pid.state()
    kwargs = {"force_est_n": 1.0, "setpoint_n": 1.0, arg: bad}
    with pytest.raises(ValueError, match=arg):
        pid.update(kwargs["force_est_n"], kwargs["setpoint_n"], 1e-3)
    with pytest.raises(ValueError, match=arg):
        pid.reset(**kwargs)
    assert pid.state() == before


def test_reset_rejects_non_finite_command():
    with pytest.raises(ValueError, match="command_v"):
        PID(DEFAULT_PID).reset(force_est_n=1.0, setpoint_n=1.0, command_v=math.nan)


@pytest.mark.parametrize(
    "field, value",
    [
        ("kp_v_per_n", -1.0),
        ("ki_v_per_ns", math.nan),
        ("kd_vs_per_n", math.inf),
        ("derivative_filter_s", -0.001),
        ("setpoint_weight_p", -0.5),
        ("setpoint_weight_d", math.nan),
        ("u_min_v", -math.inf),
        ("u_max_v", math.inf),
        ("feedforward_v", math.nan),
        ("tracking_time_s", -1.0),
        ("tracking_time_s", math.nan),
        ("kp_v_per_n", "2.0"),
        ("ki_v_per_ns", True),
    ],
)
def test_config_validation_names_field(field, value):
    with pytest.raises(ValueError, match=field) as info:
        PIDConfig(**{"kp_v_per_n": 1.0, field: value})
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("lo, hi", [(1.0, 1.0), (2.0, -2.0)])
def test_config_limits_must_be_ordered(lo, hi):
    with pytest.raises(ValueError, match="u_min_v"):
        PIDConfig(kp_v_per_n=1.0, u_min_v=lo, u_max_v=hi)


def test_config_converts_to_plain_floats():
    cfg = PIDConfig(kp_v_per_n=2, ki_v_per_ns=40, tracking_time_s=1)
    assert type(cfg.kp_v_per_n) is float and type(cfg.tracking_time_s) is float


def test_default_tracking_time_choice():
    assert DEFAULT_PID.effective_tracking_time_s == pytest.approx(2.0 / 8.0)
    assert PIDConfig(kp_v_per_n=2.0, ki_v_per_ns=40.0, kd_vs_per_n=0.02).effective_tracking_time_s == \
        pytest.approx(math.sqrt(0.02 / 40.0))
    assert PIDConfig(kp_v_per_n=2.0, ki_v_per_ns=40.0).effective_tracking_time_s == pytest.approx(0.05)
    assert PIDConfig(kp_v_per_n=2.0, tracking_time_s=0.1).effective_tracking_time_s == math.inf


# ------------------------------------------------------------ dict / state IO


def test_pid_from_dict_rejects_unknown_key():
    with pytest.raises(ValueError) as info:
        pid_from_dict({"kp_v_per_n": 1.0, "kp": 2.0})
    msg = str(info.value)
    assert "'kp'" in msg and "kp_v_per_n" in msg and "tracking_time_s" in msg and "\n" not in msg


def test_pid_from_dict_overlays_default():
    pid = pid_from_dict({"kp_v_per_n": 1.0, "tracking_time_s": 0.01})
    assert pid.config == PIDConfig(**{**DEFAULT_PID.to_dict(), "kp_v_per_n": 1.0, "tracking_time_s": 0.01})
    assert PIDConfig.from_dict(DEFAULT_PID.to_dict()) == DEFAULT_PID


def test_state_roundtrip_continues_identically():
    a = PID(DEFAULT_PID)
    a.reset(force_est_n=0.5, setpoint_n=1.0, command_v=0.2)
    rng = random.Random(3)
    for _ in range(100):
        a.update(rng.uniform(0, 2), 1.0, 1e-3)
    b = PID(DEFAULT_PID)
    b.set_state(json.loads(json.dumps(a.state())))
    for _ in range(100):
        y = rng.uniform(0, 2)
        assert a.update(y, 1.5, 1e-3) == b.update(y, 1.5, 1e-3)


def test_set_state_rejects_unknown_and_missing_keys():
    pid = PID(DEFAULT_PID)
    state = pid.state()
    with pytest.raises(ValueError, match="'bogus'"):
        pid.set_state({**state, "bogus": 0.0})
    del state["derivative_v"]
    with pytest.raises(ValueError, match="'derivative_v'"):
        pid.set_state(state)


def test_fresh_state_has_no_derivative_memory():
    assert PID(DEFAULT_PID).state()["prev_derivative_input_n"] is None


# ------------------------------------------------------------------- registry


def test_protocol_and_defaults():
    pid = make("pid")
    assert isinstance(pid, Controller) and isinstance(pid, PID)
    assert pid.name == "pid"
    assert pid.config == DEFAULT_PID
    assert DEFAULT_PID == PIDConfig(
        kp_v_per_n=2.0, ki_v_per_ns=8.0, kd_vs_per_n=0.0, derivative_filter_s=0.005,
        setpoint_weight_p=1.0, setpoint_weight_d=0.0, u_min_v=-6.0, u_max_v=6.0, schedule_above_n=1.0,
    )
    assert "pid" in available()


def test_gain_scaling_above_force():
    from controllers.pid import pulp_stiffness_n_per_m
    cfg = PIDConfig(kp_v_per_n=2.0, ki_v_per_ns=8.0, kd_vs_per_n=0.01, schedule_above_n=1.0)
    assert cfg.gain_scale(1.0) == 1.0 and cfg.gain_scale(0.3) == 1.0
    k1, k3 = pulp_stiffness_n_per_m(1.0), pulp_stiffness_n_per_m(3.0)
    assert cfg.gain_scale(3.0) == pytest.approx(k1 / k3, rel=1e-12)
    assert 0.3 < cfg.gain_scale(3.0) < 0.4            # the pulp is ~3x stiffer at 3 N
    # read at the loop's crossover the pulp is 3.4 times softer, and the scaling the same (QLV)
    from controllers.pid import LOOP_CROSSOVER_HZ
    from ebraille_sim.physics.fingertip import dynamic_stiffness_n_per_m
    from ebraille_sim.physics.params import FINGERS
    kc1, kc3 = (pulp_stiffness_n_per_m(x, frequency_hz=LOOP_CROSSOVER_HZ) for x in (1.0, 3.0))
    assert kc1 == pytest.approx(dynamic_stiffness_n_per_m(FINGERS["nominal"], 1.0, LOOP_CROSSOVER_HZ), rel=1e-12)
    assert k1 / kc1 == pytest.approx(3.38, abs=0.01)
    assert cfg.gain_scale(3.0) == pytest.approx(kc1 / kc3, rel=1e-12)
    at3 = cfg.at(3.0)
    assert at3.schedule_above_n is None and at3.kp_v_per_n == pytest.approx(2.0 * k1 / k3)
    assert at3.ki_v_per_ns / at3.kp_v_per_n == pytest.approx(4.0)
    # the controller runs the config's gains at its setpoint: same commands as the fixed equivalent
    a, b = PID(cfg), PID(at3)
    for c in (a, b):
        c.reset(force_est_n=2.5, setpoint_n=3.0, command_v=1.0)
    ua = [a.update(2.5 + 0.01 * k, 3.0, 1e-3) for k in range(20)]
    ub = [b.update(2.5 + 0.01 * k, 3.0, 1e-3) for k in range(20)]
    assert ua == ub
    with pytest.raises(ValueError, match="schedule_above_n"):
        PIDConfig(kp_v_per_n=1.0, schedule_above_n=5.0)


def test_make_with_overrides_and_unknown_override():
    assert make("pid", kp_v_per_n=1.0).config.kp_v_per_n == 1.0
    with pytest.raises(ValueError, match="'kp'"):
        make("pid", kp=1.0)


def test_make_unknown_name_lists_available():
    with pytest.raises(ValueError, match="unknown controller 'mpc'.*pid"):
        make("mpc")


def test_make_from_json_and_toml(tmp_path):
    js = tmp_path / "gains.json"
    js.write_text(json.dumps({"controller": "pid", "gains": {"kp_v_per_n": 1.5, "ki_v_per_ns": 30.0}}))
    tm = tmp_path / "gains.toml"
    tm.write_text('controller = "pid"\n[gains]\nkp_v_per_n = 1.5\nki_v_per_ns = 30.0\n')
    for path in (js, tm, str(js), str(tm)):
        cfg = make(path).config
        assert (cfg.kp_v_per_n, cfg.ki_v_per_ns, cfg.kd_vs_per_n) == (1.5, 30.0, DEFAULT_PID.kd_vs_per_n)
    assert make(js, ki_v_per_ns=5.0).config.ki_v_per_ns == 5.0


def test_make_missing_file(tmp_path):
    path = tmp_path / "nope.toml"
    with pytest.raises(FileNotFoundError) as info:
        make(path)
    assert str(path) in str(info.value) and "\n" not in str(info.value)


def test_make_file_errors(tmp_path):
    bad_name = tmp_path / "a.json"
    bad_name.write_text(json.dumps({"controller": "lqr", "gains": {}}))
    with pytest.raises(ValueError, match="'lqr'.*available: .*pid"):
        make(bad_name)
    bad_gain = tmp_path / "b.json"
    bad_gain.write_text(json.dumps({"controller": "pid", "gains": {"kd": 0.1}}))
    with pytest.raises(ValueError, match="'kd'"):
        make(bad_gain)
    bad_top = tmp_path / "c.json"
    bad_top.write_text(json.dumps({"controller": "pid", "gain": {}}))
    with pytest.raises(ValueError, match="'gain'"):
        make(bad_top)


def test_register_custom_factory(monkeypatch):
    monkeypatch.setattr(controllers, "_REGISTRY", dict(controllers._REGISTRY))

    def slow_pid(**gains):
        return make("pid", **{"kp_v_per_n": 0.5, **gains})

    before = available()
    register("pid_slow", slow_pid)
    assert available() == sorted(before + ["pid_slow"])
    assert make("pid_slow").config.kp_v_per_n == 0.5
    assert make("pid_slow", kp_v_per_n=0.7).config.kp_v_per_n == 0.7
    with pytest.raises(ValueError, match="already registered"):
        register("pid_slow", slow_pid)
    with pytest.raises(ValueError):
        register("x.toml", slow_pid)


def test_pure_integrator_default_tracking_is_dead_beat():
    cfg = PIDConfig(kp_v_per_n=0.0, ki_v_per_ns=10.0, u_min_v=-1.0, u_max_v=1.0)
    assert cfg.effective_tracking_time_s == 0.0
    pid = PID(cfg)
    pid.reset(force_est_n=0.0, setpoint_n=0.0)
    for _ in range(1000):
        assert pid.update(0.0, 2.0, 1e-3) <= 1.0
    assert pid.state()["integrator_v"] == pytest.approx(1.0 + 10.0 * 1e-3 * 2.0, abs=1e-12)
    assert pid.update(0.5, 0.0, 1e-3) == 1.0  # forward Euler: I reacts one sample later
    assert pid.update(0.5, 0.0, 1e-3) == pytest.approx(1.0 - 10.0 * 1e-3 * 0.5, abs=1e-12)
