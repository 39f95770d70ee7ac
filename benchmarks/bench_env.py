"""Speed of the Gymnasium env against Gymnasium's Pendulum-v1, measured in the same run.

* single env: steps per second of ``gym.make("EBraille/ContactForce-v0")`` and of
  ``gym.make("Pendulum-v1")`` (both with Gymnasium's default wrappers, and both unwrapped),
  random actions from a seeded generator, resets included; the ratio ours / Pendulum.
* vector env: env-steps per second of the native vector env at ``--envs`` (1024) sub-envs,
  every env-step a full control period with its physics substeps (50 at the default
  200 Hz, 10 at the device's own 1 kHz), actions from a proportional-integral law computed
  from the observations in numpy; with the default episodes' autoresets and without any
  (measurement stopped before the first episode ends), rows on threads (numba prange) and
  on one thread; each also as a ratio to Pendulum-v1's single-env steps/s and to the
  1,000,000 env-steps/s target.

* kernel alone: physics substeps per second of ``advance_batch`` on ``--envs`` rows (one
  thread, no controller, no observation), with the command held (the plants at rest) and
  replaying the inputs a vector env applied (:func:`kernel_replay_substeps_per_s`, the same
  physics as the env's): the vector env's substep rate with autoresets is reported as a
  fraction of each (target 0.8 of the replay).
* CartPole-v1: the single env's steps/s also against CartPole-v1 (with wrappers).
* reset cost: the mean wall time of one ``reset()`` of the scalar env (a new device, its R2
  calibration, episode inputs and packing) in units of one env step (a control period at
  200 Hz) measured in the same run; the target is at most 20 steps.
* threads: env-steps/s of the vector env's compiled row loop on threads (``prange``) and on
  one thread at 1-1024 sub-envs, no resets; the ratio threads / one thread, which the default
  (``parallel=None``, :class:`ebraille_sim.rl.vector_env.ThreadChoice`) measures while it runs.

With ``--only-single`` only the single env against Pendulum-v1, with Gymnasium's wrappers
and unwrapped: ``--repeat`` (3) rounds in the same process, each measuring the two envs
interleaved (500 steps of one, then of the other, ``--seconds`` each in all;
:func:`interleaved_steps_per_s`), with wrappers, then unwrapped; the medians of the rounds'
ratios.  On a machine shared with other jobs the rates drift by a factor of 2 between figures
measured one after the other; interleaved, both envs see the same load.  Then the parts of
one step without resets (:func:`step_breakdown`: the kernel's substeps of one step, the
compiled step, ``step()`` unwrapped and wrapped, Pendulum-v1), at the default physics rate
and at 5 kHz, with the ratio an env spending nothing beyond its physics would reach.

With ``--only-resets`` only the reset figures, each the median of ``--repeat`` (3) timings in
the same process: the scalar env's reset in ms and in env steps (steps and resets
interleaved), and the vector env's env-steps/s with autoresets against the same env
without any (the reference), on one thread; then the parts of one reset in env steps
(:func:`reset_parts`), and the part of a reset spent in its numerical work alone (:func:`reset_floor`:
the bench's load cycle, the averaged conversions, the R2 root and the noises' FFTs, compiled or
NumPy's), the least a reset costs with the bench protocols as written.

Run:  python benchmarks/bench_env.py [--seconds 3] [--envs 1024] [--json FILE] [--only-single | --only-resets] [--repeat 3]
      [--device-pool N]
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import time

import gymnasium as gym
import numpy as np

import ebraille_sim  # noqa: F401  (registers the id)
from ebraille_sim.rl.env import ENV_ID
from ebraille_sim.rl.vector_env import ContactForceVectorEnv

TARGET_VECTOR = 1_000_000


def single_steps_per_s(env, seconds: float, seed: int = 0) -> float:
    """Steps per second of one env over about ``seconds`` (resets included)."""
    rng = np.random.default_rng(seed)
    space = env.action_space
    if hasattr(space, "low"):
        actions = rng.uniform(space.low, space.high, size=(4096,) + space.shape).astype(np.float32)
    else:                                                 # a discrete space (CartPole)
        actions = rng.integers(0, space.n, size=4096)
    env.reset(seed=seed)
    for k in range(200):                                  # warm-up (compilation, caches)
        _, _, term, trunc, _ = env.step(actions[k])
        if term or trunc:
            env.reset()
    n = 0
    t0 = time.perf_counter()
    while True:
        for _ in range(500):
            _, _, term, trunc, _ = env.step(actions[n & 4095])
            n += 1
            if term or trunc:
                env.reset()
        dt = time.perf_counter() - t0
        if dt >= seconds:
            return n / dt


def interleaved_steps_per_s(envs, seconds: float, seed: int = 0, chunk: int = 500) -> list[float]:
    """Steps per second of each of ``envs``, stepped in turn ``chunk`` steps at a time until
    each has run about ``seconds`` (resets included, the actions and warm-up of
    :func:`single_steps_per_s`): on a machine whose load drifts, every env sees the same load,
    so their ratio holds where rates measured one after the other do not."""
    runs = []
    for env in envs:
        rng = np.random.default_rng(seed)
        space = env.action_space
        actions = rng.uniform(space.low, space.high, size=(4096,) + space.shape).astype(np.float32)
        env.reset(seed=seed)
        for k in range(200):
            _, _, term, trunc, _ = env.step(actions[k])
            if term or trunc:
                env.reset()
        runs.append([env, actions, 0, 0.0])
    while min(r[3] for r in runs) < seconds:
        for r in runs:
            env, actions, n = r[0], r[1], r[2]
            t0 = time.perf_counter()
            for _ in range(chunk):
                _, _, term, trunc, _ = env.step(actions[n & 4095])
                n += 1
                if term or trunc:
                    env.reset()
            r[3] += time.perf_counter() - t0
            r[2] = n
    return [r[2] / r[3] for r in runs]


def reset_cost_in_steps(seconds: float, seed: int = 0, **kwargs) -> tuple[float, float, float]:
    """(mean reset time in s, mean step time in s, their ratio) of one unwrapped scalar env,
    steps and resets interleaved in the same loop so both see the same machine load."""
    from ebraille_sim.rl.env import ContactForceEnv
    env = fill_pool(ContactForceEnv(**kwargs))
    env.reset(seed=seed)
    for _ in range(20):
        env.step(np.zeros(1, np.float32))
    t_reset = t_step = 0.0
    n_reset = n_step = 0
    a = np.full(1, 0.1, np.float32)
    t_end = time.perf_counter() + seconds
    while time.perf_counter() < t_end:
        t0 = time.perf_counter()
        env.reset()
        t1 = time.perf_counter()
        for _ in range(20):
            env.step(a)
        t2 = time.perf_counter()
        t_reset += t1 - t0
        t_step += t2 - t1
        n_reset += 1
        n_step += 20
    r, s = t_reset / n_reset, t_step / n_step
    return r, s, r / s


def reset_parts(n: int = 300, seed: int = 0) -> dict:
    """The parts of a reset of the scalar env (drawn readers, disturbances), each timed on ``n``
    fresh episodes (every drawn device used once: nothing cached from an earlier call) and
    given in env steps, the step timed right before and after the parts (the mean of the two):

    * ``episode draw``: :meth:`~ebraille_sim.scenarios.episodes.EpisodeDistribution.draw` (the
      spec, the device draw and its R2 calibration included);
    * ``device draw``: :func:`~ebraille_sim.scenarios.population.sample_device` alone (its
      numbers, the device and its R2 calibration);
    * ``inputs``: :func:`~ebraille_sim.rl.episode.episode_from_spec` (schedule, setpoint, the
      input table with its band-limited noises, the cell index);
    * ``plant rows``: :func:`~ebraille_sim.plant.backends.make_plant` of the drawn device;
    * ``supervisor envelope``: :meth:`controllers.supervisor.SupervisorConfig.for_device`, of
      which ``drive calibration`` (:func:`~ebraille_sim.estimation.calibration.calibrate_drive`
      uncached) is a part.
    """
    from controllers.supervisor import SupervisorConfig
    from ebraille_sim.base.seeds import SeedNode
    from ebraille_sim.estimation.calibration import _calibrate_drive
    from ebraille_sim.plant.backends import make_plant
    from ebraille_sim.rl.env import ContactForceEnv
    from ebraille_sim.rl.episode import episode_from_spec, estimator_model
    from ebraille_sim.scenarios.population import sample_device

    env = ContactForceEnv()
    env.reset(seed=seed)
    a = np.full(1, 0.1, np.float32)

    def step_s(rounds=4, k=500):
        """Mean time of one step: ``k`` steps after each of ``rounds`` resets (an episode has at
        least 800), the resets not timed."""
        total = 0.0
        for _ in range(rounds):
            env.reset()
            t0 = time.perf_counter()
            for _ in range(k):
                env.step(a)
            total += time.perf_counter() - t0
        return total / (rounds * k)

    dist = env.config.distribution()
    seeds = [c for c in SeedNode(seed + 1).spawn(2 * n)]
    # warm every part once (compiled code, caches of constant objects)
    warm = dist.draw(seeds[-1])
    episode_from_spec(warm)
    SupervisorConfig.for_device(warm.device)
    make_plant([warm.device], [1.0], models=[estimator_model(warm.device.estimator.model)])
    before = step_s()

    def timed(fn, items):
        t0 = time.perf_counter()
        for x in items:
            fn(x)
        return (time.perf_counter() - t0) / len(items)

    specs = []
    parts = {"episode draw": timed(lambda s: specs.append(dist.draw(s)), seeds[:n])}
    parts["device draw"] = timed(lambda s: sample_device(s, dist.population, dist.base_device), seeds[n:2 * n])
    parts["inputs"] = timed(episode_from_spec, specs)
    parts["plant rows"] = timed(lambda s: make_plant([s.device], [float(s.seed)],
                                                     models=[estimator_model(s.device.estimator.model)]), specs)
    parts["drive calibration"] = timed(lambda s: _calibrate_drive.__wrapped__(s.device.motor, s.device.drivetrain,
                                                                            s.device.current_sense,
                                                                            s.device.driver_supply_v), specs)
    parts["supervisor envelope"] = timed(lambda s: SupervisorConfig.for_device(s.device), specs)
    step = 0.5 * (before + step_s())
    return {"step_s": step, "parts_s": parts, "parts_in_steps": {k: v / step for k, v in parts.items()}}


FLOOR_CALLS = (("ebraille_sim.physics.fsr", "_cycle_forces"),
               ("ebraille_sim.physics.current_sense", "_mean_code_at_rest"),
               ("ebraille_sim.physics.current_sense", "_zero_and_means"),
               ("ebraille_sim.estimation.calibration", "_r2_root"),
               ("numpy.fft", "irfft"))
"""The numerical work of a reset that no rewrite of its Python removes while the bench protocols
stay as written: the unit's load cycle on the bench sampled at 1 kHz (the loop the hysteresis
compensation keeps), the conversions the drive's end-of-line calibration and the board's zeroing
average (the drive's zeroing and means in one call, the board's zeroing in another), the divider's
R2 root, and the band-limited noises' inverse FFTs."""


