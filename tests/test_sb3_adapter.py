"""The Stable-Baselines3 adapter of the native vector env, and SB3-saved policies as controllers.

The adapter's step semantics and the metadata are tested without SB3; the tests that train
need the ``rl`` extra and are skipped without it.
"""
from __future__ import annotations

import dataclasses
import json
import subprocess
import sys

import numpy as np
import pytest

import controllers
from controllers.policy import POLICY_FORMAT, load_policy, read_metadata
from ebraille_sim.physics.params import EstimatorParams
from ebraille_sim.rl.sb3 import VecEnvAdapter, policy_metadata, write_policy_metadata
from ebraille_sim.rl.vector_env import ContactForceVectorEnv

SHORT = {"episode_characters": 3}      # short episodes; max_episode_steps below ends them sooner still
N, LIMIT, SEED = 3, 12, 5


def _action(i, k):
    """Row ``i``'s action at its ``k``-th physics step of the run (independent of restarts)."""
    return np.float32(0.8 * np.sin(0.7 * k + 1.3 * i))


def _native_events(steps):
    """Per row: ('step', obs, reward, terminated, truncated) and ('reset', obs) of the native env."""
    venv = ContactForceVectorEnv(num_envs=N, max_episode_steps=LIMIT, **SHORT)
    obs, _ = venv.reset(seed=SEED)
    events = [[("reset", obs[i])] for i in range(N)]
    count = [0] * N
    pending = [False] * N
    for _ in range(steps):
        act = np.array([[_action(i, count[i])] for i in range(N)], dtype=np.float32)
        obs, rew, term, trunc, _ = venv.step(act)
        for i in range(N):
            if pending[i]:                              # NEXT_STEP autoreset: action ignored
                events[i].append(("reset", obs[i]))
                pending[i] = False
            else:
                events[i].append(("step", obs[i], float(rew[i]), bool(term[i]), bool(trunc[i])))
                count[i] += 1
                pending[i] = bool(term[i] or trunc[i])
    return events


def _adapter_events(steps):
    """The same events seen through the adapter (terminal observation from ``infos``)."""
    envs = VecEnvAdapter(ContactForceVectorEnv(num_envs=N, max_episode_steps=LIMIT, **SHORT))
    assert envs.seed(SEED) == [SEED, SEED + 1, SEED + 2]
    obs = envs.reset()
    events = [[("reset", obs[i])] for i in range(N)]
    for k in range(steps):
        act = np.array([[_action(i, k)] for i in range(N)], dtype=np.float32)
        obs, rew, done, infos = envs.step(act)
        assert rew.dtype == np.float32 and done.dtype == np.bool_ and len(infos) == N
        for i in range(N):
            info = infos[i]
            if done[i]:
                trunc = info["TimeLimit.truncated"]
                events[i].append(("step", info["terminal_observation"], float(rew[i]), not trunc, trunc))
                events[i].append(("reset", obs[i]))
            else:
                assert "terminal_observation" not in info and not info["TimeLimit.truncated"]
                events[i].append(("step", obs[i], float(rew[i]), False, False))
    return events


def test_adapter_steps_the_native_env_with_same_step_autoreset():
    """Same seed: every row sees the native env's observations, rewards, ends and next
    episodes; the adapter restarts in the step that ends (no action is lost)."""
    steps = 3 * LIMIT + 2
    native = _native_events(steps + 3)
    adapted = _adapter_events(steps)
    ends = 0
    for i in range(N):
        n = len(adapted[i])
        assert len(native[i]) >= n
        for a, b in zip(adapted[i], native[i][:n]):
            assert a[0] == b[0]
            assert np.array_equal(a[1], b[1])                   # observation, exactly
            if a[0] == "step":
                assert a[2] == pytest.approx(b[2], rel=1e-6, abs=1e-6)  # float32 reward
                assert a[3:] == b[3:]
        ends += sum(1 for e in adapted[i] if e[0] == "reset") - 1
        assert sum(1 for e in adapted[i] if e[0] == "step") == steps      # every step is a physics step
    assert ends == N * 3                                                 # truncated after LIMIT steps, 3 times


def test_adapter_interface_and_errors():
    venv = ContactForceVectorEnv(num_envs=2, **SHORT)
    envs = VecEnvAdapter(venv)
    assert envs.observation_space.shape == (7,) and envs.action_space.shape == (1,)
    assert envs.num_envs == 2 and envs.render_mode is None
    envs.set_options({"setpoint_n": 0.8, "disturbances": False})
    obs = envs.reset()
    assert obs.shape == (2, 7)
    assert [ep.setpoint_n[0] for ep in envs.get_attr("episode")] == [0.8, 0.8]
    assert envs.get_attr("max_episode_steps", indices=[1]) == [venv.max_episode_steps]
    assert envs.has_attr("config") and not envs.has_attr("no_such_attribute")
    assert envs.env_is_wrapped(object) == [False, False]
    assert envs.env_method("__repr__") == [repr(venv)] * 2
    envs.set_attr("max_episode_steps", 7)
    assert venv.max_episode_steps == 7
    with pytest.raises(ValueError, match="all 2 sub-envs share"):
        envs.set_attr("max_episode_steps", 7, indices=[0])
    with pytest.raises(ValueError, match="one set of reset options"):
        envs.set_options([{"wpm": 60.0}, {"wpm": 90.0}])
        envs.reset()
    with pytest.raises(RuntimeError, match="step_async"):
        envs.step_wait()
    with pytest.raises(ValueError, match="unwrapped ContactForceVectorEnv"):
        VecEnvAdapter(object())
    with pytest.raises(ValueError, match="out of range"):
        venv.reset_rows([2])


