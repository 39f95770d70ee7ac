"""Stable-Baselines3 adapter of the native vector env, and the metadata a saved SB3 policy needs.

Stable-Baselines3 does not take a Gymnasium ``VectorEnv``: ``PPO("MlpPolicy", envs)`` with
``envs = gym.make_vec(ENV_ID, num_envs=N, vectorization_mode="vector_entry_point")`` raises
``ValueError``.  :func:`to_sb3` presents that env (a
:class:`~ebraille_sim.rl.vector_env.ContactForceVectorEnv`) as an SB3 ``VecEnv``.  The adapter
holds no physics: every ``step_wait`` is one batched step of the native env.

The two APIs differ in how a sub-env restarts.  The native env follows Gymnasium's
``NEXT_STEP`` autoreset (the step after an end returns the first observation and ignores
the action); SB3 restarts in the same step: ``step_wait`` returns the next episode's first
observation, ``done = terminated or truncated``, the last observation of the ended episode
in ``infos[i]["terminal_observation"]`` and ``infos[i]["TimeLimit.truncated"]``.  The adapter
calls :meth:`~ebraille_sim.rl.vector_env.ContactForceVectorEnv.reset_rows` for the sub-envs that
ended, so the episodes drawn are those of the native env with the same seed, and every
SB3 step is a physics step (no step is spent on a restart).

:class:`VecEnvAdapter` holds all the logic and needs only Gymnasium;
:func:`to_sb3` makes it an instance of SB3's ``VecEnv`` (a subclass built when first
needed), so ``import ebraille_sim.rl.sb3`` does not import Stable-Baselines3 or PyTorch.

:func:`write_policy_metadata` writes the JSON file that ``--controller policy:PATH.zip``
reads beside a model saved with ``model.save`` (algorithm and the env settings the
observation depends on), the same format ``ebraille-sim train`` writes.

Examples
--------
>>> import gymnasium as gym
>>> from stable_baselines3 import PPO                                  # doctest: +SKIP
>>> from ebraille_sim.rl.sb3 import to_sb3, write_policy_metadata
>>> envs = to_sb3(gym.make_vec("EBraille/ContactForce-v0", num_envs=8,
...                            vectorization_mode="vector_entry_point"), seed=0)  # doctest: +SKIP
>>> model = PPO("MlpPolicy", envs, seed=0).learn(100_000)              # doctest: +SKIP
>>> model.save("runs/ppo")                                             # doctest: +SKIP
>>> write_policy_metadata("runs/ppo.zip", model, envs)                 # doctest: +SKIP
"""
from __future__ import annotations

import json
import os
from copy import deepcopy

import numpy as np

__all__ = ["VecEnvAdapter", "to_sb3", "policy_metadata", "write_policy_metadata"]