def reset_floor(n: int = 300, seed: int = 0) -> dict:
    """Of ``n`` resets of the scalar env (fresh episodes), the share spent in the calls of
    :data:`FLOOR_CALLS` (each wrapped by a timer while the resets run), in env steps: the
    least a reset costs with every line of its Python compiled away and the same bench
    protocols.  The step is timed after the resets (500 steps after each of 4 resets)."""
    import importlib
    from ebraille_sim.rl.env import ContactForceEnv

    env = ContactForceEnv()
    env.reset(seed=seed)
    for _ in range(5):
        env.reset()                                          # warm the compiled calls and caches
    spent = dict.fromkeys((f"{m}.{f}" for m, f in FLOOR_CALLS), 0.0)
    saved = []
    for mod_name, fn_name in FLOOR_CALLS:
        mod = importlib.import_module(mod_name)
        fn = getattr(mod, fn_name)
        key = f"{mod_name}.{fn_name}"

        def timed(*args, _fn=fn, _key=key, **kwargs):
            t0 = time.perf_counter()
            out = _fn(*args, **kwargs)
            spent[_key] += time.perf_counter() - t0
            return out
        saved.append((mod, fn_name, fn))
        setattr(mod, fn_name, timed)
    try:
        t0 = time.perf_counter()
        for _ in range(n):
            env.reset()
        reset_s = (time.perf_counter() - t0) / n
    finally:
        for mod, fn_name, fn in saved:
            setattr(mod, fn_name, fn)
    a = np.full(1, 0.1, np.float32)
    total = 0.0
    for _ in range(4):
        env.reset()
        t0 = time.perf_counter()
        for _ in range(500):
            env.step(a)
        total += time.perf_counter() - t0
    step = total / 2000
    parts = {k: v / n for k, v in spent.items()}
    floor = sum(parts.values())
    return {"step_s": step, "reset_s": reset_s, "floor_s": floor, "parts_s": parts,
            "floor_in_steps": floor / step, "reset_in_steps": reset_s / step}


