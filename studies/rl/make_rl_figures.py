"""Figures and tables of docs/rl.md: a learned policy against the PID on the standard scenarios.

Every scenario runs twice through :func:`ebraille_sim.run_scenario` (same seed, same
physics, same metrics): once with the scenario's PID, once with ``policy:POLICY``.
Writes, into ``--out`` (default studies/rl) and the figures into ``--figures`` (default
docs/figures/rl):

* ``comparison.json``: metrics of both controllers per scenario, and the policy's
  training record from its ``policy.json``;
* ``comparison.md``: the same as a Markdown table;
* ``traces.png``: true contact force of both controllers on ``setpoint_steps`` and
  ``contact_onset``;
* ``frame.png``: one ``rgb_array`` frame of the env driven by the policy;
* ``population.json``: both controllers on ``--episodes`` randomised env episodes (seeds
  1000, 1001, ...; drawn devices, passages, rates, setpoints and disturbances), each
  driving the env through the Controller protocol at the env's 200 Hz: mean episode
  return, mean |true force - setpoint| while reading, terminations and peak force.

The policy is trained beforehand with
``ebraille-sim train --algo ppo --steps N --envs 8 --out studies/rl/checkpoints/first`` (the
default ``--policy``; it runs from ``policy.zip`` and needs the ``rl`` extra); ``--policy`` also
takes a shipped policy's name (``ppo``, ``sac``, ``ppo_hc``).

Run:  python studies/rl/make_rl_figures.py [--policy studies/rl/checkpoints/first] [--out studies/rl]
"""
from __future__ import annotations

import argparse
import json
import pathlib

import numpy as np

HERE = pathlib.Path(__file__).resolve().parent
SCENARIOS = ["steady_60wpm", "steady_90wpm", "steady_120wpm", "setpoint_steps", "contact_onset"]
METRICS = ["force_rmse_n", "in_band_fraction", "char_in_band_fraction", "peak_force_n",
           "onset_overshoot_fraction", "settling_time_s", "contact_loss_count", "energy_j"]


def _fmt(v):
    if v is None:
        return "n/a"
    if isinstance(v, int):
        return str(v)
    return f"{v:.3f}"


