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
    run = build_run_inputs(spec, seed)
    schedule = run.schedule
    ctrl = make_controller(spec, controller)
    dt, n = run.dt_s, run.n_steps
    t = (np.arange(n) + 1) * dt                  # sample k: the end of period k
    sp = run.setpoint_n[:n].copy()
    try:
        plant = make_plant([spec.device], seeds=[run.sensor_seed], backend=backend)
    except (ValueError, FileNotFoundError) as exc:
        raise ScenarioError(f"{spec.source}: {exc}") from None
    plant.set_finger(spec.finger.gap_m)
    profiles = run.profiles
    # a reference controller that declares ``feedback = "true_force"`` (controllers.bounds) is fed
    # the true contact force instead of the estimate; every other controller sees the estimate
    i_fb = S.contact_force_n if getattr(ctrl, "feedback", "estimate") == "true_force" else S.force_est_n
    ctrl = wrap_controller(spec, ctrl, dt)
    tr = {c: np.zeros(n) for c in TRACE_COLUMNS if c != "character"}
    st = plant.state[0]
    # slot indices and trace columns bound to locals: the loop below runs once per control period
    i_fc, i_fe, i_v, i_i, i_x, i_e = (S.contact_force_n, S.force_est_n, S.fsr_voltage_v,
                                      S.current_a, S.board_pos_m, S.energy_j)
    ctrl.reset(force_est_n=float(st[i_fb]), setpoint_n=float(sp[0]), command_v=0.0)
    f_true, f_est, v_fsr, cmd_v, cur, xb, en = (tr["force_true_n"], tr["force_est_n"], tr["fsr_voltage_v"],
                                                tr["command_v"], tr["motor_current_a"], tr["board_pos_m"],
                                                tr["energy_j"])
    fe = float(st[i_fb])
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
        fe = float(st[i_fb])
        i_a = float(st[i_i])
        cmd_v[k] = c
        f_true[k] = st[i_fc]
        f_est[k] = st[i_fe]
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
