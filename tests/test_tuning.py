"""Robust tuning over readers and scenarios (ebraille_sim.analysis.robust) and the tune command."""
import dataclasses
import math
import pathlib

import numpy as np
import pytest

from controllers.pid import DEFAULT_PID, PID
from ebraille_sim.analysis.margins import analyse_loop
from ebraille_sim.physics.params import DeviceParams

ROOT = pathlib.Path(__file__).resolve().parents[1]


def test_describing_function_gain_equals_scaled_controller():
    # kappa L is the loop of the controller with every gain scaled by kappa
    from ebraille_sim.analysis.robust import linearisation_points, population_ms, tuning_population
    pts = linearisation_points(tuning_population(0, seed=0)[:2], [0.6, 2.0])
    cfg = dataclasses.replace(DEFAULT_PID, kp_v_per_n=1.0, ki_v_per_ns=6.0, kd_vs_per_n=0.002)
    half = dataclasses.replace(cfg, kp_v_per_n=0.5, ki_v_per_ns=3.0, kd_vs_per_n=0.001)
    assert np.allclose(population_ms(cfg, pts, 0.5), population_ms(half, pts), rtol=1e-9)
    with pytest.raises(ValueError, match="gain"):
        population_ms(cfg, pts, 0.0)


def test_friction_band_is_the_press_release_command_gap():
    from ebraille_sim.analysis.robust import friction_band_v
    dev = DeviceParams()
    g = dev.drivetrain.gear_ratio / dev.drivetrain.pinion_radius_m
    v_per_n = dev.motor.resistance_ohm / (dev.motor.torque_constant_nm_per_a * g)
    mu = dev.drivetrain.gear_loss_coefficient
    fw = 1.0 + dev.drivetrain.moving_mass_kg * dev.gravity_m_per_s2
    # mesh force pressing F + W + Fg, releasing F + W - Fg; motor command (1 +- mu) Fm +- Fc
    fg, fc = dev.drivetrain.guide_coulomb_n, dev.motor.friction_torque_nm * g
    expect = v_per_n * ((1 + mu) * (fw + fg) + fc - (1 - mu) * (fw - fg) + fc)
    assert friction_band_v(dev, 1.0) == pytest.approx(expect, rel=1e-6)
    assert 0.5 < friction_band_v(dev, 1.0) < friction_band_v(dev, 2.0)


def test_scenario_cost_rewards_in_band_and_penalises_overshoot():
    from ebraille_sim.analysis.robust import cvar, scenario_cost
    good = [{"force_rmse_n": 0.02, "in_band_fraction": 1.0, "peak_force_n": 1.1}] * 4
    worse = good[:3] + [{"force_rmse_n": 0.02, "in_band_fraction": 0.5, "peak_force_n": 1.1}]
    over = good[:3] + [{"force_rmse_n": 0.02, "in_band_fraction": 1.0, "peak_force_n": 1.5}]
    c0 = scenario_cost(good, 1.0, 1.0)
    assert c0 == pytest.approx(0.02)
    assert scenario_cost(worse, 1.0, 1.0) == pytest.approx(c0 + 2 * 0.5 + 0.5)   # worst case and CVaR25
    assert scenario_cost(over, 1.0, 1.0) == pytest.approx(c0 + 2 * (1.5 - 1.15))
    assert cvar([1.0, 0.2, 0.9, 0.8, 0.7]) == pytest.approx(0.45)                  # worst 2 of 5


def test_gains_file_of_a_schedule_round_trips_through_make(tmp_path):
    import controllers
    from ebraille_sim.analysis.robust import family_config, gains_document, gains_toml
    cfg = family_config("pid_scheduled", 1.5, 6.0, 0.002)
    doc = gains_document(cfg, "pid_scheduled")
    assert doc["controller"] == "pid_scheduled" and doc["gains"]["reference_map"] is True
    path = tmp_path / "gains.toml"
    path.write_text(gains_toml(doc, "a schedule\nof two lines"))
    assert path.read_text().startswith("# a schedule\n# of two lines\ncontroller = ")
    c = controllers.make(str(path))
    assert c.name == "pid_scheduled" and c.config == cfg
    ff = controllers.make(str(path), feedforward=True)
    assert ff.config.feedforward


