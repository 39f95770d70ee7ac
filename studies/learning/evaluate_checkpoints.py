"""Held-out benchmark scores of a training run's checkpoints beside its base design.

    python studies/learning/evaluate_checkpoints.py studies/learning/runs/residual_ppo_1khz \
        --suite quick --readers 8 --out studies/learning/checkpoints_quick.json

Runs ``ebraille-sim benchmark``'s suite (its readers and seeds, which training never drew: the
env draws its episodes from the training seed's children) on every ``checkpoints/STEPS``
policy of the run folder, the final policy and the base design, and writes the scores with
the training curve recorded in the final ``policy.json``.
"""
from __future__ import annotations

import argparse
import json
import pathlib


def main() -> None:
    from ebraille_sim.tools.benchmark import run_benchmark, summarise
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("run", help="the training run's folder (train_residual.py --out)")
    p.add_argument("--suite", default="quick")
    p.add_argument("--readers", type=int, default=8)
    p.add_argument("--jobs", type=int, default=1)
    p.add_argument("--every", type=int, default=1, help="evaluate every n-th checkpoint")
    p.add_argument("--out", required=True)
    a = p.parse_args()
    run = pathlib.Path(a.run)
    meta = json.loads((run / "policy.json").read_text()) if (run / "policy.json").is_file() else None
    ckpts = sorted((run / "checkpoints").iterdir())[::a.every]
    base = json.loads((ckpts[0] / "policy.json").read_text())["env"]["residual"]
    names = {base: None}
    for c in ckpts:
        names[f"policy:{c}"] = int(c.name)
    if meta is not None:
        names[f"policy:{run}"] = int(meta["training"]["steps"])
    res = run_benchmark(list(names), suite=a.suite, readers=a.readers, jobs=a.jobs, bounds=False)
    summary = summarise(res)
    rows = [{"controller": n if steps is None else "checkpoint", "steps": steps,
             "score": round(summary[n]["score"], 2),
             "scenarios": {k: {s: round(v, 4) for s, v in st.items() if isinstance(v, (int, float))}
                           for k, st in summary[n]["scenarios"].items()}}
            for n, steps in names.items()]
    doc = {"suite": a.suite, "readers": res.readers, "base": base, "wall_s": round(res.wall_s, 1), "rows": rows,
           "training_curve": None if meta is None else meta["training"].get("curve")}
    pathlib.Path(a.out).write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
    for r in rows:
        print(f"{str(r['steps'] if r['steps'] is not None else r['controller']):>12}  {r['score']:7.2f}")


if __name__ == "__main__":
    main()
