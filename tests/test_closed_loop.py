"""Closed-loop runs, scenario validation, metrics, CLI and determinism."""
import csv
import json
import math
import pathlib
import subprocess
import sys

import numpy as np
import pytest

import ebraille_sim
from ebraille_sim.cli import main as cli_main
from ebraille_sim.scenarios.metrics import compute_metrics, in_band, settling_time
from ebraille_sim.scenarios.spec import ScenarioError, load_scenario, parse_scenario

ROOT = pathlib.Path(__file__).resolve().parent.parent


@pytest.mark.parametrize("name", ["steady_60wpm", "steady_90wpm", "steady_120wpm"])
def test_steady_reading_holds_the_force_in_band(name):
    res = ebraille_sim.run_scenario(name, duration_s=8.0)
    m = res.metrics
    assert m["in_band_fraction"] >= 0.9
    assert m["peak_force_n"] <= 3.0
    assert m["contact_loss_count"] == 0
    assert m["characters"] > 10
    assert m["wpm"] == pytest.approx(float(name.split("_")[1][:-3]), rel=1e-9)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["steady_60wpm", "steady_90wpm", "steady_120wpm"])
def test_steady_reading_full_passage(name):
    m = ebraille_sim.run_scenario(name).metrics
    assert m["in_band_fraction"] >= 0.9 and m["peak_force_n"] <= 3.0 and m["contact_loss_count"] == 0


def test_contact_onset_respects_its_overshoot_bound():
    res = ebraille_sim.run_scenario("contact_onset")
    bound = res.spec.criteria["onset_overshoot_max"]
    assert res.metrics["onset_overshoot_fraction"] <= bound
    assert res.metrics["settling_time_s"] is not None and res.metrics["settling_time_s"] < 1.5


def test_the_first_contact_the_search_finds_starts_the_loop_softly_in_every_form():
    # contact_onset's finger is 2 mm away: the search meets it and the loop starts from 0 V with a
    # plain bumpless reset (its integrator may start below 0 V), whether the design runs compiled
    # (dob_hold_1khz) or from Python (dob_learn_1khz, identical away from refresh reading); the
    # resume of a regained contact (integrator raised to 0 V) overshot 16 % here
    a = ebraille_sim.run_scenario("contact_onset", controller="dob_hold_1khz", duration_s=2.0)
    b = ebraille_sim.run_scenario("contact_onset", controller="dob_learn_1khz", duration_s=2.0)
    np.testing.assert_array_equal(a.trace["command_v"], b.trace["command_v"])
    assert a.metrics["onset_overshoot_fraction"] < 0.10


def test_same_seed_same_trace_exactly_and_other_seed_differs():
    a = ebraille_sim.run_scenario("steady_120wpm", seed=5, duration_s=2.0)
    b = ebraille_sim.run_scenario("steady_120wpm", seed=5, duration_s=2.0)
    c = ebraille_sim.run_scenario("steady_120wpm", seed=6, duration_s=2.0)
    for col in ("force_true_n", "force_est_n", "fsr_voltage_v", "command_v"):
        np.testing.assert_array_equal(a.trace[col], b.trace[col])
    assert not np.array_equal(a.trace["fsr_voltage_v"], c.trace["fsr_voltage_v"])


def test_trace_knows_the_displayed_character_at_every_instant():
    res = ebraille_sim.run_scenario("steady_120wpm", duration_s=3.0)
    t, ci = res.trace["t_s"], res.trace["char_index"]
    assert np.all(ci[t < res.spec.reading.start_s - 1e-9] == -1)
    k = np.searchsorted(t, res.spec.reading.start_s + 0.05)
    assert ci[k] == 0
    assert res.trace["character"][k] == res.schedule.cells[0].unicode
    # 120 wpm = 10 cells/s: 0.1 s dwell
    assert res.schedule.dwell_s[0] == pytest.approx(0.1)