def test_recommended_design_beats_default_on_worst_case_in_band():
    """The design docs/tuning.md recommends, against the hand-tuned default PID, on the
    setpoint steps (with and without the ramp) for the three reader presets, on the paper's
    100 Hz path both were tuned on."""
    from ebraille_sim.analysis.robust import evaluate, summarise, tuning_population, unramped
    from controllers.schedule import RECOMMENDED, ScheduledPID
    from ebraille_sim.scenarios.spec import load_scenario, with_firmware
    pop = tuning_population(0, seed=0)[:3]
    steps = with_firmware(load_scenario("setpoint_steps"), "paper_100hz")
    for spec in (steps, unramped(steps)):
        d = summarise(evaluate(lambda: PID(DEFAULT_PID), pop, spec))["in_band_fraction"]
        r = summarise(evaluate(lambda: ScheduledPID(RECOMMENDED), pop, spec))["in_band_fraction"]
        assert r["worst"] > d["worst"] + 0.05, spec.name
        assert r["median"] > d["median"], spec.name


def test_recommended_design_holds_steady_reading_and_onset():
    """Steady reading on the three reader presets.  On the soft reader the contact onset leaves
    the FSR on its unloading hysteresis branch, where it reads 8-10 % above the true force for
    the rest of the run (the default PID holds the estimate at 1.000 N with 0.915 N on the
    finger): the true-force band there is the sensor's limit, so the controller is held to its
    estimate (what it can see) and the true force to the hysteresis-limited 0.85."""
    import dataclasses
    from ebraille_sim.analysis.robust import evaluate, summarise, tuning_population
    from ebraille_sim.scenarios.metrics import in_band
    from ebraille_sim.scenarios.runner import run_scenario
    from controllers.schedule import RECOMMENDED, ScheduledPID
    from ebraille_sim.physics.params import unit_estimator
    from ebraille_sim.scenarios.spec import load_scenario
    pop = tuning_population(0, seed=0)[:3]
    spec = load_scenario("steady_90wpm")
    for label, dev in pop:
        d = dataclasses.replace(dev, rates=spec.device.rates, estimator=unit_estimator(spec.device.estimator, dev.estimator))
        res = run_scenario(dataclasses.replace(spec, device=d), controller=ScheduledPID(RECOMMENDED),
                           duration_s=8.0)
        tr = res.trace
        read = tr["t_s"] >= spec.reading.start_s
        est_ok = in_band(tr["force_est_n"][read], tr["setpoint_n"][read], spec.setpoint.band_fraction)
        assert est_ok.mean() >= 0.95, label
        assert res.metrics["in_band_fraction"] >= (0.85 if label == "soft" else 0.95), label
    o = summarise(evaluate(lambda: ScheduledPID(RECOMMENDED), pop, load_scenario("contact_onset")))
    assert o["peak_force_n"]["worst"] <= 1.15 * 1.5


@pytest.mark.slow
def test_robust_tuning_beats_default_on_worst_case_in_band():
    """Multi-scenario tuning under Ms <= 1.6 (sliding model) on a small population."""
    from ebraille_sim.analysis.robust import TuneScenario, robust_tune, tuning_population, unramped
    from ebraille_sim.scenarios.spec import load_scenario
    spec = load_scenario("setpoint_steps")
    pop = tuning_population(0, seed=0)[:3]
    scen = [TuneScenario(spec.name, spec), TuneScenario("unramped", unramped(spec)),
            TuneScenario("steady_90wpm", load_scenario("steady_90wpm"), 6.0)]
    res = robust_tune(spec, pop, family="pid_scheduled", max_evaluations=8, scenarios=scen)
    rep = res.report()
    assert res.tuned.ms_max <= 1.6
    assert res.tuned.cost <= min(h["cost"] for h in res.history if math.isfinite(h["cost"]))
    assert (res.selected == "shipped") == (res.named_cost("shipped") < res.named_cost("tuned"))
    for name in ("setpoint_steps", "unramped"):
        t = rep["tuned"]["scenarios"][name]["metrics"]["in_band_fraction"]["worst"]
        d = rep["default"]["scenarios"][name]["metrics"]["in_band_fraction"]["worst"]
        assert t > d, name
    assert res.gains_file()["controller"] == "pid_scheduled"


