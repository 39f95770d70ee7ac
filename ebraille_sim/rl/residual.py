r"""Residual Gymnasium environment: learn a bounded correction on top of a named design.

``gym.make("EBraille/ContactForceResidual-v0", residual="dob_100hz")`` (or
:class:`ResidualEnv` directly).  The episodes are those of
:class:`ebraille_sim.rl.env.ContactForceEnv` (the same
:class:`~ebraille_sim.scenarios.episodes.EpisodeDistribution` draws, the same reward), with
three differences:

* **Rate.**  One step is one period of the firmware the policy works in: the design's control
  rate, ``control_rate_hz`` (default 1 kHz, the rate of the shipped scenarios and of both
  firmware presets), not a slower policy held inside a faster loop.
* **Residual action.**  The design's controller (:func:`controllers.make` of the name, on its
  firmware preset: every drawn device carries the preset's estimator settings) runs in the
  loop, inside the safety supervisor, exactly as ``ebraille-sim run --controller DESIGN``
  runs it; the action ``a`` in [-1, 1] adds ``a * residual_limit_v`` volts to its command
  (:class:`controllers.residual.ResidualPolicy`).  A design with a compiled form runs in the
  loop engine, one compiled call per step (:func:`residual_step`); one without (a refresh
  learner) is called from Python through the runner's per-period shim
  (:func:`ebraille_sim.scenarios.runner.python_periods`).  Both give the same steps to the
  last bit.  Zero actions reproduce
  ``run_scenario(env.episode.spec, controller=DESIGN)`` to the last bit
  (``tests/test_residual_env.py``).
* **Observation.**  What the board has, per frame: the features of
  :mod:`controllers.features` (force estimate, setpoint, error, filtered rate of the
  estimate, error integral, previous applied command, the sensed motor current
  ``S.current_meas_a`` through the current chain) and the previous residual action;
  ``history`` frames stacked, newest first (``Box`` of ``8 * history`` float32 numbers).

The reward is :func:`ebraille_sim.rl.env.reward_of` with the effort term on the residual
action (``w_u a^2``: the design's own command costs nothing, so zero actions are not
penalised), and an episode ends as the plain env's does.

**Curriculum over the population.**  With ``curriculum_steps`` > 0 the device population's
spread grows with the env's own step count ``n``: every range of
:class:`~ebraille_sim.scenarios.population.PopulationSpec` is shrunk about its centre, and
every standard deviation scaled, by ``s = s0 + (1 - s0) min(1, n / curriculum_steps)``, with
``s0 = curriculum_start`` (:func:`scaled_population`); ``s`` is taken in steps of 1/16 so
that few distributions are built.  The draw of each episode depends only on its seed and
``s``, so the same seed gives the same episodes.

**Refresh reading.**  With ``refresh_probability`` > 0 that share of the episodes (drawn from
a child of the episode seed that the rest of the draw does not use) is read in refresh mode:
every character is pressed to the setpoint, held and released to the reading spec's lift force
(``[reading] mode = "refresh"``, the mode of the benchmark's ``refresh_*`` scenarios); the
other draws of the episode stay as they are.

Reset options are those of the plain env (:data:`ebraille_sim.rl.episode.OPTION_KEYS`).

## Arguments

Those of :class:`ResidualConfig` (``residual``, ``residual_limit_v``, ``history``,
``curriculum_steps``, ``curriculum_start``, ``refresh_probability``), ``control_rate_hz``
(default 1000 Hz) and any other argument of the plain env (:class:`~ebraille_sim.rl.episode.EnvConfig`:
``safe_force_n``, ``effort_weight``, ``safety``, ``base_device``, ...); the plant is the lumped one.
An unknown argument or a value out of range is a one-line ``ValueError`` naming it.

Examples
--------
>>> import gymnasium as gym
>>> import numpy as np
>>> import ebraille_sim
>>> env = gym.make("EBraille/ContactForceResidual-v0", residual="dob_100hz", history=4)
>>> obs, info = env.reset(seed=0)
>>> obs.shape
(32,)
>>> obs, reward, terminated, truncated, info = env.step(np.zeros(1, np.float32))
>>> info["residual_v"]
0.0
"""
from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from controllers.features import C_SAFE
from controllers.residual import P_ACTION, P_FIRST, P_RESIDUAL, peek_frame
from ebraille_sim.base.compiled import entry_point, njit
from ebraille_sim.base.fields import sourced
from ebraille_sim.base.seeds import SeedNode
from ebraille_sim.base.validation import check_number, check_range
from ebraille_sim.plant import engine
from ebraille_sim.plant.layout import S
from ebraille_sim.rl.env import reward_of
from ebraille_sim.rl.episode import EnvConfig, episode_from_spec, estimator_model, validate_options
from ebraille_sim.rl.registration import RESIDUAL_ENV_ID
from ebraille_sim.rl.render import RenderedEnv

