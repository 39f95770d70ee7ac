"""``ebraille-sim train``: train a contact-force policy with Stable-Baselines3 (PPO or SAC).

The policy learns on ``EBraille/ContactForce-v0`` (randomised readers, FSR units, motors,
drive trains, passages, rates, setpoints and disturbances) through Stable-Baselines3's own
vectorisation of the registered id, with no wrapper of ours.  The output folder receives
``policy.zip`` (the SB3 model), ``policy.npz`` (its deterministic actor for NumPy,
:class:`controllers.policy.MlpActor`) and ``policy.json`` (algorithm, the env settings the
observation depends on, and the training record: steps, seed, wall time, versions, and the
estimator settings of the devices trained on), which ``--controller policy:DIR`` loads in
``ebraille-sim run``.  ``--estimator KEY=VALUE`` (repeatable, as in ``ebraille-sim benchmark``)
trains on a firmware variant: every drawn device carries those estimator settings.

Needs the ``rl`` extra: ``pip install 'ebraille-sim[rl]'``.
"""
from __future__ import annotations

NAME = "train"
HELP = "train a learned contact-force controller (PPO or SAC, needs the rl extra) and save it"

_PPO = {"n_steps": 1024, "batch_size": 256, "n_epochs": 10, "gamma": 0.99, "gae_lambda": 0.95,
        "learning_rate": 3e-4, "clip_range": 0.2, "ent_coef": 0.0}
_SAC = {"learning_starts": 5000, "batch_size": 256, "gamma": 0.99, "learning_rate": 3e-4, "buffer_size": 300_000}


MAX_STEPS = 10 ** 9
"""Most environment steps of ``--steps``."""

TRAIN_SEED_LIMIT = 2 ** 32
"""Env ``k`` is seeded with ``seed + k``, and NumPy's global seed must lie below 2**32."""

TRAIN_OWNED = ("policy.zip", "policy.json", "policy.npz")
"""What ``train`` writes into its folder."""


def add_arguments(p):
    from ebraille_sim.commands import number, whole
    p.add_argument("--algo", choices=["ppo", "sac"], default="ppo", help="algorithm (default: ppo)")
    p.add_argument("--steps", type=whole(1, MAX_STEPS), default=200_000, metavar="N",
                   help=f"environment steps, in [1, {MAX_STEPS:.0e}] (default: 200000)")
    p.add_argument("--out", default=None, metavar="DIR", help="output folder (default: runs/train-ALGO)")
    p.add_argument("--seed", type=whole(0, TRAIN_SEED_LIMIT - 1), default=0,
                   help="master seed of training; seed + envs at most 2**32 (default: 0)")
    p.add_argument("--envs", type=whole(1, 256), default=4, metavar="N",
                   help="environments stepped together, in [1, 256] (default: 4)")
    p.add_argument("--control-rate", type=number(1, 1e5), default=200.0, metavar="HZ",
                   help="env step rate = the policy's control rate, Hz; divides the 10 kHz physics rate "
                        "(default: 200)")
    p.add_argument("--threads", type=whole(1, 64), default=1, metavar="N", help="PyTorch threads, in [1, 64] (default: 1)")
    p.add_argument("--estimator", action="append", default=[], metavar="KEY=VALUE",
                   help="an estimator setting of every device trained on (repeatable), e.g. "
                        "hysteresis_compensation=true; the [estimator] keys of a scenario file, recorded in "
                        "policy.json")


def _check(args):
    from ebraille_sim.rl.env import EnvConfig
    if args.steps < 1:
        raise ValueError(f"--steps must be >= 1, got {args.steps}")
    if args.seed < 0:
        raise ValueError(f"--seed must be >= 0, got {args.seed}")
    if args.seed + args.envs > TRAIN_SEED_LIMIT:
        raise ValueError(f"--seed {args.seed} with --envs {args.envs} seeds env {args.envs - 1} with "
                         f"{args.seed + args.envs - 1}; seed + envs must be at most 2**32")
    if not 1 <= args.envs <= 256:
        raise ValueError(f"--envs must be in [1, 256], got {args.envs}")
    if not 1 <= args.threads <= 64:
        raise ValueError(f"--threads must be in [1, 64], got {args.threads}")
    try:
        EnvConfig(control_rate_hz=args.control_rate)
    except ValueError as exc:
        raise ValueError(f"--control-rate {args.control_rate:g}: {str(exc).split(': ', 1)[-1]}") from None


