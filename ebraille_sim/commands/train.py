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

``--recipe NAME`` picks a training recipe (:data:`RECIPES`): the algorithm, the env (plain or
residual on a named design, its control rate, observation history, curriculum) and the
learner's hyperparameters; ``--algo``, ``--control-rate``, ``--residual`` and ``--history``
given on the command line override the recipe's.  Without a recipe, ``train`` trains the
plain env at 200 Hz (the recipe ``ppo_200hz``, or ``sac_200hz`` with ``--algo sac``).

Needs the ``rl`` extra: ``pip install 'ebraille-sim[rl]'``.
"""
from __future__ import annotations

NAME = "train"
HELP = "train a learned contact-force controller (PPO or SAC, needs the rl extra) and save it"

_PPO = {"n_steps": 1024, "batch_size": 256, "n_epochs": 10, "gamma": 0.99, "gae_lambda": 0.95,
        "learning_rate": 3e-4, "clip_range": 0.2, "ent_coef": 0.0}
_SAC = {"learning_starts": 5000, "batch_size": 256, "gamma": 0.99, "learning_rate": 3e-4, "buffer_size": 300_000}

_RESIDUAL_PPO = {"n_steps": 2048, "batch_size": 512, "n_epochs": 10, "gamma": 0.99, "gae_lambda": 0.95,
                 "learning_rate": 1e-4, "clip_range": 0.1, "ent_coef": 0.0,
                 "policy_kwargs": {"log_std_init": -2.0, "net_arch": [64, 64]}}

_SELECT_PPO = {"n_steps": 1024, "batch_size": 512, "n_epochs": 10, "gamma": 0.99, "gae_lambda": 0.95,
               "learning_rate": 1e-4, "clip_range": 0.1, "ent_coef": 0.0,
               "policy_kwargs": {"log_std_init": -2.0, "net_arch": [64, 64]}}

VALIDATION_SEED = 7001
"""Population seed of the validation readers that choose a residual recipe's checkpoint (drawn
apart from the benchmark's readers, :func:`ebraille_sim.tools.benchmark.scenario_devices`)."""

RECIPES = {
    "ppo_200hz": {"description": "PPO on the plain env at 200 Hz (the command's default)",
                  "algo": "ppo", "control_rate_hz": 200.0, "hyperparameters": _PPO},
    "sac_200hz": {"description": "SAC on the plain env at 200 Hz", "algo": "sac", "control_rate_hz": 200.0,
                  "hyperparameters": _SAC},
    "residual_ppo_1khz": {
        "description": "PPO learning a correction of at most 1 V on dob_100hz at its 1 kHz control rate, four "
                       "frames of board signals, the population spread growing from a quarter to full over the "
                       "first half of training; the policy starts as the design (near-zero mean, std 0.14 V)",
        "algo": "ppo", "control_rate_hz": 1000.0, "residual": "dob_100hz", "residual_limit_v": 1.0, "history": 4,
        "curriculum_fraction": 0.5, "curriculum_start": 0.25, "hyperparameters": _RESIDUAL_PPO},
    "residual_ppo_refresh_1khz": {
        "description": "residual_ppo_1khz with a quarter of the episodes read in refresh mode (each character "
                       "pressed, held and released, as in the benchmark's refresh scenarios)",
        "algo": "ppo", "control_rate_hz": 1000.0, "residual": "dob_100hz", "residual_limit_v": 1.0, "history": 4,
        "curriculum_fraction": 0.5, "curriculum_start": 0.25, "refresh_probability": 0.25,
        "hyperparameters": _RESIDUAL_PPO},
    "residual_ppo_hold_1khz": {
        "description": "residual_ppo_1khz on dob_hold_1khz (the fast_1khz firmware)",
        "algo": "ppo", "control_rate_hz": 1000.0, "residual": "dob_hold_1khz", "residual_limit_v": 1.0,
        "history": 4, "curriculum_fraction": 0.5, "curriculum_start": 0.25, "hyperparameters": _RESIDUAL_PPO},
    "residual_ppo_select_1khz": {
        "description": "PPO learning a correction of at most 1 V on dob_100hz at 1 kHz (4 frames, a quarter of "
                       "the episodes in refresh mode, the full population from the start), starting exactly at "
                       "the design (the action head's weights zero); the design and a checkpoint every sixth of "
                       "the steps scored on the standard suite over 24 validation readers drawn apart from the "
                       "benchmark's, the best kept (the design on a tie)",
        "algo": "ppo", "control_rate_hz": 1000.0, "residual": "dob_100hz", "residual_limit_v": 1.0, "history": 4,
        "refresh_probability": 0.25, "zero_start": True,
        "validation": {"suite": "standard", "readers": 24, "seed": VALIDATION_SEED, "checkpoints": 6},
        "hyperparameters": _SELECT_PPO},
    "residual_ppo_select_025v_1khz": {
        "description": "residual_ppo_select_1khz with a correction of at most 0.25 V and a checkpoint every "
                       "twelfth of the steps",
        "algo": "ppo", "control_rate_hz": 1000.0, "residual": "dob_100hz", "residual_limit_v": 0.25, "history": 4,
        "refresh_probability": 0.25, "zero_start": True,
        "validation": {"suite": "standard", "readers": 24, "seed": VALIDATION_SEED, "checkpoints": 12},
        "hyperparameters": _SELECT_PPO},
}
"""Training recipes of ``--recipe``: the algorithm, the env and the learner's settings."""


