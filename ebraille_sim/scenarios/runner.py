"""Run a scenario: closed loop, trace, metrics.

Examples
--------
>>> import ebraille_sim
>>> res = ebraille_sim.run_scenario("steady_90wpm", seed=3, duration_s=4.0)
>>> bool(res.metrics["in_band_fraction"] > 0.9)
True
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from ebraille_sim.plant.layout import S, U
from ebraille_sim.plant.backends import make_plant
from ebraille_sim.plant.engine import KEPT
from ebraille_sim.scenarios.inputs import build_run_inputs, refresh_phases
from ebraille_sim.scenarios.metrics import compute_metrics
from ebraille_sim.scenarios.spec import (DEFAULT_DESIGN, ScenarioError, ScenarioSpec, load_scenario, with_estimator,
                                        with_firmware)

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


def design_firmware(controller) -> str | None:
    """The firmware preset of the design ``controller`` names (a shipped design's name or a design
    file with a ``firmware`` key; ``policy:PATH`` of a residual policy: its design's), or None (no design, or a design without a firmware).  A name
    that is no design, or a file that cannot be read, gives None here and its error when the
    controller is made."""
    import os
    if not isinstance(controller, (str, os.PathLike)):
        return None
    from controllers.designs import designs, get_design, is_design_file
    name = os.fspath(controller)
    if name.startswith("policy:"):               # a residual policy runs on the firmware of its design
        from controllers.policy import residual_design
        base = residual_design(name[len("policy:"):])
        return None if base is None or base.startswith("policy:") else design_firmware(base)
    if name not in designs() and not is_design_file(name):
        return None
    try:
        return get_design(name).firmware
    except (ValueError, FileNotFoundError, OSError):
        return None


def policy_estimator(controller) -> dict | None:
    """The estimator settings a learned policy of the whole command (``policy:PATH``) was
    trained on (:func:`controllers.policy.trained_estimator`), or None for anything else."""
    import os
    if not isinstance(controller, (str, os.PathLike)) or not os.fspath(controller).startswith("policy:"):
        return None
    from controllers.policy import trained_estimator
    return trained_estimator(os.fspath(controller)[len("policy:"):])


def on_controller_firmware(spec: ScenarioSpec, controller=None) -> tuple[ScenarioSpec, str | None, str | None]:
    """``spec`` on the estimator its controller brings, the firmware preset's name (a design's),
    and a one-line note of what was applied (None, None: the scenario's own estimator).

    A design given to the run (``controller``), or named by the scenario's ``[controller]``, runs
    on its firmware preset (:func:`design_firmware`); a learned policy of the whole command on the
    estimator it was trained on (:func:`policy_estimator`).  The default design, which the scenario
    does not name, runs on the scenario's estimator: that starts from the design's firmware and
    keeps the scenario's own ``[estimator]`` keys."""
    if controller is None and spec.controller.name == DEFAULT_DESIGN:
        return spec, None, None
    named = spec.controller.name if controller is None else controller
    firmware = design_firmware(named)
    if firmware is not None:
        return with_firmware(spec, firmware), firmware, f"firmware {firmware} (the design's)"
    trained = policy_estimator(named)
    if trained is not None:
        return (with_estimator(spec, trained, f"the estimator policy {named} was trained on"), None,
                f"estimator {trained['model']} as the policy was trained on")
    return spec, None, None


def prepare_run(scenario, controller=None, seed: int | None = None, duration_s: float | None = None,
                device=None, firmware=None) -> tuple:
    """The spec, seed, run inputs and (unwrapped) controller of one run of :func:`run_scenario`."""
    spec = scenario if isinstance(scenario, ScenarioSpec) else load_scenario(scenario)
    if device is not None:
        import dataclasses
        spec = dataclasses.replace(spec, device=device)
    if firmware is None:
        spec, _, _ = on_controller_firmware(spec, controller)
    else:
        spec = with_firmware(spec, firmware)
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
                 supervised: bool = True, recorder=None, firmware=None) -> RunResult:
    """Simulate a scenario in closed loop.

    Parameters
    ----------
    scenario : str, path or ScenarioSpec
        Scenario file, shipped scenario name, or a parsed spec.
    controller : str, path or Controller, optional
        Overrides the scenario's controller (a registered name, a design's name or file, a
        gains file, or an object implementing :class:`controllers.Controller`).  A design
        (:mod:`controllers.designs`) runs on its own firmware preset.
    seed : int, optional
        Overrides the scenario's master seed.  The same seed gives the same trace, exactly.
    duration_s : float, optional
        Overrides the scenario's duration.
    backend : str
        Plant model: ``"lumped"`` or another name in :data:`ebraille_sim.plant.backends.PLANT_BACKENDS`.
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
    recorder : Recorder, optional
        With the pymunk backend, handed to the plant it builds
        (:class:`ebraille_sim.plant.pymunk.recording.Recorder`: snapshots of the mechanism for
        drawing); it reads the plant and changes nothing in the run.  The lumped plant, whose
        periods run in one compiled call, takes none.

    firmware : str, optional
        A firmware preset (:mod:`ebraille_sim.estimation.presets`) or preset file whose
        estimator settings replace the scenario's (default: the design's, else the scenario's).

    Returns
    -------
    RunResult
    """
    if trace_every is not None and (isinstance(trace_every, bool) or not isinstance(trace_every, (int, np.integer))
                                    or trace_every < 1):
        raise ValueError(f"trace_every must be a whole number >= 1 or None, got {trace_every!r}")
    if recorder is not None and backend == "lumped":
        raise ValueError("a recorder records the pymunk mechanism; use backend='pymunk' with it, not 'lumped'")
    spec, seed, run, ctrl = prepare_run(scenario, controller, seed, duration_s, device, firmware)
    supervisor_choice(spec, supervised)
    if trace_every == 1:
        return _simulate(spec, seed, run, ctrl, backend, supervised, recorder)
    return _simulate_lean(spec, seed, run, ctrl, backend, trace_every, supervised, release_inputs=True,
                          recorder=recorder)


