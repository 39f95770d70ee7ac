"""A trained reinforcement-learning policy used as a contact-force controller.

``controllers.make("policy:PATH")`` (and ``ebraille-sim run SCENARIO --controller
policy:PATH``) loads a saved Stable-Baselines3 policy with the JSON metadata beside it
(format ``ebraille-sim-policy/1``: the algorithm and the environment settings the
observation depends on):

* ``PATH`` is a folder written by ``ebraille-sim train``: ``PATH/policy.zip`` and
  ``PATH/policy.json``;
* ``PATH`` is a model saved with SB3's ``model.save`` (``PATH.zip``, or ``PATH`` as given
  to ``model.save``): the metadata is ``PATH.json``, written after training with
  :func:`ebraille_sim.rl.sb3.write_policy_metadata` from the env the model was trained on.
  Without it the load is a one-line error naming the missing file.
* ``PATH`` is the name of a shipped policy (:func:`shipped_policies`), when no file or
  folder of that name exists: ``ppo`` and ``sac`` (trained on the default env) and
  ``ppo_hc`` (PPO trained on the hysteresis-compensated estimator).  They are package data
  (``ebraille_sim/data/policies/NAME/``: ``policy.json`` and the NumPy actor
  ``policy.npz``, no ``policy.zip``), so they run deterministically only.

A **residual policy** (trained on ``EBraille/ContactForceResidual-v0``, e.g. ``ebraille-sim
train --recipe residual_ppo_1khz``) names in its metadata the design it corrects, the
correction's limit and its observation history (``env.residual``, ``env.residual_limit_v``,
``env.history``); ``controllers.make("policy:PATH")`` returns it as a
:class:`controllers.residual.ResidualPolicy`: the design's controller with the learned
correction added, run on the design's firmware preset by the scenario runner.

The controller sees only what the microcontroller sees (estimated force, setpoint, time
step, motor current) and builds the policy's observation with the same compiled function
as the environment (:func:`ebraille_sim.rl.env.observe`), so a policy behaves in a scenario as
it did in training.

Sampling: the policy acts at the rate it was trained at (``control_rate_hz`` in
``policy.json``, 200 Hz by default).  When the scenario's loop runs faster, the controller
counts the ``dt_s`` it is given and evaluates the policy once a training period of
simulated time has passed, holding the command in between (a zero-order hold, as a
200 Hz task on a 1 kHz microcontroller would).  No wall clock is read.  The first
``update`` after ``reset`` always evaluates.

Unlike :class:`controllers.PID`, the start is not bumpless: the first command is whatever
the policy outputs for the first observation (``command_v`` given to ``reset`` is
shown to the policy as its previous action).

The deterministic actor is also kept as ``policy.npz`` beside ``policy.zip`` (written by
``ebraille-sim train`` and :func:`ebraille_sim.rl.sb3.write_policy_metadata`; format
:data:`ACTOR_FORMAT`): where it exists, a deterministic policy runs from it with NumPy
(:class:`MlpActor`), without PyTorch or Stable-Baselines3 and at the cost of a few small
matrix products per evaluation.  Otherwise, and for ``deterministic=False``,
Stable-Baselines3 (and PyTorch) are imported when the policy is loaded; install them with
``pip install 'ebraille-sim[rl]'``.

Examples
--------
>>> import controllers
>>> ctrl = controllers.make("policy:runs/train-ppo")        # doctest: +SKIP
>>> ctrl.reset(force_est_n=0.0, setpoint_n=1.0)             # doctest: +SKIP
>>> volts = ctrl.update(0.0, 1.0, 1e-3, motor_current_a=0.0)  # doctest: +SKIP
"""
from __future__ import annotations

import importlib.resources
import math
import os

import numpy as np

from ebraille_sim.base.validation import check_keys, check_number, read_table

from controllers.base import check_dt, check_finite
from controllers.features import (CURRENT_SCALE_A, N_OBS, N_Z, Z_PREV_ACTION, config_vector, observe, policy_action,
                                  reset_features, write_observation)