def env_episode(ctrl, seed: int) -> dict:
    """One randomised env episode driven by a Controller; returns its summary."""
    from ebraille_sim.rl.env import ContactForceEnv
    env = ContactForceEnv()
    _, info = env.reset(seed=seed)
    dt = env.config.dt_s
    supply = env.config.base_device.driver_supply_v   # volts per unit action, whatever the drawn supply
    ctrl.reset(force_est_n=info["force_est_n"], setpoint_n=info["setpoint_n"])
    total, errors, peak, current = 0.0, [], 0.0, 0.0
    while True:
        u = ctrl.update(info["force_est_n"], info["setpoint_n"], dt, current)
        sp = info["setpoint_n"]
        _, r, term, trunc, info = env.step(np.array([u / supply], np.float32))
        current = float(env.plant.motor_current_a[0])
        total += r
        peak = max(peak, info["force_true_n"])
        if info["time_s"] >= env.config.reading_start_s:
            errors.append(abs(info["force_true_n"] - sp))
        if term or trunc:
            return {"return": total, "mae_n": float(np.mean(errors)) if errors else None,
                    "terminated": bool(term), "peak_force_n": peak, "steps": env.episode.n_steps}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--policy", default=str(HERE / "checkpoints" / "first"),
                    help="folder with policy.json and policy.zip or policy.npz, or a shipped policy's name")
    ap.add_argument("--out", default=str(HERE), help="folder for the JSON and Markdown results")
    ap.add_argument("--figures", default=str(HERE.parents[1] / "docs" / "figures" / "rl"),
                    help="folder for the PNG figures")
    ap.add_argument("--episodes", type=int, default=20, help="randomised env episodes per controller")
    a = ap.parse_args(argv)
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    import controllers
    from controllers.policy import policy_folder
    from ebraille_sim import run_scenario
    out, figures = pathlib.Path(a.out), pathlib.Path(a.figures)
    out.mkdir(parents=True, exist_ok=True)
    figures.mkdir(parents=True, exist_ok=True)
    meta = json.loads((pathlib.Path(policy_folder(a.policy)) / "policy.json").read_text())
    spec = f"policy:{a.policy}"
    results, traces = {}, {}
    for name in SCENARIOS:
        pid = run_scenario(name)
        pol = run_scenario(name, controller=controllers.make(spec))
        results[name] = {"pid": {k: pid.metrics[k] for k in METRICS},
                         "policy": {k: pol.metrics[k] for k in METRICS}}
        traces[name] = (pid.trace, pol.trace)
        print(f"{name:16s} rmse PID {pid.metrics['force_rmse_n']:.3f} N  policy {pol.metrics['force_rmse_n']:.3f} N"
              f"   in band PID {pid.metrics['in_band_fraction']:.3f}  policy {pol.metrics['in_band_fraction']:.3f}")
    doc = {"policy": meta, "scenarios": results}
    (out / "comparison.json").write_text(json.dumps(doc, indent=2) + "\n")

    lines = ["| scenario | controller | " + " | ".join(METRICS) + " |",
             "|---|---|" + "---|" * len(METRICS)]
    for name in SCENARIOS:
        for who in ("pid", "policy"):
            lines.append(f"| {name} | {who} | " + " | ".join(_fmt(results[name][who][k]) for k in METRICS) + " |")
    (out / "comparison.md").write_text("\n".join(lines) + "\n")

    fig, axes = plt.subplots(2, 1, figsize=(8, 6), constrained_layout=True)
    for ax, name, t_max in zip(axes, ["setpoint_steps", "contact_onset"], [14.0, 6.0]):
        pid_tr, pol_tr = traces[name]
        sel = pid_tr["t_s"] <= t_max
        ax.plot(pid_tr["t_s"][sel], pid_tr["setpoint_n"][sel], "k--", lw=1, label="setpoint")
        ax.plot(pid_tr["t_s"][sel], pid_tr["force_true_n"][sel], color="#3060c0", lw=1, label="PID (true force)")
        ax.plot(pol_tr["t_s"][sel], pol_tr["force_true_n"][sel], color="#c03030", lw=1,
                label=f"{meta['algo'].upper()} policy (true force)")
        ax.set_title(name)
        ax.set_xlabel("time (s)")
        ax.set_ylabel("contact force (N)")
        ax.legend(fontsize=8)
    fig.savefig(figures / "traces.png", dpi=110)

    pop = {}
    for who, make in (("pid", lambda: controllers.make("pid")), ("policy", lambda: controllers.make(spec))):
        eps = [env_episode(make(), 1000 + k) for k in range(a.episodes)]
        pop[who] = {"mean_return": float(np.mean([e["return"] for e in eps])),
                    "mean_abs_error_n": float(np.mean([e["mae_n"] for e in eps])),
                    "terminations": int(sum(e["terminated"] for e in eps)),
                    "max_peak_force_n": float(max(e["peak_force_n"] for e in eps)), "episodes": eps}
        print(f"population {who:6s}: mean return {pop[who]['mean_return']:.1f}  mean |F - sp| "
              f"{pop[who]['mean_abs_error_n']:.3f} N  terminations {pop[who]['terminations']}")
    (out / "population.json").write_text(json.dumps(pop, indent=2) + "\n")

    from ebraille_sim.rl.env import ContactForceEnv
    env = ContactForceEnv(render_mode="rgb_array")
    obs, _ = env.reset(seed=1, options={"wpm": 90.0, "setpoint_n": 1.0})
    ctrl = controllers.make(spec)
    for _ in range(int(2.5 * env.config.control_rate_hz)):
        act = ctrl.model.predict(obs, deterministic=True)[0]
        obs, _, term, trunc, _ = env.step(np.asarray(act, np.float32).reshape(1))
        if term or trunc:
            break
    plt.imsave(figures / "frame.png", env.render())
    env.close()
    print(f"wrote {out / 'comparison.json'}, {out / 'comparison.md'}, {out / 'population.json'}, "
          f"{figures / 'traces.png'}, {figures / 'frame.png'}")


if __name__ == "__main__":
    main()