def _progress_callback(report, total: int, reports: int = 50):
    """A Stable-Baselines3 callback calling ``report(done, total)`` about ``reports`` times.

    An algorithm may run past ``total`` to finish its last rollout; the total shown then
    grows to the steps actually taken, and the last report is ``(taken, taken)``.
    """
    from stable_baselines3.common.callbacks import BaseCallback

    class _Progress(BaseCallback):
        def __init__(self):
            super().__init__()
            self.step_size = max(1, int(total) // reports)
            self.next_report = self.step_size

        def _on_step(self) -> bool:
            if self.num_timesteps >= self.next_report:
                report(self.num_timesteps, max(int(total), self.num_timesteps))
                while self.next_report <= self.num_timesteps:
                    self.next_report += self.step_size
            return True

        def _on_training_end(self) -> None:
            if self.num_timesteps != max(int(total), self.num_timesteps) or self.num_timesteps < self.next_report:
                report(self.num_timesteps, self.num_timesteps)

    return _Progress()


def train(algo: str, steps: int, out, seed: int = 0, n_envs: int = 4, control_rate_hz: float = 200.0,
          threads: int = 1, verbose: int = 0, progress=None, estimator=None) -> dict:
    """Train and save a policy; returns the ``training`` record written to ``policy.json``.

    Parameters
    ----------
    algo : {"ppo", "sac"}
    steps : int
        Environment steps (summed over the ``n_envs`` environments).
    out : path
        Output folder (created).
    seed : int
        Seeds SB3, the network initialisation and env ``k`` (``seed + k``).
    n_envs : int
    control_rate_hz : float
        Env step rate; must divide the 10 kHz physics rate.
    threads : int
        PyTorch intra-op threads.
    progress : callable, optional
        Called as ``progress(done_steps, total_steps)`` about 50 times during training.
    estimator : dict or list of str, optional
        Estimator settings of the env's base device, and so of every device drawn around it
        (:func:`ebraille_sim.tools.benchmark.estimator_settings`), such as
        ``{"hysteresis_compensation": True}``; the record's ``estimator`` holds every
        estimator field of the devices trained on.
    """
    import json
    import pathlib
    import platform
    import time

    try:
        import stable_baselines3 as sb3
        import torch
        from stable_baselines3.common.env_util import make_vec_env
    except ModuleNotFoundError:
        raise ValueError("training needs stable-baselines3; install it with pip install 'ebraille-sim[rl]'") from None
    from controllers.policy import POLICY_FORMAT

    from ebraille_sim.rl.env import ENV_ID, EnvConfig, register_envs
    from ebraille_sim.tools.benchmark import estimator_settings
    if algo not in ("ppo", "sac"):
        raise ValueError(f"algo must be 'ppo' or 'sac', got {algo!r}")
    est = estimator_settings(estimator)
    base = None
    if est:
        import dataclasses

        from ebraille_sim.base.validation import replace_checked
        from ebraille_sim.physics.params import DeviceParams
        nominal = DeviceParams()
        base = dataclasses.replace(nominal, estimator=replace_checked(nominal.estimator, **est))
    register_envs()
    cfg = EnvConfig(control_rate_hz=control_rate_hz, base_device=base)
    torch.set_num_threads(threads)
    env_kwargs = {"control_rate_hz": cfg.control_rate_hz, "max_episode_steps": cfg.max_episode_steps()}
    if base is not None:
        env_kwargs["base_device"] = base
    venv = make_vec_env(ENV_ID, n_envs=n_envs, seed=seed, env_kwargs=env_kwargs)
    if algo == "ppo":
        model = sb3.PPO("MlpPolicy", venv, seed=seed, device="cpu", verbose=verbose, **_PPO)
    else:
        model = sb3.SAC("MlpPolicy", venv, seed=seed, device="cpu", verbose=verbose, **_SAC)
    t0 = time.perf_counter()
    # PPO collects whole rollouts of n_steps per env, so it takes steps up to the next rollout
    rollout = _PPO["n_steps"] * n_envs if algo == "ppo" else 1
    planned = -(-int(steps) // rollout) * rollout
    model.learn(total_timesteps=int(steps), callback=None if progress is None else _progress_callback(progress, planned))
    wall = time.perf_counter() - t0
    returns = [ep["r"] for ep in model.ep_info_buffer] if model.ep_info_buffer else []
    out = pathlib.Path(out)
    out.mkdir(parents=True, exist_ok=True)
    model.save(out / "policy.zip")
    from controllers.policy import actor_from_sb3, save_actor
    save_actor(actor_from_sb3(model), out / "policy.npz")
    record = {
        "steps": int(model.num_timesteps), "seed": int(seed), "envs": int(n_envs), "wall_time_s": round(wall, 1),
        "steps_per_s": round(model.num_timesteps / wall, 1),
        "mean_episode_return_last_100": float(sum(returns) / len(returns)) if returns else None,
        "hyperparameters": _PPO if algo == "ppo" else _SAC, "torch_threads": int(threads),
        "versions": {"stable_baselines3": sb3.__version__, "torch": torch.__version__,
                     "python": platform.python_version()},
        "machine": {"cpus": __import__("os").cpu_count(), "processor": platform.machine()},
        "estimator": cfg.estimator_metadata(),
    }
    meta = {"format": POLICY_FORMAT, "algo": algo, "env_id": ENV_ID, "env": cfg.policy_metadata(),
            "training": record}
    (out / "policy.json").write_text(json.dumps(meta, indent=2) + "\n", encoding="utf-8")
    venv.close()
    return record


def main(args) -> int:
    import pathlib

    from ebraille_sim.commands import FrameProgress, UserError, check_out_dir, console
    from ebraille_sim.tools.benchmark import estimator_settings
    from ebraille_sim.tools.outputs import staged
    con = console(args)
    _check(args)
    try:
        estimator = estimator_settings(args.estimator)
    except ValueError as exc:
        raise UserError(f"--estimator: {exc}") from None
    out = check_out_dir(args.out if args.out is not None else pathlib.Path("runs") / f"train-{args.algo}",
                       owned=TRAIN_OWNED)
    import importlib.util
    if any(importlib.util.find_spec(m) is None for m in ("stable_baselines3", "torch")):
        raise UserError("training needs stable-baselines3; install it with pip install 'ebraille-sim[rl]'")
    bar = FrameProgress(f"train {args.algo}", enabled=con.progress, every=1)
    try:
        with staged(out, TRAIN_OWNED) as folder:
            rec = train(args.algo, args.steps, folder, seed=args.seed, n_envs=args.envs,
                        control_rate_hz=args.control_rate, threads=args.threads, progress=bar,
                        estimator=estimator)
    finally:
        bar.close()
    ret = rec["mean_episode_return_last_100"]
    con.result({"algo": args.algo, **rec, "out": str(out),
                "files": [str(out / "policy.zip"), str(out / "policy.json")]})
    firmware = "".join(f", estimator {k}={str(v).lower() if isinstance(v, bool) else v}"
                       for k, v in estimator.items())
    con.say(f"trained {args.algo.upper()} for {rec['steps']} steps in {rec['wall_time_s']:.1f} s "
          f"({rec['steps_per_s']:.0f} steps/s{firmware})" + ("" if ret is None else f"; mean episode return {ret:.1f}"))
    con.say(f"wrote {out / 'policy.zip'}, {out / 'policy.json'}  (use --controller policy:{out})")
    return 0
