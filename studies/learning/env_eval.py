"""Residual policies on held-out env episodes: reward per step and in-band share, beside zero action.

    python studies/learning/env_eval.py POLICY_DIR [POLICY_DIR ...] --episodes 16 \
        --out studies/learning/env_eval.json

Each policy runs in :class:`ebraille_sim.rl.residual.ResidualEnv` (its design, history and
rate from its ``policy.json``; the full population, no curriculum) on episodes seeded
``1_000_000 + i``, which training never drew (its envs are seeded 0..envs-1), and so does the
zero action (the design alone) on the same episodes.  Per episode: the mean reward per step,
the share of reading time with the true force within 10 % of the setpoint (the benchmark's
band), the RMS of the correction.  Reported: means, the worst 10 % of the episodes (CVaR10)
and the paired difference to the design.
"""
from __future__ import annotations

import argparse
import json
import pathlib

import numpy as np


def run_episodes(env, actor, seeds, refresh: bool):
    out = []
    for s in seeds:
        obs, _ = env.reset(seed=int(s))
        start = env.episode.spec.reading.start_s
        rew, inband, res = [], [], []
        done = False
        while not done:
            a = np.zeros(1, np.float32) if actor is None else actor.predict(obs)[0]
            obs, r, term, trunc, info = env.step(a)
            rew.append(r)
            res.append(info["residual_v"])
            if info["time_s"] >= start and info["setpoint_n"] > 0:
                inband.append(abs(info["force_true_n"] - info["setpoint_n"]) <= 0.1 * info["setpoint_n"])
            done = term or trunc
        out.append({"seed": int(s), "reward_per_step": float(np.mean(rew)), "in_band": float(np.mean(inband)),
                    "residual_rms_v": float(np.sqrt(np.mean(np.square(res)))), "terminated": bool(term)})
    return out


def cvar(x, alpha=0.1):
    x = np.sort(np.asarray(x))
    k = max(1, int(np.ceil(alpha * len(x))))
    return float(x[:k].mean())


def main() -> None:
    from controllers.policy import load_actor, read_metadata
    from ebraille_sim.rl.residual import ResidualEnv
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("policies", nargs="+")
    p.add_argument("--episodes", type=int, default=16)
    p.add_argument("--refresh", type=float, default=0.0, help="refresh_probability of the held-out episodes")
    p.add_argument("--out", required=True)
    a = p.parse_args()
    seeds = 1_000_000 + np.arange(a.episodes)
    results = {}
    base_done = {}
    for folder in a.policies:
        folder = pathlib.Path(folder)
        env_meta = read_metadata(str(folder / "policy.json"))["env"]
        env = ResidualEnv(residual=env_meta["residual"], residual_limit_v=env_meta["residual_limit_v"],
                          history=env_meta["history"], refresh_probability=a.refresh)
        key = (env_meta["residual"], a.refresh)
        if key not in base_done:
            base_done[key] = run_episodes(env, None, seeds, a.refresh)
        pol = run_episodes(env, load_actor(folder / "policy.npz"), seeds, a.refresh)
        base = base_done[key]
        results[str(folder)] = {
            "design": env_meta["residual"],
            "policy": {"reward_per_step": np.mean([e["reward_per_step"] for e in pol]),
                       "in_band_mean": np.mean([e["in_band"] for e in pol]),
                       "in_band_cvar10": cvar([e["in_band"] for e in pol]),
                       "residual_rms_v": np.mean([e["residual_rms_v"] for e in pol])},
            "design_alone": {"reward_per_step": np.mean([e["reward_per_step"] for e in base]),
                             "in_band_mean": np.mean([e["in_band"] for e in base]),
                             "in_band_cvar10": cvar([e["in_band"] for e in base])},
            "paired": {"reward_per_step_gain": np.mean([p_["reward_per_step"] - b["reward_per_step"]
                                                        for p_, b in zip(pol, base)]),
                       "in_band_gain": np.mean([p_["in_band"] - b["in_band"] for p_, b in zip(pol, base)]),
                       "episodes_better_in_band": int(sum(p_["in_band"] > b["in_band"] for p_, b in zip(pol, base))),
                       "episodes_worse_in_band": int(sum(p_["in_band"] < b["in_band"] for p_, b in zip(pol, base))),
                       "reward_per_step_sd_across_episodes": float(np.std([b["reward_per_step"] for b in base]))},
            "episodes": pol, "design_episodes": base}
        print(folder, json.dumps({k: {kk: round(float(vv), 4) for kk, vv in v.items()}
                                  for k, v in results[str(folder)].items() if k in ("policy", "design_alone", "paired")}))
    doc = {"episodes": a.episodes, "refresh_probability": a.refresh, "seeds_from": 1_000_000,
           "results": json.loads(json.dumps(results, default=float))}
    pathlib.Path(a.out).write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()
