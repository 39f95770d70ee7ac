"""The Gymnasium env: registration, checkers, determinism, episodes, reward, ends, rendering."""
from __future__ import annotations

import importlib
import math
import warnings

import gymnasium as gym
import numpy as np
import pytest

import ebraille_sim
from ebraille_sim.rl.env import ENV_ID, MAX_EPISODE_STEPS, OPTION_KEYS, ContactForceEnv, EnvConfig, register_envs
from ebraille_sim.physics.params import FINGERS, DeviceParams
from ebraille_sim.plant.layout import S


def _rollout(env, seed, actions, options=None):
    obs, info = env.reset(seed=seed, options=options)
    out = [(obs, 0.0, False, False, info)]
    for a in actions:
        step = env.step(np.array([a], np.float32))
        out.append(step)
        if step[2] or step[3]:
            break
    return out


def test_import_registers_the_id_once_without_warnings():
    spec = gym.spec(ENV_ID)
    assert spec.entry_point == "ebraille_sim.rl.env:ContactForceEnv"
    assert spec.vector_entry_point == "ebraille_sim.rl.vector_env:ContactForceVectorEnv"
    assert spec.max_episode_steps is None and MAX_EPISODE_STEPS == 1400   # the env truncates itself
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        register_envs()
        importlib.reload(ebraille_sim)
    assert gym.spec(ENV_ID) is spec


def test_default_episode_bound_matches_the_longest_episode():
    # 1 s onset + 30 cells at 60 wpm (0.2 s each) at 200 Hz
    assert EnvConfig().max_episode_steps() == round((1.0 + 30 * 0.2) * 200)
    env = ContactForceEnv()
    env.reset(seed=0, options={"wpm": 60.0})
    assert env.episode.n_steps == MAX_EPISODE_STEPS


def test_episode_bound_follows_the_control_rate():
    assert EnvConfig(control_rate_hz=1000.0).max_episode_steps() == 7000
    env = gym.make(ENV_ID, control_rate_hz=1000.0)
    env.reset(seed=0, options={"wpm": 60.0})
    steps = 0
    while True:
        _, _, term, trunc, _ = env.step(np.zeros(1, np.float32))
        steps += 1
        if term or trunc:
            break
    assert steps == 7000 and trunc and not term                 # 7 s, not cut at 1.4 s


def test_gymnasium_env_checker_passes_without_warnings():
    from gymnasium.utils.env_checker import check_env
    env = gym.make(ENV_ID, render_mode="rgb_array")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env.unwrapped)
    env.close()


def test_stable_baselines3_env_checker_passes_without_warnings():
    sb3_checker = pytest.importorskip("stable_baselines3.common.env_checker")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sb3_checker.check_env(ContactForceEnv(), warn=True)


def test_same_seed_same_trajectory_exactly_and_another_seed_differs():
    acts = np.random.default_rng(1).uniform(-0.4, 0.8, size=300)
    a = _rollout(ContactForceEnv(), 11, acts)
    b = _rollout(ContactForceEnv(), 11, acts)
    c = _rollout(ContactForceEnv(), 12, acts)
    assert len(a) == len(b)
    for x, y in zip(a, b):
        assert np.array_equal(x[0], y[0]) and x[1:4] == y[1:4] and x[4] == y[4]
    assert not all(np.array_equal(x[0], y[0]) for x, y in zip(a, c))


def test_unseeded_reset_continues_the_master_seed():
    env1, env2 = ContactForceEnv(), ContactForceEnv()
    env1.reset(seed=4)
    first = env1.episode.device
    env2.reset(seed=4)
    o1, _ = env1.reset()
    o2, _ = env2.reset()
    assert np.array_equal(o1, o2)
    assert env1.episode.device == env2.episode.device != first


def test_observations_stay_in_the_declared_bounds_and_are_float32():
    env = ContactForceEnv()
    rng = np.random.default_rng(0)
    obs, _ = env.reset(seed=2)
    for _ in range(400):
        obs, r, term, trunc, _ = env.step(rng.uniform(-1.5, 1.5, size=1).astype(np.float32))
        assert obs.dtype == np.float32 and env.observation_space.contains(obs)
        assert -1.1 - 1e-12 <= r <= 1.0
        if term or trunc:
            obs, _ = env.reset()


def test_unknown_option_and_bad_values_are_one_line_errors():
    env = ContactForceEnv()
    with pytest.raises(ValueError) as exc:
        env.reset(seed=0, options={"wmp": 90})
    msg = str(exc.value)
    assert "unknown reset option 'wmp'" in msg and ", ".join(OPTION_KEYS) in msg and "\n" not in msg
    for bad, text in [({"wpm": -3.0}, "out of range"), ({"setpoint_n": 3.0}, "out of range"),
                      ({"passage": "nope"}, "not one of"), ({"first_character": 10**9}, "out of range"), ({"gap_m": float("nan")}, "option 'gap_m' must be finite"),
                      ({"device": "nominal"}, "DeviceParams"), ({"setpoint_steps": [(2.0, 1.0), (1.0, 0.5)]},
                                                                "increase")]:
        with pytest.raises(ValueError, match=text):
            env.reset(seed=0, options=bad)