class VecEnvAdapter:
    """The SB3 ``VecEnv`` interface over a native vector env (see the module docstring).

    Use :func:`to_sb3` to get an instance Stable-Baselines3 accepts; this class alone has
    the same methods and attributes and is what tests without SB3 step.

    Parameters
    ----------
    venv : ContactForceVectorEnv
        The native vector env (``gym.make_vec(..., vectorization_mode="vector_entry_point")``
        or :class:`~ebraille_sim.rl.vector_env.ContactForceVectorEnv` directly), unwrapped.
    """

    def __init__(self, venv):
        from ebraille_sim.rl.vector_env import ContactForceVectorEnv
        if not isinstance(venv, ContactForceVectorEnv):
            raise ValueError("the SB3 adapter needs an unwrapped ContactForceVectorEnv (gym.make_vec(..., "
                             f"vectorization_mode='vector_entry_point')), got {type(venv).__name__}")
        self.venv = venv
        self.num_envs = venv.num_envs
        self.observation_space = venv.single_observation_space
        self.action_space = venv.single_action_space
        self.render_mode = venv.render_mode
        self.metadata = {"render_modes": [] if venv.render_mode is None else ["rgb_array"]}
        self.reset_infos = [{} for _ in range(self.num_envs)]
        self._seeds = [None] * self.num_envs
        self._options = [{} for _ in range(self.num_envs)]
        self._actions = None

    # -- seeding and options (used at the next reset, as SB3's VecEnv) ---------------------------
    def seed(self, seed: int | None = None) -> list:
        """Seed sub-env ``i`` with ``seed + i`` at the next :meth:`reset` (None draws a seed)."""
        if seed is None:
            seed = int(np.random.randint(0, np.iinfo(np.uint32).max, dtype=np.uint32))
        self._seeds = [int(seed) + i for i in range(self.num_envs)]
        return list(self._seeds)

    def set_options(self, options: list | dict | None = None) -> None:
        """Reset options for the next :meth:`reset` (one dict for every sub-env, or a list)."""
        if options is None:
            options = {}
        self._options = deepcopy([options] * self.num_envs if isinstance(options, dict) else list(options))

    # -- the VecEnv step API -------------------------------------------------------------------
    def reset(self) -> np.ndarray:
        """Reset every sub-env with the pending seeds and options; returns observations ``(N, 7)``."""
        opts = [o or {} for o in self._options]
        if any(o != opts[0] for o in opts[1:]):
            raise ValueError("the native vector env applies one set of reset options to every sub-env; "
                             "give set_options() a single dict")
        seeds = None if all(s is None for s in self._seeds) else list(self._seeds)
        obs, _ = self.venv.reset(seed=seeds, options=opts[0] or None)
        self.reset_infos = [{} for _ in range(self.num_envs)]
        self._seeds = [None] * self.num_envs
        self._options = [{} for _ in range(self.num_envs)]
        self._actions = None
        return obs

    def step_async(self, actions) -> None:
        """Store the actions, shape ``(N, 1)`` (or ``(N,)``), for :meth:`step_wait`."""
        self._actions = np.asarray(actions, dtype=np.float32).reshape(self.num_envs, -1)

    def step_wait(self):
        """One native step; ended sub-envs restart in the same step (SB3 semantics).

        Returns
        -------
        obs : numpy.ndarray, shape (N, 7)
        rewards : numpy.ndarray, shape (N,), float32
        dones : numpy.ndarray, shape (N,), bool
        infos : list of dict
            Per sub-env: ``force_true_n``, ``force_est_n``, ``violation``,
            ``TimeLimit.truncated`` and, when done, ``terminal_observation``.
        """
        if self._actions is None:
            raise RuntimeError("call step_async() before step_wait()")
        actions, self._actions = self._actions, None
        obs, rew, term, trunc, info = self.venv.step(actions)
        dones = term | trunc
        infos = [{"force_true_n": float(info["force_true_n"][i]), "force_est_n": float(info["force_est_n"][i]),
                  "violation": float(info["violation"][i]),
                  "TimeLimit.truncated": bool(trunc[i] and not term[i])} for i in range(self.num_envs)]
        ended = np.nonzero(dones)[0]
        if ended.size:
            for i in ended:
                infos[i]["terminal_observation"] = obs[i].copy()
            obs[ended] = self.venv.reset_rows(ended)
            for i in ended:
                self.reset_infos[i] = {}
        return obs, rew.astype(np.float32), dones, infos

    def step(self, actions):
        """:meth:`step_async` then :meth:`step_wait`."""
        self.step_async(actions)
        return self.step_wait()

    def close(self) -> None:
        self.venv.close()

    def get_images(self) -> list:
        """One RGB frame per sub-env (needs ``render_mode="rgb_array"`` on the native env)."""
        if self.render_mode != "rgb_array":
            return [None] * self.num_envs
        return list(self.venv.render())

    # -- attributes and methods: all sub-envs are rows of one native env -----------------------
    def _indices(self, indices) -> list:
        if indices is None:
            return list(range(self.num_envs))
        if isinstance(indices, (int, np.integer)):
            return [int(indices)]
        return [int(i) for i in indices]

    def _whole(self, what: str, indices) -> list:
        idx = self._indices(indices)
        if sorted(idx) != list(range(self.num_envs)):
            raise ValueError(f"{what} acts on the native vector env, which all {self.num_envs} sub-envs share; "
                             "give indices=None")
        return idx

    def get_attr(self, attr_name: str, indices=None) -> list:
        """The native env's attribute, once per requested sub-env (``episode``: each sub-env's own)."""
        idx = self._indices(indices)
        if attr_name == "episode":
            return [self.venv.episodes[i] for i in idx]
        value = getattr(self.venv, attr_name)
        return [value for _ in idx]

    def has_attr(self, attr_name: str) -> bool:
        try:
            self.get_attr(attr_name)
        except AttributeError:
            return False
        return True

    def set_attr(self, attr_name: str, value, indices=None) -> None:
        """Set an attribute of the native env (only for all sub-envs together)."""
        self._whole(f"set_attr({attr_name!r})", indices)
        setattr(self.venv, attr_name, value)

    def env_method(self, method_name: str, *method_args, indices=None, **method_kwargs) -> list:
        """Call a method of the native env once (only for all sub-envs together); its result per sub-env."""
        idx = self._whole(f"env_method({method_name!r})", indices)
        result = getattr(self.venv, method_name)(*method_args, **method_kwargs)
        return [result for _ in idx]

    def env_is_wrapped(self, wrapper_class, indices=None) -> list:
        """False for every sub-env: the rows carry no Gymnasium wrappers."""
        return [False for _ in self._indices(indices)]

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.venv!r})"


_SB3_CLASS = None