def _simulate(spec, seed, run, ctrl, backend: str, supervised: bool = True, recorder=None) -> RunResult:
    """Closed loop of one prepared run, one control period per Python iteration, full trace."""
    sp, f_true, f_est, kept, _, wall, name, wrapped = _closed_loop(spec, run, ctrl, backend, 1, supervised,
                                                                   recorder)
    tr = {"force_true_n": f_true, "force_est_n": f_est, **kept}
    return _with_supervisor(_finish(spec, seed, run, tr, sp, wall, name), spec, supervised, wrapped)


def _plant_for(spec, run, backend: str, recorder=None):
    extra = {} if recorder is None else {"recorder": recorder}
    try:
        plant = make_plant([spec.device], seeds=[run.sensor_seed], backend=backend, **extra)
    except (ValueError, FileNotFoundError) as exc:
        raise ScenarioError(f"{spec.source}: {exc}") from None
    plant.set_finger(spec.finger.gap_m)
    return plant


def _closed_loop(spec, run, ctrl, backend: str, every: int | None, supervised: bool, recorder=None):
    """The control loop of one prepared run: the true and estimated force at every period
    (the metrics need them), the other trace columns at every ``every``-th (None: not at all).

    A controller with a compiled form, alone or inside the safety supervisor, on the lumped
    plant runs all its periods in one call of the loop engine (:func:`ebraille_sim.plant.engine.run`);
    any other goes through :func:`python_periods`.

    ``recorder`` is handed to the plant (:func:`_plant_for`).

    Returns ``(setpoint, force_true, force_est, kept columns, energy at the end (J), wall s,
    controller name, the wrapped controller)``.
    """
    n = run.n_steps
    sp = run.setpoint_n[:n]                       # read only: a view, not a copy
    plant = _plant_for(spec, run, backend, recorder)
    # a reference controller that declares ``feedback = "true_force"`` (controllers.bounds) is fed
    # the true contact force instead of the estimate; every other controller sees the estimate
    i_fb = _feedback_slot(ctrl)
    ctrl_name = _name(ctrl)
    wrapped = wrap_controller(spec, ctrl, run.dt_s, supervised)
    st = plant.state[0]
    wrapped.reset(force_est_n=float(st[i_fb]), setpoint_n=float(sp[0]), command_v=0.0)
    form = _compiled_controller(ctrl, wrapped) if _is_lumped(plant) else None
    policy = None if form is not None or not _is_lumped(plant) else _compiled_policy(ctrl, wrapped, plant.control_dt_s)
    if policy is not None:
        form, bundle = policy
        rec = _engine_rows(plant, [form], sp[None, :], [run.profiles], run.dt_s, i_fb, every, n)
        rec.give_policy(0, bundle)
        wall = _run_timed(rec, n)
        rec.copy_back()
        ctrl.took(bundle[0])
        _raise_row(rec, 0, wrapped)
    elif form is None:
        rec, wall = python_periods(plant, [wrapped], sp[None, :], [run.profiles], i_fb, every, n)
    else:
        rec = _engine_rows(plant, [form], sp[None, :], [run.profiles], run.dt_s, i_fb, every, n)
        wall = _run_timed(rec, n)
        rec.copy_back()
        _raise_row(rec, 0, wrapped)
    energy_end = float(st[S.energy_j]) if n else 0.0
    return sp, rec.f_true[0], rec.f_est[0], dict(zip(KEPT, rec.kept[0])), energy_end, wall, ctrl_name, wrapped


