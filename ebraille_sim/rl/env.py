r"""Gymnasium environment: learn to hold the display against the reading finger.

One environment step is one control period of the device's microcontroller at
``control_rate_hz`` (default 200 Hz, i.e. 50 physics steps of the 10 kHz lumped plant):
the action is held as the motor command while the loop engine's period
(:func:`ebraille_sim.plant.engine.period`, the closed-loop body the scenario runner runs too)
advances the drive train, board,
fingertip, FSR, ADC and force estimator.  A learned controller and a PID therefore see
identical physics.

## Description

A Faulhaber gearmotor drives a pinion and two racks that lift a board with a 3x2
electrotactile display against the pulp of the reader's index finger.  An FSR 402 in a
voltage divider under the display is read by the microcontroller, which estimates the
force with the paper's fifth-order Wiener model.  The agent commands the motor so that the
TRUE contact force follows a comfort setpoint while the reader moves through a Braille
passage, and must never press harder than the safe force.

## Action Space

``Box(-1, 1, shape=(1,), float32)``: the motor command as a fraction of the device's
nominal driver supply, ``command_v = a * driver_supply_v`` (6 V for the Faulhaber drive).
Actions outside [-1, 1] are clipped (the H-bridge saturates), a non-finite action or one
of the wrong shape raises ``ValueError``.  The scale is the base device's supply in every
episode; a sagging supply or a battery (disturbances) clips the command again inside the
plant.

## Observation Space

``Box(low, high, shape=(7,), float32)``; only what the microcontroller sees.  Every entry
is clipped to its bounds.  ``F_s`` is ``safe_force_n`` (3 N,
:data:`~ebraille_sim.physics.params.TACTILE_FORCE_MAX_N`); ``i_s`` is the base device's
stall current at its driver supply, ``driver_supply_v / resistance_ohm`` (6 V / 21.2 ohm
= 0.283 A for the Faulhaber drive), recorded in the policy metadata.

| Num | Observation                                              | Min | Max |
|-----|----------------------------------------------------------|-----|-----|
| 0   | estimated force ``F_est / F_s``                          | -1  | 2   |
| 1   | setpoint ``F_sp / F_s``                                  | 0   | 1   |
| 2   | error ``(F_sp - F_est) / F_s``                           | -2  | 2   |
| 3   | filtered rate of the estimate ``dF_est/dt / 10 N/s``     | -3  | 3   |
| 4   | clipped error integral ``I``                             | -1  | 1   |
| 5   | previous action ``a_{k-1}``                              | -1  | 1   |
| 6   | motor current ``i / i_s``                                | -3  | 3   |

The rate is a first-order low-pass (time constant ``rate_filter_s``, 20 ms) of the
backward difference of the estimate; the integral is
``I_k = clip(I_{k-1} + dt (F_sp - F_est)/(F_s integral_time_s), -1, 1)`` with
``integral_time_s`` = 0.1 s.  Both use the step ``dt = 1/control_rate_hz`` as an argument
(:func:`observe`), and :class:`controllers.policy.PolicyController` calls the same function.

## Rewards

With the true force ``F`` at the end of the period, the setpoint ``F_sp`` that was
shown with the action, the clipped action ``a`` and the degree of violation of the safe
force ``v = clip((F - F_warn)/(F_safe - F_warn), 0, 1)`` (architecture rule 8; ``F_warn``
= ``warn_force_n`` = 2 N, ``F_safe`` = 3 N)::

    r = 1 - sqrt(min(1, |F - F_sp| / e_s)) - w_u a^2 - w_v v

with ``e_s`` = 1 N, ``w_u`` = ``effort_weight`` = 0.1 and ``w_v`` = ``violation_weight``
= 1.  A perfect, effortless step earns 1; the reward lies in [-1.1, 1], so ending an
episode early by crushing the finger forfeits the reward of the remaining steps.

## Starting State

The board rests fully retracted (``travel_min_m``), the pinion centred in its backlash,
no contact, the estimator at its steady state for the tared no-load voltage.  The pulp
surface sits ``gap_m`` above the board (0.5-1.5 mm), so every episode begins with a
contact onset.  The first character appears at ``reading_start_s`` (1 s).

## Episode End

1. Termination: the true contact force exceeds ``safe_force_n`` (3.0 N).
2. Truncation: the last character of the passage excerpt leaves the display
   (``episode_characters`` cells after ``reading_start_s``), after
   ``round(t_end / dt)`` steps.  At most :meth:`EnvConfig.max_episode_steps`: 1400 steps at
   the defaults (60 wpm, 200 Hz), 7000 at 1 kHz.  The registered id has no
   ``max_episode_steps``: the env ends its episodes itself at any control rate.

## Episodes and domain randomisation

An episode is a scenario.  Every reset spawns one ``SeedSequence`` child of the env's
master seed, and :meth:`ebraille_sim.scenarios.episodes.EpisodeDistribution.draw` turns it
into a :class:`~ebraille_sim.scenarios.spec.ScenarioSpec` (``env.episode.spec``): the
excerpt as ``[reading]`` text, a ``[setpoint]`` with steps, the ``[finger]`` gap, a
``[disturbances]`` section with the scenario models and the drawn device.  The episode's
arrays come from :func:`ebraille_sim.scenarios.inputs.build_run_inputs`, the function the
scenario runner uses, so ``run_scenario(env.episode.spec)`` replays the same episode
(``tests/test_episodes.py``).  Every random number of an episode comes from one compiled call
on the episode seed (:func:`ebraille_sim.scenarios.draws.episode_numbers`): the device from
streams of its own (the reader a population sweep draws from the same seed), every other
component from fixed draws of the episode's stream, so fixing one never shifts another:

==============  ===========================================================  ==========
component       draw                                                         source
==============  ===========================================================  ==========
device          reader pulp, FSR unit, motor, drive train from               population
                :func:`ebraille_sim.scenarios.population.sample_device` (R2
                recalibrated per FSR unit)
run seed        the spec's ``seed``: ADC noise and disturbance realisations  -
reading         passage (shipped passages), excerpt start (a word start of   [R] paper
                its text), rate uniform in 60-120 wpm
setpoint        1-3 levels uniform in 0.3-1.5 N; steps at uniform times     [E]
                during reading
finger          gap 0.5-1.5 mm; ``[disturbances.tremor]`` band-limited       [R]/[E]
                Gaussian, 8-12 Hz, RMS uniform in 0-20 um;
                ``[disturbances.pressing]`` slow drift, Gaussian 0.1-1 Hz,
                RMS uniform in 0-0.1 mm
supply          with probability 0.25 one Li-ion cell                        [E]
                (``[disturbances.battery]``, state of charge uniform in
                0.05-1: 3.4-4.2 V); otherwise the driver supply
                (``[device] driver_supply_v``) sagged by 0-15 %
==============  ===========================================================  ==========

``reset(seed=..., options=...)`` fixes any of them for evaluation; the allowed option keys
are :data:`OPTION_KEYS` (an unknown key or a value out of range raises ``ValueError``
naming it):

``device`` (a :class:`~ebraille_sim.physics.params.DeviceParams`; its rates are set to the env's),
``passage`` (a name from :func:`ebraille_sim.scenarios.passages.list_passages`), ``first_character``
(character offset of the excerpt in the passage text), ``wpm`` [1, 1000], ``setpoint_n``
(0, safe force), ``setpoint_steps`` (list of ``(time_s, force_n)``), ``gap_m`` [0, 5 mm],
``drift_amplitude_m`` [0, 1 mm] and ``tremor_amplitude_m`` [0, 0.1 mm] (the pressing and
tremor RMS is the amplitude over sqrt 2, as for a sine), ``supply_fraction`` [0.5, 1]
(driver supply as a fraction of the device's, no battery), ``disturbances`` (False: no
drift, tremor, sag or battery).

## Device pool

By default every episode draws a new device (reader, FSR unit, motor, drive train, board) and
calibrates it as a technician would: the unit's bench (its divider trim, calibration table,
creep and loop) and the drive's current calibration are most of a reset's cost.  With
``device_pool=N`` the episodes share N units instead: unit ``k`` is
``sample_devices(device_pool_seed, N)[k]`` (:func:`ebraille_sim.scenarios.population.sample_devices`),
drawn and calibrated the first time an episode takes it and kept; each episode takes a unit
uniformly from its own device stream and draws everything else (reading, setpoint, gap,
disturbances, run seed) afresh.  A reset that reuses a unit costs about 0.6 of a fresh draw
(``benchmarks/bench_env.py --only-resets``).  The policy then trains on N readers and units
rather than on the population: hold out readers it never met when evaluating it
(``device_pool_seed`` of another value, or the default ``device_pool=0``).

## Safety layer

With ``safety=True`` (the default; ``safety=False`` is the explicit opt-out) every
command passes through the safety supervisor the scenario runner uses
(:class:`controllers.supervisor.Supervisor`, limits :meth:`SupervisorConfig.for_device
<controllers.supervisor.SupervisorConfig.for_device>` of the episode's device).  The agent's
command ``a * driver_supply_v`` is the supervisor's inner controller: it sees the force
estimate, the setpoint shown with the action, the control period and the motor current,
and in normal running only limits the command's slew and the force near its cap; after a
detected fault it retracts and holds whatever the agent asks.  The applied command, as a
fraction of the supply, is what the reward's effort term and the next observation's
previous action use (``info["command_v"]`` in volts; ``info["action_v"]`` is the agent's
own; ``info["supervisor_mode"]`` and ``info["supervisor_fault"]`` its state).  A policy
trained with the layer on is therefore evaluated with it on, as in a scenario run.

## Arguments

| Parameter              | Type  | Default   | Description                                            |
|------------------------|-------|-----------|--------------------------------------------------------|
| `render_mode`          | str   | None      | None or "rgb_array" (:mod:`ebraille_sim.rl.render`)       |
| `control_rate_hz`      | float | 200.0     | env steps per second; divides the 10 kHz physics rate  |
| `safe_force_n`         | float | 3.0       | termination threshold, N (tactile maximum)             |
| `warn_force_n`         | float | 2.0       | start of the soft penalty zone, N                      |
| `episode_characters`   | int   | 30        | Braille cells read per episode                         |
| `reading_start_s`      | float | 1.0       | contact onset time before the first cell, s            |
| `wpm_range`            | tuple | (60, 120) | reading-rate range, words per minute                   |
| `setpoint_range_n`     | tuple | (0.3,1.5) | setpoint range, N                                      |
| `randomize_device`     | bool  | True      | draw a device per episode (False: the nominal device)  |
| `disturbances`         | bool  | True      | finger drift, tremor and supply sag                    |
| `effort_weight`        | float | 0.1       | ``w_u``                                                |
| `violation_weight`     | float | 1.0       | ``w_v``                                                |
| `backend`              | str   | "lumped"  | plant model for :func:`ebraille_sim.plant.backends.make_plant`|
| `base_device`          | DeviceParams | nominal | centre of the population                        |
| `safety`               | bool  | True      | safety layer: the supervisor shapes every command      |
| `device_pool`          | int   | 0         | 0: a new device every episode; N: episodes share N drawn units (below) |
| `device_pool_seed`     | int   | 0         | seed of the pool's units                               |

Examples
--------
>>> import gymnasium as gym
>>> import ebraille_sim
>>> env = gym.make("EBraille/ContactForce-v0")
>>> obs, info = env.reset(seed=3)
>>> obs.shape, obs.dtype
((7,), dtype('float32'))
>>> obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
>>> -1.1 <= reward <= 1.0
True
"""
from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from ebraille_sim.base.compiled import entry_point, njit
from ebraille_sim.base.seeds import SeedNode

