"""The learned-policy controller: same observation as the env, lazy imports, loading, errors."""
from __future__ import annotations

import dataclasses
import json
import pathlib
import subprocess
import sys

import numpy as np
import pytest

import controllers
from controllers.features import N_OBS, Z_PREV_ACTION
from controllers.policy import POLICY_FORMAT, PolicyController, load_policy, read_metadata
from ebraille_sim.rl.env import ContactForceEnv, EnvConfig
from ebraille_sim.plant.layout import S
from ebraille_sim.plant.lumped import Plant
from ebraille_sim.physics.params import DeviceParams, RateParams


class LinearPolicy:
    """A fixed policy of the observation, standing in for a trained network."""

    def predict(self, obs, deterministic=True):
        a = 0.2 + 1.5 * obs[2] + 0.4 * obs[4] - 0.3 * obs[3] + 0.1 * obs[6] - 0.2 * obs[5]
        return np.array([a], dtype=np.float32), None


def test_importing_controllers_does_not_import_torch_or_sb3():
    code = ("import sys, controllers, ebraille_sim; "
            "print(any(m in sys.modules for m in ('torch', 'stable_baselines3')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def _env_episode(policy, safety: bool, steps: int, **options):
    """``policy`` in the nominal 200 Hz env from a 1 mm gap at 0.7 N: the episode, and the true
    forces, actions and applied commands (V) of ``steps`` steps."""
    env = ContactForceEnv(randomize_device=False, safety=safety)
    obs, _ = env.reset(seed=5, options={"disturbances": False, "gap_m": 1e-3, "setpoint_n": 0.7, **options})
    forces, actions, applied = [], [], []
    for _ in range(steps):
        a = float(np.clip(policy.predict(obs)[0][0], -1, 1))
        obs, _, term, trunc, info = env.step(np.array([a], np.float32))
        forces.append(info["force_true_n"])
        actions.append(a)
        applied.append(info["command_v"])
        assert not (term or trunc)
    return env.episode, forces, actions, applied


def test_policy_in_a_1khz_loop_matches_the_200hz_env_exactly():
    """The controller rebuilds the env's observation: same actions, same forces (to 1e-9)."""
    policy = LinearPolicy()
    ep, env_forces, env_actions, _ = _env_episode(policy, False, 500, setpoint_steps=[(1.5, 1.2)])   # 2.5 s

    dev = DeviceParams(rates=RateParams(control_rate_hz=1000.0))
    plant = Plant.from_devices([dev], [ep.sensor_seed])
    plant.set_finger(1e-3)
    ctrl = PolicyController(policy, EnvConfig().policy_metadata())
    st = plant.state[0]
    ctrl.reset(force_est_n=float(st[S.force_est_n]), setpoint_n=0.7)
    loop_forces, loop_commands = [], []
    for k in range(2500):
        sp = ep.setpoint_n[k // 5]
        u = ctrl.update(float(st[S.force_est_n]), sp, 1e-3, float(st[S.current_meas_a]))
        plant.advance(u)
        if k % 5 == 0:
            loop_commands.append(u)
        if k % 5 == 4:
            loop_forces.append(float(st[S.contact_force_n]))
    assert np.max(np.abs(np.array(loop_commands) / 6.0 - env_actions)) <= 1e-9
    assert np.max(np.abs(np.array(loop_forces) - env_forces)) <= 1e-9
    assert max(env_forces) > 0.5                                  # the policy did press


def test_supervised_policy_sees_the_applied_command_as_in_the_env_safety_layer():
    """With the safety layer on, the env shows the policy the supervised (applied) command as its
    previous action; a PolicyController inside the scenario's Supervisor, at the env's 200 Hz,
    is told that command every period and so acts and presses exactly as in the env."""
    from controllers.supervisor import Supervisor, SupervisorConfig
    policy = LinearPolicy()
    ep, env_forces, _, env_applied = _env_episode(policy, True, 400)                                    # 2 s
    dev = DeviceParams(rates=RateParams(control_rate_hz=200.0))
    plant = Plant.from_devices([dev], [ep.sensor_seed])
    plant.set_finger(1e-3)
    inner = PolicyController(policy, EnvConfig().policy_metadata())
    ctrl = Supervisor(inner, SupervisorConfig.for_device(dev))
    st = plant.state[0]
    ctrl.reset(force_est_n=float(st[S.force_est_n]), setpoint_n=0.7)
    loop_forces, loop_applied = [], []
    for k in range(400):
        u = ctrl.update(float(st[S.force_est_n]), ep.setpoint_n[k], 5e-3, float(st[S.current_meas_a]))
        assert inner._z[Z_PREV_ACTION] == pytest.approx(max(-1.0, min(1.0, u / 6.0)), abs=1e-15)
        plant.advance(u)
        loop_applied.append(u)
        loop_forces.append(float(st[S.contact_force_n]))
    assert np.max(np.abs(np.array(loop_applied) - env_applied)) <= 1e-9
    assert np.max(np.abs(np.array(loop_forces) - env_forces)) <= 1e-9
    assert max(env_forces) > 0.5


def test_policy_controller_holds_between_evaluations_and_validates_inputs():
    ctrl = PolicyController(LinearPolicy(), EnvConfig().policy_metadata())
    ctrl.reset(force_est_n=0.0, setpoint_n=1.0)
    u0 = ctrl.update(0.0, 1.0, 1e-3, 0.0)
    assert [ctrl.update(0.5, 1.0, 1e-3, 0.0) for _ in range(4)] == [u0] * 4
    assert ctrl.update(0.5, 1.0, 1e-3, 0.0) != u0                # 5 ms later: a new evaluation
    with pytest.raises(ValueError, match="dt_s"):
        ctrl.update(0.5, 1.0, 0.0)
    with pytest.raises(ValueError, match="force_est_n"):
        ctrl.update(float("nan"), 1.0, 1e-3)


def _write_meta(folder, **changes):
    meta = {"format": POLICY_FORMAT, "algo": "ppo", "env_id": "EBraille/ContactForce-v0",
            "env": EnvConfig().policy_metadata(), "training": {}}
    meta.update(changes)
    (folder / "policy.json").write_text(json.dumps(meta))
    return folder / "policy.json"


def test_bad_policy_paths_and_metadata_are_one_line_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="policy file not found"):
        controllers.make(f"policy:{tmp_path}")
    with pytest.raises(ValueError, match="must be a folder"):
        controllers.make("policy:missing.txt")
    with pytest.raises(ValueError, match="unknown key 'colour'"):
        read_metadata(_write_meta(tmp_path, colour=1))
    with pytest.raises(ValueError, match="algo must be one of ppo, sac"):
        read_metadata(_write_meta(tmp_path, algo="dqn"))
    with pytest.raises(ValueError, match="unknown option 'gain'"):
        load_policy(tmp_path, gain=2)


def test_policy_metadata_carries_a_non_default_current_scale(tmp_path):
    """A base device with a 15 ohm winding: the controller built from the saved metadata
    shows the policy the current the env showed (obs[6] = I / (6 V / 15 ohm))."""
    motor = dataclasses.replace(DeviceParams().motor, resistance_ohm=15.0)
    dev = DeviceParams(motor=motor)
    env = ContactForceEnv(randomize_device=False, base_device=dev)
    env.reset(seed=3, options={"disturbances": False, "gap_m": 0.0, "setpoint_n": 0.7})
    for _ in range(3):
        obs, *_ = env.step(np.array([0.5], np.float32))
    st = env.plant.state[0]
    current_a = float(st[S.current_meas_a])
    assert abs(current_a) > 0.01 and obs[6] == pytest.approx(current_a / (6.0 / 15.0), rel=1e-6)

    meta = read_metadata(_write_meta(tmp_path, env=env.config.policy_metadata()))
    assert meta["env"]["current_scale_a"] == pytest.approx(0.4)
    ctrl = PolicyController(LinearPolicy(), meta["env"])
    ctrl.reset(force_est_n=float(st[S.force_est_n]), setpoint_n=0.7)
    ctrl.update(float(st[S.force_est_n]), 0.7, 5e-3, current_a)
    assert ctrl.last_observation[6] == obs[6]

    older = {k: v for k, v in meta["env"].items() if k != "current_scale_a"}
    assert read_metadata(_write_meta(tmp_path, env=older))["env"] == older   # the key is optional
    nominal = PolicyController(LinearPolicy(), older)
    nominal.reset(force_est_n=0.0, setpoint_n=0.7)
    nominal.update(0.0, 0.7, 5e-3, current_a)
    assert nominal.last_observation[6] == pytest.approx(current_a / (6.0 / 21.2), rel=1e-6)
    with pytest.raises(ValueError, match="current_scale_a"):
        read_metadata(_write_meta(tmp_path, env={**older, "current_scale_a": -1.0}))


def test_trained_policy_loads_and_runs_a_scenario(tmp_path):
    pytest.importorskip("stable_baselines3")
    from ebraille_sim.commands.train import train
    from ebraille_sim.scenarios.runner import run_scenario
    rec = train("ppo", 1024, tmp_path, seed=0, n_envs=1)
    assert rec["steps"] >= 1024 and rec["wall_time_s"] > 0
    assert (tmp_path / "policy.npz").is_file()
    from controllers.policy import MlpActor
    assert isinstance(controllers.make(f"policy:{tmp_path}").model, MlpActor)
    assert not isinstance(controllers.make(f"policy:{tmp_path}", deterministic=False).model, MlpActor)
    ctrl = controllers.make(f"policy:{tmp_path}")
    assert ctrl.name == "policy" and ctrl.period_s == pytest.approx(0.005)
    env = ContactForceEnv()
    obs, _ = env.reset(seed=0)
    expect = ctrl.model.predict(obs, deterministic=True)[0]
    again = controllers.make(f"policy:{tmp_path / 'policy.zip'}").model.predict(obs, deterministic=True)[0]
    assert np.array_equal(expect, again)
    res = run_scenario("contact_onset", controller=f"policy:{tmp_path}", duration_s=0.3)
    assert res.controller_name == "policy" and np.all(np.isfinite(res.trace["command_v"]))
    assert np.all(np.abs(res.trace["command_v"]) <= 6.0)


def test_shipped_learned_policies_run_by_name_from_numpy_without_pytorch(tmp_path):
    """The shipped PPO and SAC actors (package data) load by name as NumPy MLPs (no PyTorch, no
    SB3), from any folder, and hold a supervised steady reading in band."""
    code = ("import sys, controllers\n"
            "from ebraille_sim.scenarios.runner import run_scenario\n"
            "for name in ('ppo', 'sac'):\n"
            "    r = run_scenario('steady_90wpm', controller='policy:' + name, duration_s=4.0)\n"
            "    print(name, r.metrics['in_band_fraction'])\n"
            "print(any(m in sys.modules for m in ('torch', 'stable_baselines3')))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         cwd=tmp_path).stdout.split()
    assert out[-1] == "False"
    assert float(out[1]) > 0.8 and float(out[3]) > 0.8


def test_a_shipped_policy_name_gives_way_to_a_path_and_runs_deterministic_only(tmp_path, monkeypatch):
    from controllers.policy import policy_folder, shipped_policies
    shipped = shipped_policies()
    assert sorted(shipped) == ["ppo", "ppo_hc", "sac"]
    for folder in shipped.values():
        assert {p.name for p in pathlib.Path(folder).iterdir()} >= {"policy.json", "policy.npz"}
    monkeypatch.chdir(tmp_path)
    assert policy_folder("ppo") == shipped["ppo"]
    assert controllers.make("policy:ppo").model.weights[0].shape[1] == N_OBS
    (tmp_path / "ppo").mkdir()                                # a folder of that name wins: its files are read
    with pytest.raises(FileNotFoundError, match="policy file not found"):
        controllers.make("policy:ppo")
    assert policy_folder("ppo") == "ppo" and policy_folder("not_shipped") == "not_shipped"
    with pytest.raises(ValueError, match="shipped policy"):
        controllers.make("policy:not_shipped")
    with pytest.raises(ValueError, match="only its deterministic actor"):
        controllers.make(f"policy:{shipped['sac']}", deterministic=False)


def test_numpy_actor_equals_sb3_predict_and_bad_files_are_one_line(tmp_path):
    from controllers.policy import MlpActor, load_actor, save_actor
    rng = np.random.default_rng(0)
    actor = MlpActor([rng.normal(size=(8, 7)), rng.normal(size=(1, 8))], [rng.normal(size=8), rng.normal(size=1)],
                     "relu", True)
    p = save_actor(actor, tmp_path / "a.npz")
    again = load_actor(p)
    obs = rng.normal(size=7).astype(np.float32)
    h = np.maximum(actor.weights[0] @ obs + actor.biases[0], 0.0)
    assert again.predict(obs)[0][0] == pytest.approx(np.tanh(actor.weights[1] @ h + actor.biases[1])[0], abs=1e-6)
    with pytest.raises(ValueError, match="deterministic action only"):
        again.predict(obs, deterministic=False)
    (tmp_path / "bad.npz").write_bytes(b"not a zip")
    with pytest.raises(ValueError, match="bad.npz") as exc:
        load_actor(tmp_path / "bad.npz")
    assert "\n" not in str(exc.value)
    with pytest.raises(ValueError, match="do not chain"):
        MlpActor([np.ones((4, 7)), np.ones((1, 5))], [np.ones(4), np.ones(1)], "tanh", False)
    sb3 = pytest.importorskip("stable_baselines3")
    from controllers.policy import actor_from_sb3
    env = ContactForceEnv()
    obs_all = rng.uniform(env.observation_space.low, env.observation_space.high, size=(500, 7)).astype(np.float32)
    for cls in (sb3.PPO, sb3.SAC):
        model = cls("MlpPolicy", env, seed=0, device="cpu")
        a = actor_from_sb3(model)
        ref = model.predict(obs_all, deterministic=True)[0].reshape(-1)
        got = np.array([a.predict(o)[0][0] for o in obs_all])
        assert np.max(np.abs(ref - got)) <= 1e-5


def test_a_learned_policy_runs_on_the_estimator_it_was_trained_on():
    """A policy of the whole command met the env's estimator in training; a scenario runs it on
    that estimator (the unit keeping its bench's table), not on the scenario's default firmware:
    ``ppo`` on the paper's 100 Hz path, ``ppo_hc`` on it with the hysteresis compensation (its
    metadata records it)."""
    from ebraille_sim.physics.params import EstimatorParams
    from ebraille_sim.scenarios.runner import prepare_run
    from ebraille_sim.scenarios.spec import load_scenario
    base = load_scenario("steady_90wpm").device.estimator
    assert base.model == "paper:wiener:5@1000"                       # the scenario's default firmware
    for name, comp in (("ppo", False), ("ppo_hc", True)):
        est = prepare_run("steady_90wpm", controller=f"policy:{name}")[0].device.estimator
        assert est.model == EstimatorParams().model == "paper:wiener:5" and est.antialias_cutoff_hz == 20.0
        assert est.hysteresis_compensation is comp and est.hysteresis_centre_time_s == 0.0
        assert est.calibration_loads_n == base.calibration_loads_n != ()   # the unit's own table


def test_run_says_on_which_estimator_a_policy_runs(tmp_path, capsys):
    from ebraille_sim.cli import main as cli
    cli(["run", "steady_90wpm", "--controller", "policy:ppo", "--duration", "2", "--no-plot",
         "--out", str(tmp_path / "r")])
    assert "estimator paper:wiener:5 as the policy was trained on" in capsys.readouterr().out