def _sb3_class():
    """The SB3 ``VecEnv`` subclass of :class:`VecEnvAdapter` (built once; imports SB3)."""
    global _SB3_CLASS
    if _SB3_CLASS is None:
        try:
            from stable_baselines3.common.vec_env import VecEnv
        except ModuleNotFoundError:
            raise ValueError("the SB3 adapter needs stable-baselines3; install it with "
                             "pip install 'ebraille-sim[rl]'") from None

        class SB3VecEnv(VecEnvAdapter, VecEnv):
            """:class:`VecEnvAdapter` as a Stable-Baselines3 ``VecEnv``."""

            def __init__(self, venv):
                VecEnvAdapter.__init__(self, venv)

            def render(self, mode: str | None = None):
                return VecEnv.render(self, mode)

        SB3VecEnv.__module__ = __name__
        _SB3_CLASS = SB3VecEnv
    return _SB3_CLASS


def to_sb3(venv, seed: int | None = None, monitor: bool = True):
    """The native vector env as a Stable-Baselines3 ``VecEnv``.

    Parameters
    ----------
    venv : ContactForceVectorEnv
        From ``gym.make_vec(ENV_ID, num_envs=N, vectorization_mode="vector_entry_point")``.
    seed : int, optional
        Sub-env ``i`` is reset with ``seed + i`` at the first reset (as ``make_vec_env``).
    monitor : bool
        Wrap in SB3's ``VecMonitor`` (episode returns and lengths in ``infos``, shown by
        ``verbose=1`` and kept in ``model.ep_info_buffer``).

    Returns
    -------
    stable_baselines3.common.vec_env.VecEnv
    """
    envs = _sb3_class()(venv)
    if seed is not None:
        envs.seed(seed)
    if monitor:
        from stable_baselines3.common.vec_env import VecMonitor
        envs = VecMonitor(envs)
    return envs


def _env_config(env):
    """The :class:`~ebraille_sim.rl.env.EnvConfig` of an env, adapter, wrapper, config or kwargs dict."""
    from ebraille_sim.rl.env import EnvConfig
    if isinstance(env, EnvConfig):
        return env
    if isinstance(env, dict):
        return EnvConfig(**env)
    seen = env
    for _ in range(10):
        cfg = getattr(seen, "config", None)
        if isinstance(cfg, EnvConfig):
            return cfg
        nxt = getattr(seen, "venv", None) or getattr(seen, "env", None) or getattr(seen, "unwrapped", None)
        if nxt is None or nxt is seen:
            break
        seen = nxt
    raise ValueError(f"cannot find the env configuration of {type(env).__name__}; pass the env, its "
                     "EnvConfig or the keyword arguments it was made with")


def policy_metadata(model_or_algo, env) -> dict:
    """The policy metadata (``ebraille-sim-policy/1``) of an SB3 model trained on ``env``.

    Parameters
    ----------
    model_or_algo : stable_baselines3 model or str
        A PPO or SAC model, or ``"ppo"`` / ``"sac"``.
    env : env, VecEnv, EnvConfig or dict
        What the model was trained on: the adapter from :func:`to_sb3` (also wrapped),
        the native vector env, a scalar env, its :class:`~ebraille_sim.rl.env.EnvConfig` or the
        keyword arguments the env was made with (``{}`` for the defaults).
    """
    from controllers.policy import ALGORITHMS, POLICY_FORMAT

    from ebraille_sim.rl.env import ENV_ID
    algo = model_or_algo if isinstance(model_or_algo, str) else type(model_or_algo).__name__
    algo = algo.lower()
    if algo not in ALGORITHMS:
        raise ValueError(f"algorithm must be one of {', '.join(ALGORITHMS)}, got {algo!r}")
    cfg = _env_config(env)
    training = {"source": "stable-baselines3"}
    steps = getattr(model_or_algo, "num_timesteps", None)
    if isinstance(steps, (int, np.integer)):
        training["steps"] = int(steps)
    training["estimator"] = cfg.estimator_metadata()
    return {"format": POLICY_FORMAT, "algo": algo, "env_id": ENV_ID, "env": cfg.policy_metadata(),
            "training": training}


def write_policy_metadata(path, model_or_algo, env) -> str:
    """Write the metadata beside a model saved with ``model.save`` so ``policy:PATH.zip`` loads it;
    given the model (not only its algorithm), also its deterministic actor as ``PATH.npz``
    (:func:`controllers.policy.save_actor`), which then runs without PyTorch.

    Parameters
    ----------
    path : str or path-like
        The saved model, ``PATH.zip`` (or ``PATH`` as given to ``model.save``).
    model_or_algo, env
        As :func:`policy_metadata`.

    Returns
    -------
    str
        The file written, ``PATH.json``.
    """
    path = os.fspath(path)
    stem = path[:-4] if path.endswith(".zip") else path
    meta = policy_metadata(model_or_algo, env)
    out = stem + ".json"
    from ebraille_sim.base.files import write_file
    write_file(out, json.dumps(meta, indent=2) + "\n", "policy metadata")
    if not isinstance(model_or_algo, str):
        from controllers.policy import actor_from_sb3, save_actor
        save_actor(actor_from_sb3(model_or_algo), stem + ".npz")
    return out