MAX_STEPS = 10 ** 9
"""Most environment steps of ``--steps``."""

TRAIN_SEED_LIMIT = 2 ** 32
"""Env ``k`` is seeded with ``seed + k``, and NumPy's global seed must lie below 2**32."""

TRAIN_OWNED = ("policy.zip", "policy.json", "policy.npz")
"""What ``train`` writes into its folder."""


def add_arguments(p):
    from ebraille_sim.commands import number, whole
    p.add_argument("--recipe", default=None, metavar="NAME",
                   help=f"training recipe: {', '.join(RECIPES)} (default: ppo_200hz, or sac_200hz with --algo sac)")
    p.add_argument("--algo", default=None, metavar="ALGO", help="algorithm, ppo or sac (default: the recipe's)")
    p.add_argument("--steps", type=whole(1, MAX_STEPS), default=200_000, metavar="N",
                   help=f"environment steps, in [1, {MAX_STEPS:.0e}] (default: 200000)")
    p.add_argument("--out", default=None, metavar="DIR",
                   help="output folder (default: runs/train-ALGO, or runs/train-RECIPE with --recipe)")
    p.add_argument("--seed", type=whole(0, TRAIN_SEED_LIMIT - 1), default=0,
                   help="master seed of training; seed + envs at most 2**32 (default: 0)")
    p.add_argument("--envs", type=whole(1, 256), default=4, metavar="N",
                   help="environments stepped together, in [1, 256] (default: 4)")
    p.add_argument("--control-rate", type=number(1, 1e5), default=None, metavar="HZ",
                   help="env step rate = the policy's control rate, Hz; divides the 10 kHz physics rate "
                        "(default: the recipe's, 200 for ppo_200hz)")
    p.add_argument("--residual", default=None, metavar="DESIGN",
                   help="learn a correction on this design's command (a shipped design, a design file or a "
                        "controller name) instead of the whole command (default: the recipe's)")
    p.add_argument("--history", type=whole(1, 64), default=None, metavar="K",
                   help="frames of board signals in a residual policy's observation, in [1, 64] (default: the "
                        "recipe's)")
    p.add_argument("--threads", type=whole(1, 64), default=1, metavar="N", help="PyTorch threads, in [1, 64] (default: 1)")
    p.add_argument("--estimator", action="append", default=[], metavar="KEY=VALUE",
                   help="an estimator setting of every device trained on (repeatable), e.g. "
                        "hysteresis_compensation=true; the [estimator] keys of a scenario file, recorded in "
                        "policy.json")