__all__ = ["RESIDUAL_ENV_ID", "ResidualConfig", "ResidualEnv", "scaled_population", "residual_device"]


CURRICULUM_LEVELS = 16
"""The population spread of a curriculum is taken in steps of ``1 / CURRICULUM_LEVELS``."""


@dataclass(frozen=True)
class ResidualConfig:
    """What the residual env adds to :class:`~ebraille_sim.rl.episode.EnvConfig`."""
    residual: str = sourced("dob_100hz", "-", "the design the correction is added to (a shipped design or a design file)")
    residual_limit_v: float = sourced(1.0, "V", "correction at |action| = 1, added to the design's command",
                                      positive=True)
    history: int = sourced(1, "-", "frames stacked in the observation, newest first", lo=1)
    curriculum_steps: int = sourced(0, "steps", "env steps over which the population spread grows to full "
                                                "(0: the full population from the start)", nonneg=True)
    curriculum_start: float = sourced(0.25, "-", "population spread at the start of the curriculum, as a "
                                                 "fraction of the full spread", lo=0.0, hi=1.0)
    refresh_probability: float = sourced(0.0, "-", "chance that an episode is read in refresh mode (every "
                                                   "character pressed, held and released)", lo=0.0, hi=1.0)

    def __post_init__(self):
        import controllers
        from controllers.designs import designs, get_design
        from controllers.residual import MAX_HISTORY
        if not isinstance(self.residual, str) or not self.residual:
            raise ValueError(f"residual must name a design, got {self.residual!r}")
        if self.residual not in controllers.available():
            try:
                get_design(self.residual)
            except FileNotFoundError as exc:
                raise ValueError(f"residual: {exc}") from None
            except ValueError:
                raise ValueError(f"unknown design {self.residual!r} for residual; available: "
                                 f"{', '.join(designs())}, a controller ({', '.join(controllers.available())}) "
                                 "or a design file .toml/.json") from None
        check_range("residual_limit_v", self.residual_limit_v, 0.0, 100.0, lo_open=True)
        object.__setattr__(self, "history", check_number("history", self.history, 1, MAX_HISTORY, integer=True))
        object.__setattr__(self, "curriculum_steps",
                           check_number("curriculum_steps", self.curriculum_steps, 0, 10 ** 12, integer=True))
        check_range("curriculum_start", self.curriculum_start, 0.0, 1.0)
        check_range("refresh_probability", self.refresh_probability, 0.0, 1.0)

    def metadata(self) -> dict:
        """The entries a policy file records so that a controller rebuilds the policy's loop."""
        return {"residual": self.residual, "residual_limit_v": self.residual_limit_v, "history": self.history}


