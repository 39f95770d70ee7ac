"""The refresh learning of controllers/refresh.py and its use in ``pid_dob``."""
import math

import numpy as np
import pytest

import controllers
from controllers.refresh import RefreshLearner, RefreshLearning, learn_dwell

H = 1e-3


def _dwell(n_low=25, n_high=75, lo=0.4, hi=1.0):
    """One refresh dwell's setpoint as the controller sees it: the rise first, then the high
    level, then the release/lift at the low one (the next dwell's rise ends it)."""
    return [hi] * n_high + [lo] * n_low


def test_learn_dwell_is_shift_add_average_clip():
    """The learning step against a plain loop over its definition."""
    rng = np.random.default_rng(0)
    n, lead, half, gain, limit = 30, 4, 3, 0.25, 0.3
    table = 0.2 * rng.standard_normal(40)
    err = rng.standard_normal(40)
    want = table.copy()
    for k in range(n - lead):
        want[k] += gain * err[k + lead]
    padded = [want[0]] * half + list(want[:n]) + [want[n - 1]] * half
    smooth = [sum(padded[k:k + 2 * half + 1]) / (2 * half + 1) for k in range(n)]
    want[:n] = smooth
    want = [min(max(x, -limit), limit) for x in want]
    learn_dwell(table, err, n, gain, lead, half, limit)
    assert table == pytest.approx(want, rel=1e-12, abs=1e-15)


def test_learner_switches_on_at_the_second_equal_dwell_and_learns_the_high_levels_error():
    """A constant 0.05 N shortfall of the estimate in every dwell: no correction until two
    dwells of the same length and levels have ended, then exactly ``learn_dwell`` of the error
    recorded from ``after_s`` on while the setpoint is high, and the correction is returned
    sample by sample from the setpoint's rise."""
    s = RefreshLearning(gain=0.25)
    lr = RefreshLearner(s)
    lr.reset(setpoint_n=0.4)
    setpoints = [0.4] * 10 + _dwell() * 4
    out, dwell_starts = [], []
    for i, r in enumerate(setpoints):
        if i > 0 and r > setpoints[i - 1]:
            dwell_starts.append(i)
        out.append(lr.step(r - 0.05 if r > 0.5 else r, r, H))
    assert dwell_starts == [10, 110, 210, 310]
    assert not any(out[:210])                                   # first dwell: nothing to compare with
    err = np.zeros(1000)
    err[28:75] = 0.05
    table = np.zeros(1000)
    for start in (210, 310):                                    # learned at the 2nd and 3rd rises
        learn_dwell(table, err, 100, 0.25, 10, 25, 0.15)
        assert out[start:start + 100] == pytest.approx(table[:100], rel=1e-12, abs=1e-15)
    assert lr.active and np.max(out) > 0.0


@pytest.mark.parametrize("second_high_samples, second_high", [(60, 1.0), (75, 1.2)])
def test_learner_stays_off_when_the_dwells_differ(second_high_samples, second_high):
    """Dwells of different lengths, or of different levels, are not a refresh pattern."""
    lr = RefreshLearner(RefreshLearning(gain=0.5))
    lr.reset(setpoint_n=0.4)
    setpoints = [0.4] * 5 + _dwell() + _dwell(n_high=second_high_samples, hi=second_high) + _dwell()
    assert not any(lr.step(0.3, r, H) for r in setpoints)
    assert not lr.active


def test_learner_forgets_on_reset_a_long_pause_and_a_new_rate():
    lr = RefreshLearner(RefreshLearning(gain=0.5, max_period_s=0.5))
    for reset in ("reset", "pause", "rate"):
        lr.reset(setpoint_n=0.4)
        for r in [0.4] * 5 + _dwell() * 4:
            lr.step(0.8, r, H)
        assert lr.active and np.any(lr.table)
        if reset == "reset":
            lr.reset(setpoint_n=0.4)
        elif reset == "pause":
            for _ in range(501):                                 # longer than max_period_s
                lr.step(0.4, 0.4, H)
        else:
            lr.step(0.8, 1.0, 2 * H)
        assert not lr.active and not np.any(lr.table)


def _refresh_run(ctrl, n_dwells=6, bias=0.05):
    ctrl.reset(force_est_n=0.4, setpoint_n=0.4, command_v=0.2)
    rng = np.random.default_rng(5)
    out = []
    for r in [0.4] * 5 + _dwell() * n_dwells:
        y = r - bias + 0.01 * rng.standard_normal()
        out.append(ctrl.update(y, r, H, motor_current_a=0.01 * rng.random()))
    return out


def test_pid_dob_without_learning_is_unchanged_and_a_constant_setpoint_never_learns():
    """Gain 0 (the default) builds no learner; with a learner, a setpoint that never rises in a
    pattern gives the same commands as without it, bit for bit."""
    assert controllers.make("pid_dob").learner is None
    plain = controllers.make("pid_dob", hold_damping_v_per_v=0.5)
    learn = controllers.make("pid_dob", hold_damping_v_per_v=0.5, refresh_learning_gain=0.25,
                             refresh_hold_damping_v_per_v=2.0)
    rng = np.random.default_rng(2)
    for c in (plain, learn):
        c.reset(force_est_n=1.0, setpoint_n=1.0, command_v=0.4)
    for k in range(400):
        r = 1.0 if k < 200 else 1.5                             # one step: no pattern
        y, i = r + 0.05 * rng.standard_normal(), 0.01 * rng.random()
        assert learn.update(y, r, H, motor_current_a=i) == plain.update(y, r, H, motor_current_a=i)
    assert not learn.learner.active


