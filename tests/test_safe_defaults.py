"""Safe defaults: the supervisor is on unless switched off explicitly, and the default
controller's step to the top of the tactile range stays below the safe limit."""
from __future__ import annotations

import dataclasses
import json
import pathlib

import numpy as np
import pytest

from ebraille_sim.scenarios.runner import run_scenario, supervisor_choice
from ebraille_sim.scenarios.spec import load_scenario
from ebraille_sim.tools.regress import scenario_files


def test_every_shipped_scenario_is_supervised_by_default():
    for path in scenario_files():
        spec = load_scenario(path)
        on, source = supervisor_choice(spec)
        assert on, (spec.name, source)
        off, why = supervisor_choice(spec, supervised=False)
        assert not off and "supervised=False" in why


def test_opt_out_is_explicit_and_recorded():
    spec = load_scenario("steady_90wpm")
    assert "supervisor" not in spec.sections
    r = run_scenario(spec, duration_s=1.0)
    assert r.supervisor["enabled"] and r.supervisor["source"].startswith("on: default")
    assert r.supervisor["fault"] is None and r.controller_name == "pid_dob"
    off = dataclasses.replace(spec, sections={**spec.sections, "supervisor": {"enabled": False}})
    r_off = run_scenario(off, duration_s=1.0)
    assert not r_off.supervisor["enabled"] and "enabled = false" in r_off.supervisor["source"]
    assert r_off.controller_name == "pid_dob"
    r_arg = run_scenario(spec, duration_s=1.0, supervised=False)
    assert not r_arg.supervisor["enabled"] and "--no-supervisor" in r_arg.supervisor["source"]
    with pytest.raises(TypeError, match="supervised"):
        run_scenario(spec, duration_s=1.0, supervised="no")


def _step_spec(force_n: float, ramp_s: float = 0.0):
    spec = load_scenario("setpoint_steps")
    sp = dataclasses.replace(spec.setpoint, force_n=1.0, steps=((4.0, force_n),), ramp_s=ramp_s)
    return dataclasses.replace(spec, setpoint=sp, duration_s=7.0)


@pytest.mark.parametrize("supervised", [True, False])
def test_default_controller_steps_to_the_top_of_the_tactile_range_below_the_safe_limit(supervised):
    r = run_scenario(_step_spec(3.0), supervised=supervised)
    f = np.asarray(r.trace["force_true_n"])
    t = np.asarray(r.trace["t_s"])
    assert f.max() < 3.5                          # fixed gains overshoot to ~9.7 N on this step
    after = f[t > 6.0]
    # the force is held, not retracted: at 2.48 N with the supervisor, the force the firmware's
    # 56.6 mA limit holds against the break-away friction as the pulp relaxes (2.61 N with the
    # unit's own constants, 58.6 mA)
    assert after.min() > 2.3
    if supervised:
        assert r.supervisor["fault"] is None, r.supervisor["events"]


def test_run_command_logs_the_opt_out(tmp_path, capsys):
    from ebraille_sim.cli import main
    out = tmp_path / "r"
    code = main(["run", "steady_90wpm", "--duration", "3", "--no-plot", "--trace", "none", "--out", str(out),
                 "--no-supervisor", "--quiet"])
    err = capsys.readouterr().err
    assert code == 0
    assert "warning: safety supervisor off" in err and "--no-supervisor" in err
    doc = json.loads((out / "metrics.json").read_text())
    assert doc["supervisor"]["enabled"] is False
    code = main(["run", "steady_90wpm", "--duration", "3", "--no-plot", "--trace", "none", "--out",
                 str(tmp_path / "s"), "--quiet"])
    assert code == 0 and json.loads((tmp_path / "s" / "metrics.json").read_text())["supervisor"]["enabled"]
    assert "warning" not in capsys.readouterr().err


@pytest.mark.slow
def test_a_long_everyday_session_keeps_contact_with_no_stall_current():
    """Strap slips (2/min) seat after 1 mm, the supervisor's checks follow the finger's slow
    motion: 22 minutes of everyday reading keep contact, with the motor far below its rated
    current and no supervisor event (unbounded slips lost contact after about 20 min).  The late
    force is within 7 % of the setpoint: the estimator's own offset on this reader (2.6 %) and
    the film's draw for the press the session holds (single-part repeatability, 2 % one sigma;
    this seed's press reads about 2 % high)."""
    r = run_scenario("everyday_session", duration_s=1320.0, trace_every=50)
    f = np.asarray(r.trace["force_true_n"])
    t = np.asarray(r.trace["t_s"])
    assert r.supervisor["fault"] is None and r.supervisor["events"] == []
    assert r.metrics["contact_loss_count"] == 0
    late = t > 1200.0
    assert f[late].min() > 0.5 and abs(f[late].mean() - 1.0) < 0.07
    from controllers.supervisor import SupervisorConfig
    assert np.abs(r.trace["motor_current_a"]).max() < SupervisorConfig().rated_current_a