__all__ = ["ACTOR_FORMAT", "ALGORITHMS", "POLICY_FORMAT", "MlpActor", "PolicyController", "actor_from_sb3",
           "load_actor", "load_policy", "residual_design", "save_actor", "shipped_policies", "policy_folder"]

POLICY_FORMAT = "ebraille-sim-policy/1"
ALGORITHMS = ("ppo", "sac")
_META_KEYS = ("format", "algo", "env_id", "env", "training")
_ENV_KEYS = ("control_rate_hz", "safe_force_n", "warn_force_n", "rate_filter_s", "integral_time_s",
             "effort_weight", "violation_weight", "driver_supply_v")
_ENV_OPTIONAL_KEYS = ("current_scale_a", "residual", "residual_limit_v", "history")
_PERIOD_TOL = 1e-6


ACTOR_FORMAT = "ebraille-sim-mlp/1"
"""Value of ``format`` in a ``policy.npz`` written by :func:`save_actor`."""

_ACTIVATIONS = {"tanh": np.tanh, "relu": lambda x: np.maximum(x, np.float32(0.0))}
_ACTIVATION_CODES = {"tanh": 0, "relu": 1}


class MlpActor:
    """The deterministic action of a Stable-Baselines3 MLP actor, evaluated with NumPy.

    ``a = out(W_k act(... act(W_1 x + b_1) ...) + b_k)`` in float32, with ``act`` the
    hidden layers' activation (``tanh`` for SB3's PPO, ``relu`` for its SAC) and ``out``
    the identity then a clip to [-1, 1] (PPO's Gaussian mean, clipped as SB3's ``predict``
    clips it) or ``tanh`` (SAC's squashed mean).  It has SB3's ``predict`` signature, so
    :class:`PolicyController` runs it as it runs an SB3 model; it needs neither PyTorch nor
    Stable-Baselines3.  Its actions equal SB3's to float32 rounding (the sums run in another
    order; tested to 1e-5).
    """

    def __init__(self, weights, biases, activation: str, squash: bool):
        if activation not in _ACTIVATIONS:
            raise ValueError(f"unknown activation {activation!r}; allowed: {', '.join(_ACTIVATIONS)}")
        if not weights or len(weights) != len(biases):
            raise ValueError("an MLP actor needs one bias per weight matrix, and at least one layer")
        self.weights = [np.ascontiguousarray(w, dtype=np.float32) for w in weights]
        self.biases = [np.ascontiguousarray(b, dtype=np.float32) for b in biases]
        for k, (w, b) in enumerate(zip(self.weights, self.biases)):
            if w.ndim != 2 or b.shape != (w.shape[0],) or (k and w.shape[1] != self.weights[k - 1].shape[0]):
                raise ValueError(f"layer {k} of the MLP actor has shapes {w.shape} and {b.shape}, "
                                 "which do not chain")
            if not (np.all(np.isfinite(w)) and np.all(np.isfinite(b))):
                raise ValueError(f"layer {k} of the MLP actor holds non-finite weights")
        self.activation = activation
        self.squash = bool(squash)
        self._act = _ACTIVATIONS[activation]

    def vectors(self):
        """``(layers, weights)`` of this actor for the compiled forward pass
        (:func:`controllers.residual.mlp_action`), or None for one output other than a single
        action.  ``layers`` (int64): the number of layers, the activation's code (0 tanh, 1
        relu), the squash flag, then the widths from the input on; ``weights`` (float32): each
        layer's matrix (row-major), then its bias."""
        if self.weights[-1].shape[0] != 1:
            return None
        widths = [self.weights[0].shape[1]] + [w.shape[0] for w in self.weights]
        layers = np.array([len(self.weights), _ACTIVATION_CODES[self.activation], int(self.squash)] + widths,
                          dtype=np.int64)
        weights = np.concatenate([np.concatenate([w.ravel(), b]) for w, b in zip(self.weights, self.biases)])
        return layers, weights.astype(np.float32)

    def predict(self, observation, deterministic: bool = True):
        """``(action of shape (n_out,), None)`` for one observation, as SB3's ``predict``."""
        if not deterministic:
            raise ValueError("a NumPy policy gives the deterministic action only; load the .zip with "
                             "Stable-Baselines3 for sampled actions")
        h = np.asarray(observation, dtype=np.float32).reshape(-1)
        if h.shape[0] != self.weights[0].shape[1]:
            raise ValueError(f"observation of {h.shape[0]} values for an actor that takes {self.weights[0].shape[1]}")
        for w, b in zip(self.weights[:-1], self.biases[:-1]):
            h = self._act(w @ h + b)
        a = self.weights[-1] @ h + self.biases[-1]
        a = np.tanh(a) if self.squash else np.clip(a, np.float32(-1.0), np.float32(1.0))
        return a.astype(np.float32), None