def recipe_settings(recipe: str | None = None, algo: str | None = None, control_rate_hz: float | None = None,
                    residual: str | None = None, history: int | None = None) -> dict:
    """The settings of a training run: the recipe's (:data:`RECIPES`; None: ``ppo_200hz``, or
    ``sac_200hz`` for ``algo="sac"``), with the arguments that are not None replacing them.
    An unknown recipe or algorithm, a design that does not exist, or a history without a
    residual is a one-line ``ValueError`` naming it."""
    import copy
    if recipe is None:
        recipe = "sac_200hz" if algo == "sac" else "ppo_200hz"
    if recipe not in RECIPES:
        raise ValueError(f"--recipe: unknown recipe {recipe!r}; available: {', '.join(RECIPES)}")
    out = copy.deepcopy(RECIPES[recipe])
    out["recipe"] = recipe
    if algo is not None:
        if algo not in ("ppo", "sac"):
            raise ValueError(f"--algo: unknown algorithm {algo!r}; available: ppo, sac")
        if algo != out["algo"]:
            out["hyperparameters"] = copy.deepcopy(_PPO if algo == "ppo" else _SAC)
        out["algo"] = algo
    if control_rate_hz is not None:
        out["control_rate_hz"] = float(control_rate_hz)
    if residual is not None:
        from ebraille_sim.rl.residual import ResidualConfig
        try:
            ResidualConfig(residual=residual)
        except ValueError as exc:
            raise ValueError(f"--residual: {exc}") from None
        out["residual"] = residual
        out.setdefault("residual_limit_v", 1.0)
        out.setdefault("history", 1)
    if history is not None:
        if "residual" not in out:
            raise ValueError(f"--history {history}: a history is for a residual policy; give --residual DESIGN "
                             "or a residual recipe")
        out["history"] = int(history)
    return out


def _check(args):
    from ebraille_sim.rl.env import EnvConfig
    settings = recipe_settings(args.recipe, args.algo, args.control_rate, args.residual, args.history)
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
    rate = settings["control_rate_hz"]
    try:
        EnvConfig(control_rate_hz=rate)
    except ValueError as exc:
        raise ValueError(f"--control-rate {rate:g}: {str(exc).split(': ', 1)[-1]}") from None
    return settings


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


def _curve_callback(curve: list, every: int):
    """A Stable-Baselines3 callback appending, about every ``every`` steps, the learning curve's
    point ``{"steps", "episodes", "mean_return", "mean_reward_per_step"}`` (over the last 100
    finished episodes, SB3's ``ep_info_buffer``) to ``curve``."""
    from stable_baselines3.common.callbacks import BaseCallback

    class _Curve(BaseCallback):
        def __init__(self):
            super().__init__()
            self.next_point = every
            self.episodes = 0

        def _on_step(self) -> bool:
            self.episodes += int(sum(self.locals.get("dones", [])))
            if self.num_timesteps >= self.next_point:
                self._point()
                while self.next_point <= self.num_timesteps:
                    self.next_point += every
            return True

        def _point(self) -> None:
            buf = list(self.model.ep_info_buffer or [])
            if not buf:
                return
            ret = sum(e["r"] for e in buf)
            length = sum(e["l"] for e in buf)
            curve.append({"steps": int(self.num_timesteps), "episodes": self.episodes,
                          "mean_return": round(ret / len(buf), 3),
                          "mean_reward_per_step": round(ret / max(1, length), 5)})

        def _on_training_end(self) -> None:
            if not curve or curve[-1]["steps"] != self.num_timesteps:
                self._point()

    return _Curve()


def zero_action_head(model) -> None:
    """Set the PPO policy's action head (``action_net``) to zero weights and biases: its mean
    action is exactly 0 on every observation, so a residual policy starts as its design to the
    last bit, and the gradient still reaches the head through the hidden layers' features."""
    import torch
    with torch.no_grad():
        model.policy.action_net.weight.zero_()
        model.policy.action_net.bias.zero_()


