"""``ebraille-sim train --estimator``: the firmware variant a policy trains on, and its record.

The settings are parsed as ``benchmark --estimator`` parses them, become the estimator of the
env's base device (and so of every device drawn around it), and are written into
``policy.json``'s training record; files without the record load as before.
"""
from __future__ import annotations

import dataclasses
import json
import pathlib

import gymnasium as gym
import pytest

import controllers
from controllers.policy import read_metadata
from ebraille_sim.cli import main as cli
from ebraille_sim.physics.params import DeviceParams, EstimatorParams
from ebraille_sim.rl.env import ENV_ID, EnvConfig, register_envs
from ebraille_sim.rl.sb3 import policy_metadata


def _compensated() -> DeviceParams:
    d = DeviceParams()
    return dataclasses.replace(d, estimator=dataclasses.replace(d.estimator, hysteresis_compensation=True))


@pytest.mark.parametrize("setting, named", [("nope=1", "'nope'"),
                                            ("hysteresis_compensation", "'hysteresis_compensation'")])
def test_a_bad_setting_is_a_one_line_error_naming_it_before_training(setting, named, tmp_path, monkeypatch,
                                                                     capsys):
    def no_work(*a, **k):
        raise AssertionError("training started although --estimator is bad")
    monkeypatch.setattr("ebraille_sim.commands.train.train", no_work)
    code = cli(["train", "--steps", "10", "--estimator", "hysteresis_compensation=true",
                "--estimator", setting, "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.splitlines()
    assert code == 2 and len(err) == 1
    assert err[0].startswith("error: --estimator: ") and named in err[0], err
    assert ("unknown key" if "=" in setting else "must be KEY=VALUE") in err[0]
    assert not (tmp_path / "out").exists()


def test_train_builds_the_env_around_a_device_with_the_settings(tmp_path, monkeypatch):
    """``train`` hands SB3 a base device carrying the settings, and every drawn device keeps
    them; without settings the env's arguments are what they were (the nominal base device)."""
    pytest.importorskip("stable_baselines3")
    import stable_baselines3.common.env_util as env_util

    from ebraille_sim.commands.train import train
    seen = []

    class Stop(Exception):
        pass

    def fake_make_vec_env(env_id, n_envs, seed, env_kwargs):
        seen.append((env_id, dict(env_kwargs)))
        raise Stop
    monkeypatch.setattr(env_util, "make_vec_env", fake_make_vec_env)
    for estimator in (["hysteresis_compensation=true", "hysteresis_deadband_lsb=2"], None):
        with pytest.raises(Stop):
            train("ppo", 1024, tmp_path / "p", n_envs=1, estimator=estimator)
    (env_id, kwargs), (_, default_kwargs) = seen
    assert env_id == ENV_ID and "base_device" not in default_kwargs
    assert kwargs["base_device"].estimator == dataclasses.replace(
        EstimatorParams(), hysteresis_compensation=True, hysteresis_deadband_lsb=2.0)
    register_envs()
    env = gym.make(env_id, **kwargs)
    devices = []
    for seed in range(4):
        env.reset(seed=seed)
        devices.append(env.unwrapped.episode.device)
    # the settings are kept on every drawn device; its unit's bench calibration is its own
    assert all(d.estimator.hysteresis_compensation and d.estimator.hysteresis_deadband_lsb == 2.0 for d in devices)
    assert len({d.fsr for d in devices}) == 4                 # drawn devices, the estimator kept
    default = gym.make(env_id, **default_kwargs)
    default.reset(seed=0)
    dev = default.unwrapped.episode.device
    assert not dev.estimator.hysteresis_compensation and dev.fsr == devices[0].fsr
    assert dev.estimator.hysteresis_deadband_lsb == EstimatorParams().hysteresis_deadband_lsb
    assert dev.estimator.calibration_readings_n == devices[0].estimator.calibration_readings_n


def test_metadata_records_the_estimator_and_loads():
    """``policy_metadata`` records every estimator field of the base device under ``training``."""
    assert policy_metadata("ppo", {})["training"]["estimator"] == dataclasses.asdict(EstimatorParams())
    meta = policy_metadata("ppo", EnvConfig(base_device=_compensated()))
    assert meta["training"]["estimator"]["hysteresis_compensation"] is True
    assert meta["env"] == EnvConfig().policy_metadata()       # the observation does not depend on it
    json.dumps(meta)


def test_trained_policy_records_the_estimator_and_loads(tmp_path):
    pytest.importorskip("stable_baselines3")
    from ebraille_sim.commands.train import train
    rec = train("ppo", 1024, tmp_path, n_envs=1, estimator={"hysteresis_compensation": True})
    assert rec["estimator"] == dataclasses.asdict(_compensated().estimator)
    meta = read_metadata(str(tmp_path / "policy.json"))
    assert meta["training"]["estimator"]["hysteresis_compensation"] is True
    assert controllers.make(f"policy:{tmp_path}").name == "policy"


def test_shipped_policies_record_their_firmware_or_load_without_the_record():
    """The policy trained on the hysteresis-compensated estimator says so (fields added to the
    estimator since, at their defaults, are not in its record); the earlier ones, written before
    the record existed (the default estimator), load as before."""
    from controllers.policy import shipped_policies
    shipped = shipped_policies()
    hc = read_metadata(str(pathlib.Path(shipped["ppo_hc"]) / "policy.json"))
    now = dataclasses.asdict(_compensated().estimator)
    rec = hc["training"]["estimator"]
    assert set(rec) <= set(now) and rec == {k: now[k] for k in rec}
    assert {k: now[k] for k in set(now) - set(rec)} == {k: getattr(EstimatorParams(), k) for k in set(now) - set(rec)}
    assert set(now) - set(rec) == {"hysteresis_turn_lsb", "hysteresis_follow_lsb", "hysteresis_turn_time_s",
                                   "hysteresis_centre_time_s",
                                   "creep_per_decade", "calibration_loads_n", "calibration_readings_n"}
    for name in ("ppo", "sac"):
        meta = read_metadata(str(pathlib.Path(shipped[name]) / "policy.json"))
        assert "estimator" not in meta["training"]
        assert controllers.make(f"policy:{name}").name == "policy"
    assert controllers.make("policy:ppo_hc").name == "policy"