def save_actor(actor: MlpActor, path) -> str:
    """Write ``actor`` as ``policy.npz`` (format :data:`ACTOR_FORMAT`); returns the path."""
    arrays = {"format": np.array(ACTOR_FORMAT), "activation": np.array(actor.activation),
              "squash": np.array(actor.squash), "layers": np.array(len(actor.weights))}
    for k, (w, b) in enumerate(zip(actor.weights, actor.biases)):
        arrays[f"w{k}"], arrays[f"b{k}"] = w, b
    from ebraille_sim.base.files import staged_file
    path = os.fspath(path)
    with staged_file(path, "policy file") as tmp, open(tmp, "wb") as fh:
        np.savez(fh, **arrays)
    return path


MAX_ACTOR_BYTES = 256 * 2 ** 20
"""Largest ``policy.npz`` read (256 MiB; the trained actors hold a few hundred KiB)."""


def load_actor(path) -> MlpActor:
    """Read a ``policy.npz`` written by :func:`save_actor`; one-line ValueError if it is not one."""
    import io

    from ebraille_sim.base.files import read_bytes
    path = os.fspath(path)
    raw = read_bytes(path, "policy actor", MAX_ACTOR_BYTES)
    try:
        with np.load(io.BytesIO(raw), allow_pickle=False) as z:
            if "format" not in z.files or str(z["format"]) != ACTOR_FORMAT:
                raise ValueError(f"{path}: not a policy actor (format {ACTOR_FORMAT!r} expected)")
            n = int(z["layers"])
            return MlpActor([z[f"w{k}"] for k in range(n)], [z[f"b{k}"] for k in range(n)],
                            str(z["activation"]), bool(z["squash"]))
    except (OSError, KeyError, ValueError, EOFError) as exc:
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ValueError(msg if msg.startswith(path) else f"{path}: cannot read the policy actor ({msg})") from None


def actor_from_sb3(model) -> MlpActor:
    """The deterministic actor of a Stable-Baselines3 PPO or SAC model with an MLP policy."""
    policy = model.policy
    if hasattr(policy, "actor") and hasattr(policy.actor, "latent_pi"):       # SAC
        hidden, out, squash = policy.actor.latent_pi, policy.actor.mu, True
    elif hasattr(policy, "mlp_extractor") and hasattr(policy, "action_net"):   # PPO
        hidden, out, squash = policy.mlp_extractor.policy_net, policy.action_net, False
        if getattr(policy, "squash_output", False):
            raise ValueError("a PPO policy with squashed output (gSDE) is not supported by the NumPy actor")
    else:
        raise ValueError(f"unsupported policy {type(policy).__name__}: the NumPy actor reads SB3's MLP "
                         "policies of PPO and SAC")
    weights, biases, acts = [], [], set()
    for layer in list(hidden) + [out]:
        name = type(layer).__name__
        if name == "Linear":
            weights.append(layer.weight.detach().cpu().numpy())
            biases.append(layer.bias.detach().cpu().numpy())
        elif name.lower() in _ACTIVATIONS:
            acts.add(name.lower())
        else:
            raise ValueError(f"unsupported layer {name} in the policy network")
    if len(acts) > 1:
        raise ValueError(f"the policy network mixes activations {sorted(acts)}")
    return MlpActor(weights, biases, acts.pop() if acts else "tanh", squash)


