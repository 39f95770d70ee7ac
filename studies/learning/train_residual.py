"""Train a residual policy with a recipe of ``ebraille-sim train`` and keep checkpoints on the way.

    python studies/learning/train_residual.py --recipe residual_ppo_1khz --steps 2000000 \
        --out studies/learning/runs/residual_ppo_1khz --every 250000

Writes the final policy into ``OUT`` (as ``ebraille-sim train --out OUT`` does) and, every
``--every`` steps, a policy folder ``OUT/checkpoints/STEPS`` (``policy.npz`` + ``policy.json``)
that ``--controller policy:FOLDER`` and ``ebraille-sim benchmark`` accept, so that the learning
curve can be drawn against held-out benchmark scores (``evaluate_checkpoints.py``).
"""
from __future__ import annotations

import argparse
import json
import pathlib


def checkpoint_callback(out: pathlib.Path, every: int, env_meta: dict, algo: str):
    from stable_baselines3.common.callbacks import BaseCallback

    from controllers.policy import POLICY_FORMAT, actor_from_sb3, save_actor
    from ebraille_sim.rl.registration import RESIDUAL_ENV_ID

    class Checkpoints(BaseCallback):
        def __init__(self):
            super().__init__()
            self.next_save = every

        def _on_step(self) -> bool:
            if self.num_timesteps >= self.next_save:
                self.save(self.num_timesteps)
                while self.next_save <= self.num_timesteps:
                    self.next_save += every
            return True

        def save(self, steps: int) -> None:
            folder = out / "checkpoints" / f"{steps:09d}"
            folder.mkdir(parents=True, exist_ok=True)
            save_actor(actor_from_sb3(self.model), folder / "policy.npz")
            meta = {"format": POLICY_FORMAT, "algo": algo, "env_id": RESIDUAL_ENV_ID, "env": env_meta,
                    "training": {"steps": int(steps)}}
            (folder / "policy.json").write_text(json.dumps(meta, indent=2) + "\n", encoding="utf-8")

        def _on_training_start(self) -> None:
            self.save(0)

    return Checkpoints()


def main() -> None:
    from ebraille_sim.commands.train import recipe_settings, train
    from ebraille_sim.rl.episode import EnvConfig
    from ebraille_sim.rl.residual import ResidualConfig, residual_device
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--recipe", default="residual_ppo_1khz")
    p.add_argument("--steps", type=int, default=2_000_000)
    p.add_argument("--envs", type=int, default=4)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--every", type=int, default=250_000)
    p.add_argument("--out", default="studies/learning/runs/residual_ppo_1khz")
    a = p.parse_args()
    settings = recipe_settings(a.recipe)
    out = pathlib.Path(a.out)
    cfg = EnvConfig(control_rate_hz=settings["control_rate_hz"],
                    base_device=residual_device(settings["residual"]))
    rc = ResidualConfig(residual=settings["residual"], residual_limit_v=settings["residual_limit_v"],
                        history=settings["history"])
    env_meta = {**cfg.policy_metadata(), **rc.metadata()}
    rec = train(settings["algo"], a.steps, out, seed=a.seed, n_envs=a.envs, recipe=settings,
                callback=checkpoint_callback(out, a.every, env_meta, settings["algo"]),
                progress=lambda done, total: print(f"{done}/{total}", flush=True))
    print(json.dumps({k: rec[k] for k in ("steps", "wall_time_s", "steps_per_s", "mean_episode_return_last_100")}))


if __name__ == "__main__":
    main()