def test_bad_constructor_arguments_are_rejected():
    with pytest.raises(ValueError, match="control_rate_hz"):
        ContactForceEnv(control_rate_hz=300.0)            # 10 kHz / 300 Hz is not whole
    with pytest.raises(ValueError, match="warn_force_n"):
        ContactForceEnv(warn_force_n=3.5)
    with pytest.raises(ValueError, match="render_mode"):
        ContactForceEnv(render_mode="human")
    with pytest.raises(ValueError, match="unknown backend"):
        ContactForceEnv(backend="spice")


def test_every_form_of_a_finite_action_steps_the_same_and_each_step_returns_its_own_info():
    """A Python float, a float32 or float64 array of one element and an integer array step the
    same numbers; the observation and info of one step are not changed by the next (a stored
    info keeps its values)."""
    runs = []
    for form in (lambda x: x, lambda x: np.array([x], np.float32), lambda x: np.array([[x]], np.float64),
                 lambda x: np.float64(x), lambda x: np.array([round(x)], np.int64)):
        env = ContactForceEnv()
        env.reset(seed=4)
        out = []
        for k in range(60):
            x = float(np.float32(0.5 * math.sin(0.1 * k))) if k % 7 else float(k % 2)
            out.append(env.step(form(x)))
        runs.append(out)
    for i in (1, 2, 3):
        for (o1, r1, t1, u1, i1), (o2, r2, t2, u2, i2) in zip(runs[0], runs[i]):
            assert np.array_equal(o1, o2) and (r1, t1, u1) == (r2, t2, u2) and repr(i1) == repr(i2)
    assert len(runs[4]) == 60
    out = runs[0]
    first_obs, first_info = out[0][0].copy(), dict(out[0][4])
    assert out[0][4] is not out[1][4] and out[0][0] is not out[1][0]
    assert np.array_equal(out[0][0], first_obs) and out[0][4] == first_info
    assert first_info["time_s"] == 0.005 and out[1][4]["time_s"] == 0.01


def test_non_finite_python_float_action_is_a_one_line_error():
    env = ContactForceEnv()
    env.reset(seed=0)
    for bad in (float("nan"), float("inf"), -float("inf")):
        with pytest.raises(ValueError, match="action must be finite") as err:
            env.step(bad)
        assert "\n" not in str(err.value)
    assert env._k == 0


def test_nan_or_misshapen_action_is_an_error():
    env = ContactForceEnv()
    env.reset(seed=0)
    with pytest.raises(ValueError, match="finite"):
        env.step(np.array([np.nan], np.float32))
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros(3, np.float32))


def test_options_fix_components_without_shifting_the_others():
    env = ContactForceEnv()
    env.reset(seed=7)
    free = env.episode
    env.reset(seed=7, options={"wpm": 90.0, "passage": "market", "first_character": 0, "setpoint_n": 1.0})
    fixed = env.episode
    assert fixed.wpm == 90.0 and fixed.passage == "market" and "from character 0," in fixed.spec.description
    assert np.all(fixed.setpoint_n == 1.0)
    # the device, the sensor noise seed, the finger and the supply are drawn as before
    assert fixed.device == free.device and fixed.sensor_seed == free.sensor_seed
    assert fixed.gap_m == free.gap_m and fixed.supply_v == free.supply_v
    assert fixed.spec.sections == free.spec.sections
    dev = DeviceParams(finger=FINGERS["stiff"])
    env.reset(seed=7, options={"device": dev, "disturbances": False, "gap_m": 1e-3})
    ep = env.episode
    assert ep.device.finger == FINGERS["stiff"] and ep.device.rates.control_rate_hz == 200.0
    assert np.all(ep.finger_m == 1e-3) and ep.supply_v == dev.driver_supply_v
    env.reset(seed=7, options={"supply_fraction": 0.7, "tremor_amplitude_m": 0.0, "drift_amplitude_m": 0.0})
    ep = env.episode
    assert ep.supply_v == ep.device.driver_supply_v == pytest.approx(0.7 * 6.0)
    assert "battery" not in ep.spec.sections.get("disturbances", {}) and np.all(ep.finger_m == ep.gap_m)