def _write_policy(folder, model, meta: dict) -> None:
    """``policy.zip``, ``policy.npz`` and ``policy.json`` of ``model`` into ``folder``."""
    import json
    import pathlib

    from controllers.policy import actor_from_sb3, save_actor
    folder = pathlib.Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    model.save(folder / "policy.zip")
    save_actor(actor_from_sb3(model), folder / "policy.npz")
    (folder / "policy.json").write_text(json.dumps(meta, indent=2) + "\n", encoding="utf-8")


def validation_score(folder, validation: dict) -> dict:
    """The benchmark of the policy in ``folder`` on ``validation``'s suite over its readers,
    drawn from its own seed (:func:`ebraille_sim.tools.benchmark.run_benchmark` with
    ``population_seed``; no nominal reader, no bounds, one process): ``{"score", "scenarios"}``
    (:func:`~ebraille_sim.tools.benchmark.summarise`)."""
    from ebraille_sim.tools.benchmark import run_benchmark, summarise
    name = f"policy:{folder}"
    res = run_benchmark([name], suite=validation["suite"], readers=int(validation["readers"]), jobs=1, bounds=False,
                        population_seed=int(validation["seed"]))
    return summarise(res)[name]


def _selection_callback(validation: dict, every: int, meta: dict, out, record: list, t0: float):
    """A Stable-Baselines3 callback that scores the policy on the validation readers at step 0
    and about every ``every`` steps (:func:`validation_score`), appends ``{"steps", "score",
    "wall_s"}`` to ``record``, and writes a policy that scores above every earlier one into
    ``out`` (``meta`` its ``policy.json`` so far).  Step 0 of a zero-started residual policy is
    its design, so the policy written scores at least the design's on these readers."""
    import tempfile
    import time

    from stable_baselines3.common.callbacks import BaseCallback

    class _Select(BaseCallback):
        def __init__(self):
            super().__init__()
            self.next_point = 0
            self.best = None
            self.tmp = tempfile.TemporaryDirectory(prefix="ebraille-validation-")

        def _on_training_start(self) -> None:
            self._score()

        def _on_step(self) -> bool:
            if self.num_timesteps >= self.next_point:
                self._score()
            return True

        def _on_training_end(self) -> None:
            if not record or record[-1]["steps"] != self.num_timesteps:
                self._score()
            self.tmp.cleanup()

        def _score(self) -> None:
            steps = int(self.num_timesteps)
            folder = f"{self.tmp.name}/{steps}"
            _write_policy(folder, self.model, meta)
            summary = validation_score(folder, validation)
            score = float(summary["score"])
            record.append({"steps": steps, "score": round(score, 3), "wall_s": round(time.perf_counter() - t0, 1),
                           "scenarios": {k: {m: (None if v is None else round(v, 4)) for m, v in st.items()
                                             if m.endswith("_cvar10")}
                                         for k, st in summary["scenarios"].items()}})
            if self.best is None or score > self.best:
                self.best = score
                _write_policy(out, self.model, meta)
                meta_best["steps"] = steps
            while self.next_point <= self.num_timesteps:
                self.next_point += every

    meta_best = {}
    cb = _Select()
    cb.chosen = meta_best
    return cb


