"""The residual env: a bounded correction on a design, zero action = the design's run, board-only
observations, a curriculum over the population, and the residual policy as a scenario controller."""
import math

import numpy as np
import pytest

import controllers
from controllers.residual import N_FRAME, ActionSlot, ResidualPolicy
from ebraille_sim.rl.residual import ResidualEnv, scaled_population
from ebraille_sim.scenarios.population import PopulationSpec
from ebraille_sim.scenarios.runner import run_scenario

SHORT = {"episode_characters": 3}


def _rollout(env, actions, seed):
    obs, _ = env.reset(seed=seed)
    ft, obs_all, rew = [], [obs], []
    for k in range(env.episode.n_steps):
        obs, r, term, trunc, info = env.step(np.array([actions(k)], np.float32))
        ft.append(info["force_true_n"])
        obs_all.append(obs)
        rew.append(r)
        if term or trunc:
            break
    return np.array(ft), np.array(obs_all), np.array(rew)


@pytest.mark.parametrize("design", ["dob_100hz", "pid"])
def test_zero_action_reproduces_the_designs_run_exactly(design):
    env = ResidualEnv(residual=design, **SHORT)
    ft, _, _ = _rollout(env, lambda k: 0.0, seed=5)
    res = run_scenario(env.episode.spec, controller=design)
    assert ft.shape == res.trace["force_true_n"].shape
    assert np.array_equal(ft, res.trace["force_true_n"])          # to the last bit
    assert ft.max() > 0.2                                          # the episode made contact


def test_residual_changes_the_trajectory_and_is_bounded():
    env = ResidualEnv(residual="dob_100hz", residual_limit_v=0.5, **SHORT)
    base, _, _ = _rollout(env, lambda k: 0.0, seed=2)
    push, _, _ = _rollout(env, lambda k: 1.0, seed=2)
    over, _, _ = _rollout(env, lambda k: 7.0, seed=2)             # clipped to 1
    assert np.array_equal(push, over)
    assert not np.array_equal(base, push)
    assert env.controller.residual_v == 0.5


def test_same_seed_same_episode_and_observations():
    a = _rollout(ResidualEnv(history=3, **SHORT), lambda k: math.sin(0.01 * k), seed=11)
    b = _rollout(ResidualEnv(history=3, **SHORT), lambda k: math.sin(0.01 * k), seed=11)
    for x, y in zip(a, b):
        assert np.array_equal(x, y)


def test_observation_is_board_signals_with_a_history_stack():
    env = ResidualEnv(history=3, **SHORT)
    assert env.observation_space.shape == (3 * N_FRAME,)
    _, obs, _ = _rollout(env, lambda k: 0.3, seed=4)
    assert np.all(obs >= env.observation_space.low) and np.all(obs <= env.observation_space.high)
    # the newest frame's last entry is the previous residual action; older frames shift down
    assert obs[0][N_FRAME - 1] == 0.0 and obs[2][N_FRAME - 1] == pytest.approx(0.3)
    assert np.array_equal(obs[5][N_FRAME:2 * N_FRAME], obs[4][:N_FRAME])
    # the current entry is the sensed current (the board's chain), not the plant's
    st = env.plant.state[0]
    from ebraille_sim.plant.layout import S
    assert obs[-1][6] == pytest.approx(np.clip(st[S.current_meas_a] / env.config.current_scale_a, -3, 3), rel=1e-6)


