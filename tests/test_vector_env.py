"""The native vector env: equal to N scalar envs, NEXT_STEP autoreset, batched step, errors."""
from __future__ import annotations

import os

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import ebraille_sim  # noqa: F401  (registers the id)
from ebraille_sim.plant.layout import S
from ebraille_sim.rl.env import ENV_ID, ContactForceEnv
from ebraille_sim.rl.vector_env import ContactForceVectorEnv

SHORT = {"episode_characters": 3}        # ~1.2-1.3 s episodes, so autoresets happen in a short test


def _compare(n, steps, seed, vec_kwargs, env_kwargs, max_episode_steps=None, action_seed=0):
    """Step a vector env and n scalar envs with the same actions; return the largest difference."""
    venv = ContactForceVectorEnv(num_envs=n, max_episode_steps=max_episode_steps, **vec_kwargs, **env_kwargs)
    envs = [ContactForceEnv(**env_kwargs) for _ in range(n)]
    if max_episode_steps is not None:
        envs = [gym.wrappers.TimeLimit(e, max_episode_steps) for e in envs]
    vobs, _ = venv.reset(seed=seed)
    sobs = np.array([e.reset(seed=seed + i)[0] for i, e in enumerate(envs)])
    worst = float(np.max(np.abs(vobs - sobs)))
    rng = np.random.default_rng(action_seed)
    done = [False] * n
    ends = 0
    for _ in range(steps):
        act = rng.uniform(-0.5, 0.9, size=(n, 1)).astype(np.float32)
        vobs, vrew, vterm, vtrunc, vinfo = venv.step(act)
        for i, e in enumerate(envs):
            if done[i]:
                obs, _ = e.reset()
                rew, term, trunc = 0.0, False, False
                ends += 1
            else:
                obs, rew, term, trunc, info = e.step(act[i])
                assert abs(info["force_true_n"] - vinfo["force_true_n"][i]) <= 1e-9
            worst = max(worst, float(np.max(np.abs(obs - vobs[i]))), abs(rew - vrew[i]))
            assert (term, trunc) == (bool(vterm[i]), bool(vtrunc[i]))
            done[i] = term or trunc
    return worst, ends


def test_vector_env_equals_scalar_envs_through_autoresets():
    worst, ends = _compare(3, 600, seed=20, vec_kwargs={}, env_kwargs=SHORT)
    assert ends >= 3                                   # every sub-env went through an autoreset
    assert worst <= 1e-9


def test_vector_env_equals_scalar_envs_with_a_time_limit_and_another_rate():
    worst, ends = _compare(2, 250, seed=5, vec_kwargs={"parallel": False},
                           env_kwargs={**SHORT, "control_rate_hz": 100.0}, max_episode_steps=40)
    assert ends >= 8 and worst <= 1e-9


def test_parallel_and_serial_batches_are_identical():
    out = []
    for parallel in (True, False):
        venv = ContactForceVectorEnv(num_envs=5, parallel=parallel, **SHORT)
        venv.reset(seed=9)
        rng = np.random.default_rng(3)
        trace = [venv.step(rng.uniform(-1, 1, size=(5, 1)).astype(np.float32))[0] for _ in range(150)]
        out.append(np.array(trace))
    assert np.array_equal(out[0], out[1])


def test_make_vec_uses_the_native_vector_env_in_next_step_mode():
    envs = gym.make_vec(ENV_ID, num_envs=3)
    assert isinstance(envs.unwrapped, ContactForceVectorEnv)
    assert envs.metadata["autoreset_mode"] is AutoresetMode.NEXT_STEP
    assert envs.unwrapped.max_episode_steps == 1400
    obs, _ = envs.reset(seed=0)
    assert obs.shape == (3, 7) and obs.dtype == np.float32 and envs.observation_space.contains(obs)
    obs, rew, term, _, info = envs.step(envs.action_space.sample())
    assert rew.shape == (3,) and term.dtype == np.bool_ and info["force_true_n"].shape == (3,)
    envs.close()


def test_next_step_autoreset_returns_the_new_episode_with_zero_reward():
    venv = ContactForceVectorEnv(num_envs=2, max_episode_steps=5)
    venv.reset(seed=1)
    act = np.zeros((2, 1), np.float32)
    for k in range(5):
        obs, rew, term, trunc, _ = venv.step(act)
    assert np.all(trunc) and not np.any(term)
    ref = ContactForceEnv()
    ref.reset(seed=1)
    expect, _ = ref.reset()                            # the second episode of sub-env 0
    obs, rew, term, trunc, _ = venv.step(np.ones((2, 1), np.float32))
    assert np.array_equal(obs[0], expect)
    assert np.all(rew == 0.0) and not np.any(term | trunc)


def test_seed_sequence_and_reset_options():
    venv = ContactForceVectorEnv(num_envs=2)
    a, _ = venv.reset(seed=[7, 3])
    b = np.array([ContactForceEnv().reset(seed=s)[0] for s in (7, 3)])
    assert np.array_equal(a, b)
    venv.reset(seed=0, options={"wpm": 100.0, "setpoint_n": 0.8})
    assert all(ep.wpm == 100.0 and np.all(ep.setpoint_n == 0.8) for ep in venv.episodes)
    with pytest.raises(ValueError, match="unknown reset option 'speed'"):
        venv.reset(seed=0, options={"speed": 1})
    with pytest.raises(ValueError, match="2 seeds"):
        venv.reset(seed=[1, 2, 3])