from ebraille_sim.physics.params import TACTILE_FORCE_MAX_N
from ebraille_sim.plant import engine
from ebraille_sim.plant.layout import S, U
from ebraille_sim.rl.episode import (MAX_EPISODE_STEPS, OPTION_KEYS, EnvConfig, Episode, draw_episode,
                                     episode_from_spec, estimator_model, validate_options)
from ebraille_sim.rl.registration import ENV_ID, register_envs
from ebraille_sim.rl.render import RenderedEnv
from controllers.compiled import KIND_EXTERNAL
from controllers.supervisor import CF, FAULTS, MODES, SV
from controllers.features import (C_CMD_SCALE, C_DT, C_SAFE, C_WARN, C_WU, C_WV, ERROR_SCALE_N, N_OBS, N_Z, OBS_HIGH, OBS_LOW, Z_PREV_ACTION, Z_STEP, _clip,
                                  observe, reset_features, write_observation)

__all__ = [
    "ActionCommand",
    "ENV_ID",
    "MAX_EPISODE_STEPS",
    "N_OBS",
    "OBS_HIGH",
    "OBS_LOW",
    "OPTION_KEYS",
    "ContactForceEnv",
    "EnvConfig",
    "Episode",
    "draw_episode",
    "episode_from_spec",
    "estimator_model",
    "make_supervisor",
    "observe",
    "post_step",
    "register_envs",
    "reward_of",
    "HeldCommand",
    "validate_options",
]


