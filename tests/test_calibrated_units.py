"""Every scenario unit is calibrated at assembly unless the file asks for a miscalibrated one."""
import dataclasses
import warnings

import numpy as np
import pytest

from ebraille_sim.estimation.calibration import DEFAULT_FORCES_N, DEFAULT_HOLDS_S, steady_estimate
from ebraille_sim.estimation.registry import cached_model
from ebraille_sim.physics.params import CircuitParams
from ebraille_sim.scenarios.runner import run_scenario
from ebraille_sim.scenarios.spec import ScenarioError, ScenarioWarning, parse_scenario
from ebraille_sim.tools.sweep import plan_sweep


def _scenario(fsr="high_k", **device):
    return parse_scenario({"name": f"steady_{fsr}", "seed": 1, "duration_s": 7.0, "reading": {"wpm": 90},
                           "device": {"fsr": fsr, **device}}, source="inline")


def _held_force(spec):
    """Mean true and estimated force over the reading after the onset (t > 4 s), N."""
    tr = run_scenario(spec).trace
    w = tr["t_s"] > 4.0
    return float(np.mean(tr["force_true_n"][w])), float(np.mean(tr["force_est_n"][w]))


def _bench_errors(dev, circuit):
    """Relative errors of the steady estimate at the bench's known loads and holds."""
    model = cached_model(dev.estimator.model)
    return np.array([(steady_estimate(model, f, dev.fsr, circuit, h) - f) / f
                     for f in DEFAULT_FORCES_N for h in DEFAULT_HOLDS_S])


@pytest.mark.parametrize("fsr", ["nominal", "low_k", "high_k"])
def test_every_preset_reads_the_bench_loads_as_the_nominal_unit_does(fsr):
    dev = _scenario(fsr).device
    err = _bench_errors(dev, dev.circuit)
    # the film's creep and the units' curves leave a spread over the loads and holds that the
    # one-point trim at 1 N does not fit (nominal 6.0 % RMS, 14.7 % at most; low_k 7.3 %, 17.3 %;
    # the calibration table corrects the loads, test_drawn_units_read_the_reading_range_through_their_calibration_table)
    assert np.sqrt(np.mean(err ** 2)) < 0.08 and np.max(np.abs(err)) < 0.18
    if fsr != "nominal":                                           # the nominal unit's divider is wrong for it
        assert np.mean(np.abs(_bench_errors(dev, CircuitParams()))) > 0.15
    else:                                   # trimmed to read 1 N at 1 N held 20 s; the shipped R2 is the
        model = cached_model(dev.estimator.model)        # least-squares fit over the grid, 2.2 % lower
        assert steady_estimate(model, 1.0, dev.fsr, dev.circuit, 20.0) == pytest.approx(1.0, abs=1e-6)
        assert dev.circuit.r2_ohm == pytest.approx(CircuitParams().r2_ohm, rel=0.03)


def test_a_high_k_unit_holds_the_force_as_the_nominal_unit_does():
    true_hk, est_hk = _held_force(_scenario("high_k"))
    true_nom, _ = _held_force(_scenario("nominal"))
    assert est_hk == pytest.approx(1.0, abs=0.01)
    assert true_hk == pytest.approx(true_nom, abs=0.02)          # the calibration tolerance of the nominal unit
    assert abs(true_hk - 1.0) < 0.1                                # in the 10 % band
    true_raw, est_raw = _held_force(_scenario("high_k", calibrate=False))
    assert true_raw / est_raw > 1.25 and abs(est_raw - 1.0) < 0.1    # the uncalibrated unit reads ~30 % low


def test_a_given_r2_needs_calibrate_false():
    with pytest.raises(ScenarioError, match=r"r2_ohm is set by the bench calibration; set \[device\] calibrate"):
        _scenario(circuit_overrides={"r2_ohm": 2000.0})
    spec = _scenario(calibrate=False, circuit_overrides={"r2_ohm": 2000.0})
    assert spec.device.circuit.r2_ohm == 2000.0 and spec.calibrated is False


def test_a_unit_no_divider_calibrates_gets_the_end_of_the_range_with_a_warning():
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        spec = _scenario("nominal", fsr_overrides={"resistance_at_1n_ohm": 5e6})
    assert spec.device.circuit.r2_ohm == pytest.approx(50000.0, rel=0.05)
    msgs = [str(w.message) for w in caught if w.category is ScenarioWarning]
    assert len(msgs) == 1 and "the end of the range, and the unit reads off" in msgs[0]