def test_metadata_for_a_plain_sb3_zip_and_the_missing_file_error(tmp_path):
    venv = ContactForceVectorEnv(num_envs=1, control_rate_hz=500.0, **SHORT)
    zip_path = tmp_path / "ppo.zip"
    zip_path.write_bytes(b"not read before the metadata")
    with pytest.raises(ValueError, match=r"has no metadata .*ppo\.json.*write_policy_metadata"):
        controllers.make(f"policy:{zip_path}")
    with pytest.raises(ValueError, match=r"has no metadata .*ppo\.json"):
        load_policy(tmp_path / "ppo")                       # the name given to model.save
    written = write_policy_metadata(tmp_path / "ppo", "ppo", VecEnvAdapter(venv))
    assert written == str(tmp_path / "ppo.json")
    meta = read_metadata(written)
    assert meta["format"] == POLICY_FORMAT and meta["algo"] == "ppo"
    assert meta["env"] == venv.config.policy_metadata() and meta["env"]["control_rate_hz"] == 500.0
    assert policy_metadata("SAC", {"control_rate_hz": 500.0})["env"] == meta["env"]   # kwargs give the same
    assert json.loads((tmp_path / "ppo.json").read_text())["training"] == {
        "source": "stable-baselines3", "estimator": json.loads(json.dumps(dataclasses.asdict(EstimatorParams())))}
    with pytest.raises(ValueError, match="algorithm must be one of ppo, sac"):
        policy_metadata("dqn", venv)
    with pytest.raises(ValueError, match="cannot find the env configuration"):
        policy_metadata("ppo", object())


def test_importing_the_adapter_does_not_import_sb3_or_torch():
    code = ("import sys, ebraille_sim.rl.sb3; "
            "print(any(m in sys.modules for m in ('torch', 'stable_baselines3')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_ppo_learns_on_the_adapter_and_runs_as_a_scenario_controller(tmp_path):
    pytest.importorskip("stable_baselines3")
    import gymnasium as gym
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecEnv

    import ebraille_sim  # noqa: F401  (registers the id)
    from ebraille_sim.rl.sb3 import to_sb3
    from ebraille_sim.scenarios.runner import run_scenario

    native = gym.make_vec("EBraille/ContactForce-v0", num_envs=2, vectorization_mode="vector_entry_point",
                          max_episode_steps=40, **SHORT)
    envs = to_sb3(native, seed=0)
    assert isinstance(envs, VecEnv) and isinstance(envs.unwrapped, VecEnvAdapter)
    model = PPO("MlpPolicy", envs, n_steps=64, batch_size=64, n_epochs=2, seed=0, device="cpu")
    before = [p.detach().clone() for p in model.policy.parameters()]
    model.learn(total_timesteps=256)
    assert model.num_timesteps == 256
    assert any(not np.array_equal(a.numpy(), b.detach().numpy()) for a, b in zip(before, model.policy.parameters()))
    lengths = [ep["l"] for ep in model.ep_info_buffer]
    assert lengths == [40] * 6                 # 128 steps per env: 3 episodes truncated at 40 steps each

    model.save(tmp_path / "ppo")
    write_policy_metadata(tmp_path / "ppo.zip", model, envs)
    ctrl = controllers.make(f"policy:{tmp_path / 'ppo.zip'}")
    assert ctrl.period_s == pytest.approx(0.005)
    obs = envs.reset()
    # the controller runs the NumPy actor (policy.npz), equal to SB3's predict to float32 rounding
    np.testing.assert_allclose(ctrl.model.predict(obs[0], deterministic=True)[0],
                               model.predict(obs[0], deterministic=True)[0], rtol=0, atol=1e-5)
    res = run_scenario("contact_onset", controller=f"policy:{tmp_path / 'ppo.zip'}", duration_s=0.3)
    assert res.controller_name == "policy" and np.all(np.isfinite(res.trace["command_v"]))
    assert np.all(np.abs(res.trace["command_v"]) <= 6.0)
    envs.close()


def test_train_reports_progress_to_the_steps_actually_taken(tmp_path):
    pytest.importorskip("stable_baselines3")
    from ebraille_sim.commands.train import train
    calls = []
    rec = train("ppo", 512, tmp_path / "p", n_envs=1, progress=lambda done, total: calls.append((done, total)))
    dones = [d for d, _ in calls]
    assert dones == sorted(dones) and len(calls) >= 10
    assert calls[-1] == (rec["steps"], rec["steps"]) == (1024, 1024)      # one whole PPO rollout of 1024
    assert all(total == 1024 for _, total in calls)
