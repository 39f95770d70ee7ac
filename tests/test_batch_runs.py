"""Batched runs: plants of several runs advanced together give the runs' own traces and metrics."""
import dataclasses
import math

import numpy as np
import pytest

import controllers
from ebraille_sim.scenarios.population import sample_devices
from ebraille_sim.scenarios.runner import run_batch, run_scenario
from ebraille_sim.scenarios.spec import load_scenario


class _Failing:
    """A PID that raises (``mode`` "raise") or returns NaN ("nan") from period ``at`` on."""

    def __init__(self, mode, at):
        self.inner, self.mode, self.at, self.k, self.name = controllers.make("pid"), mode, at, 0, f"failing_{mode}"

    def reset(self, **kw):
        self.inner.reset(**kw)

    def update(self, force_est_n, setpoint_n, dt_s, current_a=None):
        self.k += 1
        if self.k > self.at:
            if self.mode == "raise":
                raise ValueError("controller gave up")
            return math.nan
        return self.inner.update(force_est_n, setpoint_n, dt_s, current_a)


def _runs():
    spec = load_scenario("steady_90wpm")
    devices = sample_devices(4, 3, base=spec.device)
    runs = [dict(scenario=spec, controller=c, seed=10 + i, duration_s=1.8, device=d)
            for i, (c, d) in enumerate([("pid", devices[0]), ("lqg", devices[1]), ("pid", devices[2]),
                                        ("pid", None)])]
    runs.append(dict(scenario="fault_controller_nan", seed=3, duration_s=1.8))    # watchdog wrapper
    runs.append(dict(scenario="contact_onset", controller="pid", seed=4, duration_s=2.3))  # its own group
    runs.append(dict(scenario=spec, controller="pid", seed=5, duration_s=-1.0))       # fails in preparation
    return runs


def test_batched_runs_equal_single_runs_exactly():
    runs = _runs()
    batched = run_batch(runs)
    assert len(batched) == len(runs)
    for kw, res in zip(runs, batched):
        try:
            ref = run_scenario(**kw)
        except ValueError as exc:
            assert isinstance(res, ValueError) and str(res) == str(exc)
            continue
        assert set(res.trace) == set(ref.trace)
        for col, arr in ref.trace.items():
            np.testing.assert_array_equal(res.trace[col], arr, err_msg=col)
        assert {k: v for k, v in res.metrics.items() if k != "real_time_factor"} == \
               {k: v for k, v in ref.metrics.items() if k != "real_time_factor"}
        assert res.controller_name == ref.controller_name and res.seed == ref.seed
    assert batched[0].metrics["force_rmse_n"] is not None
    assert batched[0].metrics != batched[2].metrics                     # different readers
    lean = run_batch(runs, keep_traces=False)
    for a, b in zip(batched, lean):
        if isinstance(a, Exception):
            assert str(a) == str(b)
            continue
        assert b.trace == {}
        assert {k: v for k, v in a.metrics.items() if k != "real_time_factor"} == \
               {k: v for k, v in b.metrics.items() if k != "real_time_factor"}


@pytest.mark.parametrize("mode, message", [("raise", "controller gave up"), ("nan", "command_v must be finite")])
def test_a_failing_row_fails_alone_with_the_single_run_error(mode, message):
    # without the supervisor, whose watchdog would hold a NaN command at 0 V instead
    spec = load_scenario("steady_90wpm")
    spec = dataclasses.replace(spec, sections={**spec.sections, "supervisor": {"enabled": False}})
    runs = [dict(scenario=spec, controller="pid", seed=1, duration_s=1.7),
            dict(scenario=spec, controller=_Failing(mode, 300), seed=2, duration_s=1.7),
            dict(scenario=spec, controller="pid", seed=3, duration_s=1.7)]
    out = run_batch(runs)
    assert isinstance(out[1], ValueError) and message in str(out[1])
    with pytest.raises(ValueError) as single:
        run_scenario(spec, controller=_Failing(mode, 300), seed=2, duration_s=1.7)
    assert str(out[1]) == str(single.value)
    for i in (0, 2):
        ref = run_scenario(**runs[i])
        np.testing.assert_array_equal(out[i].trace["force_true_n"], ref.trace["force_true_n"])


@pytest.mark.parametrize("name", ["steady_90wpm", "refresh_60wpm"])
def test_a_thinned_trace_keeps_the_metrics_and_every_kth_sample(name):
    full = run_scenario(name, duration_s=4.0, seed=6)
    drop = lambda m: {k: v for k, v in m.items() if k != "real_time_factor"}   # noqa: E731
    for every in (7, None):
        lean = run_scenario(name, duration_s=4.0, seed=6, trace_every=every)
        assert drop(lean.metrics) == drop(full.metrics)
        if every is None:
            assert lean.trace == {}
            continue
        assert list(lean.trace) == list(full.trace)
        for col, arr in full.trace.items():
            np.testing.assert_array_equal(lean.trace[col], arr[every - 1::every], err_msg=col)
    with pytest.raises(ValueError, match="trace_every must be a whole number >= 1 or None"):
        run_scenario(name, duration_s=1.0, trace_every=0)


def test_character_column_is_a_lookup_of_the_cells():
    res = run_scenario("steady_90wpm", duration_s=3.0, seed=1)
    ci, cells = res.trace["char_index"], res.schedule.cells
    expected = np.array([cells[j].unicode if j >= 0 else "" for j in ci])
    np.testing.assert_array_equal(res.trace["character"], expected)
    assert res.trace["character"].dtype == expected.dtype and (ci >= 0).any() and (ci < 0).any()