def train(algo: str, steps: int, out, seed: int = 0, n_envs: int = 4, control_rate_hz: float = 200.0,
          threads: int = 1, verbose: int = 0, progress=None, estimator=None, recipe=None, callback=None) -> dict:
    """Train and save a policy; returns the ``training`` record written to ``policy.json``.

    Parameters
    ----------
    algo : {"ppo", "sac"}
    steps : int
        Environment steps (summed over the ``n_envs`` environments), >= 1.
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
    recipe : str or dict, optional
        A recipe's name (:data:`RECIPES`) or the settings :func:`recipe_settings` returns; it
        replaces ``algo`` and ``control_rate_hz``.  A residual recipe trains
        :class:`ebraille_sim.rl.residual.ResidualEnv` on its design.
    callback : stable_baselines3 callback, optional
        Called by SB3 besides the progress and learning-curve callbacks (e.g. checkpoints).

    The record holds the learning curve (``curve``: mean episode return and mean reward per
    step of the last 100 episodes, about 50 points) and the recipe.
    """
    import json
    import pathlib
    import platform
    import time

    if isinstance(steps, bool) or not isinstance(steps, int) or steps < 1:
        raise ValueError(f"steps must be a whole number >= 1, got {steps!r}")
    settings = recipe_settings(None, algo, control_rate_hz) if recipe is None else (
        recipe_settings(recipe) if isinstance(recipe, str) else recipe)
    try:
        import stable_baselines3 as sb3
        import torch
        from stable_baselines3.common.callbacks import CallbackList
        from stable_baselines3.common.env_util import make_vec_env
    except ModuleNotFoundError:
        raise ValueError("training needs stable-baselines3; install it with pip install 'ebraille-sim[rl]'") from None
    from controllers.policy import POLICY_FORMAT

    from ebraille_sim.rl.env import ENV_ID, EnvConfig, register_envs
    from ebraille_sim.tools.benchmark import estimator_settings
    algo = settings["algo"]
    control_rate_hz = settings["control_rate_hz"]
    hyper = settings["hyperparameters"]
    est = estimator_settings(estimator)
    base = None
    if est:
        import dataclasses

        from ebraille_sim.base.validation import replace_checked
        from ebraille_sim.physics.params import DeviceParams
        nominal = DeviceParams()
        base = dataclasses.replace(nominal, estimator=replace_checked(nominal.estimator, **est))
    register_envs()
    torch.set_num_threads(threads)
    residual = settings.get("residual")
    extra_meta = {}
    if residual is None:
        env_id = ENV_ID
        cfg = EnvConfig(control_rate_hz=control_rate_hz, base_device=base)
        env_kwargs = {"control_rate_hz": cfg.control_rate_hz, "max_episode_steps": cfg.max_episode_steps()}
    else:
        from ebraille_sim.rl.residual import RESIDUAL_ENV_ID, ResidualConfig, residual_device
        env_id = RESIDUAL_ENV_ID
        rc = ResidualConfig(residual=residual, residual_limit_v=settings["residual_limit_v"],
                            history=settings["history"],
                            curriculum_steps=int(settings.get("curriculum_fraction", 0.0) * steps / n_envs),
                            curriculum_start=settings.get("curriculum_start", 0.25),
                            refresh_probability=settings.get("refresh_probability", 0.0))
        cfg = EnvConfig(control_rate_hz=control_rate_hz, base_device=residual_device(residual, base))
        env_kwargs = {"residual": rc.residual, "residual_limit_v": rc.residual_limit_v, "history": rc.history,
                      "curriculum_steps": rc.curriculum_steps, "curriculum_start": rc.curriculum_start,
                      "refresh_probability": rc.refresh_probability,
                      "control_rate_hz": cfg.control_rate_hz}
        extra_meta = rc.metadata()
    if base is not None:
        env_kwargs["base_device"] = base
    venv = make_vec_env(env_id, n_envs=n_envs, seed=seed, env_kwargs=env_kwargs)
    cls = sb3.PPO if algo == "ppo" else sb3.SAC
    model = cls("MlpPolicy", venv, seed=seed, device="cpu", verbose=verbose, **hyper)
    if settings.get("zero_start"):
        zero_action_head(model)
    out = pathlib.Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    # PPO collects whole rollouts of n_steps per env, so it takes steps up to the next rollout
    rollout = hyper["n_steps"] * n_envs if algo == "ppo" else 1
    planned = -(-int(steps) // rollout) * rollout
    curve: list = []
    callbacks = [_curve_callback(curve, max(1, planned // 50))]
    if progress is not None:
        callbacks.append(_progress_callback(progress, planned))
    validation = settings.get("validation")
    selected: list = []
    select = None
    if validation is not None:
        base_meta = {"format": POLICY_FORMAT, "algo": algo, "env_id": env_id,
                     "env": {**cfg.policy_metadata(), **extra_meta}, "training": {"recipe": settings["recipe"]}}
        select = _selection_callback(validation, max(1, planned // int(validation["checkpoints"])), base_meta, out,
                                     selected, t0)
        callbacks.append(select)
    if callback is not None:
        callbacks.append(callback)
    model.learn(total_timesteps=int(steps), callback=CallbackList(callbacks))
    wall = time.perf_counter() - t0
    returns = [ep["r"] for ep in model.ep_info_buffer] if model.ep_info_buffer else []
    if select is None:
        from controllers.policy import actor_from_sb3, save_actor
        model.save(out / "policy.zip")
        save_actor(actor_from_sb3(model), out / "policy.npz")
    record = {
        "steps": int(model.num_timesteps), "seed": int(seed), "envs": int(n_envs), "wall_time_s": round(wall, 1),
        "steps_per_s": round(model.num_timesteps / wall, 1),
        "mean_episode_return_last_100": float(sum(returns) / len(returns)) if returns else None,
        "recipe": settings["recipe"], "hyperparameters": hyper, "torch_threads": int(threads),
        "versions": {"stable_baselines3": sb3.__version__, "torch": torch.__version__,
                     "python": platform.python_version()},
        "machine": {"cpus": __import__("os").cpu_count(), "processor": platform.machine()},
        "estimator": cfg.estimator_metadata(),
        "curve": curve,
    }
    if residual is not None:
        record["curriculum"] = {"steps_per_env": env_kwargs["curriculum_steps"],
                                "start": env_kwargs["curriculum_start"]}
        record["refresh_probability"] = env_kwargs["refresh_probability"]
    if select is not None:
        record["validation"] = {**validation, "chosen_steps": select.chosen["steps"],
                                "chosen_score": max(p["score"] for p in selected), "design_score": selected[0]["score"],
                                "checkpoints": selected}
    meta = {"format": POLICY_FORMAT, "algo": algo, "env_id": env_id, "env": {**cfg.policy_metadata(), **extra_meta},
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
    settings = _check(args)
    try:
        estimator = estimator_settings(args.estimator)
    except ValueError as exc:
        raise UserError(f"--estimator: {exc}") from None
    algo = settings["algo"]
    out = check_out_dir(args.out if args.out is not None else pathlib.Path("runs") / f"train-{algo if args.recipe is None else args.recipe}",
                       owned=TRAIN_OWNED)
    import importlib.util
    if any(importlib.util.find_spec(m) is None for m in ("stable_baselines3", "torch")):
        raise UserError("training needs stable-baselines3; install it with pip install 'ebraille-sim[rl]'")
    bar = FrameProgress(f"train {settings['recipe']}", enabled=con.progress, every=1)
    try:
        with staged(out, TRAIN_OWNED) as folder:
            rec = train(algo, args.steps, folder, seed=args.seed, n_envs=args.envs, threads=args.threads,
                        progress=bar, estimator=estimator, recipe=settings)
    finally:
        bar.close()
    ret = rec["mean_episode_return_last_100"]
    con.result({"algo": algo, **rec, "out": str(out),
                "files": [str(out / "policy.zip"), str(out / "policy.json")]})
    firmware = "".join(f", estimator {k}={str(v).lower() if isinstance(v, bool) else v}"
                       for k, v in estimator.items())
    con.say(f"trained {algo.upper()} ({settings['recipe']}) for {rec['steps']} steps in {rec['wall_time_s']:.1f} s "
          f"({rec['steps_per_s']:.0f} steps/s{firmware})" + ("" if ret is None else f"; mean episode return {ret:.1f}"))
    con.say(f"wrote {out / 'policy.zip'}, {out / 'policy.json'}  (use --controller policy:{out})")
    return 0