def test_episode_draws_stay_in_their_ranges():
    env = ContactForceEnv()
    for seed in range(12):
        env.reset(seed=seed)
        ep = env.episode
        assert 60.0 <= ep.wpm <= 120.0
        assert np.all((ep.setpoint_n >= 0.3) & (ep.setpoint_n <= 1.5))
        assert len(np.unique(ep.setpoint_n)) <= 3
        assert 0.5e-3 <= ep.gap_m <= 1.5e-3
        on_battery = "battery" in ep.spec.sections.get("disturbances", {})
        assert (3.0 < ep.supply_v < 4.2) if on_battery else (0.85 * 6.0 - 1e-12 <= ep.supply_v <= 6.0)
        assert len(ep.schedule) == 30 and ep.schedule.start_s[0] == 1.0
        assert ep.n_steps == round(ep.schedule.t_end_s * 200) <= MAX_EPISODE_STEPS


def test_truncation_at_the_end_of_the_passage():
    env = ContactForceEnv()
    env.reset(seed=0, options={"wpm": 600.0})
    n = env.episode.n_steps
    assert n == round((1.0 + 30 * 60 / (5 * 600)) * 200)      # 1.6 s at 200 Hz
    for k in range(n):
        _, _, term, trunc, info = env.step(np.zeros(1, np.float32))
        assert not term
        assert trunc == (k == n - 1)
    assert info["char_index"] == -1
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros(1, np.float32))


def test_reward_formula_and_termination_past_the_safe_force():
    env = ContactForceEnv(randomize_device=False, safety=False)
    _, info = env.reset(seed=1, options={"disturbances": False, "gap_m": 0.5e-3, "setpoint_n": 1.0,
                                           "device": DeviceParams(finger=FINGERS["stiff"])})
    seen_violation = False
    for _ in range(2000):
        _, r, term, trunc, info = env.step(np.ones(1, np.float32))
        f = info["force_true_n"]
        v = min(1.0, max(0.0, (f - 2.0) / 1.0))
        assert info["violation"] == pytest.approx(v, abs=1e-12)
        expect = 1.0 - math.sqrt(min(1.0, abs(f - 1.0))) - 0.1 * 1.0 - 1.0 * v
        assert r == pytest.approx(expect, abs=1e-12)
        seen_violation |= 0.0 < v < 1.0
        if term:
            break
    assert term and not trunc and info["force_true_n"] > 3.0
    assert seen_violation
    # Gymnasium's convention: no step after termination without a reset (one line), then a reset works
    with pytest.raises(RuntimeError, match=r"ended \(terminated or truncated\); call reset\(\)") as err:
        env.step(np.ones(1, np.float32))
    assert "\n" not in str(err.value)
    env.reset(seed=2)
    assert env.step(np.zeros(1, np.float32))[0].shape == (7,)


def test_a_step_after_termination_is_refused_on_the_python_path_too():
    """The step through the per-period shim (a plant without compiled rows) keeps the same rule."""
    from ebraille_sim.rl.env import C_CMD_SCALE, HeldCommand
    env = ContactForceEnv(randomize_device=False, safety=False)
    env.reset(seed=1, options={"disturbances": False, "gap_m": 0.5e-3, "setpoint_n": 1.0,
                               "device": DeviceParams(finger=FINGERS["stiff"])})
    env._ws = None
    env._agent = HeldCommand(None, env._c[C_CMD_SCALE])
    for _ in range(2000):
        _, _, term, trunc, _ = env.step(np.ones(1, np.float32))
        if term:
            break
    assert term and not trunc
    with pytest.raises(RuntimeError, match="call reset"):
        env.step(np.ones(1, np.float32))


def test_a_pid_drives_the_env_to_its_setpoint():
    from controllers import make
    env = ContactForceEnv(randomize_device=False)
    _, info = env.reset(seed=3, options={"disturbances": False, "setpoint_n": 1.0, "gap_m": 1e-3})
    pid = make("pid")
    pid.reset(force_est_n=info["force_est_n"], setpoint_n=1.0)
    forces = []
    for _ in range(800):                                        # 4 s
        u = pid.update(info["force_est_n"], info["setpoint_n"], env.config.dt_s)
        _, _, term, _, info = env.step(np.array([u / 6.0], np.float32))
        forces.append(info["force_true_n"])
        assert not term
    tail = np.array(forces[-200:])
    assert np.all(np.abs(tail - 1.0) < 0.1)


def test_render_draws_device_force_and_cell():
    env = ContactForceEnv(render_mode="rgb_array")
    env.reset(seed=0, options={"wpm": 120.0})
    first = env.render()
    for _ in range(260):                                        # past the 1 s onset: a cell is shown
        env.step(np.array([0.12], np.float32))
    later = env.render()
    assert first.shape == later.shape == (360, 720, 3) and first.dtype == np.uint8
    assert later.std() > 10
    assert np.mean(np.any(first != later, axis=2)) > 0.01
    env.close()
    quiet = ContactForceEnv()
    quiet.reset(seed=0)
    with pytest.warns(UserWarning, match="render_mode"):
        assert quiet.render() is None


