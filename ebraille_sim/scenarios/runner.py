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
from ebraille_sim.scenarios.compiled_loop import KEPT, ROW
from ebraille_sim.scenarios.inputs import build_run_inputs, refresh_phases
from ebraille_sim.scenarios.metrics import compute_metrics
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
        With :func:`run_scenario`'s ``trace_every`` = k every k-th sample only; with None empty.
    schedule : ReadingSchedule
    controller_name : str
        The name of the controller chosen for the run (the scenario's or the override),
        without the wrappers (injected faults, supervisor) the scenario adds around it.
    seed : int
    supervisor : dict
        The safety supervisor of the run (:func:`supervisor_choice`): ``enabled``, ``source``
        (why it is on or off) and, when it ran, its latched ``fault`` (None) and its
        ``events`` (time s, description).
    """
    spec: ScenarioSpec
    metrics: dict
    trace: dict
    schedule: object
    controller_name: str
    seed: int
    supervisor: dict = None


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


def supervisor_choice(spec: ScenarioSpec, supervised: bool = True) -> tuple[bool, str]:
    """Whether a run of ``spec`` is supervised, and why.

    The safety supervisor (:mod:`controllers.supervisor`) is on unless switched off
    explicitly: by ``supervised=False`` (the command line's ``--no-supervisor``) or by the
    scenario's ``[supervisor] enabled = false``.  A scenario without a ``[supervisor]``
    section runs with the default supervisor for its device.
    """
    if not isinstance(supervised, bool):
        raise TypeError(f"supervised must be True or False, got {supervised!r}")
    section = spec.sections.get("supervisor")
    if not supervised:
        return False, "off: switched off for this run (supervised=False, --no-supervisor)"
    if section is None:
        return True, "on: default limits for the device"
    if section.get("enabled", True) is False:
        return False, f"off: {spec.source} sets [supervisor] enabled = false"
    return True, f"on: limits of {spec.source} [supervisor]" if section else "on: default limits for the device"


def wrap_controller(spec: ScenarioSpec, ctrl, dt_s: float, supervised: bool = True):
    """Apply the scenario's controller wrappers: injected controller faults, then the safety
    supervisor (on unless switched off, :func:`supervisor_choice`)."""
    import importlib

    from ebraille_sim.scenarios.spec import DELEGATES
    on, _ = supervisor_choice(spec, supervised)
    for key in DELEGATES:
        section = spec.sections.get(key)
        if key == "supervisor":
            if not on:
                continue
            section = {} if section is None else section
        elif section is None:
            continue
        wrap = getattr(importlib.import_module(DELEGATES[key]), "wrap_controller", None)
        if wrap is not None:
            ctrl = wrap(section, ctrl, dt_s, device=spec.device)
    return ctrl


def prepare_run(scenario, controller=None, seed: int | None = None, duration_s: float | None = None,
                device=None) -> tuple:
    """The spec, seed, run inputs and (unwrapped) controller of one run of :func:`run_scenario`."""
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
    run = build_run_inputs(spec, seed)
    ctrl = make_controller(spec, controller)
    return spec, seed, run, ctrl


def run_scenario(scenario, controller=None, seed: int | None = None, duration_s: float | None = None,
                 backend: str = "lumped", device=None, trace_every: int | None = 1,
                 supervised: bool = True) -> RunResult:
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
    trace_every : int or None
        Samples of the returned trace: 1 (default) keeps every control period; ``k`` keeps
        every ``k``-th (samples ``k - 1, 2k - 1, ...``, the ends of periods ``k, 2k, ...``);
        None returns no trace (an empty dict).  The metrics are always computed from every
        control period and do not depend on it; above 1 the run holds only the true and
        estimated force at the full rate, which bounds the memory of long sessions.
    supervised : bool
        False switches the safety supervisor off for this run (recorded in
        ``RunResult.supervisor``); True (default) leaves the scenario's choice, which is on
        unless the file sets ``[supervisor] enabled = false``.

    Returns
    -------
    RunResult
    """
    if trace_every is not None and (isinstance(trace_every, bool) or not isinstance(trace_every, (int, np.integer))
                                    or trace_every < 1):
        raise ValueError(f"trace_every must be a whole number >= 1 or None, got {trace_every!r}")
    spec, seed, run, ctrl = prepare_run(scenario, controller, seed, duration_s, device)
    supervisor_choice(spec, supervised)
    if trace_every == 1:
        return _simulate(spec, seed, run, ctrl, backend, supervised)
    return _simulate_lean(spec, seed, run, ctrl, backend, trace_every, supervised, release_inputs=True)


def _simulate(spec, seed, run, ctrl, backend: str, supervised: bool = True) -> RunResult:
    """Closed loop of one prepared run, one control period per Python iteration, full trace."""
    sp, f_true, f_est, kept, _, wall, name, wrapped = _closed_loop(spec, run, ctrl, backend, 1, supervised)
    tr = {"force_true_n": f_true, "force_est_n": f_est, **kept}
    return _with_supervisor(_finish(spec, seed, run, tr, sp, wall, name), spec, supervised, wrapped)


def _plant_for(spec, run, backend: str):
    try:
        plant = make_plant([spec.device], seeds=[run.sensor_seed], backend=backend)
    except (ValueError, FileNotFoundError) as exc:
        raise ScenarioError(f"{spec.source}: {exc}") from None
    plant.set_finger(spec.finger.gap_m)
    return plant


def _closed_loop(spec, run, ctrl, backend: str, every: int | None, supervised: bool):
    """The control loop of one prepared run: the true and estimated force at every period
    (the metrics need them), the other trace columns at every ``every``-th (None: not at all).

    Returns ``(setpoint, force_true, force_est, kept columns, energy at the end (J), wall s,
    controller name, the wrapped controller)``.
    """
    dt, n = run.dt_s, run.n_steps
    sp = run.setpoint_n[:n]                       # read only: a view, not a copy
    plant = _plant_for(spec, run, backend)
    # a reference controller that declares ``feedback = "true_force"`` (controllers.bounds) is fed
    # the true contact force instead of the estimate; every other controller sees the estimate
    i_fb = S.contact_force_n if getattr(ctrl, "feedback", "estimate") == "true_force" else S.force_est_n
    ctrl_name = _name(ctrl)
    ctrl_unwrapped = ctrl
    ctrl = wrap_controller(spec, ctrl, dt, supervised)
    st = plant.state[0]
    ctrl.reset(force_est_n=float(st[i_fb]), setpoint_n=float(sp[0]), command_v=0.0)
    f_true, f_est = np.zeros(n), np.zeros(n)
    n_kept = 0 if every is None else n // every
    kept = np.zeros((len(KEPT), n_kept))
    form = _loop_form(ctrl_unwrapped, ctrl, plant, backend)
    if form is not None and _loop_not_compiled():
        # compile (or load from the cache) before the timed loop: zero periods change nothing
        _run_compiled(form, plant, run, ctrl, sp[:0], i_fb, every, np.zeros(0), np.zeros(0),
                      np.zeros((len(KEPT), 0)))
    wall0 = time.perf_counter()
    if form is not None:
        _run_compiled(form, plant, run, ctrl, sp, i_fb, every, f_true, f_est, kept)
    else:
        _run_periods(plant, run, ctrl, sp, i_fb, every, f_true, f_est, kept)
    wall = time.perf_counter() - wall0
    energy_end = float(st[S.energy_j]) if n else 0.0
    return sp, f_true, f_est, dict(zip(KEPT, kept)), energy_end, wall, ctrl_name, ctrl


def _loop_not_compiled() -> bool:
    """Whether this process has not yet compiled (or loaded) the compiled loop."""
    from ebraille_sim.scenarios import compiled_loop
    return not getattr(compiled_loop.run_loop, "signatures", True)


_USE_COMPILED_LOOP = True
"""Run a loop in one compiled call when it can (:func:`_loop_form`); False forces the
per-period loop (for tests that compare the two)."""


def _loop_form(ctrl, wrapped, plant, backend: str):
    """What :func:`_run_compiled` needs to run the loop of ``wrapped`` in one compiled call:
    ``(kind, state, params, sv_state, sv_cfg)`` (the supervisor's vectors None when it
    runs unsupervised), or None when it cannot.

    It can on the lumped plant with one device, for a controller ``ctrl`` with a compiled
    form (:func:`controllers.compiled.compiled_form`) that runs unwrapped, or wrapped only in
    an enabled safety supervisor (whose period is compiled too).
    """
    from ebraille_sim.plant.loop import Plant
    if backend != "lumped" or type(plant) is not Plant or plant.n != 1:
        return None
    return _compiled_controller(ctrl, wrapped)


def _compiled_controller(ctrl, wrapped):
    """The controller part of :func:`_loop_form` (any plant)."""
    if not _USE_COMPILED_LOOP:
        return None
    from controllers.compiled import compiled_form
    form = compiled_form(ctrl)
    if form is None:
        return None
    kind, cstate, cparams = form
    if wrapped is ctrl:
        return kind, cstate, cparams, None, None
    from controllers.supervisor import Supervisor
    if type(wrapped) is Supervisor and wrapped.inner is ctrl:
        sv = compiled_form(wrapped)
        if sv is not None:
            return kind, cstate, cparams, sv[0], sv[1]
    return None


def _run_compiled(form, plant, run, ctrl, sp, i_fb: int, every, f_true, f_est, kept) -> None:
    """The loop of :func:`_closed_loop` in one call of
    :func:`ebraille_sim.scenarios.compiled_loop.run_loop`; raises what the per-period loop raises."""
    from ebraille_sim.scenarios.compiled_loop import profile_arrays, run_loop
    kind, cstate, cparams, sv_state, sv_cfg = form
    supervised = sv_state is not None
    if not supervised:
        sv_state = sv_cfg = np.zeros(0)
    n = len(f_true)
    slots, table = profile_arrays(run.profiles, n)
    st = plant.state[0]
    status, k, value = run_loop(st, plant.params[0], plant.inputs[0], plant.substeps, kind, cstate, cparams,
                                supervised, sv_state, sv_cfg, sp, run.dt_s, i_fb, slots, table,
                                0 if every is None else every, f_true, f_est, kept)
    _raise_status(status, k, value, ctrl, st, sp, run.dt_s, i_fb)


def _raise_status(status: int, k: int, value: float, ctrl, st, sp, dt_s: float, i_fb: int) -> None:
    """Raise what the per-period loop raises for a compiled loop's error ``status`` (none for OK)."""
    from ebraille_sim.scenarios.compiled_loop import BAD_COMMAND, BAD_CONTROLLER_INPUT
    if status == BAD_CONTROLLER_INPUT:
        # the controller's own check names the bad argument
        ctrl.update(float(st[i_fb]), sp[k], dt_s, float(st[S.current_a]) if k else 0.0)
        raise ValueError(f"non-finite controller input at control period {k}")
    if status == BAD_COMMAND:
        raise ValueError(f"command_v must be finite, got {value}")


def _run_periods(plant, run, ctrl, sp, i_fb: int, every, f_true, f_est, kept) -> None:
    """The loop of :func:`_closed_loop`, one control period per Python iteration."""
    dt, n = run.dt_s, len(f_true)
    st = plant.state[0]
    # slot indices and trace columns bound to locals: the loop below runs once per control period
    i_fc, i_fe, i_v, i_i, i_x, i_e = (S.contact_force_n, S.force_est_n, S.fsr_voltage_v,
                                      S.current_a, S.board_pos_m, S.energy_j)
    cmd_v, v_fsr, cur, xb, en = (kept[ROW.command_v], kept[ROW.fsr_voltage_v], kept[ROW.motor_current_a],
                                 kept[ROW.board_pos_m], kept[ROW.energy_j])
    fe = float(st[i_fb])
    i_a = 0.0
    update = ctrl.update
    advance = plant.advance
    inp = plant.inputs[0]
    varying = [(U[name], arr) for name, arr in run.profiles.items()]
    due = -1 if every is None else every - 1          # next period whose end is kept
    q = 0
    for k in range(n):
        for j, arr in varying:
            inp[j] = arr[k]
        c = update(fe, sp[k], dt, i_a)
        advance(c)
        fe = float(st[i_fb])
        i_a = float(st[i_i])
        f_true[k] = st[i_fc]
        f_est[k] = st[i_fe]
        if k == due:
            cmd_v[q] = c
            v_fsr[q] = st[i_v]
            cur[q] = i_a
            xb[q] = st[i_x]
            en[q] = st[i_e]
            q += 1
            due += every


def _simulate_lean(spec, seed, run, ctrl, backend: str, every: int | None, supervised: bool = True,
                   release_inputs: bool = False) -> RunResult:
    """:func:`_simulate` keeping the true and estimated force at every period and the other
    trace columns at every ``every``-th period (None: not at all); the same metrics.

    ``release_inputs`` empties ``run.profiles`` once the loop has run (for a run whose inputs
    nobody else holds: a long session's metrics then run without them in memory)."""
    sp, f_true, f_est, kept, energy_end, wall, name, wrapped = _closed_loop(spec, run, ctrl, backend, every,
                                                                            supervised)
    dt, n = run.dt_s, run.n_steps
    if release_inputs:
        run.profiles.clear()                      # the metrics do not read them: free them first
    tr = {"force_true_n": f_true, "force_est_n": f_est, "energy_j": np.array([energy_end])}
    res = _with_supervisor(_finish(spec, seed, run, tr, sp, wall, name, keep_trace=False), spec,
                           supervised, wrapped)
    if every is None:
        return res
    sel = slice(every - 1, None, every)
    out = {"t_s": ((np.arange(n) + 1) * dt)[sel], "setpoint_n": sp[sel], "force_true_n": f_true[sel].copy(),
           "force_est_n": f_est[sel].copy(), **kept}
    out["char_index"] = run.schedule.index_at(out["t_s"])
    out["character"] = character_column(out["char_index"], run.schedule.cells)
    res.trace = {c: out[c] for c in TRACE_COLUMNS}
    return res


def _finish(spec, seed, run, tr: dict, sp: np.ndarray, wall: float, controller_name: str,
            keep_trace: bool = True) -> RunResult:
    """Check a finished loop's trace, complete its columns and compute the metrics
    (``keep_trace`` False: ``tr`` holds only what the metrics read; the result's trace is empty)."""
    f_true = tr["force_true_n"]
    if not np.all(np.isfinite(f_true)):
        raise FloatingPointError(f"{spec.source}: the simulation diverged (non-finite force)")
    schedule = run.schedule
    n = run.n_steps
    t = np.arange(1, n + 1, dtype=float)          # sample k: the end of period k, (k + 1) dt
    t *= run.dt_s
    tr["t_s"] = t
    tr["setpoint_n"] = sp
    ci = schedule.index_at(t)
    tr["char_index"] = ci
    cells = schedule.cells
    if keep_trace:
        tr["character"] = character_column(ci, cells)
        tr = {c: tr[c] for c in TRACE_COLUMNS}
    window = tr
    if spec.reading.mode == "refresh":
        # refresh mode: a character's in-band window is the hold part of its dwell only
        _, hold = refresh_phases(spec, schedule, t)
        window = dict(tr, char_index=np.where(hold, ci, -1))
    metrics = compute_metrics(window, spec.reading.start_s, spec.setpoint.band_fraction, schedule, wall)
    # electrotactile legibility beside the force metrics (stimulation during the same windows)
    from ebraille_sim.scenarios.legibility import legibility_metrics
    metrics.update(legibility_metrics(f_true, sp, window["char_index"], cells))
    return RunResult(spec, metrics, tr if keep_trace else {}, schedule, controller_name, seed)


def character_column(char_index: np.ndarray, cells) -> np.ndarray:
    """The Unicode Braille character shown at each sample ("" where none), by table look-up."""
    table = np.array([c.unicode for c in cells] + [""])
    ci = np.asarray(char_index)
    return table[np.where(ci >= 0, ci, len(cells))]


BATCH_TRACE_BYTES = 256 * 2**20
"""Most trace memory one batched plant of :func:`run_batch` holds (its rows are split to
stay below it), bytes."""

COMPILED_BATCH_ROWS = 128
"""Most runs of one call of :func:`ebraille_sim.scenarios.compiled_loop.run_rows` (each row
holds its supervisor's state, about 140 kB, besides its trace and inputs)."""

_BATCH_SLOTS = ("contact_force_n", "force_est_n", "fsr_voltage_v", "current_a", "board_pos_m", "energy_j")
_BATCH_COLUMNS = ("force_true_n", "force_est_n", "fsr_voltage_v", "motor_current_a", "board_pos_m", "energy_j")
_RUN_ERRORS = (ValueError, FloatingPointError, FileNotFoundError)


def run_batch(runs: list, keep_traces: bool = True) -> list:
    """Several runs of :func:`run_scenario` (lumped plant), their plants advanced together.

    Runs with the same number of control periods and the same rates share one packed plant:
    every control period calls each run's controller (Python objects, in a loop) and then
    advances all rows in one compiled call (:func:`ebraille_sim.plant.kernel.advance_batch`).
    Rows are independent, so every run's trace and metrics are those of :func:`run_scenario`
    with the same arguments, exactly (``real_time_factor`` aside: the batch's loop time is
    shared equally among its rows).

    Parameters
    ----------
    runs : list of dict
        Keyword arguments of :func:`run_scenario` per run (``scenario``, ``controller``,
        ``seed``, ``duration_s``, ``device``; no ``backend``).
    keep_traces : bool
        False returns every result with an empty trace (its metrics unchanged): a sweep
        keeps only metrics, so the batch's traces are not copied out.

    Returns
    -------
    list
        Per run, in order: its :class:`RunResult`, or the ``ValueError``,
        ``FloatingPointError`` or ``FileNotFoundError`` that :func:`run_scenario` would have
        raised for it.
    """
    out: list = [None] * len(runs)
    groups: dict = {}
    made: dict = {}
    for i, kw in enumerate(runs):
        try:
            prepared = prepare_run(**_with_controller_copy(kw, made))
        except _RUN_ERRORS as exc:
            out[i] = exc
            continue
        spec, _, run, _ = prepared
        groups.setdefault((run.n_steps, run.dt_s, spec.device.rates), []).append((i, prepared))
    for (n, _, _), members in groups.items():
        per_row = 8 * max(1, n) * (len(_BATCH_COLUMNS) + 1)
        size = max(1, BATCH_TRACE_BYTES // per_row)
        for j in range(0, len(members), size):
            part = members[j:j + size]
            for i, res in zip((m[0] for m in part), _simulate_batch([m[1] for m in part], keep_traces)):
                out[i] = res
    return out


def _with_controller_copy(kw: dict, made: dict) -> dict:
    """``kw`` with a controller named by a string replaced by a fresh copy (unpickled) of one
    object made for that name (:func:`make_controller` once per name and batch; a
    controller's design, e.g. the LQG's Riccati solutions, does not depend on the run)."""
    import copy
    import pickle
    name = kw.get("controller")
    if not isinstance(name, str):
        return kw
    if name not in made:
        try:
            proto = make_controller(None, name)
        except _RUN_ERRORS:
            return kw                                # prepare_run raises it for this run
        try:
            made[name] = (pickle.dumps(proto, pickle.HIGHEST_PROTOCOL), None)
        except (pickle.PicklingError, TypeError, AttributeError):
            made[name] = (None, proto)
    blob, proto = made[name]
    return {**kw, "controller": pickle.loads(blob) if blob is not None else copy.deepcopy(proto)}


def _simulate_batch(prepared: list, keep_traces: bool = True) -> list:
    """:func:`_simulate` of several prepared runs with equal length and rates.

    Runs whose controller has a compiled form go through :func:`_simulate_compiled_rows`
    (all of them in one compiled call); the others share one plant stepped from Python
    (:func:`_simulate_python_rows`).
    """
    if len(prepared) > 1 and any(getattr(p[3], "feedback", "estimate") == "true_force" for p in prepared):
        # a controller fed the true force runs on its own (:func:`_simulate` reads it from the state)
        return [r for p in prepared for r in _simulate_batch([p], keep_traces)]
    if len(prepared) > 1 and _USE_COMPILED_LOOP:
        out = [res for j in range(0, len(prepared), COMPILED_BATCH_ROWS)
               for res in _simulate_compiled_rows(prepared[j:j + COMPILED_BATCH_ROWS], keep_traces)]
        rest = [r for r in range(len(prepared)) if out[r] is None]
        if rest:
            for r, res in zip(rest, _simulate_python_rows([prepared[r] for r in rest], keep_traces)):
                out[r] = res
        return out
    return _simulate_python_rows(prepared, keep_traces)


def _wrap_shared(spec, ctrl, dt_s: float, cache: dict):
    """:func:`wrap_controller` (supervised), the supervisor's configuration shared by the runs
    of one device and scenario sections (built once: :meth:`SupervisorConfig.for_device`)."""
    from controllers.supervisor import Supervisor
    key = (id(spec.sections), id(spec.device), dt_s)
    hit = cache.get(key)
    if hit is not None:
        return Supervisor(ctrl, hit[0].config)
    wrapped = wrap_controller(spec, ctrl, dt_s)
    if type(wrapped) is Supervisor and wrapped.inner is ctrl:
        cache[key] = (wrapped, spec)                   # the spec keeps the ids of the key alive
    return wrapped


def _plant_rows(spec, run, cache: dict) -> tuple:
    """Initial ``(state, params, inputs)`` rows of the lumped plant of one run, packed once per
    device (:func:`_plant_for`) and copied with the run's sensor seed."""
    from ebraille_sim.plant.layout import P
    key = id(spec.device)
    hit = cache.get(key)
    if hit is None:
        plant = _plant_for(spec, run, "lumped")
        hit = cache[key] = (plant.state[0].copy(), plant.params[0].copy(), plant.inputs[0].copy(), plant.substeps,
                            spec.device)
    state, params, inputs = hit[0].copy(), hit[1].copy(), hit[2].copy()
    params[P.seed] = float(run.sensor_seed)
    inputs[U.finger_pos_m] = spec.finger.gap_m
    return state, params, inputs, hit[3]


def _padded(rows: list, dtype=float) -> np.ndarray:
    """Rows of different lengths as one zero-padded 2-D array."""
    out = np.zeros((len(rows), max((len(r) for r in rows), default=0)), dtype=dtype)
    for i, r in enumerate(rows):
        out[i, :len(r)] = r
    return out


def _simulate_compiled_rows(prepared: list, keep_traces: bool = True) -> list:
    """The runs of ``prepared`` that can run compiled (:func:`_compiled_controller`), all in one
    call of :func:`ebraille_sim.scenarios.compiled_loop.run_rows`; None for the others.

    Each row is the computation of :func:`_simulate` (or :func:`_simulate_lean` without a
    trace) of the same run: the same plant rows, controller and supervisor vectors and
    inputs, stepped by the same compiled loop, so traces and metrics are equal to the last
    bit (``real_time_factor`` aside: the call's time is shared equally among its rows).
    """
    from ebraille_sim.scenarios.compiled_loop import run_rows
    m = len(prepared)
    out: list = [None] * m
    run0 = prepared[0][2]
    dt, n = run0.dt_s, run0.n_steps
    i_fb = S.force_est_n
    wraps: dict = {}
    plants: dict = {}
    rows = []                        # (index, wrapped, name, form, plant rows)
    for r, (spec, _, run, ctrl) in enumerate(prepared):
        try:
            wrapped = _wrap_shared(spec, ctrl, dt, wraps)
            form = _compiled_controller(ctrl, wrapped)
            if form is None:
                continue
            prow = _plant_rows(spec, run, plants)
            wrapped.reset(force_est_n=float(prow[0][i_fb]), setpoint_n=float(run.setpoint_n[0]), command_v=0.0)
        except _RUN_ERRORS as exc:
            out[r] = exc
            continue
        rows.append((r, wrapped, _name(ctrl), form, prow))
    if not rows:
        return out
    k = len(rows)
    runs = [prepared[row[0]][2] for row in rows]
    states = np.array([row[4][0] for row in rows])
    params = np.array([row[4][1] for row in rows])
    inputs = np.array([row[4][2] for row in rows])
    n_sub = rows[0][4][3]
    kinds = np.array([row[3][0] for row in rows], dtype=np.int64)
    cstates = _padded([row[3][1] for row in rows])
    cparams = _padded([row[3][2] for row in rows])
    supervised = np.array([row[3][3] is not None for row in rows])
    sizes = [(0, 0) if row[3][3] is None else (row[3][3].size, row[3][4].size) for row in rows]
    sv_states = np.zeros((k, max(z[0] for z in sizes)))
    sv_cfgs = np.zeros((k, max(z[1] for z in sizes)))
    for i, row in enumerate(rows):
        if row[3][3] is not None and sizes[i] == sv_states.shape[1:] + sv_cfgs.shape[1:]:
            # the supervisor reads and writes its row from now on (nothing to copy back)
            row[1].bind(sv_states[i], sv_cfgs[i])
            rows[i] = row[:3] + (row[3][:3] + (None, None), row[4])
        elif row[3][3] is not None:
            sv_states[i, :sizes[i][0]] = row[3][3]
            sv_cfgs[i, :sizes[i][1]] = row[3][4]
    setpoints = np.empty((k, n))
    for i, run in enumerate(runs):
        setpoints[i] = run.setpoint_n[:n]
    names = [list(run.profiles) for run in runs]
    counts = np.array([len(x) for x in names], dtype=np.int64)
    slots = np.zeros((k, max(counts)), dtype=np.int64)
    table = np.zeros((k, max(counts), n))
    for i, run in enumerate(runs):
        for j, name in enumerate(names[i]):
            slots[i, j] = U[name]
            table[i, j] = run.profiles[name][:n]
    every = 1 if keep_traces else 0
    f_true, f_est = np.zeros((k, n)), np.zeros((k, n))
    kept = np.zeros((k, len(KEPT), n * every))
    status, periods, values = np.zeros(k, dtype=np.int64), np.zeros(k, dtype=np.int64), np.zeros(k)
    args = [states, params, inputs, n_sub, kinds, cstates, cparams, supervised, sv_states, sv_cfgs, setpoints,
            dt, i_fb, slots, counts, table, every, f_true, f_est, kept, status, periods, values]
    if not getattr(run_rows, "signatures", True):
        # compile (or load from the cache) before the timed call: zero rows change nothing
        run_rows(*[a[:0] if isinstance(a, np.ndarray) else a for a in args])
    wall0 = time.perf_counter()
    run_rows(*args)
    wall = (time.perf_counter() - wall0) / k
    for i, (r, wrapped, name, form, _) in enumerate(rows):
        # the controller and supervisor objects read their vectors: copy the rows back
        form[1][:] = cstates[i, :len(form[1])]
        if form[3] is not None:
            form[3][:] = sv_states[i, :len(form[3])]
        spec, seed, run, _ = prepared[r]
        try:
            _raise_status(int(status[i]), int(periods[i]), float(values[i]), wrapped, states[i], setpoints[i], dt,
                          i_fb)
            if keep_traces:
                tr = {"force_true_n": f_true[i], "force_est_n": f_est[i], **dict(zip(KEPT, kept[i]))}
            else:
                tr = {"force_true_n": f_true[i], "force_est_n": f_est[i],
                      "energy_j": np.array([float(states[i, S.energy_j]) if n else 0.0])}
            res = _finish(spec, seed, run, tr, setpoints[i], wall, name, keep_trace=keep_traces)
            out[r] = _with_supervisor(res, spec, True, wrapped)
        except _RUN_ERRORS as exc:
            out[r] = exc
    return out


def _simulate_python_rows(prepared: list, keep_traces: bool = True) -> list:
    """:func:`_simulate` of several prepared runs with equal length and rates, one plant
    stepped by one compiled call per control period, each controller called from Python."""
    from ebraille_sim.plant import kernel
    if len(prepared) == 1:
        spec, seed, run, ctrl = prepared[0]
        try:
            if keep_traces:
                return [_simulate(spec, seed, run, ctrl, "lumped")]
            return [_simulate_lean(spec, seed, run, ctrl, "lumped", None)]
        except _RUN_ERRORS as exc:
            return [exc]
    specs = [p[0] for p in prepared]
    runs = [p[2] for p in prepared]
    try:
        plant = make_plant([s.device for s in specs], seeds=[r.sensor_seed for r in runs], backend="lumped")
    except (ValueError, FileNotFoundError):
        # one row cannot be packed: run each on its own, for the error of that row alone
        return [r for p in prepared for r in _simulate_python_rows([p], keep_traces)]
    m = len(prepared)
    run0 = runs[0]
    dt, n = run0.dt_s, run0.n_steps
    out: list = [None] * m
    state, inputs = plant.state, plant.inputs
    inputs[:, U.finger_pos_m] = [s.finger.gap_m for s in specs]
    sp = np.stack([r.setpoint_n[:n] for r in runs], axis=1)           # (n, rows)
    updates: list = [None] * m
    names: list = [""] * m
    wrapped: list = [None] * m
    i_fe, i_i = S.force_est_n, S.current_a
    for r, (spec, _, _, ctrl) in enumerate(prepared):
        try:
            names[r] = _name(ctrl)
            ctrl = wrap_controller(spec, ctrl, dt)
            ctrl.reset(force_est_n=float(state[r, i_fe]), setpoint_n=float(sp[0, r]), command_v=0.0)
        except _RUN_ERRORS as exc:
            out[r] = exc
            continue
        updates[r] = ctrl.update
        wrapped[r] = ctrl
    # inputs that vary: one column of the plant's inputs per name, all rows that have it
    varying = []
    for name in dict.fromkeys(k for r in runs for k in r.profiles):
        rows = [r for r in range(m) if name in runs[r].profiles]
        table = np.stack([runs[r].profiles[name] for r in rows], axis=1)  # (n, len(rows))
        varying.append((U[name], None if len(rows) == m else np.array(rows), table))
    slots = np.array([S[name] for name in _BATCH_SLOTS])
    buf = np.empty((n, m, len(slots)))
    cmd = np.zeros((n, m))
    live = [r for r in range(m) if out[r] is None]
    fes = state[:, i_fe].tolist()
    ias = [0.0] * m
    i_cmd = U.command_v
    cmd_now = inputs[:, i_cmd]
    cmd_now[:] = 0.0
    cs = [0.0] * m
    sub = plant.substeps
    wall0 = time.perf_counter()
    for k in range(n):
        for j, rows, table in varying:
            if rows is None:
                inputs[:, j] = table[k]
            else:
                inputs[rows, j] = table[k]
        sp_k = sp[k]
        failed = False
        for r in live:
            try:
                c = updates[r](fes[r], sp_k[r], dt, ias[r])
                if type(c) is not float:
                    c = float(c) if isinstance(c, (float, int)) else float(np.ravel(c)[0])
            except _RUN_ERRORS as exc:
                out[r] = exc
                failed = True
                c = 0.0
            cs[r] = c
        cmd_now[:] = cs
        if not np.isfinite(cmd_now).all():
            for r in live:
                if out[r] is None and not math.isfinite(cs[r]):
                    out[r] = ValueError(f"command_v must be finite, got {cs[r]}")
            failed = True
        if failed:                                   # a failed row holds a zero command from now on
            for r in live:
                if out[r] is not None:
                    cs[r] = 0.0
                    cmd_now[r] = 0.0
            live = [r for r in live if out[r] is None]
        kernel.advance_batch(state, plant.params, inputs, sub)
        cmd[k] = cmd_now
        buf[k] = state[:, slots]
        fes = state[:, i_fe].tolist()
        ias = state[:, i_i].tolist()
    wall = (time.perf_counter() - wall0) / m
    for r in live:
        if keep_traces:
            tr = {col: np.ascontiguousarray(buf[:, r, q]) for q, col in enumerate(_BATCH_COLUMNS)}
            tr["command_v"] = np.ascontiguousarray(cmd[:, r])
        else:                                           # what the metrics read
            tr = {col: np.ascontiguousarray(buf[:, r, _BATCH_COLUMNS.index(col)])
                  for col in ("force_true_n", "force_est_n")}
            tr["energy_j"] = buf[-1:, r, _BATCH_COLUMNS.index("energy_j")].copy()
        spec, seed, run, _ = prepared[r]
        try:
            out[r] = _with_supervisor(_finish(spec, seed, run, tr, np.ascontiguousarray(sp[:, r]), wall,
                                              names[r], keep_trace=keep_traces), spec, True, wrapped[r])
        except _RUN_ERRORS as exc:
            out[r] = exc
    return out


def _with_supervisor(res: RunResult, spec, supervised: bool, wrapped) -> RunResult:
    """``res`` with its :attr:`RunResult.supervisor` record (the choice, the fault, the events)."""
    on, source = supervisor_choice(spec, supervised)
    res.supervisor = {"enabled": on, "source": source}
    if on:
        sup = _find_supervisor(wrapped)
        res.supervisor.update(fault=sup.fault, events=[[t_ev, text] for t_ev, text in sup.events])
    return res


def _name(ctrl) -> str:
    return getattr(ctrl, "name", type(ctrl).__name__)


def _find_supervisor(ctrl):
    """The :class:`controllers.supervisor.Supervisor` in a chain of wrappers (outermost first)."""
    from controllers.supervisor import Supervisor
    while not isinstance(ctrl, Supervisor):
        ctrl = ctrl.inner
    return ctrl
