"""The compiled controller steps and the loop engine's one-call runs give the numbers of the
per-period shim (Python controllers handing their command to the engine) to the last bit."""
from __future__ import annotations

import math

import numpy as np
import pytest

import controllers
import ebraille_sim
from controllers.compiled import KIND_DOB, KIND_EXTERNAL, KIND_LQG, KIND_PID, MAP_POINTS, PP, PS, controller_reset, controller_step, map_reference
from ebraille_sim.plant import engine
from ebraille_sim.scenarios import runner

CONTROLLERS = ["pid", "pid_scheduled", "pid_feedforward", "pid_friction", "lqg", "actuator_bound", "pid_dob"]
KINDS = {"lqg": KIND_LQG, "pid_dob": KIND_DOB}
SCENARIOS = [("steady_90wpm", 2.0), ("setpoint_steps", 6.0), ("battery_sag", 3.0), ("pressing_90wpm", 3.0),
             ("refresh_120wpm", 2.0)]


class PythonProxy:
    """A plain Python controller around another one (no compiled form: the per-period loop)."""

    def __init__(self, inner):
        self.inner = inner
        self.name = inner.name
        feedback = getattr(inner, "feedback", None)
        if feedback is not None:
            self.feedback = feedback

    def reset(self, **kw):
        self.inner.reset(**kw)

    def update(self, force_est_n, setpoint_n, dt_s, motor_current_a=None):
        return self.inner.update(force_est_n, setpoint_n, dt_s, motor_current_a)


def _compiled_rows(args) -> int:
    """Rows of an engine call that step a compiled controller over periods (0 for a zero-period
    warm-up call and for the per-period shim's calls, whose rows are all external)."""
    kinds, n_periods = args[4], args[18]
    return int(np.sum(kinds != KIND_EXTERNAL)) if n_periods > 0 else 0


@pytest.fixture
def loop_calls(monkeypatch):
    """Count the engine calls that run a compiled controller."""
    calls = []
    real = engine.run

    def counted(*args):
        if _compiled_rows(args):
            calls.append(1)
        return real(*args)

    monkeypatch.setattr(engine, "run", counted)
    return calls


def _metrics(res):
    return {k: v for k, v in res.metrics.items() if k != "real_time_factor"}


def _assert_same_runs(a, b):
    assert a.trace.keys() == b.trace.keys()
    for col in a.trace:
        assert np.array_equal(a.trace[col], b.trace[col]), col
    assert _metrics(a) == _metrics(b)


@pytest.mark.parametrize("scenario,duration_s", SCENARIOS)
@pytest.mark.parametrize("name", CONTROLLERS)
def test_compiled_loop_equals_the_per_period_loop(name, scenario, duration_s, loop_calls, monkeypatch):
    ctrl_c = controllers.make(name)
    ctrl_p = controllers.make(name)
    res_c = ebraille_sim.run_scenario(scenario, controller=ctrl_c, duration_s=duration_s, supervised=False)
    assert len(loop_calls) == 1
    monkeypatch.setattr(runner, "_USE_COMPILED_LOOP", False)
    res_p = ebraille_sim.run_scenario(scenario, controller=ctrl_p, duration_s=duration_s, supervised=False)
    assert len(loop_calls) == 1
    _assert_same_runs(res_c, res_p)
    # the compiled run left its final state in the Python object
    _, s_c, _ = ctrl_c.compiled()
    _, s_p, _ = ctrl_p.compiled()
    assert np.array_equal(s_c, s_p)


def test_default_pid_schedules_its_gains_above_one_newton_in_the_compiled_loop():
    """setpoint_steps goes above 1 N, where the default PID scales its gains: the same run
    with the schedule off gives another trace (so the scaling is exercised in the loop)."""
    a = ebraille_sim.run_scenario("setpoint_steps", controller="pid", duration_s=6.0, supervised=False)
    b = ebraille_sim.run_scenario("setpoint_steps", controller=controllers.make("pid", schedule_above_n=None),
                                  duration_s=6.0, supervised=False)
    assert a.trace["setpoint_n"].max() > 1.0
    assert not np.array_equal(a.trace["command_v"], b.trace["command_v"])