@pytest.mark.parametrize("action", ["0.5", b"1", np.array([1 + 0j]), np.array(["0.5"]), {"a": 1}, [None], True,
                                    np.array([0.5], dtype=object)])
def test_only_real_numbers_are_actions(action):
    """Strings, bytes, booleans, complex numbers and objects are one-line ValueErrors, never stepped."""
    env = gym.make(ENV_ID).unwrapped
    env.reset(seed=1)
    with pytest.raises(ValueError, match="action must be a real number or an array of real numbers") as err:
        env.step(action)
    assert "\n" not in str(err.value)
    assert env._k == 0


def test_vector_env_rejects_non_real_actions():
    envs = gym.make_vec(ENV_ID, num_envs=2, vectorization_mode="vector_entry_point")
    envs.reset(seed=1)
    with pytest.raises(ValueError, match="real number"):
        envs.step(np.array([["0.5"], ["1"]]))
    with pytest.raises(ValueError, match="real number"):
        envs.step(np.array([[1 + 1j], [0.0]]))
    envs.close()


def test_safety_layer_latches_a_fault_and_ignores_the_agent_then():
    env = ContactForceEnv(randomize_device=False)
    _, info = env.reset(seed=2, options={"disturbances": False, "gap_m": 1e-3, "setpoint_n": 1.0})
    for _ in range(600):                                     # reach contact
        *_, info = env.step(np.array([0.2], np.float32))
    env._st[S.force_est_n] = float("nan")                    # a broken estimate
    *_, info = env.step(np.array([1.0], np.float32))
    assert info["supervisor_fault"] == "fsr_out_of_range" and info["command_v"] <= 0.0
    for _ in range(20):
        *_, info = env.step(np.array([1.0], np.float32))
        assert info["command_v"] <= 0.0


def test_safety_flag_is_validated():
    with pytest.raises(ValueError, match="safety"):
        ContactForceEnv(safety="yes")
def test_safety_layer_is_on_by_default_and_holds_a_full_push_below_the_safe_limit():
    """The agent pushes at full command on a stiff reader: with the safety layer the true
    force stays below the supervisor's 3.5 N safe limit (the episode may still end at the
    env's 3 N termination); the explicit opt-out ``safety=False`` lets the same push go far
    past it.  The opt-out env's termination is moved to 20 N so that it does not end the
    episode in the 5 ms step that crosses 3 N (on the tap-dissipation pulp that step ends at
    3.29 N): the unsupervised push runs up to the drive's stall push, the force the stall
    current applies at the lower edge of the friction band (17.07 N)."""
    opts = {"disturbances": False, "gap_m": 0.5e-3, "setpoint_n": 1.0, "device": DeviceParams(finger=FINGERS["stiff"])}
    env = ContactForceEnv(randomize_device=False)
    assert env.config.safety
    _, info = env.reset(seed=1, options=opts)
    peak, term, trunc = 0.0, False, False
    while not (term or trunc):
        _, r, term, trunc, info = env.step(np.ones(1, np.float32))
        peak = max(peak, info["force_true_n"])
        assert info["action_v"] == pytest.approx(6.0)
    assert 2.5 < peak < 3.5
    off = ContactForceEnv(randomize_device=False, safety=False, safe_force_n=20.0)
    off.reset(seed=1, options=opts)
    peak_off, term, trunc, t_past = 0.0, False, False, None
    while not (term or trunc):
        *_, term, trunc, info = off.step(np.ones(1, np.float32))
        peak_off = max(peak_off, info["force_true_n"])
        if t_past is None and peak_off > 3.5:
            t_past = info["time_s"]
    assert "supervisor_mode" not in info
    assert t_past is not None and t_past < 0.1                # past 3.5 N within 0.1 s of the push
    # the unit's own stall push (its true constants, not the firmware's bounds)
    from ebraille_sim.physics import limits
    dev = opts["device"]
    b = limits.drive_bounds(dev)
    i_stall = dev.driver_supply_v / dev.motor.resistance_ohm
    tf = b["friction_current_a"] * b["push_force_per_a_n"]
    f_lo = limits.push_force_bound_n(i_stall, b["push_force_per_a_n"], 1.0, 1.0, dev.motor.breakaway_ratio * tf,
                                     -b["weight_n"]) - dev.drivetrain.guide_coulomb_n * dev.drivetrain.guide_breakaway_ratio
    f_hi = limits.push_force_bound_n(i_stall, b["push_force_per_a_n"], 1.0, 1.0, tf, b["weight_n"])
    assert f_lo - 0.05 < peak_off < f_hi                       # 17.07 N, five times the safe limit