@njit(cache=True)
def reward_of(c, force_true_n, setpoint_n, action):
    """Reward and degree of violation ``(r, v)`` of one step (formula in the module docstring)."""
    e = abs(force_true_n - setpoint_n) / ERROR_SCALE_N
    if e > 1.0:
        e = 1.0
    v = _clip((force_true_n - c[C_WARN]) / (c[C_SAFE] - c[C_WARN]), 0.0, 1.0)
    r = 1.0 - math.sqrt(e) - c[C_WU] * action * action - c[C_WV] * v
    return r, v


@njit(cache=True)
def post_step(z, c, force_est_n, force_true_n, current_a, setpoint_shown_n, setpoint_next_n, action, obs):
    """Everything after the physics of one step: reward, termination, next observation.

    Returns ``(reward, violation, terminated)``.
    """
    r, v = reward_of(c, force_true_n, setpoint_shown_n, action)
    z[Z_PREV_ACTION] = action
    z[Z_STEP] += 1.0
    observe(z, c, force_est_n, setpoint_next_n, current_a, c[C_DT], obs)
    return r, v, force_true_n > c[C_SAFE]


# The scalar env's workspace: one float64 array per episode holding what its compiled step
# reads and writes besides the plant's state and input rows, so that the step is one call of
# five arguments (Numba's dispatcher checks the type of every argument on each call).  The
# state and inputs stay arguments of their own: the plant kernel's substeps run about a fifth
# slower on slices of one array, which the compiler must assume to overlap.  Slot 0 is the
# agent's command in volts (written by the step); then the episode's sizes and flags; then the
# start offsets of the parts (part i spans [offset i, offset i+1)); then the parts.  The
# plant's parameter row, the supervisor's state and configuration, the features and the
# observation (float32, viewing its part's bytes) are views of their parts.
W_ACTION_V, W_SAFETY, W_SUBSTEPS, W_DT, W_PROF_STRIDE = range(5)
W_OFFSETS = 5
(P_PARAMS, P_SV, P_CFG, P_Z, P_OBS, P_C, P_SETPOINT, P_PROF, P_ROWS) = range(9)
N_PARTS = 9
W_HEADER = W_OFFSETS + N_PARTS + 1
N_OBS_SLOTS = (N_OBS + 1) // 2
"""Slots of the observation's part: the float32 observation is a view of its bytes."""