def test_policy_in_a_scenario_sees_what_it_saw_in_training():
    """The residual policy as a controller, fed a fixed action sequence, replays the env run."""
    env = ResidualEnv(history=2, **SHORT)
    acts = [float(np.float32(0.2 * math.sin(0.02 * k))) for k in range(100000)]   # the env gets float32
    ft, obs, _ = _rollout(env, lambda k: acts[k], seed=8)
    seen = []

    class Replay:
        def predict(self, o, deterministic=True):
            seen.append(np.array(o))
            return np.array([acts[len(seen) - 1]]), None

    cfg = env.config
    pol = ResidualPolicy(controllers.make("dob_100hz"), Replay(), 1.0, 1000.0, 2, cfg.safe_force_n, cfg.warn_force_n,
                         cfg.rate_filter_s, cfg.integral_time_s, cfg.base_device.driver_supply_v, cfg.current_scale_a)
    res = run_scenario(env.episode.spec, controller=pol)
    assert np.array_equal(res.trace["force_true_n"], ft)
    assert np.array_equal(np.array(seen), obs[:len(seen)])


def test_curriculum_grows_the_population_spread():
    env = ResidualEnv(curriculum_steps=40, curriculum_start=0.25, **SHORT)
    assert env.spread() == 0.25
    env.steps_taken = 20
    assert env.spread() == 0.625
    env.steps_taken = 400
    assert env.spread() == 1.0
    full = PopulationSpec()
    half = scaled_population(full, 0.5)
    assert half.finger_b_scale == pytest.approx((0.875, 1.625))
    assert half.motor_r_sigma == pytest.approx(0.025)
    none = scaled_population(full, 0.0)
    assert none.gear_efficiency[0] == none.gear_efficiency[1]


@pytest.mark.parametrize("kwargs, match", [
    ({"residual": "no_such_design"}, "unknown design 'no_such_design'"),
    ({"residual_limit_v": 0.0}, "residual_limit_v"),
    ({"history": 0}, "history"),
    ({"curriculum_start": 1.5}, "curriculum_start"),
    ({"refresh_probability": -0.1}, "refresh_probability"),
    ({"nope": 1}, "unknown argument 'nope'"),
    ({"backend": "pymunk"}, "lumped plant"),
])
def test_bad_arguments_are_one_line_errors(kwargs, match):
    with pytest.raises(ValueError, match=match) as exc:
        ResidualEnv(**kwargs)
    assert "\n" not in str(exc.value)


def test_nan_action_is_refused():
    env = ResidualEnv(**SHORT)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="finite"):
        env.step(np.array([np.nan], np.float32))


def test_action_slot_and_nan_policy_output():
    slot = ActionSlot()
    pol = ResidualPolicy(controllers.make("pid_dob"), slot, 1.0, 1000.0)
    pol.reset(force_est_n=0.0, setpoint_n=1.0)
    slot.action = math.nan
    with pytest.raises(ValueError, match="non-finite action"):
        pol.update(0.0, 1.0, 1e-3, 0.0)


def test_registered_id_makes_the_residual_env():
    import gymnasium as gym

    from ebraille_sim.rl.registration import RESIDUAL_ENV_ID, register_envs
    register_envs()
    env = gym.make(RESIDUAL_ENV_ID, residual="dob_hold_1khz", history=2, **SHORT)
    obs, _ = env.reset(seed=1)
    assert obs.shape == (2 * N_FRAME,)
    assert env.unwrapped.episode.device.estimator.model == "paper:wiener:5@1000"     # the design's firmware


def test_refresh_share_reads_some_episodes_in_refresh_mode_and_keeps_the_rest():
    plain = ResidualEnv(**SHORT)
    mixed = ResidualEnv(refresh_probability=0.5, **SHORT)
    modes = []
    for seed in range(8):
        plain.reset(seed=seed)
        mixed.reset(seed=seed)
        a, b = plain.episode.spec, mixed.episode.spec
        modes.append(b.reading.mode)
        assert a.device == b.device and a.reading.text == b.reading.text and a.seed == b.seed
        if b.reading.mode == "refresh":
            # the setpoint falls to the lift force between presses
            assert mixed.episode.setpoint_n.min() < plain.episode.setpoint_n[plain.episode.setpoint_n > 0].min()
    assert 0 < modes.count("refresh") < 8
    always = ResidualEnv(refresh_probability=1.0, **SHORT)
    always.reset(seed=0)
    assert always.episode.spec.reading.mode == "refresh"