def test_metrics_on_a_synthetic_trace():
    t = np.arange(1, 2001) * 1e-3
    sp = np.ones_like(t)
    f = np.where(t < 0.5, 2 * t, 1.0)
    f[1500:1600] = 1.2                                  # out of band for 0.1 s
    f[1800:1801] = 0.0                                  # one contact loss
    tr = {"t_s": t, "setpoint_n": sp, "force_true_n": f, "force_est_n": f + 0.01,
          "energy_j": np.linspace(0, 1, 2000), "char_index": np.where(np.arange(2000) >= 999, (np.arange(2000) - 999) // 100, -1)}
    m = compute_metrics(tr, 1.0, 0.1)
    read = t >= 1.0
    assert m["in_band_fraction"] == pytest.approx(np.mean(in_band(f[read], 1.0, 0.1)))
    assert m["in_band_fraction"] == pytest.approx(900 / 1001, abs=1e-12)    # 100 + 1 samples out
    assert m["contact_loss_count"] == 1
    assert m["estimate_rmse_n"] == pytest.approx(0.01)
    assert m["peak_force_n"] == pytest.approx(1.2)
    assert m["char_in_band_fraction"] == pytest.approx(10 / 11)  # only char 5 (out for 99 % of its dwell) fails
    assert m["onset_overshoot_fraction"] == 0.0
    # first contact at t = 0.011 s (2t > 0.02 N), in band from t = 0.450 s (2t >= 0.9 N)
    assert settling_time(t, f, sp, 0.1) == pytest.approx(0.450 - 0.011, abs=1e-9)
    assert m["energy_j"] == 1.0


def _write(tmp_path, text, name="s.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


@pytest.mark.parametrize("text,match", [
    ('name = "x"\n[reading]\nwmp = 90\n', "unknown key 'wmp' in \\[reading\\]; allowed: .*wpm"),
    ('name = "x"\n[reading]\nwpm = -3\n', "wpm = -3 is out of range \\(0, 1000\\]"),
    ('name = "x"\n[reading]\nwpm = 0\n', "wpm = 0 is out of range"),
    ('name = "x"\n[rates]\ncontrol_hz = nan\n', "control_hz must be finite"),
    ('name = "x"\n[setpoint]\nforce_n = inf\n', "force_n must be finite"),
    ('name = "x"\n[device]\nfinger = "squishy"\n', "finger = 'squishy' is not one of: nominal, soft, stiff"),
    ('name = "x"\n[device.finger_overrides]\nstiffnes = 1\n', "unknown key 'stiffnes' in \\[device.finger_overrides\\]"),
    ('name = "x"\n[rates]\ncontrol_hz = 3000\n', "whole multiple"),
    ('name = "x"\nbogus = 1\n', "unknown key 'bogus' in the top level"),
    ('[reading]\nwpm = 90\n', "missing required key 'name'"),
    ('name = "x"\n[reading\nwpm = 90\n', "malformed TOML"),
    ('name = "x"\n[rates]\ncontrol_hz = 1\n', "control_hz = 1 is below the 1000 Hz rate of the force estimate"),
    ('name = "x"\n[rates]\ncontrol_hz = 50\nsensor_hz = 1000\n', "3.08 mechanical|below the 1000 Hz rate"),
    ('name = "x"\n[rates]\nsensor_hz = 1050\nphysics_hz = 10500\ncontrol_hz = 1050\n',
     "sensor_rate_hz \\(1050\\) must be a whole multiple of the estimator model's rate \\(1000 Hz\\)"),
    ('name = "x"\n[rates]\nsensor_hz = 100\n[estimator]\nfirmware = "paper_100hz"\nantialias_cutoff_hz = 60\n',
     "antialias_cutoff_hz 60 must lie in \\(0, 50\\) Hz, below the Nyquist frequency"),
    ('name = "x"\n[rates]\nphysics_hz = 1000\n', "physics_rate_hz 1000 is too low"),
    ('name = "x"\n[device.drivetrain_overrides]\ngear_efficiency = 5\n', "gear_efficiency = 5 must be in \\(0, 1\\]"),
    ('name = "x"\n[device.circuit_overrides]\nadc_bits = 10.5\n', "adc_bits must be a whole number"),
    ('name = "x"\nseed = ' + "[" * 2000 + "]" * 2000 + "\n", "nested too deeply"),
])
def test_scenario_validation_errors_name_the_problem(tmp_path, text, match):
    with pytest.raises(ScenarioError, match=match) as info:
        load_scenario(_write(tmp_path, text))
    assert "\n" not in str(info.value)


def test_invalid_utf8_is_named_with_its_offset(tmp_path):
    p = tmp_path / "s.toml"
    p.write_bytes(b'name = "x"\n# caf\xe9\n')
    with pytest.raises(ScenarioError, match=r"s.toml: not valid UTF-8 \(byte 0xe9 at offset 16\); TOML files must be UTF-8"):
        load_scenario(p)


def test_cr_only_line_ends_read_as_line_breaks(tmp_path):
    text = (ROOT / "scenarios" / "setpoint_steps.toml").read_bytes()
    p = tmp_path / "setpoint_steps.toml"
    p.write_bytes(text.replace(b"\n", b"\r"))
    assert b"\n" not in p.read_bytes()
    a, b = load_scenario(p), load_scenario(ROOT / "scenarios" / "setpoint_steps.toml")
    assert a.setpoint == b.setpoint and a.reading == b.reading and a.duration_s == b.duration_s == 14.0


def test_setpoint_below_the_tactile_range_warns_not_fails():
    from ebraille_sim.scenarios.spec import ScenarioWarning
    with pytest.warns(ScenarioWarning, match=r"x: \[setpoint\] force_n = 0.1 N, steps at 2 s = 0.15 N are below "
                                             r"the 0.2 N lower end of the tactile range"):
        spec = parse_scenario({"name": "x", "setpoint": {"force_n": 0.1, "steps": [[2.0, 0.15], [3.0, 1.0]]}},
                              source="x")
    assert spec.setpoint.force_n == 0.1
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        parse_scenario({"name": "x", "setpoint": {"force_n": 0.2}}, source="x")       # the range's own end


@pytest.mark.parametrize("doc,match", [
    # 3600 s at 1 MHz: 3.6e9 control periods x 264 B (8 B x (14 + 12 inputs + 7)) = 950.4 GB
    ({"duration_s": 3600, "rates": {"control_hz": 1e6, "sensor_hz": 1e6, "physics_hz": 1e6}},
     r"duration_s = 3600 s; at control_hz = 1e\+06 that is 3.6e\+09 control periods x 264 B .* = 950.4 GB, "
     r"above the 2 GB bound"),
    # 0.001 wpm: 12000 s per cell, the default passage's cells end after ~6e6 s
    ({"reading": {"wpm": 0.001}}, r"the reading of \d+ cells at 0.001 wpm ends at .* GB, above the 2 GB bound"),
])
def test_runs_beyond_the_memory_bound_are_refused_before_allocating(doc, match):
    from ebraille_sim.scenarios.inputs import build_run_inputs
    spec = parse_scenario({"name": "x", **doc}, source="x")
    with pytest.raises(ScenarioError, match=match):
        build_run_inputs(spec)


def test_memory_bound_admits_an_hour_at_one_kilohertz():
    from ebraille_sim.scenarios.inputs import BYTES_PER_CONTROL_SAMPLE, MAX_CONTROL_SAMPLES, check_run_size
    spec = parse_scenario({"name": "x", "duration_s": 3600}, source="x")
    assert check_run_size(spec, 3600.0) == 3_600_000
    assert MAX_CONTROL_SAMPLES * BYTES_PER_CONTROL_SAMPLE <= 2e9 < (MAX_CONTROL_SAMPLES + 1) * BYTES_PER_CONTROL_SAMPLE


def test_cli_prints_a_warning_as_one_line(tmp_path):
    src = _write(tmp_path, 'name = "low"\nduration_s = 0.3\n[setpoint]\nforce_n = 0.1\n')
    out = tmp_path / "o"
    proc = subprocess.run([sys.executable, "-m", "ebraille_sim", "run", str(src), "--out", str(out), "--no-plot"],
                          capture_output=True, text=True, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr.splitlines() == [
        "warning: s.toml: [setpoint] force_n = 0.1 N is below the 0.2 N lower end of the tactile range "
        "([R] seed paper: tactile forces 0.2-3 N): the reader may not feel the display"]
    assert (out / "metrics.json").exists()


def test_missing_scenario_file_is_named(tmp_path):
    with pytest.raises(ScenarioError, match="not found"):
        load_scenario(tmp_path / "nope.toml")


def test_every_shipped_scenario_is_valid():
    for f in sorted((ROOT / "scenarios").glob("*.toml")):
        spec = load_scenario(f)
        assert spec.name == f.stem


def test_cli_run_writes_outputs(tmp_path, capsys):
    out = tmp_path / "run"
    rc = cli_main(["run", "steady_90wpm", "--duration", "2.5", "--out", str(out), "--seed", "3"])
    assert rc == 0
    assert "in_band_fraction" in capsys.readouterr().out
    doc = json.loads((out / "metrics.json").read_text())
    assert doc["seed"] == 3 and 0.0 <= doc["metrics"]["in_band_fraction"] <= 1.0
    with open(out / "trace.csv") as fh:
        header = next(csv.reader(fh))
    for col in ("t_s", "setpoint_n", "force_true_n", "force_est_n", "fsr_voltage_v", "command_v",
                "motor_current_a", "board_pos_m", "character"):
        assert col in header
    assert (out / "force.png").stat().st_size > 10_000


@pytest.mark.parametrize("argv,match", [
    (["run", "no_such_scenario"], "not found"),
    (["run", "steady_90wpm", "--seed", "-1"], "seed"),
    (["run", "steady_90wpm", "--duration", "-2"], "argument --duration: must lie in (0, inf)"),
    (["run", "steady_90wpm", "--controller", "nope"], "nope"),
    (["run"], "required"),
])
def test_cli_bad_input_exits_2_with_one_line(tmp_path, capsys, argv, match):
    out = tmp_path / "o"
    rc = cli_main(argv + ["--out", str(out)] if len(argv) > 1 else argv)
    err = capsys.readouterr().err
    assert rc == 2
    assert err.startswith("error: ") and err.count("\n") == 1
    assert match in err
    assert not out.exists()


def test_cli_bad_scenario_file_writes_nothing(tmp_path):
    bad = _write(tmp_path, 'name = "x"\n[reading]\nwpm = nan\n')
    out = tmp_path / "o"
    proc = subprocess.run([sys.executable, "-m", "ebraille_sim", "run", str(bad), "--out", str(out)],
                          capture_output=True, text=True, cwd=ROOT)
    assert proc.returncode == 2
    assert proc.stderr.strip() == (f"error: {bad.name}: [reading] wpm must be finite, got nan; "
                                   "admissible: a finite number in (0, 1000]")
    assert "Traceback" not in proc.stderr
    assert not out.exists()


def test_cli_list_names_scenarios_and_controllers(capsys):
    assert cli_main(["list"]) == 0
    out = capsys.readouterr().out
    assert "steady_90wpm" in out and "pid" in out and "paper:wiener:5" in out


@pytest.mark.parametrize("name", ["../../x", "/etc/evil", "a/b", "..", "", ".hidden", "x" * 101, "a b"])
def test_a_scenario_name_cannot_leave_the_run_folder(name):
    from ebraille_sim.scenarios.spec import ScenarioError, parse_scenario
    with pytest.raises(ScenarioError, match="must be 1-100 letters, digits") as err:
        parse_scenario({"name": name, "reading": {"wpm": 90}}, source="inline")
    assert "\n" not in str(err.value)