def test_bad_arguments_and_actions_are_one_line_errors():
    with pytest.raises(ValueError, match="num_envs"):
        ContactForceVectorEnv(num_envs=0)
    with pytest.raises(ValueError, match="unknown argument 'colour'"):
        ContactForceVectorEnv(num_envs=2, colour="red")
    with pytest.raises(ValueError, match="backend"):
        ContactForceVectorEnv(num_envs=2, backend="pymunk")
    venv = ContactForceVectorEnv(num_envs=2)
    with pytest.raises(RuntimeError, match="reset"):
        venv.step(np.zeros((2, 1), np.float32))
    venv.reset(seed=0)
    with pytest.raises(ValueError, match=r"non-finite in envs \[1\]"):
        venv.step(np.array([[0.0], [np.nan]], np.float32))
    with pytest.raises(ValueError, match="shape"):
        venv.step(np.zeros((3, 1), np.float32))


def test_vector_render_gives_one_frame_per_env():
    venv = ContactForceVectorEnv(num_envs=2, render_mode="rgb_array")
    venv.reset(seed=0)
    frames = venv.render()
    assert len(frames) == 2 and frames[0].shape == (360, 720, 3)
    venv.close()


def test_parallel_argument():
    assert ContactForceVectorEnv(num_envs=1).parallel is False          # one sub-env: no choice to make
    assert ContactForceVectorEnv(num_envs=1)._choice is None
    assert ContactForceVectorEnv(num_envs=3, parallel=True).parallel is True
    assert ContactForceVectorEnv(num_envs=3, parallel=False)._choice is None
    with pytest.raises(ValueError, match="parallel must be True, False or None"):
        ContactForceVectorEnv(num_envs=3, parallel="yes")


def test_vector_episode_bound_follows_the_control_rate():
    envs = gym.make_vec(ENV_ID, num_envs=2, control_rate_hz=1000.0)
    assert envs.unwrapped.max_episode_steps == 7000                 # 7 s at 1 kHz, not 1400 steps
    envs.reset(seed=0, options={"wpm": 60.0})
    assert int(envs.unwrapped._n_steps.min()) == 7000
    envs.close()


def test_the_python_shim_step_equals_the_compiled_step():
    """The env's step through the runner's per-period shim (the Python supervisor around the
    agent's command, as on a plant without compiled rows) gives the compiled step's observations,
    rewards, episode ends and supervisor modes exactly, with the current and speed limits acting."""
    from ebraille_sim.rl.env import C_CMD_SCALE, ContactForceEnv, HeldCommand

    def force_shim(env):
        env._ws = None
        env._agent = HeldCommand(env._sup, env._c[C_CMD_SCALE])

    fast, slow = ContactForceEnv(), ContactForceEnv()
    rng = np.random.default_rng(5)
    modes = set()
    for episode in range(3):
        o1, _ = fast.reset(seed=10 + episode)
        o2, _ = slow.reset(seed=10 + episode)
        force_shim(slow)
        assert np.array_equal(o1, o2)
        for step in range(400):
            a = rng.uniform(-1.0, 1.0, size=(1,)).astype(np.float32)
            if step % 60 < 30:
                a[:] = 1.0                                    # long full pushes: current and speed limits act
            r1, r2 = fast.step(a), slow.step(a)
            for x, y in zip(r1[:4], r2[:4]):
                assert np.array_equal(x, y), (episode, step)
            assert r1[4]["supervisor_mode"] == r2[4]["supervisor_mode"]
            modes.add(r1[4]["supervisor_mode"])
            if r1[2] or r1[3]:
                break
    assert len(modes) >= 2                                    # the supervisor shaped commands
    fast.close()
    slow.close()


def test_default_threading_follows_the_timings_and_changes_no_number():
    """ThreadChoice keeps the way whose timed steps were faster and re-times the other every
    PROBE_EVERY steps; the default env, whichever way it steps, gives the one-thread numbers."""
    from ebraille_sim.rl.vector_env import PROBE_EVERY, PROBE_STEPS, ThreadChoice
    cost = {False: 2.0, True: 1.0}
    ch = ThreadChoice()
    ways = []
    for k in range(3 * PROBE_EVERY):
        if k == PROBE_EVERY + 10:
            cost[True] = 5.0                      # threads become slow (the other cores got busy)
        w = ch.pick()
        ways.append(w)
        ch.record(w, cost[w])
    assert ways[:1 + PROBE_STEPS] == [False] * (1 + PROBE_STEPS)
    assert ways[1 + PROBE_STEPS:2 + 2 * PROBE_STEPS] == [True] * (1 + PROBE_STEPS)
    assert ways[2 + 2 * PROBE_STEPS + 5] is True             # threads measured faster: kept
    assert ch.threads is False and ways[-1] is False          # the running mean saw them slow down
    assert sum(1 for w in ways[-PROBE_EVERY:] if w) <= PROBE_STEPS + 1   # only probes on threads

    a = ContactForceVectorEnv(num_envs=4, parallel=False)
    b = ContactForceVectorEnv(num_envs=4)
    oa, _ = a.reset(seed=11)
    ob, _ = b.reset(seed=11)
    rng = np.random.default_rng(0)
    used = set()
    for _ in range(300):
        act = rng.uniform(-1, 1, size=(4, 1)).astype(np.float32)
        oa, ra, ta, tra, _ = a.step(act)
        ob, rb, tb, trb, _ = b.step(act)
        used.add(bool(b.parallel))
        np.testing.assert_array_equal(oa, ob)
        np.testing.assert_array_equal(ra, rb)
    if (os.cpu_count() or 1) >= 2:
        assert b._choice is not None