def _feedback_slot(ctrl) -> int:
    """The state slot fed back to ``ctrl``: the estimate, or the true force for a reference
    controller that declares ``feedback = "true_force"``."""
    return S.contact_force_n if getattr(ctrl, "feedback", "estimate") == "true_force" else S.force_est_n


def _is_lumped(plant) -> bool:
    """Whether ``plant`` is the compiled lumped plant (the loop engine steps its rows)."""
    from ebraille_sim.plant.lumped import Plant
    return type(plant) is Plant


_USE_COMPILED_LOOP = True
"""Run a built-in controller's loop in the loop engine with the controller compiled (one call
for all periods); False hands every controller's command in from Python, one period per call
(:func:`python_periods`: for tests that compare the two)."""


def _compiled_controller(ctrl, wrapped, inner=None):
    """``(kind, state, params, sv_state, sv_cfg)`` of a controller ``ctrl`` with a compiled form
    (:func:`controllers.compiled.compiled_form`) that runs unwrapped (the supervisor's vectors
    None) or wrapped only in an enabled safety supervisor; None for any other.

    ``inner`` (default ``ctrl``) is the object the supervisor wraps: a residual policy around
    ``ctrl`` (:class:`controllers.residual.ResidualPolicy`), whose sum the loop engine composes
    (:func:`ebraille_sim.plant.engine.inner_command`)."""
    if not _USE_COMPILED_LOOP:
        return None
    from controllers.compiled import compiled_form
    form = compiled_form(ctrl)
    if form is None:
        return None
    kind, cstate, cparams = form
    inner = ctrl if inner is None else inner
    if wrapped is inner:
        return kind, cstate, cparams, None, None
    from controllers.supervisor import Supervisor
    if type(wrapped) is Supervisor and wrapped.inner is inner:
        sv = compiled_form(wrapped)
        if sv is not None:
            return kind, cstate, cparams, sv[0], sv[1]
    return None


def _compiled_policy(ctrl, wrapped, dt_s: float):
    """``(form, arrays)`` of a residual policy ``ctrl`` whose design has a compiled form and
    whose model is a deterministic MLP actor evaluated every period
    (:meth:`controllers.residual.ResidualPolicy.compiled_policy`), alone or inside an enabled safety
    supervisor: the design's form (:func:`_compiled_controller`) and the policy's arrays for
    :meth:`ebraille_sim.plant.engine.Rows.give_policy`; None for any other controller."""
    from controllers.residual import ResidualPolicy
    if type(ctrl) is not ResidualPolicy:
        return None
    form = _compiled_controller(ctrl.base, wrapped, inner=ctrl)
    bundle = None if form is None else ctrl.compiled_policy(dt_s)
    return None if bundle is None else (form, bundle)


