"""Run a scenario: closed loop, trace, metrics.

Examples
--------
>>> import ebraille_sim
>>> res = ebraille_sim.run_scenario("steady_90wpm", seed=3)        # doctest: +SKIP
>>> res.metrics["in_band_fraction"] > 0.9                          # doctest: +SKIP
True
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from ebraille_sim.plant.layout import S, U
from ebraille_sim.plant.loop import make_plant
from ebraille_sim.scenarios.metrics import compute_metrics
from ebraille_sim.physics.noise import seed_from
from ebraille_sim.scenarios.spec import ScenarioError, ScenarioSpec, load_scenario

TRACE_COLUMNS = ["t_s", "setpoint_n", "force_true_n", "force_est_n", "fsr_voltage_v", "command_v",
                 "motor_current_a", "board_pos_m", "energy_j", "char_index", "character"]


@dataclass
class RunResult:
    """Outcome of one scenario run.

    Attributes
    ----------
    spec : ScenarioSpec
    metrics : dict
        See :mod:`ebraille_sim.scenarios.metrics`.
    trace : dict of ndarray
        Named arrays of shape (n_steps,), sampled at the control rate (columns
        :data:`TRACE_COLUMNS`); sample ``k`` is the state at the end of control period ``k``.
    schedule : ReadingSchedule
    controller_name : str
    seed : int
    """
    spec: ScenarioSpec
    metrics: dict
    trace: dict
    schedule: object
    controller_name: str
    seed: int


def reading_text(spec: ScenarioSpec) -> str:
    """The text a scenario reads (passage, inline text or file)."""
    r = spec.reading
    if r.text is not None:
        return r.text
    if r.file is not None:
        import pathlib
        p = pathlib.Path(r.file)
        if not p.is_absolute():
            p = pathlib.Path(spec.base_dir) / p
        try:
            return p.read_text(encoding="utf-8")
        except OSError as exc:
            raise ScenarioError(f"{spec.source}: cannot read [reading] file {str(p)!r}: {exc.strerror}") from None
    from ebraille_sim.scenarios.passages import load_passage
    try:
        return load_passage(r.passage)
    except ValueError as exc:
        raise ScenarioError(f"{spec.source}: {exc}") from None


def build_schedule_for(spec: ScenarioSpec, rng: np.random.Generator):
    """Reading schedule of a scenario, repeating the text to fill ``duration_s``."""
    from ebraille_sim.scenarios.braille import text_to_cells
    from ebraille_sim.scenarios.reading import build_schedule, mean_dwell_s
    r = spec.reading
    try:
        cells = text_to_cells(reading_text(spec))
    except ValueError as exc:
        raise ScenarioError(f"{spec.source}: {exc}") from None
    if not cells:
        raise ScenarioError(f"{spec.source}: the reading text is empty")
    if spec.duration_s is not None:
        need = int(math.ceil((spec.duration_s - r.start_s) / mean_dwell_s(r.wpm) * 1.6)) + 1
        reps = max(1, int(math.ceil(need / len(cells))))
        cells = (cells * reps)[:max(need, 1)]
    if r.max_characters is not None:
        cells = cells[:r.max_characters]
    return build_schedule(cells, r.wpm, start_s=r.start_s, jitter_fraction=r.jitter_fraction,
                          word_pause_s=r.word_pause_s, line_pause_s=r.line_pause_s,
                          rng=rng if r.jitter_fraction > 0 else None)


def setpoint_profile(spec: ScenarioSpec, t_s: np.ndarray, schedule=None) -> np.ndarray:
    """Force setpoint at the times ``t_s`` (steps, optionally ramped over ``ramp_s``).

    In refresh mode (``[reading] mode = "refresh"``) the ``schedule`` is required and the
    setpoint drops to ``refresh_lift_force_n`` while each character is lifted or
    released (see :func:`refresh_phases`).
    """
    sp = _base_setpoint(spec, t_s)
    if spec.reading.mode == "refresh":
        if schedule is None:
            raise ValueError("setpoint_profile: refresh mode needs the reading schedule")
        pressed, _ = refresh_phases(spec, schedule, t_s)
        lift = np.minimum(spec.reading.refresh_lift_force_n, sp)
        sp = np.where(pressed, sp, lift)
    return sp


def refresh_phases(spec: ScenarioSpec, schedule, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-character refresh phases at the times ``t_s``.

    Each dwell ``[s, s + d)`` is split into lift ``[0, l)``, press ``[l, l + p)``, hold
    ``[l + p, 1 - r)`` and release ``[1 - r, 1)`` in units of ``d``, with ``l``, ``p``,
    ``r`` the ``refresh_*_fraction`` keys of ``[reading]``: the display leaves the skin
    (setpoint at the lift force) while the pattern changes at the character boundary,
    presses during ``p`` (the time allowed to reach the band) and holds.

    Returns
    -------
    pressed : ndarray of bool, shape t_s.shape
        True during press and hold, and outside the schedule.
    hold : ndarray of bool, shape t_s.shape
        True during the hold part of a dwell (the character's in-band window).
    """
    r = spec.reading
    k = np.asarray(schedule.index_at(t_s))
    inside = k >= 0
    kk = np.where(inside, k, 0)
    start = np.asarray(schedule.start_s)[kk] if len(schedule) else np.zeros_like(t_s)
    dwell = np.asarray(schedule.dwell_s)[kk] if len(schedule) else np.ones_like(t_s)
    u = (t_s - start) / dwell
    lo = r.refresh_lift_fraction
    hold_lo = lo + r.refresh_press_fraction
    hold_hi = 1.0 - r.refresh_release_fraction
    pressed = ~inside | ((u >= lo) & (u < hold_hi))
    hold = inside & (u >= hold_lo) & (u < hold_hi)
    return pressed, hold