@pytest.mark.parametrize("every", [None, 7])
def test_thin_traces_are_the_same_in_both_loops(every, monkeypatch):
    a = ebraille_sim.run_scenario("pressing_90wpm", controller="pid_friction", duration_s=2.0, supervised=False,
                                  trace_every=every)
    monkeypatch.setattr(runner, "_USE_COMPILED_LOOP", False)
    b = ebraille_sim.run_scenario("pressing_90wpm", controller="pid_friction", duration_s=2.0, supervised=False,
                                  trace_every=every)
    _assert_same_runs(a, b)
    assert (len(a.trace["t_s"]) == 2000 // 7) if every else a.trace == {}


def test_a_python_controller_runs_the_per_period_loop(loop_calls):
    proxy = ebraille_sim.run_scenario("steady_90wpm", controller=PythonProxy(controllers.make("pid_scheduled")),
                                      duration_s=1.0, supervised=False)
    assert loop_calls == []
    direct = ebraille_sim.run_scenario("steady_90wpm", controller="pid_scheduled", duration_s=1.0, supervised=False)
    assert len(loop_calls) == 1
    _assert_same_runs(proxy, direct)
    f, sp = direct.trace["force_true_n"][-1], direct.trace["setpoint_n"][-1]
    assert sp > 0.5 and abs(f - sp) < 0.25 * sp                   # the loop holds the force


def test_true_force_feedback_in_the_compiled_loop():
    """actuator_bound is fed the true force: its loop differs from the same PID fed the estimate."""
    from controllers.bounds import TrueForce
    bound = ebraille_sim.run_scenario("pressing_90wpm", controller="actuator_bound", duration_s=2.0, supervised=False)
    inner = controllers.make("actuator_bound").inner
    est = ebraille_sim.run_scenario("pressing_90wpm", controller=inner, duration_s=2.0, supervised=False)
    assert not np.array_equal(bound.trace["command_v"], est.trace["command_v"])
    again = ebraille_sim.run_scenario("pressing_90wpm", controller=TrueForce(controllers.make("actuator_bound").inner),
                                      duration_s=2.0, supervised=False)
    assert np.array_equal(bound.trace["command_v"], again.trace["command_v"])


SUPERVISED_CASES = [("steady_90wpm", "pid", 3.0), ("setpoint_steps", "pid", 6.0), ("contact_onset", "pid", 3.0),
                    ("pressing_90wpm", "pid_feedforward", 4.0), ("refresh_120wpm", "lqg", 3.0),
                    ("battery_sag", "pid_friction", 4.0), ("fault_fsr_stuck", "pid", 6.0),
                    ("fault_motor_stall", "pid", 6.0), ("fault_finger_withdrawn", "pid_scheduled", 8.0),
                    ("fault_fsr_open", "pid", 6.0), ("fault_fsr_short", "actuator_bound", 6.0)]


@pytest.mark.parametrize("scenario, controller, duration", SUPERVISED_CASES)
def test_supervised_runs_use_the_compiled_loop_and_equal_the_per_period_loop(scenario, controller, duration,
                                                                             loop_calls, monkeypatch):
    """With the safety supervisor on (the default) the compiled loop steps the supervisor's
    compiled period around the compiled controller: every trace column, the metrics and the
    supervisor's record (fault, events) equal the per-period loop's, where the Python
    Supervisor calls the Python controller, faults and mid-run inner resets included."""
    fast = ebraille_sim.run_scenario(scenario, controller=controller, duration_s=duration)
    assert fast.supervisor["enabled"] and len(loop_calls) == 1
    monkeypatch.setattr(runner, "_USE_COMPILED_LOOP", False)
    slow = ebraille_sim.run_scenario(scenario, controller=controller, duration_s=duration)
    assert len(loop_calls) == 1
    _assert_same_runs(fast, slow)
    assert fast.supervisor == slow.supervisor
    if scenario in ("fault_fsr_stuck", "fault_motor_stall"):
        assert fast.supervisor["fault"] is not None and fast.supervisor["events"]


def test_a_bad_setpoint_raises_the_controllers_error_in_the_compiled_loop():
    spec, _, run, ctrl = runner.prepare_run("steady_90wpm", "pid", duration_s=0.05)
    sp = run.setpoint_n[:run.n_steps].copy()
    sp[3] = math.nan
    plant = runner._plant_for(spec, run, "lumped")
    ctrl.reset(force_est_n=0.0, setpoint_n=1.0, command_v=0.0)
    form = runner._compiled_controller(ctrl, ctrl)
    n = run.n_steps
    rows = runner._engine_rows(plant, [form], sp[None, :], [run.profiles], run.dt_s, runner.S.force_est_n, 1, n)
    runner._run_timed(rows, n)
    assert rows.status[0] == engine.BAD_CONTROLLER_INPUT and rows.periods[0] == 3
    with pytest.raises(ValueError, match="setpoint_n must be finite"):
        runner._raise_row(rows, 0, ctrl)


def test_a_non_finite_external_command_stops_its_row_only():
    """The engine refuses a non-finite command of one row (status BAD_COMMAND, the row's plant not
    advanced in that period) and steps the other rows."""
    spec, _, run, _ = runner.prepare_run("steady_90wpm", "pid", duration_s=0.05)
    from ebraille_sim.plant.backends import make_plant
    plant = make_plant([spec.device, spec.device], seeds=[1, 1])
    n = 4
    sp = np.full((2, n), 1.0)
    rows = runner._engine_rows(plant, [runner._external_form()] * 2, sp, [{}, {}], run.dt_s, runner.S.force_est_n,
                               1, n)
    rows.u_ext[:] = [2.0, math.nan]
    before = rows.states[1].copy()
    engine.run(*rows.arguments(0, n))
    assert list(rows.status) == [engine.OK, engine.BAD_COMMAND] and rows.periods[1] == 0
    assert np.array_equal(rows.states[1], before)
    assert rows.states[0, runner.S.current_a] > 0.0 and rows.states[0, runner.S.time_s] > 0.0
    assert np.all(rows.kept[0, engine.ROW.command_v] == 2.0)


def test_other_backends_and_wrapped_controllers_have_no_compiled_loop():
    spec, _, run, ctrl = runner.prepare_run("steady_90wpm", "pid", duration_s=0.05)
    assert runner._compiled_controller(ctrl, ctrl) is not None
    assert runner._compiled_controller(ctrl, PythonProxy(ctrl)) is None
    assert runner._compiled_controller(PythonProxy(ctrl), PythonProxy(ctrl)) is None
    assert not runner._is_lumped(runner._plant_for(spec, run, "pymunk"))


# --- the compiled steps against the classes, on random inputs -------------------------------

def _random_walk(name, seed, n=400):
    rng = np.random.default_rng(seed)
    a, b = controllers.make(name), controllers.make(name)
    kind, s, p = b.compiled()
    out_a, out_b = [], []
    for k in range(n):
        y = float(rng.uniform(-0.5, 3.5))
        r = float(rng.choice([0.3, 1.0, 2.0, 2.9, rng.uniform(0.0, 3.2)]))
        h = float(rng.choice([1e-3, 1e-3, 2e-3, rng.uniform(1e-4, 0.03)]))
        cur = float(rng.normal(0.0, 0.2))
        if k % 97 == 0:
            u0 = float(rng.uniform(-8.0, 8.0))
            a.reset(force_est_n=y, setpoint_n=r, command_v=u0)
            controller_reset(kind, s, p, y, r, u0)
        out_a.append(a.update(y, r, h, cur))
        out_b.append(controller_step(kind, s, p, y, r, h, cur))
    return np.array(out_a), np.array(out_b), kind


@pytest.mark.parametrize("name", CONTROLLERS)
def test_the_class_and_the_compiled_step_give_the_same_commands(name):
    ua, ub, kind = _random_walk(name, seed=len(name))
    assert kind == KINDS.get(name, KIND_PID)
    assert np.array_equal(ua, ub)
    assert np.all(np.isfinite(ua)) and np.ptp(ua) > 0.1          # the inputs moved the command


@pytest.mark.parametrize("scenario,duration_s", [("setpoint_steps", 6.0), ("pressing_90wpm", 3.0)])
def test_the_hold_damping_of_pid_dob_is_the_same_in_both_loops(scenario, duration_s, loop_calls, monkeypatch):
    """pid_dob with its hold damping on (the back-EMF read from the current, applied in a hold):
    one compiled call gives the per-period loop's trace, and the damping changed the command."""
    runs = []
    for use_compiled, kv in ((True, 0.5), (False, 0.5), (True, 0.0)):
        monkeypatch.setattr(runner, "_USE_COMPILED_LOOP", use_compiled)
        runs.append(ebraille_sim.run_scenario(scenario, controller=controllers.make("pid_dob", hold_damping_v_per_v=kv),
                                              duration_s=duration_s))
    assert len(loop_calls) == 2
    _assert_same_runs(runs[0], runs[1])
    assert not np.array_equal(runs[0].trace["command_v"], runs[2].trace["command_v"])


def test_pid_dob_with_a_refresh_learner_has_no_compiled_form():
    assert controllers.make("pid_dob", refresh_learning_gain=0.25).compiled() is None
    assert controllers.make("pid_dob").compiled()[0] == KIND_DOB


def test_pid_state_round_trip_after_compiled_steps():
    pid = controllers.make("pid")
    pid.reset(force_est_n=0.5, setpoint_n=1.5, command_v=0.3)
    kind, s, p = pid.compiled()
    for _ in range(5):
        controller_step(kind, s, p, 0.7, 1.5, 1e-3, 0.0)
    st = pid.state()
    assert st["integrator_v"] == s[PS.integrator_v] and st["prev_error_n"] == pytest.approx(0.8)
    other = controllers.make("pid")
    other.set_state(st)
    assert other.update(0.9, 1.5, 1e-3) == pid.update(0.9, 1.5, 1e-3)


def test_the_reference_map_interpolates_as_numpy():
    c = controllers.make("pid_scheduled")
    f = c._p[PP.map_force_n0:PP.map_force_n0 + MAP_POINTS]
    e = c._p[PP.map_estimate_n0:PP.map_estimate_n0 + MAP_POINTS]
    rng = np.random.default_rng(0)
    xs = np.concatenate([rng.uniform(0.2, 3.3, 3000), f, [0.2000000001, 2.9999999, 3.0, 3.5]])
    for x in xs:
        assert map_reference(c._p, float(x)) == float(np.interp(x, f, e)), x
    assert map_reference(c._p, 0.1) == 0.1 * e[0] / f[0]
    assert c.reference(1.0) != 1.0                                # the map moves the setpoint


def test_the_compiled_pid_follows_the_recursion_of_the_pid_docstring():
    """An independent Python transcription of controllers/pid.py's recursion (forward-Euler
    integral with capped back-calculation, backward-difference filtered derivative, gains
    scaled by PIDConfig.gain_scale) gives the compiled PID's commands exactly."""
    cfg = controllers.pid.PIDConfig(kp_v_per_n=2.0, ki_v_per_ns=8.0, kd_vs_per_n=0.01, derivative_filter_s=0.005,
                                    setpoint_weight_p=0.8, setpoint_weight_d=0.5, u_min_v=-2.0, u_max_v=2.5,
                                    schedule_above_n=1.0)
    pid = controllers.PID(cfg)
    inv_tt = 1.0 / cfg.effective_tracking_time_s
    rng = np.random.default_rng(5)
    y0, r0 = 0.4, 1.5
    pid.reset(force_est_n=y0, setpoint_n=r0, command_v=0.7)
    a0 = cfg.gain_scale(r0)
    i = 0.7 - cfg.kp_v_per_n * a0 * (cfg.setpoint_weight_p * r0 - y0)
    d, w_prev, e_prev, res_prev = 0.0, cfg.setpoint_weight_d * r0 - y0, 0.0, 0.0
    for _ in range(500):
        y, r, h = float(rng.uniform(0.0, 3.0)), float(rng.choice([0.5, 1.0, 2.5])), float(rng.uniform(5e-4, 5e-3))
        a = cfg.gain_scale(r)
        kp, ki, kd = cfg.kp_v_per_n * a, cfg.ki_v_per_ns * a, cfg.kd_vs_per_n * a
        i = i + ki * h * e_prev + min(h * inv_tt, 1.0) * res_prev
        w = cfg.setpoint_weight_d * r - y
        d = (cfg.derivative_filter_s * d + kd * (w - w_prev)) / (cfg.derivative_filter_s + h)
        v = kp * (cfg.setpoint_weight_p * r - y) + i + d
        u = min(max(v, cfg.u_min_v), cfg.u_max_v)
        w_prev, e_prev, res_prev = w, r - y, u - v
        assert pid.update(y, r, h) == u


@pytest.fixture
def rows_calls(monkeypatch):
    """Compiled rows of every engine call."""
    calls = []
    real = engine.run

    def counted(*args):
        calls.append(_compiled_rows(args))
        return real(*args)

    monkeypatch.setattr(engine, "run", counted)
    return calls


def test_a_batch_of_unsupervised_rows_runs_in_one_compiled_call(rows_calls):
    import dataclasses
    from ebraille_sim.scenarios.spec import load_scenario
    spec = load_scenario("pressing_90wpm")
    spec = dataclasses.replace(spec, sections={**spec.sections, "supervisor": {"enabled": False}})
    runs = [{"scenario": spec, "controller": name, "seed": seed, "duration_s": 1.5}
            for name, seed in (("pid", 1), ("lqg", 2), ("pid_friction", 3))]
    batch = runner.run_batch(runs)
    assert [r for r in rows_calls if r] == [3]
    for kw, res in zip(runs, batch):
        single = ebraille_sim.run_scenario(**kw)
        assert not single.supervisor["enabled"]
        _assert_same_runs(res, single)


def test_batched_compiled_rows_equal_single_runs_bit_for_bit(rows_calls):
    """Supervised rows of several controllers, readers and seeds (two rows per reader, which
    share its packed plant and supervisor limits) in one compiled call: every trace column,
    metric, supervisor record and final controller state equals that of a single run."""
    import dataclasses
    from ebraille_sim.scenarios.population import sample_devices
    from ebraille_sim.scenarios.spec import load_scenario
    spec = load_scenario("tremor_90wpm")
    spec = dataclasses.replace(spec, reading=dataclasses.replace(spec.reading, start_s=0.5))
    devices = sample_devices(7, 3, base=spec.device)
    runs = [{"scenario": spec, "controller": name, "seed": seed, "duration_s": 1.2, "device": devices[seed % 3]}
            for name, seed in (("pid", 1), ("lqg", 2), ("pid_friction", 3), ("pid_scheduled", 4), ("pid", 5),
                               ("lqg", 6), ("pid", 4))]
    for keep in (True, False):
        rows_calls.clear()
        batch = runner.run_batch(runs, keep_traces=keep)
        assert [r for r in rows_calls if r] == [len(runs)]
        for kw, res in zip(runs, batch):
            single = ebraille_sim.run_scenario(**kw, trace_every=1 if keep else None)
            assert _metrics(res) == _metrics(single)
            assert res.supervisor == single.supervisor and res.controller_name == single.controller_name
            assert set(res.trace) == set(single.trace)
            for col, arr in single.trace.items():
                assert np.array_equal(res.trace[col], arr), col
    # the rows differ: readers, seeds and controllers change the numbers
    rmse = [r.metrics["force_rmse_n"] for r in batch]
    assert len(set(rmse)) == len(rmse)