def test_drawn_units_follow_the_scenario_calibration():
    cal = plan_sweep([_scenario("high_k")], readers=3, seed=5)
    raw = plan_sweep([_scenario("high_k", calibrate=False)], readers=3, seed=5)
    r_cal = [d.circuit.r2_ohm for d in cal.devices["steady_high_k"]]
    r_raw = [d.circuit.r2_ohm for d in raw.devices["steady_high_k"]]
    assert len(set(r_cal)) == 3 and all(r != CircuitParams().r2_ohm for r in r_cal)
    assert r_raw == [CircuitParams().r2_ohm] * 3
    assert [d.fsr for d in cal.devices["steady_high_k"]] == [d.fsr for d in raw.devices["steady_high_k"]]


def test_drawn_units_read_the_reading_range_through_their_calibration_table():
    """Each drawn unit's bench stores its table (0.5, 1, 1.5, 2 N, five presses each), its creep
    and its loop; through the table the steady reading of a press held 20 s is within 5 % of the force
    from 0.5 to 2 N on every one of 20 units (the loads' 2 % and the mean scatter of five presses
    remain),
    where the divider's one-point calibration leaves units 6 % and more off at 0.5 or 2 N (the
    units whose exponent is far from the model's).  The table changes no other draw: the divider's
    R2 and the units are the same."""
    import dataclasses
    from ebraille_sim.estimation.firmware import table_calibrated_n
    from ebraille_sim.scenarios.population import PopulationSpec, sample_devices
    with_table = sample_devices(23, 20)
    without = sample_devices(23, 20, PopulationSpec(calibration_table=False))
    assert [d.circuit for d in with_table] == [d.circuit for d in without]
    assert [d.fsr for d in with_table] == [d.fsr for d in without]
    forces = (0.5, 0.75, 1.0, 1.25, 1.5, 2.0)
    worst_table = worst_one_point = 0.0
    for d in with_table:
        e = d.estimator
        assert e.calibration_loads_n == (0.5, 1.0, 1.5, 2.0) and 0.0 < e.creep_per_decade < 0.1
        table = np.array(e.calibration_readings_n + e.calibration_loads_n)
        model = cached_model(e.model)
        quiet = dataclasses.replace(d.fsr, press_repeatability=0.0)
        for f in forces:
            raw = steady_estimate(model, f, quiet, d.circuit, 20.0)
            worst_table = max(worst_table, abs(table_calibrated_n(raw, table, 0, 4, 4) / f - 1.0))
            worst_one_point = max(worst_one_point, abs(raw / f - 1.0))
    assert worst_table < 0.05 and worst_one_point > 0.06


def test_a_scenario_unit_carries_its_bench_table_and_a_given_loop_stays_as_given():
    """Calibrated (the default), a scenario's unit stores its bench's table at 0.5-2 N, its creep
    and its loop; an ``[estimator] hysteresis_fraction`` the file gives is kept, the rest of the
    bench's fields are still measured; ``calibrate = false`` stores nothing."""
    dev = _scenario("nominal").device
    assert dev.estimator.calibration_loads_n == (0.5, 1.0, 1.5, 2.0)
    assert dev.estimator.calibration_readings_n[1] == 1.0            # anchored at the divider's 1 N
    assert dev.estimator.creep_per_decade is not None and dev.estimator.hysteresis_fraction is not None
    given = parse_scenario({"name": "x", "estimator": {"hysteresis_fraction": 0.05}}, source="inline").device
    assert given.estimator.hysteresis_fraction == 0.05
    assert given.estimator.calibration_loads_n == dev.estimator.calibration_loads_n
    raw = _scenario("nominal", calibrate=False).device
    assert raw.estimator.calibration_loads_n == () and raw.estimator.hysteresis_fraction is None


def test_a_scenario_units_bench_is_made_once_and_equals_a_fresh_bench():
    from ebraille_sim.estimation.calibration import calibrate_device, with_calibration_table
    from ebraille_sim.physics.params import unit_estimator
    from ebraille_sim.scenarios.spec import load_scenario
    a, b = load_scenario("steady_90wpm").device, load_scenario("steady_90wpm").device
    assert a.estimator is b.estimator                               # the stored bench, not a new one
    raw = load_scenario("steady_90wpm").device
    fresh = with_calibration_table(calibrate_device(dataclasses.replace(raw, estimator=unit_estimator(raw.estimator))))
    assert fresh == a