def _base_setpoint(spec: ScenarioSpec, t_s: np.ndarray) -> np.ndarray:
    sp = np.full_like(t_s, spec.setpoint.force_n, dtype=float)
    prev = spec.setpoint.force_n
    ramp = spec.setpoint.ramp_s
    for t0, f in spec.setpoint.steps:
        if ramp > 0:
            frac = np.clip((t_s - t0) / ramp, 0.0, 1.0)
            sp = np.where(t_s >= t0, prev + (f - prev) * frac, sp)
        else:
            sp = np.where(t_s >= t0, f, sp)
        prev = f
    return sp


def make_controller(spec: ScenarioSpec, controller=None):
    """The controller object for a run: ``controller`` (name, path or object) or the scenario's."""
    import controllers
    if controller is None:
        try:
            return controllers.make(spec.controller.name, **spec.controller.gains)
        except (ValueError, TypeError, FileNotFoundError) as exc:
            raise ScenarioError(f"{spec.source}: [controller] {exc}") from None
    if isinstance(controller, str):
        return controllers.make(controller)
    return controller


def input_profiles(spec: ScenarioSpec, t_s: np.ndarray, rng: np.random.Generator, plant) -> dict:
    """Per-period plant inputs from the scenario's delegate sections, as arrays over ``t_s``.

    Each section's module returns ``{input_name: ("set" | "add", array)}``; "add" profiles
    are added to the plant's constant input (e.g. finger motion around the gap).  Only
    inputs that vary are returned.
    """
    import importlib

    from ebraille_sim.scenarios.spec import DELEGATES
    base = {name: np.full(len(t_s), plant.inputs[0, j]) for name, j in U.items() if name != "command_v"}
    touched = set()
    for key, section in spec.sections.items():
        mod = importlib.import_module(DELEGATES[key])
        build = getattr(mod, "build_inputs", None)
        if build is None:
            continue
        for name, (mode, arr) in build(section, t_s, rng, spec.device).items():
            if name not in base:
                raise ScenarioError(f"{spec.source}: [{key}] drives unknown input {name!r}")
            base[name] = base[name] + arr if mode == "add" else np.broadcast_to(arr, t_s.shape).astype(float)
            touched.add(name)
    return {name: base[name] for name in sorted(touched)}


def wrap_controller(spec: ScenarioSpec, ctrl, dt_s: float):
    """Apply the scenario's controller wrappers (e.g. a safety supervisor)."""
    import importlib

    from ebraille_sim.scenarios.spec import DELEGATES
    for key, section in spec.sections.items():
        mod = importlib.import_module(DELEGATES[key])
        wrap = getattr(mod, "wrap_controller", None)
        if wrap is not None:
            ctrl = wrap(section, ctrl, dt_s, device=spec.device)
    return ctrl