def shipped_policies() -> dict[str, str]:
    """The shipped policies, ``{name: folder}`` (``ebraille_sim/data/policies/NAME``), sorted by name.

    >>> sorted(shipped_policies())
    ['ppo', 'ppo_hc', 'sac']
    """
    root = importlib.resources.files("ebraille_sim") / "data" / "policies"
    return {p.name: str(p) for p in sorted(root.iterdir(), key=lambda p: p.name)
            if p.is_dir() and (p / "policy.json").is_file()}


def policy_folder(path) -> str:
    """The folder of the shipped policy named ``path`` when no file or folder ``path`` (nor
    ``path.zip``) exists; otherwise ``path`` unchanged (a path that exists wins over a name).

    >>> policy_folder("ppo").endswith("ppo")
    True
    """
    path = os.fspath(path)
    if os.path.exists(path) or os.path.exists(path + ".zip"):
        return path
    return shipped_policies().get(path, path)


def _paths(path: str) -> tuple[str, str]:
    path = policy_folder(path)
    if os.path.isdir(path):
        return os.path.join(path, "policy.zip"), os.path.join(path, "policy.json")
    if path.endswith(".zip"):
        return path, path[:-4] + ".json"
    if os.path.isfile(path + ".zip"):
        return path + ".zip", path + ".json"
    raise ValueError(f"policy path {path!r} must be a folder written by 'ebraille-sim train', a .zip file "
                     f"saved by Stable-Baselines3 or a shipped policy ({', '.join(shipped_policies())})")


def _actor_path(zip_path: str) -> str:
    """``policy.npz`` beside ``policy.zip`` (``PATH.npz`` beside ``PATH.zip``)."""
    return zip_path[:-4] + ".npz"


def read_metadata(json_path: str) -> dict:
    """Read and validate ``policy.json``; one-line errors for anything unexpected."""
    meta = read_table(json_path, "policy metadata")
    check_keys(json_path, meta, _META_KEYS)
    if meta.get("format") != POLICY_FORMAT:
        raise ValueError(f"{json_path}: format must be {POLICY_FORMAT!r}, got {meta.get('format')!r}")
    if meta.get("algo") not in ALGORITHMS:
        raise ValueError(f"{json_path}: algo must be one of {', '.join(ALGORITHMS)}, got {meta.get('algo')!r}")
    env = meta.get("env")
    if not isinstance(env, dict):
        raise ValueError(f"{json_path}: 'env' must be an object")
    check_keys(f"{json_path} 'env'", env, _ENV_KEYS + _ENV_OPTIONAL_KEYS)
    for key in _ENV_KEYS:
        check_number(f"{json_path}: env.{key}", env.get(key))
    if "current_scale_a" in env:
        check_number(f"{json_path}: env.current_scale_a", env["current_scale_a"], lo=0.0, lo_open=True)
    if "residual" in env:
        from controllers.residual import MAX_HISTORY
        if not isinstance(env["residual"], str) or not env["residual"]:
            raise ValueError(f"{json_path}: env.residual must name a design, got {env['residual']!r}")
        check_number(f"{json_path}: env.residual_limit_v", env.get("residual_limit_v"), lo=0.0, lo_open=True)
        check_number(f"{json_path}: env.history", env.get("history"), 1, MAX_HISTORY, integer=True)
    return meta


def residual_design(path) -> str | None:
    """The design a residual policy at ``path`` corrects (``env.residual`` of its metadata), or
    None (a policy of the whole command, or no readable policy there)."""
    try:
        _, json_path = _paths(path)
        env = read_metadata(json_path)["env"]
    except (ValueError, OSError):
        return None
    return env.get("residual")