_EXTERNAL_FORM = None


def _external_form():
    """The engine form of a row whose command is handed in (a Python controller's)."""
    global _EXTERNAL_FORM
    if _EXTERNAL_FORM is None:
        from controllers.compiled import KIND_EXTERNAL
        _EXTERNAL_FORM = (KIND_EXTERNAL, np.zeros(0), np.zeros(0), None, None)
    return _EXTERNAL_FORM


def _engine_rows(plant, forms: list, sp: np.ndarray, profiles: list, dt_s: float, i_fb: int, every, n_record: int):
    """The loop engine's rows (:class:`ebraille_sim.plant.engine.Rows`) of a lumped ``plant``
    whose row ``r`` runs the controller ``forms[r]`` (:func:`_compiled_controller`), on the
    setpoints ``sp[r]`` and the varying inputs ``profiles[r]``.

    The plant's arrays are the rows' (stepped in place); one row's controller and supervisor
    vectors are its live vectors too, and its input table the run's own array where it is one."""
    from ebraille_sim.plant.engine import Rows
    from ebraille_sim.scenarios.inputs import profile_table
    m, n = sp.shape
    every = 0 if every is None else int(every)
    if m == 1:
        kind, cs, cp, sv, cfg = forms[0]
        names = list(profiles[0])
        slots = np.array([[U[name] for name in names]], dtype=np.int64).reshape(1, len(names))
        table = profile_table(profiles[0], n)
        if table is None:
            table = np.zeros((len(names), n))
            for j, name in enumerate(names):
                table[j] = np.asarray(profiles[0][name], dtype=float)[:n]
        supervised = sv is not None
        sv2 = (sv if supervised else np.zeros(0))[None, :]
        cfg2 = (cfg if supervised else np.zeros(0))[None, :]
        return Rows(plant.state, plant.params, plant.inputs, plant.substeps, np.array([kind], dtype=np.int64),
                    cs[None, :], cp[None, :], np.array([supervised]), sv2, cfg2, sp, dt_s, i_fb, slots,
                    np.array([len(names)], dtype=np.int64), table[None, :, :], every, n_record)
    rows = Rows.pack([(plant.state[r], plant.params[r], plant.inputs[r], plant.substeps) for r in range(m)],
                     [f[:3] for f in forms], [None if f[3] is None else (f[3], f[4]) for f in forms], sp, dt_s,
                     i_fb, profiles, every, n_record)
    return rows


def _run_timed(rows, n: int) -> float:
    """All ``n`` periods of ``rows`` in one engine call (compiled, or loaded from the cache,
    before the clock starts); the wall time of the call, s."""
    from ebraille_sim.plant.engine import run
    if not getattr(run, "signatures", True):
        run(*rows.arguments(0, 0))                 # zero periods change nothing
    wall0 = time.perf_counter()
    run(*rows.arguments(0, n))
    return time.perf_counter() - wall0


def _raise_row(rows, r: int, ctrl) -> None:
    """Raise what the plant or the controller raises for row ``r``'s engine status (none for OK)."""
    from ebraille_sim.plant.engine import BAD_COMMAND, BAD_CONTROLLER_INPUT
    status, k, value = int(rows.status[r]), int(rows.periods[r]), float(rows.values[r])
    if status == BAD_CONTROLLER_INPUT:
        # the controller's own check names the bad argument
        st = rows.states[r]
        ctrl.update(float(st[rows.i_feedback]), rows.setpoints[r, k], rows.dt, float(st[S.current_meas_a]) if k else 0.0)
        raise ValueError(f"non-finite controller input at control period {k}")
    if status == BAD_COMMAND:
        raise ValueError(f"command_v must be finite, got {value}")