def run_scenario(scenario, controller=None, seed: int | None = None, duration_s: float | None = None,
                 backend: str = "lumped", device=None) -> RunResult:
    """Simulate a scenario in closed loop.

    Parameters
    ----------
    scenario : str, path or ScenarioSpec
        Scenario file, shipped scenario name, or a parsed spec.
    controller : str, path or Controller, optional
        Overrides the scenario's controller (a registered name, a gains file, or an object
        implementing :class:`controllers.Controller`).
    seed : int, optional
        Overrides the scenario's master seed.  The same seed gives the same trace, exactly.
    duration_s : float, optional
        Overrides the scenario's duration.
    backend : str
        Plant model: ``"lumped"`` or another name in :data:`ebraille_sim.plant.loop.PLANT_BACKENDS`.
    device : DeviceParams, optional
        Replaces the scenario's device (e.g. a reader drawn by
        :func:`ebraille_sim.scenarios.population.sample_devices`).

    Returns
    -------
    RunResult
    """
    spec = scenario if isinstance(scenario, ScenarioSpec) else load_scenario(scenario)
    if device is not None:
        import dataclasses
        spec = dataclasses.replace(spec, device=device)
    if duration_s is not None:
        if not (math.isfinite(duration_s) and duration_s > 0):
            raise ScenarioError(f"duration_s must be a positive finite number, got {duration_s}")
        import dataclasses
        spec = dataclasses.replace(spec, duration_s=float(duration_s))
    seed = spec.seed if seed is None else int(seed)
    if seed < 0:
        raise ScenarioError(f"seed must be >= 0, got {seed}")
    ss_sensor, ss_reading, ss_inputs = np.random.SeedSequence(seed).spawn(3)
    schedule = build_schedule_for(spec, np.random.default_rng(ss_reading))
    ctrl = make_controller(spec, controller)
    dev = spec.device
    dt = 1.0 / dev.rates.control_rate_hz
    t_end = spec.duration_s if spec.duration_s is not None else schedule.t_end_s
    n = int(round(t_end / dt))
    if n < 1:
        raise ScenarioError(f"{spec.source}: duration {t_end:g} s is shorter than one control period")
    t = (np.arange(n) + 1) * dt
    sp = setpoint_profile(spec, t - dt, schedule)
    try:
        plant = make_plant([dev], seeds=[seed_from(ss_sensor)], backend=backend)
    except (ValueError, FileNotFoundError) as exc:
        raise ScenarioError(f"{spec.source}: {exc}") from None
    plant.set_finger(spec.finger.gap_m)
    profiles = input_profiles(spec, t - dt, np.random.default_rng(ss_inputs), plant)
    ctrl = wrap_controller(spec, ctrl, dt)
    tr = {c: np.zeros(n) for c in TRACE_COLUMNS if c != "character"}
    st = plant.state[0]
    i_fc, i_fe, i_v, i_i, i_x, i_e = (S["contact_force_n"], S["force_est_n"], S["fsr_voltage_v"],
                                      S["current_a"], S["board_pos_m"], S["energy_j"])
    ctrl.reset(force_est_n=float(st[i_fe]), setpoint_n=float(sp[0]), command_v=0.0)
    f_true, f_est, v_fsr, cmd_v, cur, xb, en = (tr["force_true_n"], tr["force_est_n"], tr["fsr_voltage_v"],
                                                tr["command_v"], tr["motor_current_a"], tr["board_pos_m"],
                                                tr["energy_j"])
    fe = float(st[i_fe])
    i_a = 0.0
    update = ctrl.update
    advance = plant.advance
    inp = plant.inputs[0]
    varying = [(U[name], arr) for name, arr in profiles.items()]
    wall0 = time.perf_counter()
    for k in range(n):
        for j, arr in varying:
            inp[j] = arr[k]
        c = update(fe, sp[k], dt, i_a)
        advance(c)
        fe = float(st[i_fe])
        i_a = float(st[i_i])
        cmd_v[k] = c
        f_true[k] = st[i_fc]
        f_est[k] = fe
        v_fsr[k] = st[i_v]
        cur[k] = i_a
        xb[k] = st[i_x]
        en[k] = st[i_e]
    wall = time.perf_counter() - wall0
    if not np.all(np.isfinite(f_true)):
        raise FloatingPointError(f"{spec.source}: the simulation diverged (non-finite force)")
    tr["t_s"] = t
    tr["setpoint_n"] = sp
    ci = schedule.index_at(t)
    tr["char_index"] = ci
    cells = schedule.cells
    tr["character"] = np.array([cells[j].unicode if j >= 0 else "" for j in ci])
    window = tr
    if spec.reading.mode == "refresh":
        # refresh mode: a character's in-band window is the hold part of its dwell only
        _, hold = refresh_phases(spec, schedule, t)
        window = dict(tr, char_index=np.where(hold, ci, -1))
    metrics = compute_metrics(window, spec.reading.start_s, spec.setpoint.band_fraction, schedule, wall)
    # electrotactile legibility beside the force metrics (stimulation during the same windows)
    from ebraille_sim.scenarios.legibility import legibility_metrics
    metrics.update(legibility_metrics(f_true, sp, window["char_index"], cells))
    return RunResult(spec, metrics, tr, schedule, getattr(ctrl, "name", type(ctrl).__name__), seed)