def thread_table(sizes=(1, 4, 16, 64, 256, 1024)) -> list[dict]:
    """Env-steps/s of the vector env's row loop on threads and on one thread, no resets
    (best of 3 timings).  Each variant steps a fresh vector env whose episodes (60 wpm, 1400
    steps) outlast the 4 timed-and-warm-up passes: the row loop itself does not stop at an
    episode's end."""
    from ebraille_sim.rl.vector_env import step_rows, step_rows_serial
    rows = []
    for n in sizes:
        steps = max(5, min(300, 20000 // n))
        rates = {}
        for label, fn in (("one_thread", step_rows_serial), ("threads", step_rows)):
            venv = ContactForceVectorEnv(num_envs=n, parallel=False)
            venv.reset(seed=0, options={"wpm": 60.0})
            assert 4 * steps < int(venv._n_steps.min())
            a = np.zeros(n)

            def call():
                fn(venv.state, venv.params, venv.inputs, venv._z, venv._c, venv._slots, venv._counts, venv._tables,
                   venv._setpoint,
                   venv._n_steps, a, venv._active, venv.config.substeps, venv._obs, venv._reward,
                   venv._violation, venv._terminated, venv._truncated, False, venv._no_sv, venv._no_sv,
                   venv._dt)
            for _ in range(steps):
                call()
            best = float("inf")
            for _ in range(3):
                t0 = time.perf_counter()
                for _ in range(steps):
                    call()
                best = min(best, time.perf_counter() - t0)
            rates[label] = n * steps / best
            venv.close()
        rows.append({"envs": n, "one_thread_env_steps_per_s": rates["one_thread"],
                     "threads_env_steps_per_s": rates["threads"],
                     "ratio_threads_to_one": rates["threads"] / rates["one_thread"]})
    return rows


def _law(obs):
    """Proportional-integral law on the observation (error and error integral): holds contact
    without crossing the safe force, so episodes end by truncation as in training."""
    return np.clip(0.05 + 0.6 * obs[:, 2:3] + 0.2 * obs[:, 4:5] - 0.05 * obs[:, 3:4], -1.0, 1.0).astype(np.float32)


def vector_steps_per_s(seconds: float, n_envs: int, resets: bool, **kwargs) -> tuple[float, int, int]:
    """(env-steps/s, episode ends, substeps per env-step) of the native vector env.

    With ``resets`` the measurement runs for 1.2 times the longest episode (every sub-env
    passes through at least one autoreset, at the rate training sees); without, every episode
    is read at 60 wpm (the longest) and the measurement stops before the first one is
    truncated (or after ``seconds``).
    """
    venv = ContactForceVectorEnv(num_envs=n_envs, **kwargs)
    obs, _ = venv.reset(seed=0, options=None if resets else {"wpm": 60.0})
    limit = int(1.2 * venv.config.max_episode_steps()) if resets else int(venv.episodes[0].n_steps) - 30
    for _ in range(20):
        obs, *_ = venv.step(_law(obs))
    ends = 0
    steps = 0
    t0 = time.perf_counter()
    while True:
        for _ in range(10):
            obs, _, term, trunc, _ = venv.step(_law(obs))
            ends += int(np.count_nonzero(term | trunc))
            steps += 1
        dt = time.perf_counter() - t0
        if steps >= limit or (not resets and dt >= seconds):
            venv.close()
            return steps * n_envs / dt, ends, venv.config.substeps


def kernel_substeps_per_s(n_envs: int, seconds: float) -> float:
    """Physics substeps per second of the plant kernel alone (``advance_batch`` on the rows of
    a freshly reset vector env, command held, one thread): the bound a vector env's physics
    substep rate is compared with."""
    from ebraille_sim.plant import kernel
    venv = ContactForceVectorEnv(num_envs=n_envs, parallel=False)
    venv.reset(seed=0, options={"wpm": 60.0})
    s, p, u = venv.state.copy(), venv.params.copy(), venv.inputs.copy()
    sub = venv.config.substeps
    venv.close()
    kernel.advance_batch(s, p, u, sub)
    calls = 0
    t0 = time.perf_counter()
    while True:
        kernel.advance_batch(s, p, u, sub)
        calls += 1
        dt = time.perf_counter() - t0
        if dt >= seconds:
            return calls * n_envs * sub / dt


def kernel_replay_substeps_per_s(n_envs: int, seconds: float, periods: int = 200) -> float:
    """Physics substeps per second of the plant kernel alone doing the vector env's own physics:
    the inputs of ``periods`` control periods of a vector env (one thread, 60 wpm, the
    proportional-integral actions of :func:`_law`, no reset) recorded, then replayed from the
    same start state by ``advance_batch``, one call a period (as the env calls it), over and over.
    The plants move as they did in the env; a held command (:func:`kernel_substeps_per_s`)
    leaves them at rest, which the kernel runs faster than any loop."""
    from ebraille_sim.plant import kernel
    venv = ContactForceVectorEnv(num_envs=n_envs, parallel=False)
    obs, _ = venv.reset(seed=0, options={"wpm": 60.0})
    for _ in range(20):
        obs, *_ = venv.step(_law(obs))
    s0, p = venv.state.copy(), venv.params.copy()
    recorded = []
    for _ in range(min(periods, int(venv.episodes[0].n_steps) - 60)):
        obs, *_ = venv.step(_law(obs))
        recorded.append(venv.inputs.copy())
    sub = venv.config.substeps
    venv.close()
    calls = 0
    t0 = time.perf_counter()
    while True:
        s = s0.copy()
        for u in recorded:
            kernel.advance_batch(s, p, u, sub)
        calls += len(recorded)
        dt = time.perf_counter() - t0
        if dt >= seconds:
            return calls * n_envs * sub / dt


def fill_pool(env):
    """``env`` (wrapped or not) with every unit of its device pool drawn (none without a pool):
    a long training run meets each unit many times, so a reset's steady cost is that of a
    unit already drawn."""
    dist = env.unwrapped.config.distribution()
    for k in range(dist.device_pool):
        dist.pool_device(k)
    return env


def only_resets(seconds: float, n_envs: int, repeat: int, device_pool: int = 0) -> dict:
    """The reset figures (medians of ``repeat`` timings): the scalar env's reset in ms and in
    env steps, and the vector env's env-steps/s with autoresets and without (one thread);
    with ``device_pool`` also the scalar env's reset with that pool (its units drawn first)."""
    scalar = [reset_cost_in_steps(seconds) for _ in range(repeat)]
    if device_pool:
        pooled = [reset_cost_in_steps(seconds, device_pool=device_pool) for _ in range(repeat)]
        print(f"scalar env reset with device_pool={device_pool} (every unit drawn first): "
              f"{statistics.median(x[0] for x in pooled) * 1e3:.3f} ms, "
              f"{statistics.median(x[2] for x in pooled):.1f} env steps (runs: "
              f"{', '.join(f'{x[2]:.1f}' for x in pooled)})", flush=True)
    mixed, plain, ends = [], [], []
    for _ in range(repeat):
        rate, n_ends, _ = vector_steps_per_s(seconds, n_envs, True, parallel=False)
        mixed.append(rate)
        ends.append(n_ends)
        plain.append(vector_steps_per_s(seconds, n_envs, False, parallel=False)[0])
    r = statistics.median(x[0] for x in scalar)
    s = statistics.median(x[1] for x in scalar)
    ratio = statistics.median(x[2] for x in scalar)
    out = {"repeat": repeat, "reset_s": r, "step_s": s, "reset_in_steps": ratio,
           "reset_in_steps_runs": [x[2] for x in scalar], "envs": n_envs,
           "vector_autoresets_env_steps_per_s": statistics.median(mixed),
           "vector_no_resets_env_steps_per_s": statistics.median(plain),
           "episode_ends": statistics.median(ends)}
    out["ratio_autoresets_to_no_resets"] = out["vector_autoresets_env_steps_per_s"] / out["vector_no_resets_env_steps_per_s"]
    if device_pool:
        out["device_pool"] = {"units": device_pool, "reset_s": statistics.median(x[0] for x in pooled),
                              "reset_in_steps": statistics.median(x[2] for x in pooled),
                              "reset_in_steps_runs": [x[2] for x in pooled]}
    print(f"scalar env reset: {r * 1e3:.3f} ms, step {s * 1e3:.4f} ms (200 Hz), median of {repeat} "
          f"(runs: {', '.join(f'{x[2]:.1f}' for x in scalar)} steps)")
    print(f"vector env {n_envs} envs, one thread: autoresets {out['vector_autoresets_env_steps_per_s']:10.0f} "
          f"env-steps/s ({out['episode_ends']:.0f} episode ends), no resets "
          f"{out['vector_no_resets_env_steps_per_s']:10.0f} env-steps/s, ratio {out['ratio_autoresets_to_no_resets']:5.2f}")
    runs = [reset_parts(seed=j) for j in range(repeat)]
    out["parts_in_steps"] = {k: statistics.median(r["parts_in_steps"][k] for r in runs) for k in runs[0]["parts_in_steps"]}
    out["parts_runs"] = runs
    print(f"parts of a reset, env steps, median of {repeat}: "
          + ", ".join(f"{k} {v:.1f}" for k, v in out["parts_in_steps"].items())
          + " (the device draw is part of the episode draw, the drive calibration of the supervisor envelope)")
    floors = [reset_floor(seed=10_000 + j) for j in range(repeat)]   # seeds no other part drew (fresh units)
    out["floor_in_steps"] = statistics.median(f["floor_in_steps"] for f in floors)
    out["floor_runs"] = floors
    print(f"the reset's own numerical work (bench load cycle, averaged conversions, R2 root, noise FFTs), "
          f"median of {repeat}: {out['floor_in_steps']:.1f} env steps of a reset of "
          f"{statistics.median(f['reset_in_steps'] for f in floors):.1f} (timers on: "
          + ", ".join(f"{k.rsplit('.', 1)[1]} {statistics.median(f['parts_s'][k] for f in floors) * 1e6:.1f} us"
                      for k in floors[0]["parts_s"]) + ")")
    print(f"load average (1 min) at end {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    print(f"one reset = {ratio:.1f} env steps (target <= 20)")
    return out


def step_breakdown(seconds: float, chunk: int = 500, **kwargs) -> dict:
    """Microseconds per step, without resets, of the parts of the single env's step and of
    Pendulum-v1, timed interleaved in chunks of ``chunk`` calls for about ``seconds`` each:

    * ``kernel``: :func:`ebraille_sim.plant.kernel.advance` of one env step's physics
      substeps alone (on a copy of an episode's plant rows, the command held);
    * ``compiled_step``: the env's one compiled call per step (loop engine period, safety
      supervisor, reward, observation) as :meth:`ContactForceEnv.step` calls it;
    * ``unwrapped`` and ``wrapped``: ``env.step`` of the env itself and of ``gym.make``'s;
    * ``pendulum`` and ``pendulum_unwrapped``.

    ``bound_ratio`` is ``pendulum / kernel``: the ratio to Pendulum-v1 (with wrappers) of an
    env that spent nothing beyond its physics substeps.  ``kwargs`` go to ``gym.make``."""
    from ebraille_sim.plant import kernel
    env = gym.make(ENV_ID, **kwargs)
    uw = env.unwrapped
    pend = gym.make("Pendulum-v1")
    a = np.full(1, 0.1, np.float32)

    def fresh():                       # a 60 wpm episode (1400 steps at 200 Hz) held at a small command
        env.reset(seed=0, options={"wpm": 60.0})
    fresh()
    pend.reset(seed=0)                 # stepped on past its TimeLimit's 200 steps (truncated, not refused)
    for _ in range(400):               # the kernel's rows taken in contact, 2 s into the episode
        env.step(a)
    s, p, u = uw._st.copy(), uw.plant.params[0].copy(), uw._inp.copy()
    n_sub = uw.config.substeps
    calls = {
        "kernel": lambda: kernel.advance(s, p, u, n_sub),
        "compiled_step": lambda: uw._step_fn(uw._st, uw._inp, uw._ws, uw._k, 0.1),
        "unwrapped": lambda: uw.step(a),
        "wrapped": lambda: env.step(a),
        "pendulum": lambda: pend.step(a),
        "pendulum_unwrapped": lambda: pend.unwrapped.step(a),
    }
    spent = {k: 0.0 for k in calls}
    count = {k: 0 for k in calls}
    for f in calls.values():          # warm-up (compilation, caches)
        f()
    while min(spent.values()) < seconds:
        for key, f in calls.items():
            if uw._n_steps - uw._k <= chunk:
                fresh()               # outside the clock
            t0 = time.perf_counter()
            for _ in range(chunk):
                f()
            spent[key] += time.perf_counter() - t0
            count[key] += chunk
    out = {f"{k}_us": 1e6 * spent[k] / count[k] for k in calls}
    out["bound_ratio"] = out["pendulum_us"] / out["kernel_us"]
    out["ratio_no_resets"] = out["pendulum_us"] / out["wrapped_us"]
    return out


def only_single(seconds: float, repeat: int, device_pool: int = 0) -> dict:
    """The single env against Pendulum-v1, with wrappers and unwrapped: ``repeat`` rounds of
    the two envs stepped interleaved (:func:`interleaved_steps_per_s`), and the medians of the
    rounds' ratios ours / Pendulum; ``device_pool`` > 0 gives our env that device pool, its
    units drawn before the clock starts (:func:`fill_pool`)."""
    rounds = []
    opts = {"device_pool": device_pool} if device_pool else {}
    for i in range(repeat):
        ours, pend = interleaved_steps_per_s([fill_pool(gym.make(ENV_ID, **opts)), gym.make("Pendulum-v1")], seconds)
        ours_raw, pend_raw = interleaved_steps_per_s([fill_pool(gym.make(ENV_ID, **opts)).unwrapped,
                                                      gym.make("Pendulum-v1").unwrapped], seconds)
        row = {"pendulum_steps_per_s": pend, "ours_steps_per_s": ours,
               "pendulum_unwrapped_steps_per_s": pend_raw, "ours_unwrapped_steps_per_s": ours_raw}
        row["ratio"] = row["ours_steps_per_s"] / row["pendulum_steps_per_s"]
        row["ratio_unwrapped"] = row["ours_unwrapped_steps_per_s"] / row["pendulum_unwrapped_steps_per_s"]
        rounds.append(row)
        print(f"round {i + 1}: with wrappers ours {row['ours_steps_per_s']:8.0f} Pendulum-v1 "
              f"{row['pendulum_steps_per_s']:8.0f} ratio {row['ratio']:5.2f};  unwrapped ours "
              f"{row['ours_unwrapped_steps_per_s']:8.0f} Pendulum-v1 {row['pendulum_unwrapped_steps_per_s']:8.0f} "
              f"ratio {row['ratio_unwrapped']:5.2f}", flush=True)
    out = {"repeat": repeat, "rounds": rounds}
    for key in rounds[0]:
        out[key] = statistics.median(r[key] for r in rounds)
    runs = ", ".join(f"{r['ratio']:.2f}" for r in rounds)
    runs_raw = ", ".join(f"{r['ratio_unwrapped']:.2f}" for r in rounds)
    print(f"single env{f' (device_pool={device_pool})' if device_pool else ''} / Pendulum-v1, median of {repeat} rounds: with wrappers {out['ratio']:5.2f} "
          f"(runs: {runs}), unwrapped {out['ratio_unwrapped']:5.2f} (runs: {runs_raw})")
    from ebraille_sim.physics.params import DeviceParams, RateParams
    for label, kwargs in (("breakdown", {}),
                          ("breakdown_5khz", {"base_device": DeviceParams(rates=RateParams(physics_rate_hz=5000.0))})):
        b = out[label] = step_breakdown(seconds, **kwargs)
        print(f"step parts, no resets{' (physics at 5 kHz)' if kwargs else ''}, us: kernel {b['kernel_us']:.2f}, "
              f"compiled step {b['compiled_step_us']:.2f}, unwrapped {b['unwrapped_us']:.2f}, wrapped "
              f"{b['wrapped_us']:.2f}; Pendulum-v1 {b['pendulum_us']:.2f} (unwrapped {b['pendulum_unwrapped_us']:.2f}); "
              f"ratio {b['ratio_no_resets']:.2f}, with nothing but the physics {b['bound_ratio']:.2f}", flush=True)
    print(f"load average (1 min) at end {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=3.0, help="measuring time per figure, s")
    ap.add_argument("--envs", type=int, default=1024, help="sub-envs of the vector env")
    ap.add_argument("--json", default=None, help="also write the results to this file")
    ap.add_argument("--only-resets", action="store_true",
                    help="only the reset cost (ms and env steps) and the vector env with and without autoresets")
    ap.add_argument("--only-single", action="store_true",
                    help="only the single env against Pendulum-v1, with wrappers and unwrapped (rounds, medians)")
    ap.add_argument("--device-pool", type=int, default=0,
                    help="with --only-single or --only-resets: also (resets) or instead (single) measure the env "
                         "with this device pool, its units drawn before the clock starts")
    ap.add_argument("--repeat", type=int, default=3,
                    help="timings per figure (rounds with --only-single) with --only-resets or --only-single (median)")
    a = ap.parse_args(argv)
    if a.repeat < 1:
        ap.error(f"--repeat must be at least 1, got {a.repeat}")
    if a.device_pool < 0:
        ap.error(f"--device-pool must be at least 0, got {a.device_pool}")
    if a.only_single and a.only_resets:
        ap.error("--only-single and --only-resets exclude each other")
    if a.only_single:
        res = {"machine": {"cpus": os.cpu_count(), "python": platform.python_version(),
                           "processor": platform.machine(), "load_average_1min_at_start": os.getloadavg()[0]},
               "seconds_per_figure": a.seconds}
        res["single"] = only_single(a.seconds, a.repeat, a.device_pool)
        res["machine"]["load_average_1min_at_end"] = os.getloadavg()[0]
        if a.json:
            with open(a.json, "w", encoding="utf-8") as fh:
                json.dump(res, fh, indent=2)
        return res
    if a.only_resets:
        res = {"machine": {"cpus": os.cpu_count(), "python": platform.python_version(),
                           "processor": platform.machine(), "load_average_1min_at_start": os.getloadavg()[0]},
               "seconds_per_figure": a.seconds}
        res["resets"] = only_resets(a.seconds, a.envs, a.repeat, a.device_pool)
        res["machine"]["load_average_1min_at_end"] = os.getloadavg()[0]
        if a.json:
            with open(a.json, "w", encoding="utf-8") as fh:
                json.dump(res, fh, indent=2)
        return res

    res = {"machine": {"cpus": os.cpu_count(), "python": platform.python_version(),
                       "processor": platform.machine(), "load_average_1min_at_start": os.getloadavg()[0]},
           "seconds_per_figure": a.seconds}
    pend = single_steps_per_s(gym.make("Pendulum-v1"), a.seconds)
    pend_raw = single_steps_per_s(gym.make("Pendulum-v1").unwrapped, a.seconds)
    cart = single_steps_per_s(gym.make("CartPole-v1"), a.seconds)
    ours = single_steps_per_s(gym.make(ENV_ID), a.seconds)
    ours_raw = single_steps_per_s(gym.make(ENV_ID).unwrapped, a.seconds)
    res["single"] = {"pendulum_steps_per_s": pend, "ours_steps_per_s": ours, "ratio": ours / pend,
                     "pendulum_unwrapped_steps_per_s": pend_raw, "ours_unwrapped_steps_per_s": ours_raw,
                     "ratio_unwrapped": ours_raw / pend_raw, "cartpole_steps_per_s": cart,
                     "ratio_cartpole": ours / cart}
    print(f"single env (gym.make, wrappers): ours {ours:10.0f} steps/s   Pendulum-v1 {pend:10.0f} steps/s   "
          f"ratio {ours / pend:5.2f}")
    print(f"single env (gym.make, wrappers): ours {ours:10.0f} steps/s   CartPole-v1 {cart:10.0f} steps/s   "
          f"ratio {ours / cart:5.2f}")
    print(f"single env (unwrapped):          ours {ours_raw:10.0f} steps/s   Pendulum-v1 {pend_raw:10.0f} steps/s   "
          f"ratio {ours_raw / pend_raw:5.2f}")

    r_s, s_s, ratio = reset_cost_in_steps(a.seconds)
    res["reset"] = {"reset_s": r_s, "step_s": s_s, "reset_in_steps": ratio}
    print(f"scalar env reset: {r_s * 1e3:.3f} ms, step {s_s * 1e3:.4f} ms (200 Hz): one reset = {ratio:.1f} steps")

    res["threads"] = thread_table()
    for row in res["threads"]:
        print(f"vector env {row['envs']:5d} envs, no resets: one thread {row['one_thread_env_steps_per_s']:10.0f} "
              f"env-steps/s, threads {row['threads_env_steps_per_s']:10.0f} env-steps/s, "
              f"threads/one {row['ratio_threads_to_one']:5.2f}")

    rows = []
    for label, resets, kwargs in [("200 Hz, autoresets, default", True, {}),
                                  ("200 Hz, autoresets, threads", True, {"parallel": True}),
                                  ("200 Hz, no resets, threads", False, {"parallel": True}),
                                  ("200 Hz, no resets, 1 thread", False, {"parallel": False}),
                                  ("1 kHz, autoresets, threads", True, {"control_rate_hz": 1000.0, "parallel": True}),
                                  ("1 kHz, no resets, threads", False, {"control_rate_hz": 1000.0, "parallel": True}),
                                  ("1 kHz, no resets, 1 thread", False, {"control_rate_hz": 1000.0,
                                                                         "parallel": False})]:
        rate, ends, sub = vector_steps_per_s(a.seconds, a.envs, resets, **kwargs)
        rows.append({"case": label, "envs": a.envs, "substeps_per_step": sub, "env_steps_per_s": rate,
                     "physics_substeps_per_s": rate * sub, "episode_ends": ends,
                     "ratio_to_pendulum_single": rate / pend, "ratio_to_target": rate / TARGET_VECTOR})
        print(f"vector env {a.envs} envs, {label:29s} ({sub:2d} substeps/step): {rate:11.0f} env-steps/s  "
              f"{rate * sub / 1e6:6.1f} M substeps/s  episode ends {ends:5d}  x{rate / pend:6.1f} Pendulum  "
              f"{rate / TARGET_VECTOR:5.2f} of 1M target")
    res["vector"] = rows
    bound = kernel_substeps_per_s(a.envs, a.seconds)
    default = rows[0]
    res["kernel_alone_substeps_per_s"] = bound
    res["vector_default_to_kernel"] = default["physics_substeps_per_s"] / bound
    print(f"kernel alone, {a.envs} rows, one thread, command held (plants at rest): {bound / 1e6:.1f} M substeps/s; "
          f"vector env default (autoresets) = {res['vector_default_to_kernel']:.2f} of it")
    replay = kernel_replay_substeps_per_s(a.envs, a.seconds)
    res["kernel_replay_substeps_per_s"] = replay
    res["vector_default_to_kernel_replay"] = default["physics_substeps_per_s"] / replay
    print(f"kernel alone, {a.envs} rows, one thread, replaying the vector env's inputs: {replay / 1e6:.1f} M "
          f"substeps/s; vector env default (autoresets) = {res['vector_default_to_kernel_replay']:.2f} of it "
          f"(target >= 0.8)")
    res["machine"]["load_average_1min_at_end"] = os.getloadavg()[0]
    print(f"load average (1 min) at start {res['machine']['load_average_1min_at_start']:.2f}, "
          f"at end {res['machine']['load_average_1min_at_end']:.2f} on {os.cpu_count()} cores")
    print(f"one reset = {ratio:.1f} env steps (target <= 20)")
    if a.json:
        with open(a.json, "w", encoding="utf-8") as fh:
            json.dump(res, fh, indent=2)
    return res


if __name__ == "__main__":
    main()