def _bang_bang(env, seed):
    """An episode under a +/- 1 correction switching every 50 steps: observations, (reward,
    command, correction) per step, and the steps after which the supervisor had restarted the policy."""
    obs, _ = env.reset(seed=seed)
    out, steps, restarts = [obs], [], []
    for k in range(env.episode.n_steps):
        obs, r, term, trunc, info = env.step(np.array([1.0 if (k // 50) % 2 else -1.0], np.float32))
        out.append(obs)
        steps.append((r, info["command_v"], info["residual_v"], info["force_true_n"]))
        if env.controller._first:
            restarts.append(k + 1)
        if term or trunc:
            break
    return np.array(out), np.array(steps), restarts


@pytest.mark.parametrize("design", ["dob_100hz", "pid"])
def test_compiled_step_is_the_python_shims_step(design, monkeypatch):
    """The design's compiled controller plus the correction inside the loop engine gives the
    observations, rewards and commands of the design and the residual policy stepped from
    Python, through a supervisor's restart of the policy."""
    import ebraille_sim.scenarios.runner as runner
    fast = ResidualEnv(residual=design, history=2, **SHORT)
    a = _bang_bang(fast, seed=0)
    assert fast._fast is not None
    monkeypatch.setattr(runner, "_USE_COMPILED_LOOP", False)
    shim = ResidualEnv(residual=design, history=2, **SHORT)
    b = _bang_bang(shim, seed=0)
    assert shim._fast is None
    assert a[2] and a[2] == b[2]                                   # the supervisor restarted the policy
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])


def test_a_design_without_a_compiled_form_runs_from_python():
    env = ResidualEnv(residual="dob_learn_1khz", **SHORT)
    env.reset(seed=1)
    assert env._fast is None
    obs, r, term, trunc, info = env.step(np.array([0.5], np.float32))
    assert info["residual_v"] == 0.5 and math.isfinite(r)


def test_resumed_policy_resumes_its_design_as_the_design_alone():
    """A supervisor's resume after regained contact starts the design's integrator at 0 V or
    above, as it starts the design alone (controllers.compiled.resume_controller)."""
    from controllers.compiled import PS, resume_controller
    alone = controllers.make("dob_100hz")
    res = ResidualPolicy(controllers.make("dob_100hz"), ActionSlot(), limit_v=1.0, control_rate_hz=1000.0)
    for c in (alone, res):
        c.reset(force_est_n=0.0, setpoint_n=1.0)
        c.update(0.2, 1.0, 1e-3, 0.01)
        resume_controller(c, force_est_n=0.1, setpoint_n=1.0)     # bumpless from 0 V would start it below 0
    assert alone.compiled()[1][PS.integrator_v] == 0.0
    assert np.array_equal(res.base.compiled()[1], alone.compiled()[1])
    assert res.residual == 0.0 and res.observation.shape == (N_FRAME,)


def _random_actor(seed=0, history=4):
    from controllers.policy import MlpActor
    rng = np.random.default_rng(seed)
    w = [rng.normal(0, 0.3, (64, history * N_FRAME)), rng.normal(0, 0.2, (64, 64)), rng.normal(0, 0.3, (1, 64))]
    b = [rng.normal(0, 0.1, 64), rng.normal(0, 0.1, 64), np.array([0.05])]
    return MlpActor(w, b, "tanh", False)


def test_compiled_mlp_is_the_numpy_actor_to_float32_rounding():
    from controllers.residual import mlp_action
    actor = _random_actor()
    layers, weights = actor.vectors()
    buf = np.zeros(128, np.float32)
    rng = np.random.default_rng(1)
    for _ in range(200):
        obs = rng.uniform(-2, 2, 4 * N_FRAME).astype(np.float32)
        want = float(actor.predict(obs)[0][0])
        assert mlp_action(layers, weights, obs, buf) == pytest.approx(want, abs=2e-6)
    res = ResidualPolicy(controllers.make("dob_100hz"), ActionSlot(), 1.0, 1000.0)
    assert res.compiled_policy(1e-3) is None and res.compiled_policy(1e-3, handed=True) is not None


def test_a_residual_mlp_policy_runs_in_the_loop_engine_as_from_python(monkeypatch):
    """``run`` of a residual policy with an MLP actor runs in the loop engine (the actor never
    called from Python) and gives the run of the policy stepped from Python, to the float32
    rounding of the actor's sums."""
    import ebraille_sim.scenarios.runner as runner
    actor = _random_actor()
    calls = []
    predict = actor.predict
    monkeypatch.setattr(actor, "predict", lambda o, deterministic=True: calls.append(1) or predict(o, deterministic))

    def policy():
        return ResidualPolicy(controllers.make("dob_100hz"), actor, 1.0, 1000.0, 4)

    fast = run_scenario("strap_slip", controller=policy(), duration_s=3.0, firmware="paper_100hz")
    assert not calls
    monkeypatch.setattr(runner, "_USE_COMPILED_LOOP", False)
    slow = run_scenario("strap_slip", controller=policy(), duration_s=3.0, firmware="paper_100hz")
    assert len(calls) == len(slow.trace["force_true_n"])
    diff = np.abs(fast.trace["force_true_n"] - slow.trace["force_true_n"]).max()
    assert diff < 1e-4
    assert np.abs(fast.trace["command_v"] - slow.trace["command_v"]).max() < 1e-3
    assert fast.metrics["in_band_fraction"] == pytest.approx(slow.metrics["in_band_fraction"], abs=2e-3)
    assert not np.array_equal(fast.trace["force_true_n"], run_scenario(
        "strap_slip", controller="dob_100hz", duration_s=3.0).trace["force_true_n"])     # the policy acts


def test_a_policy_row_runs_beside_other_rows_as_it_runs_alone():
    """``engine.run`` steps the row given a residual policy (``Rows.give_policy``) with the policy
    and every other row with its own controller: each row's trace is that of the row run alone,
    to the last bit, and the policy acts.  Without a policy the argument is ``NO_POLICY``, of the
    types of a policy's arrays (one compiled ``run`` for both)."""
    import numba
    from ebraille_sim.physics.params import DeviceParams
    from ebraille_sim.plant import engine
    from ebraille_sim.plant.backends import make_plant
    actor = _random_actor()
    n = 400
    sp = np.full(n, 1.2)

    def plant():
        return make_plant([DeviceParams()], seeds=[1])

    def policy():
        pol = ResidualPolicy(controllers.make("dob_100hz"), actor, 1.0, 1000.0, 4)
        return pol, pol.compiled_policy(plant().control_dt_s)

    def single(with_policy):
        pol, bundle = policy()
        rows = engine.Rows.single(plant(), *pol.base.compiled(), setpoint_n=sp)
        if with_policy:
            rows.give_policy(0, bundle)
        engine.run(*rows.arguments(0, n))
        return rows.f_true[0]

    alone_policy, alone_design = single(True), single(False)
    pol, bundle = policy()
    p0, p1 = plant(), plant()
    rows = engine.Rows.pack([(p.state[0], p.params[0], p.inputs[0], p.substeps) for p in (p0, p1)],
                            [controllers.make("dob_100hz").compiled(), pol.base.compiled()], [None, None],
                            np.stack([sp, sp]), p0.control_dt_s, engine.S.force_est_n, [{}, {}], 0, n)
    rows.give_policy(1, bundle)
    engine.run(*rows.arguments(0, n))
    assert list(rows.status) == [engine.OK, engine.OK]
    assert np.array_equal(rows.f_true[0], alone_design) and np.array_equal(rows.f_true[1], alone_policy)
    assert not np.array_equal(alone_policy, alone_design)
    assert numba.typeof(engine.NO_POLICY) == numba.typeof(bundle)
