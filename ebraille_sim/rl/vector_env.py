"""Native vector form of :class:`ebraille_sim.rl.env.ContactForceEnv`: N devices, one batched step.

``gymnasium.make_vec("EBraille/ContactForce-v0", num_envs=N)`` builds this class (the id's
``vector_entry_point``).  The N plants live as rows of packed arrays (state ``(N, N_STATE)``,
parameters ``(N, N_PARAM)``, inputs ``(N, N_INPUT)``, see :mod:`ebraille_sim.plant.layout`) and one
compiled call steps all of them: for every row it runs one period of the loop engine
(:func:`ebraille_sim.plant.engine.period`, the scalar env's and the scenario runner's loop
body) with the row's action as the command, its period inputs (finger position, driver
supply, ... as built for the episode's spec by :func:`ebraille_sim.scenarios.inputs.build_run_inputs`)
and its safety supervisor, and then :func:`ebraille_sim.rl.env.post_step` (the scalar env's
reward, termination and observation).
With ``parallel=True`` the rows are spread over threads with ``numba.prange``; rows are
independent, so the result does not depend on the thread count.  The default
(``parallel=None``) uses threads only where they pay, measured while it runs: with at least
two cores and two sub-envs it times the compiled step both ways (:class:`ThreadChoice`: after
one untimed call of each, :data:`PROBE_STEPS` steps of each), keeps the faster, and times the
other again every :data:`PROBE_EVERY` steps, so a machine whose load changes is followed.
Which way runs changes no number.  Idle on 2 cores threads ran 2.4-3.0 times faster than
one thread from 16 to 1024 sub-envs; with other work on both cores (load average 6) they ran
at 0.09-0.60 times one thread (``benchmarks/bench_env.py`` prints this table), which is why
no fixed rule serves.

Sub-env ``i`` is exactly the scalar env reset with seed ``seed + i`` (or ``seeds[i]``): the
same episode draws, the same packed rows (built by :meth:`ebraille_sim.plant.lumped.Plant.from_devices`)
and the same compiled step; ``tests/test_vector_env.py`` checks trajectories agree to 1e-9.

Autoreset follows Gymnasium's ``AutoresetMode.NEXT_STEP``: the step after a sub-env
terminates or truncates resets it (its action is ignored) and returns its first
observation with reward 0 and ``terminated = truncated = False``.  A sub-env is also
truncated after ``max_episode_steps`` steps (the scalar env's ``TimeLimit``; default: the
config's :meth:`~ebraille_sim.rl.env.EnvConfig.max_episode_steps`, which no episode exceeds).

Only the ``"lumped"`` backend has packed rows; the pymunk mechanism runs through the scalar
env.

Examples
--------
>>> import gymnasium as gym
>>> import numpy as np
>>> import ebraille_sim
>>> envs = gym.make_vec("EBraille/ContactForce-v0", num_envs=4)
>>> obs, info = envs.reset(seed=0)
>>> obs.shape
(4, 7)
>>> obs, rew, term, trunc, info = envs.step(np.zeros((4, 1), np.float32))
>>> rew.shape, term.dtype
((4,), dtype('bool'))
"""
from __future__ import annotations

import math
import os
import time

import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space
from ebraille_sim.base.compiled import njit, prange
from ebraille_sim.base.seeds import SeedNode
from ebraille_sim.base.validation import check_count, check_seeds

from controllers.compiled import KIND_EXTERNAL
from ebraille_sim.plant import engine
from ebraille_sim.rl.env import (
    C_CMD_SCALE,
    N_OBS,
    N_Z,
    OBS_HIGH,
    OBS_LOW,
    Z_STEP,
    EnvConfig,
    check_action,
    draw_episode,
    estimator_model,
    make_supervisor,
    post_step,
    reset_features,
    validate_options,
    write_observation,
)
from ebraille_sim.plant.layout import N_INPUT, N_PARAM, N_STATE, S, U

__all__ = ["ContactForceVectorEnv", "PROBE_EVERY", "PROBE_STEPS", "ThreadChoice", "step_row", "step_rows",
           "step_rows_serial"]

PROBE_STEPS = 4
"""Steps timed in each way of stepping when the default compares them."""

PROBE_EVERY = 256
"""Steps between two timings of the way of stepping not in use (default ``parallel``)."""

MAX_NUM_ENVS = 2 ** 16
"""Most sub-envs of one vector env (``num_envs``): their state and episode arrays are
allocated up front, so a count beyond any machine's memory is refused before any is."""