def residual_device(design: str, base=None):
    """``base`` (default the nominal device) with the estimator settings of the design's
    firmware preset (unchanged for a design without one, or a controller's name)."""
    from ebraille_sim.base.validation import replace_checked
    from ebraille_sim.estimation.presets import get_firmware
    from ebraille_sim.physics.params import DeviceParams
    from ebraille_sim.scenarios.runner import design_firmware
    base = DeviceParams() if base is None else base
    fw = design_firmware(design)
    if fw is None:
        return base
    return dataclasses.replace(base, estimator=replace_checked(base.estimator, **get_firmware(fw).estimator))


def scaled_population(spec, spread: float):
    """``spec`` (a :class:`~ebraille_sim.scenarios.population.PopulationSpec`) with every
    range shrunk about its centre and every standard deviation scaled by ``spread`` in [0, 1]."""
    check_range("spread", spread, 0.0, 1.0)
    changes = {}
    for f in dataclasses.fields(spec):
        v = getattr(spec, f.name)
        if isinstance(v, tuple):
            mid, half = 0.5 * (v[0] + v[1]), 0.5 * (v[1] - v[0])
            changes[f.name] = (mid - spread * half, mid + spread * half)
        elif isinstance(v, float):
            changes[f.name] = spread * v
    return dataclasses.replace(spec, **changes)


@functools.lru_cache(maxsize=2 * CURRICULUM_LEVELS)
def _distribution_at(cfg: EnvConfig, level: int):
    """The config's episode distribution with the population at spread ``level / CURRICULUM_LEVELS``."""
    dist = cfg.distribution()
    if dist.population is None or level >= CURRICULUM_LEVELS:
        return dist
    return dataclasses.replace(dist, population=scaled_population(dist.population, level / CURRICULUM_LEVELS))


@njit(cache=True)
def residual_step(state, params, inputs, n_sub, kind, cstate, cparams, supervised, sv, cfg, setpoint, dt, slots,
                  table, k, p, z, frames, obs_policy, c, layers, weights, zc, fc, buf, obs_next):
    """One step of the residual env in one compiled call: period ``k`` of the residual policy
    with the agent's action ``p[P_ACTION]`` on the design's compiled controller inside the
    supervisor (:func:`ebraille_sim.plant.engine.policy_period`), then the reward (on the
    residual action held) and the next observation (``obs_next``,
    :meth:`~controllers.residual.ResidualPolicy.peek`).

    Returns ``(status, command_v, force_true_n, force_est_n, reward, violation, terminated)``;
    a status other than :data:`ebraille_sim.plant.engine.OK` leaves the plant at the period's start.
    """
    status, u = engine.policy_period(state, params, inputs, n_sub, kind, cstate, cparams, supervised, sv, cfg,
                                     setpoint[k], dt, S.force_est_n, slots, table, k, p, z, frames, obs_policy, c,
                                     layers, weights, zc, fc, buf)
    if status != engine.OK:
        return status, u, math.nan, math.nan, math.nan, 0.0, False
    ft = state[S.contact_force_n]
    fe = state[S.force_est_n]
    r, v = reward_of(c, ft, setpoint[k], p[P_RESIDUAL])
    peek_frame(z, frames, c, fe, setpoint[k + 1], state[S.current_meas_a], dt, p[P_FIRST] != 0.0, p[P_RESIDUAL],
               obs_next)
    return status, u, ft, fe, r, v, ft > c[C_SAFE]