def trained_estimator(path) -> dict | None:
    """The estimator settings a policy of the whole command at ``path`` was trained on
    (``training.estimator`` of its metadata, without the training unit's bench fields,
    :data:`~ebraille_sim.physics.params.UNIT_ESTIMATOR_FIELDS`; a policy whose metadata does
    not record them met the env's default device, the paper's 100 Hz path), or None (a residual
    policy, which runs on its design's firmware, or no readable policy there)."""
    import dataclasses

    from ebraille_sim.physics.params import UNIT_ESTIMATOR_FIELDS, EstimatorParams
    try:
        _, json_path = _paths(path)
        meta = read_metadata(json_path)
    except (ValueError, OSError):
        return None
    if meta["env"].get("residual") is not None:
        return None
    est = meta.get("training", {}).get("estimator")
    est = dataclasses.asdict(EstimatorParams()) if not isinstance(est, dict) else est
    return {k: v for k, v in est.items() if k not in UNIT_ESTIMATOR_FIELDS}


def _load_sb3(algo: str, zip_path: str):
    try:
        import stable_baselines3 as sb3
    except ModuleNotFoundError:
        raise ValueError("a policy controller needs stable-baselines3; install it with "
                         "pip install 'ebraille-sim[rl]'") from None
    if not os.path.isfile(zip_path):
        raise FileNotFoundError(f"policy file not found: {zip_path}")
    cls = {"ppo": sb3.PPO, "sac": sb3.SAC}[algo]
    return cls.load(zip_path, device="cpu")


class PolicyController:
    """Contact-force controller that runs a saved SB3 policy (see the module docstring).

    Parameters
    ----------
    model : object
        Anything with ``predict(obs, deterministic=True) -> (action, state)`` taking an
        observation of shape (7,) float32 and returning an action of shape (1,).
    env_settings : dict
        The ``env`` entry of ``policy.json`` (:meth:`ebraille_sim.rl.env.EnvConfig.policy_metadata`).
        ``current_scale_a`` is optional (default :data:`controllers.features.CURRENT_SCALE_A`,
        the nominal drive's stall current, for files written before it was recorded).
    deterministic : bool
        Use the policy's mean action (default True).
    """

    name = "policy"

    def __init__(self, model, env_settings: dict, deterministic: bool = True):
        self.model = model
        self.deterministic = bool(deterministic)
        try:
            rate = float(env_settings["control_rate_hz"])
            settings = {k: float(env_settings[k]) for k in ("safe_force_n", "warn_force_n", "rate_filter_s",
                                                            "integral_time_s")}
        except KeyError as exc:
            raise ValueError(f"policy metadata has no env setting {exc.args[0]!r}") from None
        if not (math.isfinite(rate) and rate > 0):
            raise ValueError(f"control_rate_hz must be a positive number, got {rate!r}")
        self.supply_v = float(env_settings["driver_supply_v"])
        if not self.supply_v > 0:
            raise ValueError(f"driver_supply_v must be > 0, got {self.supply_v}")
        self.period_s = 1.0 / rate
        current_scale_a = float(env_settings.get("current_scale_a", CURRENT_SCALE_A))
        self._c = config_vector(rate, driver_supply_v=self.supply_v, current_scale_a=current_scale_a, **settings)
        self._z = np.zeros(N_Z)
        self._obs = np.zeros(N_OBS, dtype=np.float32)
        self._since_s = 0.0
        self._first = True
        self._command_v = 0.0
        self.last_observation = self._obs

    def reset(self, *, force_est_n: float, setpoint_n: float, command_v: float = 0.0) -> None:
        """Forget the history; the next ``update`` evaluates the policy."""
        fe = check_finite("force_est_n", force_est_n)
        check_finite("setpoint_n", setpoint_n)
        u0 = check_finite("command_v", command_v)
        reset_features(self._z, fe)
        self._z[Z_PREV_ACTION] = min(1.0, max(-1.0, u0 / self.supply_v))
        self._since_s = 0.0
        self._first = True
        self._command_v = u0

    def applied(self, command_v: float) -> None:
        """The command that reached the drive this period (V), when a supervisor shaped it.

        The env's safety layer shows the policy the applied command, as a fraction of the
        supply, as its previous action; :class:`controllers.supervisor.Supervisor` calls this
        every period so that the next observation shows the same here.
        """
        u = float(command_v)
        if math.isfinite(u):
            self._z[Z_PREV_ACTION] = min(1.0, max(-1.0, u / self.supply_v))

    def update(self, force_est_n: float, setpoint_n: float, dt_s: float,
               motor_current_a: float | None = None) -> float:
        """Motor command, V; the policy is evaluated once per training period (held in between).

        ``motor_current_a`` None (a drive without current sensing) is observed as 0 A.
        """
        dt = check_dt(dt_s)
        fe = check_finite("force_est_n", force_est_n)
        sp = check_finite("setpoint_n", setpoint_n)
        ia = 0.0 if motor_current_a is None else check_finite("motor_current_a", motor_current_a)
        if self._first:
            write_observation(self._z, self._c, fe, sp, ia, self._obs)
        else:
            self._since_s += dt
            if self._since_s < self.period_s * (1.0 - _PERIOD_TOL):
                return self._command_v
            observe(self._z, self._c, fe, sp, ia, self._since_s, self._obs)
        self._first = False
        self._since_s = 0.0
        a = policy_action(self.model, self._obs, self.deterministic)
        self._z[Z_PREV_ACTION] = a
        self._command_v = a * self.supply_v
        return self._command_v