class ThreadChoice:
    """Which way the default vector env steps its rows: one thread or threads, by timing.

    :meth:`pick` names the way of the next step and :meth:`record` takes its wall time.  Each
    way's first call is not timed (it loads the compiled function and, for threads, starts the
    pool); then :data:`PROBE_STEPS` steps of each are timed, the faster way is kept, and every
    :data:`PROBE_EVERY` steps the other way is timed again for :data:`PROBE_STEPS` steps.
    """

    def __init__(self):
        self.threads = False
        self._warm = {False: False, True: False}
        self._times = {False: [], True: []}
        self._mean = {False: math.inf, True: math.inf}
        self._probing: bool | None = None
        self._countdown = PROBE_EVERY

    def pick(self) -> bool:
        """True: step on threads; False: on one thread."""
        for way in (False, True):
            if not self._warm[way] or (self._mean[way] == math.inf and len(self._times[way]) < PROBE_STEPS):
                return way
        if self._probing is not None:
            return self._probing
        self._countdown -= 1
        if self._countdown <= 0:
            self._probing = not self.threads
            self._times[self._probing] = []
            return self._probing
        return self.threads

    def record(self, way: bool, seconds: float) -> None:
        """The wall time of a step taken the way :meth:`pick` named (the way in use keeps a
        running mean of its last :data:`PROBE_STEPS` steps)."""
        if not self._warm[way]:
            self._warm[way] = True
            return
        times = self._times[way]
        times.append(float(seconds))
        if len(times) > PROBE_STEPS:
            del times[0]
        if len(times) < PROBE_STEPS:
            return
        self._mean[way] = sum(times) / len(times)
        if self._probing is None or way == self._probing:
            if way == self._probing:
                self._probing = None
                self._countdown = PROBE_EVERY
                self._times[way] = []
            self.threads = self._mean[True] < self._mean[False]


@njit(cache=True, _nrt=False)
def step_row(i, state, params, inputs, z, c, slots, counts, tables, setpoint, n_steps, actions, n_sub,
             obs, reward, violation, terminated, truncated, safety, sv2, cfg2, dt_s):
    """One control period of row ``i``: the clipped action, as a command in volts, is the
    external command of one period of the loop engine (:func:`ebraille_sim.plant.engine.period`:
    the row's varying inputs ``tables[i, j, k]`` at slots ``slots[i, :counts[i]]``, the row's
    supervisor (state ``sv2[i]``, configuration ``cfg2[i]``) when ``safety``, the command held
    within the base supply, the physics); then reward and observation, as the scalar env's step.
    """
    a = actions[i]
    if a < -1.0:
        a = -1.0
    elif a > 1.0:
        a = 1.0
    k = int(z[i, Z_STEP])
    scale = c[i, C_CMD_SCALE]
    sp = setpoint[i, min(k, setpoint.shape[1] - 1)]
    m = counts[i]
    code, u = engine.period(state[i], params[i], inputs[i], n_sub, KIND_EXTERNAL, sv2[i, :0], sv2[i, :0], a * scale,
                            scale, safety, sv2[i], cfg2[i], sp, dt_s, S.force_est_n, slots[i, :m], tables[i, :m], k)
    if code != engine.OK:
        state[i, S.contact_force_n] = math.nan               # reported as a diverged simulation
        return
    if safety:
        a = u / scale
    r, v, term = post_step(z[i], c[i], state[i, S.force_est_n], state[i, S.contact_force_n], state[i, S.current_meas_a],
                           setpoint[i, k], setpoint[i, k + 1], a, obs[i])
    reward[i] = r
    violation[i] = v
    terminated[i] = term
    truncated[i] = k + 1 >= n_steps[i]


@njit(parallel=True, cache=True)
def step_rows(state, params, inputs, z, c, slots, counts, tables, setpoint, n_steps, actions, active, n_sub,
              obs, reward, violation, terminated, truncated, safety, sv2, cfg2, dt_s):
    """:func:`step_row` for every active row, rows spread over threads (``numba.prange``)."""
    for i in prange(state.shape[0]):
        if active[i]:
            step_row(i, state, params, inputs, z, c, slots, counts, tables, setpoint, n_steps, actions, n_sub,
                     obs, reward, violation, terminated, truncated, safety, sv2, cfg2, dt_s)


@njit(cache=True, _nrt=False)
def step_rows_serial(state, params, inputs, z, c, slots, counts, tables, setpoint, n_steps, actions, active, n_sub,
                     obs, reward, violation, terminated, truncated, safety, sv2, cfg2, dt_s):
    """:func:`step_row` for every active row on one thread."""
    for i in range(state.shape[0]):
        if active[i]:
            step_row(i, state, params, inputs, z, c, slots, counts, tables, setpoint, n_steps, actions, n_sub,
                     obs, reward, violation, terminated, truncated, safety, sv2, cfg2, dt_s)