def test_pid_dob_tracks_the_learned_reference_and_switches_the_damping_in_refresh():
    """Once the pattern is on, ``pid_dob`` with learning and ``kv_refresh`` = ``kv`` gives the
    commands of ``pid_dob`` fed the reference ``r + correction``: the correction enters the
    reference only (the hold damping's gate still sees the setpoint itself)."""
    learn = controllers.make("pid_dob", refresh_learning_gain=0.25)
    out_learn = _refresh_run(learn)
    assert learn.learner.active and np.any(learn.learner.table)
    other = controllers.make("pid_dob", refresh_learning_gain=0.25, refresh_hold_damping_v_per_v=2.0)
    out_other = _refresh_run(other)
    on = 5 + 2 * 100                                            # the learner is on from the 3rd rise
    assert out_learn[:on] == out_other[:on]                     # kv 0 before and kv 2 only with the learner on
    assert out_learn[on:] != out_other[on:]
    plain = controllers.make("pid_dob")
    assert _refresh_run(plain)[:on] == out_learn[:on]
    assert _refresh_run(plain)[on:] != out_learn[on:]


@pytest.mark.parametrize("gains, match", [
    ({"refresh_learning_gain": -0.1}, "refresh_learning_gain"),
    ({"refresh_learning_gain": math.nan}, "refresh_learning_gain"),
    ({"refresh_learning_gain": 0.25, "refresh_learning_lead_s": -0.01}, "refresh_learning_lead_s"),
    ({"refresh_learning_gain": 0.25, "refresh_learning_smoothing_s": 1.0}, "refresh_learning_smoothing_s"),
    ({"refresh_learning_limit_fraction": 0.0}, "refresh_learning_limit_fraction"),
    ({"refresh_hold_damping_v_per_v": 7.0}, "refresh_hold_damping_v_per_v"),
])
def test_bad_learning_settings_one_line(gains, match):
    with pytest.raises(ValueError, match=match) as exc:
        controllers.make("pid_dob", **gains)
    assert "\n" not in str(exc.value)


def test_learning_holds_refresh_characters_a_plain_loop_loses():
    """Closed loop, 1 kHz estimator path with the compensation and its turn test: on a drawn
    reader whose force sags through every hold at 60 wpm (training reader 7 of
    studies/benchmark/make_dob_tuning.py, drawn as that study drew it: the divider's one-point
    calibration, no calibration table), the learning holds most characters the same gains lose.
    (With its bench's table, creep and loop the same reader's plain loop holds 0.94 of them.)"""
    import dataclasses

    from ebraille_sim.base.validation import replace_checked
    from ebraille_sim.scenarios.population import PopulationSpec, device_from_variates
    from ebraille_sim.scenarios.runner import run_scenario
    from ebraille_sim.scenarios.spec import load_scenario

    spec = dataclasses.replace(load_scenario("refresh_60wpm"), duration_s=8.0)
    u = [0.9392319175306981, 0.561609565908339, 0.6593547338892862, 0.3350060645830333, 0.8789727001447462,
         0.09272620183087377, 0.9556861372102897, 0.13084888412029827, 0.021039366640042245, 0.8808671159452015,
         0.505193468155093, 0.7116741461475302, 0.6267461490195707,
         0.5, 0.5, 0.5]             # reader 7 of sample_devices(7, 8)
    z = [-0.5813121625236413, 3.3602500555335917, -0.10800992319986062]        # when it was found
    dev = device_from_variates(u, z, PopulationSpec(calibration_table=False), spec.device)
    dev = dataclasses.replace(dev, estimator=replace_checked(
        dev.estimator, hysteresis_compensation=True, model="paper:wiener:5@1000", antialias_cutoff_hz=50.0,
        hysteresis_turn_lsb=1.75, hysteresis_centre_time_s=0.0))     # fast_1khz
    gains = {"kp_v_per_n": 2.9, "ki_v_per_ns": 5.1, "compensation_fraction": 0.67, "q_time_constant_s": 0.002,
             "hold_damping_v_per_v": 0.5}
    seed = spec.seed + 101 * 57
    plain = run_scenario(spec, controller=controllers.make("pid_dob", **gains), seed=seed, device=dev,
                         trace_every=None).metrics["char_in_band_fraction"]
    learn = run_scenario(spec, controller=controllers.make("pid_dob", **gains, refresh_learning_gain=0.25,
                                                           refresh_hold_damping_v_per_v=1.5),
                         seed=seed, device=dev, trace_every=None).metrics["char_in_band_fraction"]
    assert plain < 0.5 < 0.8 < learn