FAILED_IN_PYTHON = 3
"""Engine status of a row whose Python controller raised (:func:`python_periods`): the engine
skips it from then on."""


def python_periods(plant, controllers: list, sp: np.ndarray, profiles: list, i_fb: int, every, n: int,
                   errors: list | None = None, k0: int = 0, n_record: int | None = None):
    """The one shim through which Python controllers (and plants other than the lumped one)
    enter the closed loop: per control period, every row's controller is called from Python on
    what it measured at the end of the previous period, and its command is handed to the loop
    engine (:func:`ebraille_sim.plant.engine.run` for that one period, the controller's kind
    :data:`~controllers.compiled.KIND_EXTERNAL`), which writes the period's inputs, holds the
    command, advances the physics and records.

    A plant without compiled rows (the pymunk backend) is advanced by its own ``advance``
    with the same order of operations, recorded here.

    Parameters
    ----------
    plant : a plant backend with ``m`` devices
    controllers : list of m controllers (already wrapped and reset)
    sp : ndarray, shape (m, n)
        Setpoint per row and period.
    profiles : list of m dicts
        Each row's varying inputs.
    i_fb : int
        The state slot fed back as the force.
    every : int or None
        Keep the trace columns every ``every``-th period (None: none).
    errors : list, optional
        Filled with each row's exception (None for a row that ran); without it the first
        row's exception is raised.
    k0 : int
        The first period: periods ``k0 .. k0 + n - 1`` run (an env steps one at a time).
    n_record : int, optional
        Periods recorded (default ``n``; 0 records nothing).

    Returns
    -------
    (rows, wall)
        The engine's rows (``f_true``, ``f_est``, ``kept``, ``states``) and the loop's wall time, s.
    """
    m = sp.shape[0]
    lumped = _is_lumped(plant)
    n_record = n if n_record is None else n_record
    if lumped:
        rows = _engine_rows(plant, [_external_form()] * m, sp, profiles, plant.control_dt_s, i_fb, every, n_record)
        run = rows.stepper()
    else:
        from ebraille_sim.plant.engine import Rows
        rows = Rows(plant.state, None, plant.inputs, plant.substeps, None, None, None, None, None, None, sp,
                    plant.control_dt_s, i_fb, None, None, None, 0 if every is None else every, n_record)
    dt = rows.dt
    errs: list = [None] * m
    st = rows.states
    u_ext = rows.u_ext
    status = rows.status
    updates = [c.update for c in controllers]
    varying = [(U[name], arr) for name, arr in profiles[0].items()] if not lumped else None
    fes = st[:, i_fb].tolist()
    ias = st[:, S.current_meas_a].tolist()                  # the firmware's reading of the current
    live = list(range(m))
    failed = np.count_nonzero                               # cheaper per call than status.any()
    wall0 = time.perf_counter()
    for k in range(k0, k0 + n):
        for r in live:
            try:
                c = updates[r](fes[r], sp[r, k], dt, ias[r])
                if type(c) is not float:
                    c = float(c) if isinstance(c, (float, int)) else float(np.ravel(c)[0])
            except _RUN_ERRORS as exc:
                errs[r] = exc
                status[r] = FAILED_IN_PYTHON
                continue
            u_ext[r] = c
        if lumped:
            run(*rows.arguments(k, 1))
        else:
            _python_plant_period(plant, varying, rows, k, float(u_ext[0]))
        if failed(status):
            for r in live:
                if status[r] != 0 and errs[r] is None:
                    try:
                        _raise_row(rows, r, controllers[r])
                    except _RUN_ERRORS as exc:
                        errs[r] = exc
            live = [r for r in live if status[r] == 0]
            if not live:
                break
        fes = st[:, i_fb].tolist()
        ias = st[:, S.current_meas_a].tolist()
    wall = time.perf_counter() - wall0
    if errors is not None:
        errors[:] = errs
    elif errs[0] is not None:
        raise errs[0]
    return rows, wall


