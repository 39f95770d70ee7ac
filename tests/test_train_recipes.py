"""``ebraille-sim train --recipe``: recipes, residual policies on a design, their files, and bad input."""
from __future__ import annotations

import json

import numpy as np
import pytest

import controllers
from controllers.policy import MlpActor, residual_design, save_actor
from controllers.residual import N_FRAME, ResidualPolicy
from ebraille_sim.cli import main as cli
from ebraille_sim.commands.train import RECIPES, recipe_settings
from ebraille_sim.rl.episode import EnvConfig
from ebraille_sim.rl.residual import ResidualConfig, residual_device
from ebraille_sim.scenarios.runner import design_firmware, run_scenario


def test_recipes_resolve_and_flags_override():
    s = recipe_settings("residual_ppo_1khz")
    assert (s["algo"], s["control_rate_hz"], s["residual"], s["history"]) == ("ppo", 1000.0, "dob_100hz", 4)
    s = recipe_settings("residual_ppo_1khz", residual="dob_hold_1khz", history=2)
    assert (s["residual"], s["history"]) == ("dob_hold_1khz", 2)
    assert recipe_settings()["recipe"] == "ppo_200hz" and recipe_settings(algo="sac")["recipe"] == "sac_200hz"
    assert recipe_settings(control_rate_hz=500.0)["control_rate_hz"] == 500.0
    assert all(r["description"] for r in RECIPES.values())


@pytest.mark.parametrize("kwargs, named", [({"recipe": "nope"}, "unknown recipe 'nope'"),
                                           ({"algo": "dqn"}, "unknown algorithm 'dqn'"),
                                           ({"residual": "no_such_design"}, "unknown design 'no_such_design'"),
                                           ({"history": 3}, "--history 3")])
def test_bad_recipe_settings_are_one_line_errors(kwargs, named):
    with pytest.raises(ValueError, match=named) as exc:
        recipe_settings(**kwargs)
    assert "\n" not in str(exc.value)


@pytest.mark.parametrize("argv, named", [(["--recipe", "nope"], "--recipe"),
                                         (["--residual", "no_such_design"], "--residual"),
                                         (["--history", "0"], "--history"),
                                         (["--history", "2"], "--history"),
                                         (["--steps", "0"], "--steps")])
def test_bad_train_arguments_exit_2_with_one_line_before_training(argv, named, tmp_path, monkeypatch, capsys):
    def no_work(*a, **k):
        raise AssertionError("training started although an argument is bad")
    monkeypatch.setattr("ebraille_sim.commands.train.train", no_work)
    code = cli(["train", "--out", str(tmp_path / "out")] + argv)
    err = capsys.readouterr().err.splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith("error: ") and named in err[0], err
    assert not (tmp_path / "out").exists()


def _zero_residual_policy(folder, design="dob_100hz", history=2):
    """A residual policy file whose actor outputs exactly zero."""
    cfg = EnvConfig(control_rate_hz=1000.0, base_device=residual_device(design))
    rc = ResidualConfig(residual=design, history=history)
    folder.mkdir(parents=True, exist_ok=True)
    w = [np.ones((4, history * N_FRAME), np.float32), np.zeros((1, 4), np.float32)]
    save_actor(MlpActor(w, [np.zeros(4, np.float32), np.zeros(1, np.float32)], "tanh", False), folder / "policy.npz")
    meta = {"format": "ebraille-sim-policy/1", "algo": "ppo", "env_id": "EBraille/ContactForceResidual-v0",
            "env": {**cfg.policy_metadata(), **rc.metadata()}, "training": {}}
    (folder / "policy.json").write_text(json.dumps(meta), encoding="utf-8")
    return f"policy:{folder}"


def test_a_residual_policy_runs_on_its_designs_firmware_and_zero_is_the_design(tmp_path):
    name = _zero_residual_policy(tmp_path / "zero")
    assert residual_design(str(tmp_path / "zero")) == "dob_100hz"
    assert design_firmware(name) == "paper_100hz"
    assert design_firmware("policy:ppo") is None
    ctrl = controllers.make(name)
    assert isinstance(ctrl, ResidualPolicy) and ctrl.history == 2 and ctrl.limit_v == 1.0
    a = run_scenario("pressing_90wpm", controller=name, duration_s=2.0)
    b = run_scenario("pressing_90wpm", controller="dob_100hz", duration_s=2.0)
    assert np.array_equal(a.trace["force_true_n"], b.trace["force_true_n"])
    assert np.array_equal(a.trace["command_v"], b.trace["command_v"])


def test_residual_training_is_reproducible_and_records_its_curve(tmp_path):
    pytest.importorskip("stable_baselines3")
    from ebraille_sim.commands.train import train
    settings = recipe_settings("residual_ppo_1khz", history=2)
    settings["hyperparameters"] = {**settings["hyperparameters"], "n_steps": 256, "batch_size": 128, "n_epochs": 2}
    recs = [train("ppo", 512, tmp_path / f"p{i}", n_envs=1, recipe=settings) for i in range(2)]
    w = [np.load(tmp_path / f"p{i}" / "policy.npz") for i in range(2)]
    assert all(np.array_equal(w[0][k], w[1][k]) for k in w[0].files)
    assert recs[0]["recipe"] == "residual_ppo_1khz" and recs[0]["curriculum"]["steps_per_env"] == 256
    meta = json.loads((tmp_path / "p0" / "policy.json").read_text())
    assert meta["env"]["residual"] == "dob_100hz" and meta["env"]["history"] == 2
    assert meta["env"]["control_rate_hz"] == 1000.0
    assert isinstance(controllers.make(f"policy:{tmp_path / 'p0'}"), ResidualPolicy)


def test_select_recipe_starts_at_the_design_and_keeps_the_best_validation_score(tmp_path):
    """The selecting recipe's step 0 is its design on the validation readers (the action head
    zero), every checkpoint is scored there, and the policy written is the best of them, the
    design on a tie."""
    pytest.importorskip("stable_baselines3")
    from ebraille_sim.commands.train import train, validation_score
    from ebraille_sim.tools.benchmark import run_benchmark, summarise
    settings = recipe_settings("residual_ppo_select_1khz", history=2)
    assert settings["zero_start"] and settings["validation"]["readers"] >= 16
    settings["hyperparameters"] = {**settings["hyperparameters"], "n_steps": 256, "batch_size": 128, "n_epochs": 2,
                                   "learning_rate": 3e-3}
    val = {"suite": "quick", "readers": 2, "seed": 7001, "checkpoints": 2}
    settings["validation"] = val
    rec = train("ppo", 1024, tmp_path / "sel", n_envs=2, recipe=settings)
    v = rec["validation"]
    steps = [c["steps"] for c in v["checkpoints"]]
    assert steps[0] == 0 and steps[-1] == rec["steps"] and len(steps) >= 3
    design = summarise(run_benchmark(["dob_100hz"], suite="quick", readers=2, bounds=False, population_seed=7001))
    assert v["design_score"] == round(design["dob_100hz"]["score"], 3)
    scores = [c["score"] for c in v["checkpoints"]]
    assert v["chosen_score"] == max(scores) and scores[steps.index(v["chosen_steps"])] == max(scores)
    assert steps.index(v["chosen_steps"]) == scores.index(max(scores))        # the first best: the design on a tie
    assert validation_score(tmp_path / "sel", val)["score"] == pytest.approx(v["chosen_score"], abs=1e-3)
    assert len(set(scores)) > 1                                                # training moved the policy