class ResidualEnv(RenderedEnv, gym.Env):
    __doc__ = __doc__

    metadata = {"render_modes": ["rgb_array"], "render_fps": 25}

    def __init__(self, residual: str = "dob_100hz", residual_limit_v: float = 1.0, history: int = 1,
                 curriculum_steps: int = 0, curriculum_start: float = 0.25, refresh_probability: float = 0.0,
                 control_rate_hz: float = 1000.0, render_mode: str | None = None, **env_kwargs):
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode {render_mode!r} is not supported; allowed: None, rgb_array")
        self.render_mode = render_mode
        self._renderer = None
        if env_kwargs.get("backend", "lumped") != "lumped":
            raise ValueError(f"the residual env runs the lumped plant, got backend {env_kwargs['backend']!r}")
        self.residual_config = ResidualConfig(residual=residual, residual_limit_v=residual_limit_v, history=history,
                                              curriculum_steps=curriculum_steps, curriculum_start=curriculum_start,
                                              refresh_probability=refresh_probability)
        allowed = [f.name for f in dataclasses.fields(EnvConfig) if f.name != "control_rate_hz"]
        for key in env_kwargs:
            if key not in allowed:
                raise ValueError(f"unknown argument {key!r} of the residual env; allowed besides its own: "
                                 f"{', '.join(allowed)}")
        base = residual_device(residual, env_kwargs.pop("base_device", None))
        self.config = EnvConfig(control_rate_hz=control_rate_hz, base_device=base, **env_kwargs)
        from controllers.residual import N_FRAME, frame_bounds
        lo, hi = frame_bounds(self.residual_config.history)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)
        self.observation_space = spaces.Box(lo, hi, dtype=np.float32)
        self._n_frame = N_FRAME
        self._c = self.config.config_vector()
        self._master: SeedNode | None = None
        self.episode = None
        self.plant = None
        self.steps_taken = 0
        self._k = 0
        self._n_steps = 0
        self._fast = None

    # -- curriculum -------------------------------------------------------------------------
    def spread(self) -> float:
        """The population spread of the next episode (1: the full population)."""
        rc = self.residual_config
        if rc.curriculum_steps == 0:
            return 1.0
        s0 = rc.curriculum_start
        s = s0 + (1.0 - s0) * min(1.0, self.steps_taken / rc.curriculum_steps)
        return math.floor(s * CURRICULUM_LEVELS + 1e-9) / CURRICULUM_LEVELS

    # -- episode ----------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        from controllers.residual import ActionSlot, ResidualPolicy
        from ebraille_sim.plant.backends import make_plant
        from ebraille_sim.scenarios.runner import make_controller, wrap_controller
        opt = validate_options(options, self.config.safe_force_n)
        if seed is not None:
            self._master = SeedNode(int(seed))
        elif self._master is None:
            self._master = SeedNode(int(self.np_random.integers(0, 2**63)))
        ss = self._master.spawn(1)[0]
        level = int(round(self.spread() * CURRICULUM_LEVELS))
        spec = _distribution_at(self.config, level).draw(ss, opt)
        p = self.residual_config.refresh_probability
        if p > 0.0 and np.random.default_rng(ss.spawn(1)[0]).random() < p:     # a child the draw did not use
            spec = dataclasses.replace(spec, reading=dataclasses.replace(spec.reading, mode="refresh"))
        ep = episode_from_spec(spec)
        dev = ep.device
        self.plant = make_plant([dev], [ep.sensor_seed], backend="lumped", models=[estimator_model(dev.estimator.model)])
        self.plant.inputs[0] = ep.run.initial_inputs()
        self._st = self.plant.state[0]
        cfg = self.config
        rc = self.residual_config
        self._slot = ActionSlot()
        self.controller = ResidualPolicy(make_controller(ep.spec, rc.residual), self._slot, rc.residual_limit_v,
                                         cfg.control_rate_hz, rc.history, cfg.safe_force_n, cfg.warn_force_n,
                                         cfg.rate_filter_s, cfg.integral_time_s, cfg.base_device.driver_supply_v,
                                         cfg.current_scale_a)
        self._wrapped = wrap_controller(ep.spec, self.controller, ep.run.dt_s, cfg.safety)
        self._sp = ep.run.setpoint_n[None, :ep.n_steps]
        fe = float(self._st[S.force_est_n])
        self._wrapped.reset(force_est_n=fe, setpoint_n=float(self._sp[0, 0]), command_v=0.0)
        self._fast = self._fast_step(ep)
        self.episode = ep
        self._k = 0
        self._n_steps = ep.n_steps
        obs = self._observe()
        return obs, {"force_true_n": float(self._st[S.contact_force_n]), "force_est_n": fe,
                     "setpoint_n": float(ep.setpoint_n[0]), "spread": level / CURRICULUM_LEVELS}

    def _fast_step(self, ep):
        """The compiled step's arguments (:func:`residual_step`) when the design has a compiled
        form and runs alone or inside the safety supervisor, else None (the design then runs
        from Python, through the runner's per-period shim)."""
        from ebraille_sim.scenarios.runner import _compiled_controller, _engine_rows
        pol = self.controller
        form = _compiled_controller(pol.base, self._wrapped, inner=pol)
        if form is None:
            return None
        rows = _engine_rows(self.plant, [form], self._sp, [ep.run.profiles], self.plant.control_dt_s, S.force_est_n,
                            None, 0)
        c = int(rows.counts[0])
        bundle = pol.compiled_policy(rows.dt, handed=True)
        args = [rows.states[0], rows.params[0], rows.inputs[0], rows.n_sub, int(rows.kinds[0]), rows.cstates[0],
                rows.cparams[0], bool(rows.supervised[0]), rows.sv_states[0], rows.sv_cfgs[0], ep.setpoint_n,
                rows.dt, rows.slots[0, :c], rows.tables[0, :c], 0, *bundle[:4], self._c, *bundle[5:],
                np.empty_like(pol._obs)]
        return entry_point(residual_step, *args), args, bundle[0]

    def _step_fast(self, a: float, k: int):
        step, args, p = self._fast
        args[14] = k
        p[P_ACTION] = a
        status, u, ft, fe, r, v, term = step(*args)
        if status != engine.OK:
            raise ValueError(f"command_v must be finite, got {u}" if status == engine.BAD_COMMAND else
                             f"non-finite controller input at control period {k}")
        self.controller.took(p)
        return u, ft, fe, r, v, term, args[-1].copy()

    def _observe(self) -> np.ndarray:
        st = self._st
        return self.controller.peek(float(st[S.force_est_n]), float(self.episode.setpoint_n[self._k]),
                                    self.config.dt_s, float(st[S.current_meas_a]))

    def step(self, action):
        from ebraille_sim.rl.env import check_action
        from ebraille_sim.scenarios.runner import python_periods
        if self.episode is None:
            raise RuntimeError("call reset() before step()")
        a = check_action(action)
        k = self._k
        if k >= self._n_steps:
            raise RuntimeError("the episode has ended (terminated or truncated); call reset() before step()")
        a = -1.0 if a < -1.0 else (1.0 if a > 1.0 else a)
        ep = self.episode
        if self._fast is not None:
            u, ft, fe, r, v, term, obs = self._step_fast(a, k)
        else:
            self._slot.action = a
            rows, _ = python_periods(self.plant, [self._wrapped], self._sp, [ep.run.profiles], S.force_est_n, None,
                                     1, k0=k, n_record=0)
            u = float(rows.u_ext[0])
            ft = float(self._st[S.contact_force_n])
            fe = float(self._st[S.force_est_n])
            r, v = reward_of(self._c, ft, float(ep.setpoint_n[k]), self.controller.residual)
            term = ft > self.config.safe_force_n
            obs = None
        self._k = k + 1
        self.steps_taken += 1
        if not math.isfinite(ft):
            raise FloatingPointError("the simulation diverged (non-finite contact force)")
        truncated = self._k >= self._n_steps
        if term:
            self._n_steps = self._k
        if obs is None:
            obs = self._observe()
        info = {"force_true_n": ft, "force_est_n": fe,
                "setpoint_n": float(ep.setpoint_n[self._k]), "command_v": u,
                "residual_v": self.controller.residual_v, "violation": float(v), "time_s": self._k * self.config.dt_s}
        return obs, float(r), bool(term), bool(truncated), info