class ContactForceVectorEnv(VectorEnv):
    """``num_envs`` contact-force envs stepped together (see the module docstring).

    Parameters
    ----------
    num_envs : int
        Number of sub-envs, >= 1.
    max_episode_steps : int, optional
        Truncate a sub-env after this many steps (default: the config's
        :meth:`~ebraille_sim.rl.env.EnvConfig.max_episode_steps`).
    render_mode : str, optional
        None or ``"rgb_array"`` (``render()`` returns one frame per sub-env).
    parallel : bool, optional
        Spread the rows over threads (numba ``prange``); False runs them on one thread;
        None (default) times both ways while it runs and keeps the faster
        (:class:`ThreadChoice`), on one thread where a single core or sub-env leaves no choice.
    **env_kwargs
        The scalar env's arguments (:class:`ebraille_sim.rl.env.EnvConfig`); ``backend`` must be
        ``"lumped"``.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 25, "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(self, num_envs: int = 1, max_episode_steps: int | None = None, render_mode: str | None = None,
                 parallel: bool | None = None, **env_kwargs):
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
            raise ValueError(f"num_envs must be an integer >= 1, got {num_envs!r}")
        check_count("num_envs", num_envs, MAX_NUM_ENVS)
        if max_episode_steps is not None and (isinstance(max_episode_steps, bool) or
                                              not isinstance(max_episode_steps, (int, np.integer)) or
                                              max_episode_steps < 1):
            raise ValueError(f"max_episode_steps must be an integer >= 1 or None, got {max_episode_steps!r}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode {render_mode!r} is not supported; allowed: None, rgb_array")
        if parallel is not None and not isinstance(parallel, (bool, np.bool_)):
            raise ValueError(f"parallel must be True, False or None, got {parallel!r}")
        backend = env_kwargs.pop("backend", "lumped")
        if backend != "lumped":
            raise ValueError(f"the vector env steps packed lumped plants; backend {backend!r} is not supported "
                             "(use gymnasium.make_vec(..., vectorization_mode='sync') for other backends)")
        allowed = set(EnvConfig.__dataclass_fields__) - {"rate_filter_s", "integral_time_s", "backend"}
        for key in env_kwargs:
            if key not in allowed:
                raise ValueError(f"unknown argument {key!r}; allowed: {', '.join(sorted(allowed))}")
        self.config = EnvConfig(**env_kwargs)
        self.num_envs = int(num_envs)
        self.max_episode_steps = (self.config.max_episode_steps() if max_episode_steps is None
                                  else int(max_episode_steps))
        self.render_mode = render_mode
        cpus = os.cpu_count() or 1
        self._choice = ThreadChoice() if parallel is None and cpus >= 2 and self.num_envs >= 2 else None
        self.parallel = (False if parallel is None else bool(parallel)) if self._choice is None else False
        self._step_fn = step_rows if self.parallel else step_rows_serial
        self.single_action_space = spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.single_observation_space = spaces.Box(OBS_LOW.copy(), OBS_HIGH.copy(), dtype=np.float32)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        n = self.num_envs
        self.state = np.zeros((n, N_STATE))
        self.params = np.zeros((n, N_PARAM))
        self.inputs = np.zeros((n, N_INPUT))
        self._z = np.zeros((n, N_Z))
        self._c = np.tile(self.config.config_vector(), (n, 1))
        width = self.config.max_episode_steps() + 2
        self._slots = np.zeros((n, N_INPUT), dtype=np.int64)      # each row's varying inputs: slots,
        self._counts = np.zeros(n, dtype=np.int64)                # how many,
        self._tables = np.zeros((n, 0, width))                    # and their values per period
        self._setpoint = np.zeros((n, width))
        self._n_steps = np.zeros(n, dtype=np.int64)
        self._obs = np.zeros((n, N_OBS), dtype=np.float32)
        self._reward = np.zeros(n)
        self._violation = np.zeros(n)
        self._terminated = np.zeros(n, dtype=np.bool_)
        self._truncated = np.zeros(n, dtype=np.bool_)
        self._prev_done = np.zeros(n, dtype=np.bool_)
        self._active = np.ones(n, dtype=np.bool_)
        self._masters: list = [None] * n
        self._rngs: list = [None] * n
        self.episodes: list = [None] * n
        self._sups: list = [None] * n
        self._sv2 = self._svcfg2 = None          # the supervisors' live arrays, one row per sub-env
        self._renderer = None
        self._ready = False
        self._no_sv = np.zeros((n, 1))            # the supervisor arrays of rows without one
        self._dt = float(self.config.dt_s)
        self._substeps = self.config.substeps

    # -- episodes ------------------------------------------------------------------------------
    def _load_row(self, i: int, options: dict) -> None:
        """Draw sub-env ``i``'s next episode and write its rows (as the scalar env's reset)."""
        self._load_rows([i], options)

    def _load_rows(self, rows, options: dict) -> None:
        """Draw the next episode of every sub-env in ``rows`` and write their rows, each as the
        scalar env's reset; the supervisors' buffers are widened at most once per call."""
        from ebraille_sim.plant.lumped import initial_state, pack_params
        rows = [int(i) for i in rows]
        eps = []
        for i in rows:
            if self._masters[i] is None:
                self._masters[i] = SeedNode(int(self._rngs[i].integers(0, 2**63)))
            eps.append(draw_episode(self._masters[i].spawn(1)[0], self.config, options))
        longest = max(ep.n_steps for ep in eps)
        varying = max(len(ep.run.profiles) for ep in eps)
        if longest + 1 > self._setpoint.shape[1] or varying > self._tables.shape[1]:
            width = max(longest + 2, self._setpoint.shape[1])
            self._tables = np.pad(self._tables, ((0, 0), (0, max(0, varying - self._tables.shape[1])),
                                                 (0, width - self._tables.shape[2])))
            self._setpoint = np.pad(self._setpoint, ((0, 0), (0, width - self._setpoint.shape[1])))
        sups = []
        for i, ep in zip(rows, eps):
            dev = ep.device
            run = ep.run
            p = pack_params(dev, ep.sensor_seed, estimator_model(dev.estimator.model))
            self.params[i] = p
            self.state[i] = initial_state(dev, p, None)
            self.inputs[i] = run.initial_inputs()
            n = ep.n_steps
            self._counts[i] = len(run.profiles)
            for j, (name, arr) in enumerate(run.profiles.items()):
                self._slots[i, j] = U[name]
                self._tables[i, j, :n] = arr
            self._setpoint[i, :n + 1] = ep.setpoint_n
            self._n_steps[i] = min(n, self.max_episode_steps)
            fe = float(self.state[i, S.force_est_n])
            reset_features(self._z[i], fe)
            write_observation(self._z[i], self._c[i], fe, ep.setpoint_n[0], float(self.state[i, S.current_meas_a]),
                              self._obs[i])
            self.episodes[i] = ep
            if self.config.safety:
                sup = make_supervisor(dev)
                sup.reset(force_est_n=fe, setpoint_n=float(ep.setpoint_n[0]), command_v=0.0)
                if self._dt < sup.min_control_period_s:
                    raise ValueError(f"control period {self._dt:g} s is below the {sup.min_control_period_s:g} s "
                                     "the safety supervisor is sized for")
                sups.append((i, sup))
        if not sups:
            return
        width = max(sup.compiled()[0].size for _, sup in sups)
        cwidth = max(sup.compiled()[1].size for _, sup in sups)
        if self._sv2 is None or width > self._sv2.shape[1] or cwidth > self._svcfg2.shape[1]:
            # the window buffers' lengths depend on the device: rows are padded to the widest
            new = {i for i, _ in sups}
            old = [(k, s_) for k, s_ in enumerate(self._sups) if s_ is not None and k not in new]
            width = max([width] + [s_.compiled()[0].size for _, s_ in old]) + 64
            cwidth = max([cwidth] + [s_.compiled()[1].size for _, s_ in old])
            sv2, cfg2 = np.zeros((self.num_envs, width)), np.zeros((self.num_envs, cwidth))
            for k, s_ in old:
                a_, c_ = s_.compiled()
                s_.bind(sv2[k, :a_.size], cfg2[k, :c_.size])
            self._sv2, self._svcfg2 = sv2, cfg2
        for i, sup in sups:
            sv, cfg = sup.compiled()
            sup.bind(self._sv2[i, :sv.size], self._svcfg2[i, :cfg.size])
            self._sups[i] = sup

    def reset(self, *, seed=None, options: dict | None = None):
        """Reset every sub-env.

        Parameters
        ----------
        seed : int or sequence of int, optional
            An int gives sub-env ``i`` the seed ``seed + i``; a sequence gives one seed per
            sub-env (None entries are left unseeded).
        options : dict, optional
            Reset options applied to every sub-env's first episode (keys
            :data:`ebraille_sim.rl.env.OPTION_KEYS`); autoresets draw every component afresh.
        """
        opt = validate_options(options, self.config.safe_force_n)
        n = self.num_envs
        seeds = check_seeds("seed", seed, n)
        super().reset(seed=seeds[0] if seeds and seeds[0] is not None else None)
        for i, s in enumerate(seeds):
            if s is not None:
                self._rngs[i], _ = seeding.np_random(int(s))
                self._masters[i] = SeedNode(int(s))
            elif self._rngs[i] is None:
                self._rngs[i], _ = seeding.np_random(None)
        self._load_rows(range(n), opt)
        self._prev_done[:] = False
        self._ready = True
        return self._obs.copy(), {}

    def reset_rows(self, indices) -> np.ndarray:
        """Start the next episode of the given sub-envs now, without waiting for the next step.

        Each sub-env draws its next episode as an autoreset would (the same draws), and
        its pending autoreset is cleared, so the next :meth:`step` steps the new episode
        with the given action.  This is the same-step autoreset of Stable-Baselines3
        (:mod:`ebraille_sim.rl.sb3`).

        Parameters
        ----------
        indices : sequence of int
            Sub-envs to reset.

        Returns
        -------
        numpy.ndarray
            Their first observations, shape ``(len(indices), 7)``.
        """
        if not self._ready:
            raise RuntimeError("call reset() before reset_rows()")
        rows = [int(i) for i in indices]
        for i in rows:
            if not 0 <= i < self.num_envs:
                raise ValueError(f"sub-env index {i} is out of range for {self.num_envs} envs")
        if rows:
            self._load_rows(rows, {})
            self._prev_done[rows] = False
        return self._obs[rows].copy()

    def step(self, actions):
        """Step every sub-env; sub-envs that ended on the previous step are reset instead."""
        if not self._ready:
            raise RuntimeError("call reset() before step()")
        a = check_action(actions, self.num_envs)[:, 0]
        done = self._prev_done
        np.logical_not(done, out=self._active)
        safety = self.config.safety
        sv2, cfg2 = (self._sv2, self._svcfg2) if safety else (self._no_sv, self._no_sv)
        choice = self._choice
        if choice is not None:
            way = choice.pick()
            fn = step_rows if way else step_rows_serial
            t0 = time.perf_counter()
        else:
            fn = self._step_fn
        fn(self.state, self.params, self.inputs, self._z, self._c, self._slots, self._counts, self._tables, self._setpoint,
           self._n_steps, a, self._active, self._substeps, self._obs, self._reward,
           self._violation, self._terminated, self._truncated, safety, sv2, cfg2, self._dt)
        if choice is not None:
            choice.record(way, time.perf_counter() - t0)
            self.parallel = choice.threads
        if done.any():
            self._load_rows(np.flatnonzero(done), {})
            self._reward[done] = 0.0
            self._violation[done] = 0.0
            self._terminated[done] = False
            self._truncated[done] = False
        fc = self.state[:, S.contact_force_n]
        if not np.isfinite(fc).all():
            raise FloatingPointError("the simulation diverged (non-finite contact force)")
        self._prev_done = self._terminated | self._truncated
        every = np.ones(self.num_envs, dtype=np.bool_)
        info = {"force_true_n": fc.copy(), "_force_true_n": every, "force_est_n": self.state[:, S.force_est_n].copy(),
                "_force_est_n": every.copy(), "violation": self._violation.copy(), "_violation": every.copy()}
        return (self._obs.copy(), self._reward.copy(), self._terminated.copy(), self._truncated.copy(), info)

    def render(self):
        """One RGB frame per sub-env (tuple of arrays), or None without a render mode."""
        if self.render_mode is None:
            from gymnasium import logger
            logger.warn("render() called without a render_mode; pass render_mode='rgb_array'")
            return None
        if not self._ready:
            raise RuntimeError("call reset() before render()")
        from ebraille_sim.rl.render import Renderer, snapshot_from
        if self._renderer is None:
            self._renderer = Renderer()
        dt = self.config.dt_s
        return tuple(self._renderer.draw(snapshot_from(self.state[i], self.inputs[i], self.episodes[i],
                                                       int(self._z[i, Z_STEP]), dt, self.config.safe_force_n))
                     for i in range(self.num_envs))

    def close_extras(self, **kwargs):
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def __repr__(self) -> str:
        return f"ContactForceVectorEnv(num_envs={self.num_envs}, control_rate_hz={self.config.control_rate_hz:g})"