def load_policy(path, make_base=None, **overrides):
    """Load a saved policy and its metadata (see the module docstring for the paths).

    Parameters
    ----------
    path : str or path-like
        A folder written by ``ebraille-sim train``, or a model saved with ``model.save``
        (``PATH.zip`` or ``PATH``) with ``PATH.json`` beside it.
    make_base : callable, optional
        Builds the controller of a design by name (:func:`controllers.make`, which passes
        itself); needed for a residual policy (``env.residual`` in its metadata), which is
        returned as a :class:`controllers.residual.ResidualPolicy` around that design.
    **overrides
        ``deterministic`` (bool) only; anything else is an error.
    """
    for key in overrides:
        if key != "deterministic":
            raise ValueError(f"unknown option {key!r} for a policy controller; allowed: deterministic")
    det = overrides.get("deterministic", True)
    if not isinstance(det, bool):
        raise ValueError(f"deterministic must be True or False, got {det!r}")
    if not str(path):
        raise ValueError("policy: needs a path, e.g. policy:runs/train-ppo")
    zip_path, json_path = _paths(path)
    npz_path = _actor_path(zip_path)
    use_actor = det and os.path.isfile(npz_path)
    if not use_actor and not os.path.exists(zip_path):
        if os.path.isfile(npz_path):
            raise ValueError(f"policy {zip_path[:-4]} has only its deterministic actor ({npz_path}); "
                             "deterministic=False needs the Stable-Baselines3 model policy.zip")
        raise FileNotFoundError(f"policy file not found: {zip_path}")
    if not os.path.isfile(json_path):
        raise ValueError(f"policy {zip_path} has no metadata {json_path} (algorithm and env settings it was "
                         f"trained with); write it with ebraille_sim.rl.sb3.write_policy_metadata("
                         f"{zip_path!r}, model, env)")
    meta = read_metadata(json_path)
    model = load_actor(npz_path) if use_actor else _load_sb3(meta["algo"], zip_path)
    env = meta["env"]
    if "residual" in env:
        from controllers.residual import ResidualPolicy
        if make_base is None:
            raise ValueError(f"policy {json_path} corrects the design {env['residual']!r}; load it with "
                             f"controllers.make('policy:{path}')")
        return ResidualPolicy(make_base(env["residual"]), model, float(env["residual_limit_v"]),
                              float(env["control_rate_hz"]), int(env["history"]), float(env["safe_force_n"]),
                              float(env["warn_force_n"]), float(env["rate_filter_s"]), float(env["integral_time_s"]),
                              float(env["driver_supply_v"]), float(env.get("current_scale_a", CURRENT_SCALE_A)),
                              deterministic=det)
    return PolicyController(model, env, deterministic=det)