def _python_plant_period(plant, varying: list, rows, k: int, c: float) -> None:
    """One period of a one-device plant without compiled rows (:func:`python_periods`): the
    engine's order of operations (inputs, checked command, advance, record), in Python."""
    from ebraille_sim.plant.engine import BAD_COMMAND, ROW
    inp = plant.inputs[0]
    for j, arr in varying:
        inp[j] = arr[k]
    if not math.isfinite(c):
        rows.status[0], rows.periods[0], rows.values[0] = BAD_COMMAND, k, c
        return
    plant.advance(c)
    st = plant.state[0]
    if rows.f_true.shape[1] == 0:
        return
    rows.f_true[0, k] = st[S.contact_force_n]
    rows.f_est[0, k] = st[S.force_est_n]
    every = rows.every
    if every > 0 and (k + 1) % every == 0:
        q = (k + 1) // every - 1
        kept = rows.kept[0]
        kept[ROW.command_v, q] = c
        kept[ROW.fsr_voltage_v, q] = st[S.fsr_voltage_v]
        kept[ROW.motor_current_a, q] = st[S.current_a]         # plant truth: the trace's record
        kept[ROW.board_pos_m, q] = st[S.board_pos_m]
        kept[ROW.energy_j, q] = st[S.energy_j]


def _simulate_lean(spec, seed, run, ctrl, backend: str, every: int | None, supervised: bool = True,
                   release_inputs: bool = False, recorder=None) -> RunResult:
    """:func:`_simulate` keeping the true and estimated force at every period and the other
    trace columns at every ``every``-th period (None: not at all); the same metrics.

    ``release_inputs`` empties ``run.profiles`` once the loop has run (for a run whose inputs
    nobody else holds: a long session's metrics then run without them in memory)."""
    sp, f_true, f_est, kept, energy_end, wall, name, wrapped = _closed_loop(spec, run, ctrl, backend, every,
                                                                            supervised, recorder)
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
"""Most runs of one call of the loop engine's :func:`ebraille_sim.plant.engine.run` (each row
holds its supervisor's state, about 140 kB, besides its trace and inputs)."""

_BATCH_COLUMNS = ("force_true_n", "force_est_n", "fsr_voltage_v", "motor_current_a", "board_pos_m", "energy_j")
_RUN_ERRORS = (ValueError, FloatingPointError, FileNotFoundError)