def pack_workspace(parts, safety: bool, substeps: int, dt_s: float, prof_stride: int,
                   buffer: np.ndarray | None = None, filled: tuple = ()) -> np.ndarray:
    """The workspace of :func:`scalar_step`: the header, then ``parts`` in the order of the
    ``P_*`` indices (an array is copied as float64, an int ``n`` reserves ``n`` zeros).

    With ``buffer`` (float64, 1-D) long enough, the workspace is its first slots (the header
    and the reserved parts cleared, the others overwritten), not a new array: an env keeps one
    buffer over its episodes, so that a reset does not map and clear the supervisor's ring
    buffers afresh.  The reserved parts whose ``P_*`` indices are in ``filled`` are left as
    they are in a reused buffer: the caller writes all of them (the supervisor clears its
    state and copies its configuration), and clearing them first would only write them twice.
    """
    offsets = [W_HEADER]
    pos = W_HEADER
    for x in parts:
        pos += x if type(x) is int else x.size
        offsets.append(pos)
    if buffer is not None and buffer.shape[0] >= pos:
        ws = buffer[:pos]
        ws[:W_HEADER] = 0.0
        for i, x in enumerate(parts):
            if type(x) is int and i not in filled:
                ws[offsets[i]:offsets[i + 1]] = 0.0
    else:
        ws = np.zeros(pos)
    ws[W_SAFETY] = 1.0 if safety else 0.0
    ws[W_SUBSTEPS] = substeps
    ws[W_DT] = dt_s
    ws[W_PROF_STRIDE] = prof_stride
    ws[W_OFFSETS:W_OFFSETS + N_PARTS + 1] = offsets
    for i, x in enumerate(parts):
        if type(x) is not int:
            ws[offsets[i]:offsets[i + 1]] = x.ravel()
    return ws


def workspace_part(ws: np.ndarray, i: int) -> np.ndarray:
    """Part ``i`` (a ``P_*`` index) of a workspace, as a view."""
    return ws[int(ws[W_OFFSETS + i]):int(ws[W_OFFSETS + i + 1])]


@njit(cache=True, inline="always")
def _part(ws, i):
    return ws[int(ws[W_OFFSETS + i]):int(ws[W_OFFSETS + i + 1])]