def _on_paper_path(folder, name: str) -> str:
    """A copy of the shipped scenario ``name`` on the paper's 100 Hz firmware (where the paper's
    two readings of the input delay differ, and where the PID family was tuned), as a file."""
    text = (ROOT / "scenarios" / f"{name}.toml").read_text(encoding="utf-8")
    path = folder / f"{name}.toml"
    path.write_text(text + '\n[estimator]\nfirmware = "paper_100hz"\n', encoding="utf-8")
    return str(path)


@pytest.mark.slow
def test_tune_command_writes_a_gains_file_that_run_accepts(tmp_path):
    import subprocess
    import sys
    out = tmp_path / "tune"
    r = subprocess.run([sys.executable, "-m", "ebraille_sim", "tune", _on_paper_path(tmp_path, "contact_onset"),
                        "--population", "0",
                        "--evaluations", "4", "--scenarios", "single", "--out", str(out)],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    for f in ("gains.toml", "gains_hand.toml", "report.md", "report.json", "bode.png", "nyquist.png",
              "population.png"):
        assert (out / f).is_file(), f
    assert 'controller = "pid_scheduled"' in (out / "gains.toml").read_text()
    assert "reference_map = true" in (out / "gains.toml").read_text()
    import json
    rep = json.loads((out / "report.json").read_text())
    assert rep["delays"] == [0, 1] and len(rep["ms_labels"]) == 2 * len(rep["labels"])
    assert {(r["controller"], r["nk"]) for r in rep["delay_margins"]} == \
        {(c, k) for c in ("gains.toml", "default PID") for k in (0, 1)}
    md = (out / "report.md").read_text()
    assert "under both readings of the paper's input delay (nk = 0 and 1)" in md and "| nominal, nk 1 |" in md
    r = subprocess.run([sys.executable, "-m", "ebraille_sim", "run", "contact_onset", "--controller",
                        str(out / "gains.toml"), "--duration", "2", "--out", str(tmp_path / "run")],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr


def test_tune_report_gives_margins_only_for_a_stable_loop(tmp_path):
    from ebraille_sim.analysis.plots import plot_bode
    from ebraille_sim.commands.tune import _loop_cells
    fixed = dataclasses.replace(DEFAULT_PID, schedule_above_n=None)
    a1, a2 = analyse_loop(DEFAULT_PID, force_n=1.0), analyse_loop(fixed, force_n=2.0)
    # the loop of test_margins.test_default_pid_margins_at_1n_and_0_6n
    assert _loop_cells(a1.summary()) == ["stable", "33.9 deg at 6.43 Hz", "1.46 at 9.34 Hz", "3.54"]
    assert _loop_cells(a2.summary()) == ["unstable", "-", "-", "unstable"]
    assert a1.margin_label() == "PM 33.9 deg at 6.43 Hz, GM 1.46"
    plot_bode([a1, a2], tmp_path / "bode.png")
    assert (tmp_path / "bode.png").stat().st_size > 10_000


def test_tune_keeps_the_shipped_controller_that_beats_the_optimum_and_counts_its_runs(tmp_path, capsys):
    """On steady reading the shipped pid_scheduled beats the Ms <= 1.5 optimum: it is kept, with the reason
    (its max Ms on the presets at 1 N is 1.56, above that bound and below the default 1.6)."""
    import json
    import tomllib

    from controllers.schedule import RECOMMENDED
    from ebraille_sim.analysis.robust import gains_document
    from ebraille_sim.cli import main as cli
    out = tmp_path / "t"
    assert cli(["tune", _on_paper_path(tmp_path, "steady_90wpm"), "--population", "0", "--evaluations", "4", "--scenarios", "single",
                "--duration", "2.0", "--ms-max", "1.5", "--out", str(out), "--json"]) == 0
    cap = capsys.readouterr()
    doc = json.loads(cap.out)
    assert doc["ms_bound"] == 1.5 and doc["ms_max_tuned"] <= 1.5
    assert doc["selected"] == "shipped"
    assert doc["named_costs"]["shipped"] < doc["named_costs"]["tuned"]
    assert doc["gains"] == gains_document(RECOMMENDED, "pid_scheduled")["gains"]
    assert doc["ms_max"] == pytest.approx(doc["shipped"]["ms_max"]) and doc["ms_max"] > 1.5
    assert "exceeds the bound 1.5" in doc["selection_reason"]
    text = (out / "gains.toml").read_text()
    assert text.startswith("# kept the shipped pid_scheduled: on steady_90wpm its cost is")
    assert "kp_v_per_n = 0.859" in text
    rep = json.loads((out / "report.json").read_text())
    with open(out / "gains_tuned.toml", "rb") as fh:
        assert tomllib.load(fh)["gains"] == rep["tuned"]["gains"]
    assert rep["selected"] == "shipped" and "## Selection" in (out / "report.md").read_text()
    # progress: periodic lines on a non-terminal stderr, ending at the runs actually made (5 devices x
    # 1 scenario x (4 references + the candidates within the bound))
    runs = 5 * (4 + sum(h["ms_max"] <= 1.5 for h in rep["history"]))
    lines = cap.err.strip().splitlines()
    assert lines[-1] == f"tune steady_90wpm: runs {runs}/{runs}"
    assert all("\r" not in ln for ln in lines)


def test_run_with_a_gains_file_labels_the_run_and_records_the_gains(tmp_path, capsys):
    import json

    from controllers.schedule import ScheduleConfig
    from ebraille_sim.analysis.robust import gains_document, gains_toml
    from ebraille_sim.cli import main as cli
    cfg = ScheduleConfig(kp_v_per_n=0.6, ki_v_per_ns=1.5, kd_vs_per_n=0.0)
    gains = tmp_path / "gains.toml"
    gains.write_text(gains_toml(gains_document(cfg, "pid_scheduled"), "a comment line"))
    # 0.3 s ends before reading: the criteria fail (status 1); only the labelling is checked here
    assert cli(["run", "steady_90wpm", "--controller", str(gains), "--duration", "0.3", "--trace", "none",
                "--no-plot", "--out", str(tmp_path / "r")]) == 1
    assert f"controller pid_scheduled (gains {gains})" in capsys.readouterr().out
    doc = json.loads((tmp_path / "r" / "metrics.json").read_text())
    assert doc["controller"] == "pid_scheduled" and doc["controller_file"] == str(gains)
    assert doc["controller_gains"] == dataclasses.asdict(cfg)
    assert doc["controller_gains"]["kp_v_per_n"] == 0.6


def test_tune_scenarios_keep_the_named_scenarios_estimator():
    """Every scenario of the tuning set runs with the named scenario's [estimator] settings
    (the population and the Ms check are built on its device); a shipped primary changes nothing."""
    import pathlib

    from ebraille_sim.analysis.robust import standard_scenarios, with_estimator
    from ebraille_sim.commands.tune import _scenarios
    from ebraille_sim.scenarios.spec import load_scenario
    fast = load_scenario(str(pathlib.Path(__file__).resolve().parent / "data" / "setpoint_steps_fast.toml"))
    est = fast.device.estimator
    assert (est.model, est.antialias_cutoff_hz) == ("paper:wiener:5@1000", 50.0)
    for arg in ("standard", "steady_120wpm,contact_onset_unramped", "single"):
        scen = _scenarios(arg, fast, None)
        assert all(sc.spec.device.estimator == est for sc in scen), arg
    names = [sc.name for sc in standard_scenarios(fast)]
    assert names == ["setpoint_steps", "setpoint_steps_unramped", "steady_90wpm", "contact_onset", "strap_slip"]
    steady = [sc for sc in standard_scenarios(fast) if sc.name == "steady_90wpm"][0]
    assert steady.duration_s == 12.0
    assert steady.spec.reading == load_scenario("steady_90wpm").reading
    shipped = load_scenario("setpoint_steps")
    for sc in standard_scenarios(shipped)[2:]:
        assert sc.spec == load_scenario(sc.name), sc.name
    assert with_estimator(shipped, shipped.device.estimator) is shipped


def _nk0(device):
    return dataclasses.replace(device, estimator=dataclasses.replace(device.estimator, model="paper:wiener:5:nk0"))


def test_the_ms_check_covers_both_readings_of_the_papers_delay():
    """Every device with a paper estimator at its own rate is linearised with nk = 0 and nk = 1; on
    a population built on the literal reading (nk = 0) the check still sees MATLAB's reading,
    where the default PID's Ms is far higher (3.5 against 2.1 on the nominal reader at 1 N)."""
    from ebraille_sim.analysis.robust import linearisation_points, point_labels, population_ms
    pop = [("nominal", _nk0(DeviceParams()))]
    pts = linearisation_points(pop, [0.6, 1.0])
    assert [(p.nk, p.force_n) for p in pts] == [(0, 0.6), (0, 1.0), (1, 0.6), (1, 1.0)]
    assert point_labels(pts, 2) == ["nominal, nk 0", "nominal, nk 1"]
    ms = population_ms(DEFAULT_PID, pts)
    alone = population_ms(DEFAULT_PID, linearisation_points(pop, [0.6, 1.0], delays=False))
    np.testing.assert_allclose(alone, ms[:2], rtol=1e-12)
    assert 1.9 < ms[1] < 2.2 and 3.3 < ms[3] < 3.8 and np.max(ms) > 1.5 * np.max(alone)
    # the 1 kHz estimator is re-discretised without a delay: nothing to choose, one reading
    fast = dataclasses.replace(DeviceParams(), estimator=dataclasses.replace(DeviceParams().estimator,
                                                                             model="paper:wiener:5@1000"))
    assert [p.nk for p in linearisation_points([("fast", fast)], [1.0])] == [None]


@pytest.mark.slow
def test_robust_tuning_meets_the_bound_under_both_readings_of_the_delay():
    """Tuned on a device whose estimator reads the paper literally (nk = 0), the gains still meet
    Ms <= 1.6 with MATLAB's reading (nk = 1), the one that binds; checked on nk = 0 alone
    the same search would accept gains that exceed it there (the default gains, scaled to the
    bound on nk = 0 alone, reach Ms > 2 with nk = 1)."""
    from ebraille_sim.analysis.robust import (TuneScenario, _scaled_to_bound, family_config, linearisation_points,
                                              population_ms, robust_tune)
    from ebraille_sim.scenarios.spec import load_scenario
    spec = load_scenario("contact_onset")
    spec = dataclasses.replace(spec, device=_nk0(spec.device))
    pop = [("nominal", _nk0(DeviceParams()))]
    res = robust_tune(spec, pop, family="pid", ms_max=1.6, max_evaluations=4,
                      scenarios=[TuneScenario(spec.name, spec, 2.5)])
    assert res.delays == [0, 1] and res.ms_labels == ["nominal, nk 0", "nominal, nk 1"]
    forces = res.forces_n
    only1 = [p for p in linearisation_points(pop, forces) if p.nk == 1]
    assert np.max(population_ms(res.tuned.config, only1)) <= 1.6 + 1e-9
    only0 = linearisation_points(pop, forces, delays=False)
    cfg0, _ = _scaled_to_bound((2.0, 8.0, 0.0), lambda *g: family_config("pid", *g), only0, 1.6, 1.0)
    assert np.max(population_ms(cfg0, only1)) > 2.0


def test_tune_reports_the_margins_under_both_readings_of_the_delay():
    from ebraille_sim.commands.tune import _delay_margins
    rows = _delay_margins({"default PID": lambda f: DEFAULT_PID}, DeviceParams(), [1.0])
    pm = {r["nk"]: r["phase_margin_deg"] for r in rows}
    assert set(pm) == {0, 1} and abs(pm[1] - 33.9) < 0.5 and abs(pm[0] - 57.0) < 0.5
    fast = dataclasses.replace(DeviceParams(), estimator=dataclasses.replace(DeviceParams().estimator,
                                                                             model="paper:wiener:5@1000"))
    assert _delay_margins({"default PID": lambda f: DEFAULT_PID}, fast, [1.0]) == []