def run_batch(runs: list, keep_traces: bool = True) -> list:
    """Several runs of :func:`run_scenario` (lumped plant), their plants advanced together.

    Runs with the same number of control periods and the same rates are rows of one call of
    the loop engine (:func:`ebraille_sim.plant.engine.run`): runs whose controller is compiled
    run all their periods in that call; the others share one plant stepped through
    :func:`python_periods` (their controllers called from Python each period).
    Rows are independent, so every run's trace and metrics are those of :func:`run_scenario`
    with the same arguments, exactly (``real_time_factor`` aside: the batch's loop time is
    shared equally among its rows).

    Parameters
    ----------
    runs : list of dict
        Keyword arguments of :func:`run_scenario` per run (``scenario``, ``controller``,
        ``seed``, ``duration_s``, ``device``, ``firmware``; no ``backend``).
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
    firmware = design_firmware(name) if kw.get("firmware") is None else None
    if firmware is not None:
        kw = {**kw, "firmware": firmware}                    # the design's firmware, kept with its copy
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
    from ebraille_sim.plant.lumped import reseed
    reseed(params, spec.device, run.sensor_seed)
    inputs[U.finger_pos_m] = spec.finger.gap_m
    return state, params, inputs, hit[3]


def _simulate_compiled_rows(prepared: list, keep_traces: bool = True) -> list:
    """The runs of ``prepared`` that can run compiled (:func:`_compiled_controller`), all in one
    call of the loop engine (:func:`ebraille_sim.plant.engine.run`); None for the others.

    Each row is the computation of :func:`_simulate` (or :func:`_simulate_lean` without a
    trace) of the same run: the same plant rows, controller and supervisor vectors and
    inputs, stepped by the same engine, so traces and metrics are equal to the last bit
    (``real_time_factor`` aside: the call's time is shared equally among its rows).
    """
    from ebraille_sim.plant.engine import Rows
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
    runs = [prepared[row[0]][2] for row in rows]
    setpoints = np.empty((len(rows), n))
    for i, run in enumerate(runs):
        setpoints[i] = run.setpoint_n[:n]
    rec = Rows.pack([row[4] for row in rows], [row[3][:3] for row in rows],
                    [None if row[3][3] is None else (row[3][3], row[3][4]) for row in rows], setpoints, dt, i_fb,
                    [run.profiles for run in runs], 1 if keep_traces else 0, n)
    wall = _run_timed(rec, n) / len(rows)
    rec.copy_back()
    for i, (r, wrapped, name, form, _) in enumerate(rows):
        spec, seed, run, _ = prepared[r]
        try:
            _raise_row(rec, i, wrapped)
            out[r] = _with_supervisor(_finish(spec, seed, run, _row_trace(rec, i, keep_traces), setpoints[i], wall,
                                              name, keep_trace=keep_traces), spec, True, wrapped)
        except _RUN_ERRORS as exc:
            out[r] = exc
    return out


def _row_trace(rec, i: int, keep_traces: bool) -> dict:
    """Row ``i``'s trace columns of the engine's record (only what the metrics read without
    ``keep_traces``)."""
    tr = {"force_true_n": rec.f_true[i], "force_est_n": rec.f_est[i]}
    if keep_traces:
        tr.update(zip(KEPT, rec.kept[i]))
    else:
        n = rec.f_true.shape[1]
        tr["energy_j"] = np.array([float(rec.states[i, S.energy_j]) if n else 0.0])
    return tr


def _simulate_python_rows(prepared: list, keep_traces: bool = True) -> list:
    """:func:`_simulate` of several prepared runs with equal length and rates, one plant
    stepped through :func:`python_periods` (each controller called from Python)."""
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
    dt, n = runs[0].dt_s, runs[0].n_steps
    out: list = [None] * m
    plant.inputs[:, U.finger_pos_m] = [s.finger.gap_m for s in specs]
    sp = np.stack([r.setpoint_n[:n] for r in runs])                   # (rows, n)
    names: list = [""] * m
    wrapped: list = [None] * m
    live = []
    for r, (spec, _, _, ctrl) in enumerate(prepared):
        try:
            names[r] = _name(ctrl)
            w = wrap_controller(spec, ctrl, dt)
            w.reset(force_est_n=float(plant.state[r, S.force_est_n]), setpoint_n=float(sp[r, 0]), command_v=0.0)
        except _RUN_ERRORS as exc:
            out[r] = exc
            continue
        wrapped[r] = w
        live.append(r)
    if not live:
        return out
    if len(live) < m:
        plant = _plant_subset(plant, live)
    errors: list = []
    rec, wall = python_periods(plant, [wrapped[r] for r in live], sp[live], [runs[r].profiles for r in live],
                               S.force_est_n, 1 if keep_traces else None, n, errors)
    wall /= len(live)
    for i, r in enumerate(live):
        if errors[i] is not None:
            out[r] = errors[i]
            continue
        spec, seed, run, _ = prepared[r]
        try:
            out[r] = _with_supervisor(_finish(spec, seed, run, _row_trace(rec, i, keep_traces), sp[r], wall,
                                              names[r], keep_trace=keep_traces), spec, True, wrapped[r])
        except _RUN_ERRORS as exc:
            out[r] = exc
    return out


def _plant_subset(plant, rows: list):
    """The lumped plant of only ``rows`` of ``plant`` (copies of their rows)."""
    import copy
    sub = copy.copy(plant)
    sub.state, sub.params, sub.inputs = plant.state[rows], plant.params[rows], plant.inputs[rows]
    sub.devices = [plant.devices[r] for r in rows]
    return sub


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