@njit(cache=True, _nrt=False)
def scalar_step(state, inputs, ws, k, action):
    """One step of the scalar env on a lumped plant, in one compiled call on its workspace.

    ``state`` and ``inputs`` are the plant's rows, ``ws`` the episode's workspace
    (:func:`pack_workspace`), ``k`` the period (below the episode's steps: not checked here),
    ``action`` the agent's (finite) action.  The clipped action, as a command in volts, is the
    external command of one period of the loop engine (:func:`ebraille_sim.plant.engine.period`:
    the period's varying inputs, the safety supervisor when the workspace's safety flag is set,
    the command held within the base supply, the physics); then reward, termination and the
    next observation (:func:`post_step`, into the workspace's parts).

    Returns
    -------
    (reward, terminated, force_true_n, force_est_n, setpoint_n, command_v, violation, time_s, mode, fault)
        The info's numbers after the step (``setpoint_n`` and ``time_s`` of period ``k + 1``,
        the supervisor's mode and fault codes, 0 without the safety layer); a non-finite
        ``force_true_n`` means the simulation diverged.
    """
    c = _part(ws, P_C)
    setpoint = _part(ws, P_SETPOINT)
    rows = _part(ws, P_ROWS)
    table = _part(ws, P_PROF).reshape((rows.shape[0], int(ws[W_PROF_STRIDE])))
    a = _clip(action, -1.0, 1.0)
    scale = c[C_CMD_SCALE]
    ws[W_ACTION_V] = a * scale
    safety = ws[W_SAFETY] != 0.0
    sv = _part(ws, P_SV)
    code, u = engine.period(state, _part(ws, P_PARAMS), inputs, int(ws[W_SUBSTEPS]), KIND_EXTERNAL, c[:0], c[:0],
                            a * scale, scale, safety, sv, _part(ws, P_CFG), setpoint[k], ws[W_DT], S.force_est_n,
                            rows, table, k)
    if code != engine.OK:
        return (math.nan, False, math.nan, math.nan, setpoint[k + 1], u, 0.0, (k + 1) * ws[W_DT], 0.0, 0.0)
    if safety:
        a = u / scale
        mode = sv[SV.mode]
        fault = sv[SV.fault]
    else:
        mode = fault = 0.0
    ft = state[S.contact_force_n]
    r, v, term = post_step(_part(ws, P_Z), c, state[S.force_est_n], ft, state[S.current_meas_a],
                           setpoint[k], setpoint[k + 1], a, _part(ws, P_OBS).view(np.float32)[:N_OBS])
    return (r, term, ft, state[S.force_est_n], setpoint[k + 1], inputs[U.command_v], v, (k + 1) * ws[W_DT], mode,
            fault)


class ActionCommand:
    """The agent as the supervisor's inner controller: returns the command it was handed."""

    name = "agent"

    def __init__(self):
        self.command_v = 0.0

    def reset(self, *, force_est_n: float, setpoint_n: float, command_v: float = 0.0) -> None:
        pass

    def update(self, force_est_n, setpoint_n, dt_s, motor_current_a=None) -> float:
        return self.command_v


class HeldCommand:
    """The agent as a Python controller of the runner's per-period shim: the command of the
    safety layer around it (or its own, without one) held within +/- ``scale_v``."""

    name = "agent"

    def __init__(self, inner, scale_v: float):
        self.inner = inner
        self.scale_v = float(scale_v)
        self.command_v = 0.0

    def reset(self, *, force_est_n: float, setpoint_n: float, command_v: float = 0.0) -> None:
        pass

    def update(self, force_est_n, setpoint_n, dt_s, motor_current_a=None) -> float:
        if self.inner is None:
            u = self.command_v
        else:
            self.inner.inner.command_v = self.command_v
            u = self.inner.update(force_est_n, setpoint_n, dt_s, motor_current_a)
        return -self.scale_v if u < -self.scale_v else (self.scale_v if u > self.scale_v else u)


def make_supervisor(device, config=None, state_out=None, config_out=None):
    """The safety layer of one env: a supervisor for ``device`` around an :class:`ActionCommand`.

    ``config`` is its configuration when already made (default
    ``SupervisorConfig.for_device(device)``); ``state_out`` and ``config_out`` hold its
    arrays (:class:`~controllers.supervisor.Supervisor`).
    """
    from controllers.supervisor import Supervisor, SupervisorConfig
    if config is None:
        config = SupervisorConfig.for_device(device)
    return Supervisor(ActionCommand(), config, state_out=state_out, config_out=config_out)



def check_action(action, n: int | None = None):
    """A float (``n`` None, shape (1,) action) or an (n, 1) float64 array.

    Only real numbers are actions: strings, bytes, booleans, complex numbers, dicts and
    other objects, non-finite values and misshapen input raise a one-line ``ValueError``.
    """
    if n is None and type(action) is np.ndarray and action.shape == (1,) and action.dtype.kind == "f":
        x = float(action[0])
        if math.isfinite(x):
            return x
    try:
        raw = np.asarray(action)
    except (TypeError, ValueError):
        raw = np.asarray(None, dtype=object)
    if raw.dtype.kind not in "fiu":
        what = type(action).__name__ if raw.dtype.kind == "O" else f"{type(action).__name__} of {raw.dtype}"
        raise ValueError(f"action must be a real number or an array of real numbers, got {what}")
    a = raw.astype(np.float64, copy=False)
    want = (1,) if n is None else (n, 1)
    if a.shape != want:
        if n is None and a.size == 1:
            a = a.reshape(1)
        elif n is not None and a.shape == (n,):
            a = a.reshape(n, 1)
        else:
            raise ValueError(f"action must have shape {want}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        bad = np.nonzero(~np.isfinite(a[:, 0] if n is not None else a))[0]
        raise ValueError(f"action must be finite, got {float(a.ravel()[0])!r}" if n is None else
                         f"action must be finite; non-finite in envs {bad[:8].tolist()}"
                         + (f" ({bad.size} in all)" if bad.size > 8 else ""))
    return float(a[0]) if n is None else a


# ---------------------------------------------------------------------------------------------
# the environment
# ---------------------------------------------------------------------------------------------

_NO_ARRAY = np.zeros(0)
_FLOAT_DTYPES = (np.dtype(np.float32), np.dtype(np.float64))
_MODE_NAMES = {float(i): name for i, name in enumerate(MODES)}
_FAULT_NAMES = {0.0: None, **{float(i + 1): name for i, name in enumerate(FAULTS)}}


class ContactForceEnv(RenderedEnv, gym.Env):
    __doc__ = __doc__

    metadata = {"render_modes": ["rgb_array"], "render_fps": 25}

    def __init__(self, render_mode: str | None = None, control_rate_hz: float = 200.0,
                 safe_force_n: float = TACTILE_FORCE_MAX_N, warn_force_n: float = 2.0, episode_characters: int = 30,
                 reading_start_s: float = 1.0, wpm_range=(60.0, 120.0), setpoint_range_n=(0.3, 1.5),
                 randomize_device: bool = True, disturbances: bool = True, effort_weight: float = 0.1,
                 violation_weight: float = 1.0, backend: str = "lumped", base_device=None, safety: bool = True,
                 device_pool: int = 0, device_pool_seed: int = 0):
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode {render_mode!r} is not supported; allowed: None, "
                             f"{', '.join(self.metadata['render_modes'])}")
        self.render_mode = render_mode
        self.config = EnvConfig(control_rate_hz=control_rate_hz, safe_force_n=safe_force_n,
                                warn_force_n=warn_force_n, episode_characters=episode_characters,
                                reading_start_s=reading_start_s, wpm_range=wpm_range,
                                setpoint_range_n=setpoint_range_n, randomize_device=randomize_device,
                                disturbances=disturbances, effort_weight=effort_weight,
                                violation_weight=violation_weight, backend=backend, base_device=base_device,
                                safety=safety, device_pool=device_pool, device_pool_seed=device_pool_seed)
        from ebraille_sim.plant.backends import PLANT_BACKENDS
        if backend not in PLANT_BACKENDS:
            raise ValueError(f"unknown backend {backend!r}; available: {', '.join(sorted(PLANT_BACKENDS))}")
        self.action_space = spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)
        self.observation_space = spaces.Box(OBS_LOW.copy(), OBS_HIGH.copy(), dtype=np.float32)
        self._master: SeedNode | None = None
        self.plant = None
        self.episode: Episode | None = None
        self._z = np.zeros(N_Z)
        self._c = self.config.config_vector()
        self._obs = np.zeros(N_OBS, dtype=np.float32)
        self._k = 0
        self._varying = []
        self._renderer = None
        self._history = None
        self._sup = None
        self._agent = None
        self._compiled = False
        self._ws = None
        self._buffer = None
        self._step_fn = None
        self._n_steps = 0
        self._dt = self.config.dt_s
        self._sv = self._svcfg = _NO_ARRAY

    # -- episode ---------------------------------------------------------------------------
    def next_episode_seed(self, seed=None) -> SeedNode:
        """The episode's seed sequence: a child of the master seed (``seed`` re-seeds it), a
        :class:`~ebraille_sim.base.seeds.SeedNode` (NumPy's ``SeedSequence`` of the same
        entropy and key, hashed by compiled code)."""
        if seed is not None:
            self._master = SeedNode(int(seed))
        elif self._master is None:
            self._master = SeedNode(int(self.np_random.integers(0, 2**63)))
        return self._master.spawn(1)[0]

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        opt = validate_options(options, self.config.safe_force_n)
        from ebraille_sim.plant.backends import make_plant
        from ebraille_sim.plant.lumped import Plant
        ep = draw_episode(self.next_episode_seed(seed), self.config, opt)
        dev = ep.device
        self.plant = make_plant([dev], [ep.sensor_seed], backend=self.config.backend,
                                models=[estimator_model(dev.estimator.model)])
        self.plant.inputs[0] = ep.run.initial_inputs()
        self._st = self.plant.state[0]
        self._inp = self.plant.inputs[0]
        self._varying = [(U[name], arr) for name, arr in ep.run.profiles.items()]
        self._compiled = isinstance(self.plant, Plant)
        self._ws = None
        self.episode = ep
        self._k = 0
        self._n_steps = ep.n_steps
        fe = float(self._st[S.force_est_n])
        self._sup = None
        self._sv = self._svcfg = _NO_ARRAY
        svc = None
        if self.config.safety:
            from controllers.supervisor import SupervisorConfig
            svc = SupervisorConfig.for_device(dev)
        if self._compiled:
            self._bind_workspace(ep, svc)                     # makes the supervisor in the workspace
        elif svc is not None:
            self._sup = make_supervisor(dev, svc)
        if not self._compiled:
            self._agent = HeldCommand(self._sup, self._c[C_CMD_SCALE])
        if self._sup is not None:
            self._sup.reset(force_est_n=fe, setpoint_n=float(ep.setpoint_n[0]), command_v=0.0)
            if self.config.dt_s < self._sup.min_control_period_s:
                raise ValueError(f"control period {self.config.dt_s:g} s is below the "
                                 f"{self._sup.min_control_period_s:g} s the safety supervisor is sized for")
            self._sv, self._svcfg = self._sup.compiled()
        reset_features(self._z, fe)
        write_observation(self._z, self._c, fe, ep.setpoint_n[0], float(self._st[S.current_meas_a]), self._obs)
        if self.render_mode is not None:
            self._history = {"t_s": [0.0], "force_true_n": [float(self._st[S.contact_force_n])],
                             "force_est_n": [fe], "setpoint_n": [float(ep.setpoint_n[0])]}
        return self._obs.copy(), self._info(0.0)

    def _bind_workspace(self, ep: Episode, svc) -> None:
        """Pack the episode's arrays into one workspace (:func:`pack_workspace`, in the env's
        buffer) and make the plant's parameter row, the features and the observation views of
        it; with a supervisor configuration ``svc``, make the supervisor with its arrays in it."""
        plant = self.plant
        n = ep.n_steps
        varying = self._varying
        rows = np.array([j for j, _ in varying], dtype=np.float64)
        sv_n = cfg_n = 0
        if svc is not None:
            packed = svc.pack()
            sv_n, cfg_n = int(packed[CF.state_len]), packed.size
        parts = (plant.params, sv_n, cfg_n, self._z.copy(), N_OBS_SLOTS, self._c, ep.setpoint_n, len(varying) * n,
                 rows)                  # the supervisor fills its parts, the profiles are copied in below
        ws = pack_workspace(parts, svc is not None, plant.substeps, self._dt, n, self._buffer,
                            filled=(P_SV, P_CFG, P_PROF))
        prof = workspace_part(ws, P_PROF)
        for j, (_, arr) in enumerate(varying):
            prof[j * n:(j + 1) * n] = arr
        if self._buffer is None or ws.base is not self._buffer:
            self._buffer = np.empty(ws.size + ws.size // 4)   # for the next episodes (a quarter to spare)
        plant.params = workspace_part(ws, P_PARAMS).reshape(plant.params.shape)
        if svc is not None:
            self._sup = make_supervisor(ep.device, svc, workspace_part(ws, P_SV), workspace_part(ws, P_CFG))
        self._z = workspace_part(ws, P_Z)
        self._obs = workspace_part(ws, P_OBS).view(np.float32)[:N_OBS]
        self._chars = ep.char_index.tolist()
        self._ws = ws
        if self._step_fn is None:
            self._step_fn = entry_point(scalar_step, self._st, self._inp, ws, 0, 0.0)

    def _info(self, violation: float) -> dict:
        st = self._st
        k = self._k
        ep = self.episode
        sup = self._sup
        if sup is None:
            return {"force_true_n": float(st[S.contact_force_n]), "force_est_n": float(st[S.force_est_n]),
                    "setpoint_n": float(ep.setpoint_n[k]), "command_v": float(self._inp[U.command_v]),
                    "violation": float(violation), "time_s": k * self._dt, "char_index": int(ep.char_index[k])}
        return {"force_true_n": float(st[S.contact_force_n]), "force_est_n": float(st[S.force_est_n]),
                "setpoint_n": float(ep.setpoint_n[k]), "command_v": float(self._inp[U.command_v]),
                "violation": float(violation), "time_s": k * self._dt, "char_index": int(ep.char_index[k]),
                "action_v": sup.inner.command_v, "supervisor_mode": sup.mode, "supervisor_fault": sup.fault}

    def step(self, action):
        ws = self._ws
        if ws is None:
            return self._step_python(action)
        if type(action) is np.ndarray and action.dtype in _FLOAT_DTYPES and action.size == 1:
            a = action.item()
            if a - a != 0.0:                                    # inf or nan
                a = check_action(action)
        elif type(action) is float and action - action == 0.0:
            a = action
        else:
            a = check_action(action)
        k = self._k
        if k >= self._n_steps:
            raise RuntimeError("the episode has ended (terminated or truncated); call reset() before step()")
        r, term, ft, fe, sp, cv, v, t, mode, fault = self._step_fn(self._st, self._inp, ws, k, a)
        self._k = k = k + 1
        if ft - ft != 0.0:                                      # inf or nan
            raise FloatingPointError("the simulation diverged (non-finite contact force)")
        if self._sup is None:
            info = {"force_true_n": ft, "force_est_n": fe, "setpoint_n": sp, "command_v": cv, "violation": v,
                    "time_s": t, "char_index": self._chars[k]}
        else:
            av = ws[W_ACTION_V]                                 # numpy's float64, as sup.inner keeps it
            self._sup.inner.command_v = av
            info = {"force_true_n": ft, "force_est_n": fe, "setpoint_n": sp, "command_v": cv, "violation": v,
                    "time_s": t, "char_index": self._chars[k], "action_v": av,
                    "supervisor_mode": _MODE_NAMES[mode], "supervisor_fault": _FAULT_NAMES[fault]}
        if self._history is not None:
            self._record(info, ft)
        truncated = k >= self._n_steps
        if term:
            self._n_steps = k                                   # a step after termination is refused
        return self._obs.copy(), r, term, truncated, info

    def _record(self, info: dict, force_true_n: float) -> None:
        h = self._history
        h["t_s"].append(info["time_s"])
        h["force_true_n"].append(force_true_n)
        h["force_est_n"].append(info["force_est_n"])
        h["setpoint_n"].append(info["setpoint_n"])

    def _step_python(self, action):
        """The step on a plant that is not the compiled lumped one (another backend): the agent's
        command enters the loop through the runner's per-period shim
        (:func:`ebraille_sim.scenarios.runner.python_periods`), as a Python controller's does."""
        from ebraille_sim.scenarios.runner import python_periods
        if self.episode is None:
            raise RuntimeError("call reset() before step()")
        a = check_action(action)
        a = -1.0 if a < -1.0 else (1.0 if a > 1.0 else a)
        ep = self.episode
        k = self._k
        if k >= self._n_steps:
            raise RuntimeError("the episode has ended (terminated or truncated); call reset() before step()")
        scale = self._c[C_CMD_SCALE]
        self._agent.command_v = a * scale
        python_periods(self.plant, [self._agent], ep.setpoint_n[None, :ep.n_steps], [ep.run.profiles], S.force_est_n, None, 1,
                       k0=k, n_record=0)
        st = self._st
        if self._sup is not None:
            a = float(self._inp[U.command_v]) / scale
        self._k = k + 1
        ft = float(st[S.contact_force_n])
        if not math.isfinite(ft):
            raise FloatingPointError("the simulation diverged (non-finite contact force)")
        r, v, term = post_step(self._z, self._c, float(st[S.force_est_n]), ft, float(st[S.current_meas_a]),
                               ep.setpoint_n[k], ep.setpoint_n[k + 1], a, self._obs)
        info = self._info(v)
        if self._history is not None:
            self._record(info, ft)
        truncated = self._k >= self._n_steps
        if term:
            self._n_steps = self._k                             # a step after termination is refused
        return self._obs.copy(), float(r), bool(term), truncated, info

    # -- rendering ---------------------------------------------------------------------------
    def _render_history(self):
        return self._history
