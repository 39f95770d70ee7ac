"""Tests of ebraille_sim.estimation.paper_models (the published FSR estimators)."""

import math

import numpy as np
import pytest

from ebraille_sim.estimation.blockmodels import BlockModel
from ebraille_sim.estimation.paper_models import (
    DEFAULT_ESTIMATOR,
    INPUT_RANGE_V,
    KINDS,
    NK,
    ORDERS,
    SAMPLE_TIME_S,
    TRANSCRIPTION_DECISIONS,
    paper_model,
    paper_model_table,
)

ALL_KEYS = [(k, o) for k in KINDS for o in ORDERS]

W5_B = (-0.529, 1.0, -0.631, 0.339, -0.179)
W5_F = (-0.264, -1.558, 0.176, 0.581, 0.065)
W5_OUT_X = (-0.229, -0.149, -0.092, 0.000)
W5_OUT_Y = (2.834, 1.496, 0.843, 0.063)


@pytest.mark.parametrize("kind, order", ALL_KEYS)
def test_all_models_load(kind, order):
    for cancel in (True, False):
        m = paper_model(kind, order, cancel_unit_root=cancel)
        assert isinstance(m, BlockModel)
        assert m.kind == kind
        assert m.dt_s == SAMPLE_TIME_S == 0.01
        assert m.linear.nk == NK == 1
    raw = paper_model(kind, order, cancel_unit_root=False).linear
    assert len(raw.b) == order and len(raw.f) == order


@pytest.mark.parametrize("kind, order", [(k, o) for k, o in ALL_KEYS if k != "linear"])
def test_fixed_b1_read_as_plus_one(kind, order):
    assert paper_model(kind, order, cancel_unit_root=False).linear.b[1] == 1.0


@pytest.mark.parametrize("kind, order", [(k, o) for k, o in ALL_KEYS if k != "linear"])
def test_nonlinearities_strictly_monotone(kind, order):
    m = paper_model(kind, order)
    if m.input_nl is not None:
        assert m.input_nl.monotonicity() != 0
        assert len(m.input_nl.x_bp) == 4
    if m.output_nl is not None:
        assert m.output_nl.monotonicity() == -1
        assert len(m.output_nl.x_bp) == 4


def test_default_estimator():
    assert DEFAULT_ESTIMATOR == ("wiener", 5)


def test_wiener5_printed_coefficients():
    raw = paper_model("wiener", 5, cancel_unit_root=False)
    assert raw.linear.b == W5_B
    assert raw.linear.f == W5_F
    assert raw.output_nl.x_bp == W5_OUT_X
    assert raw.output_nl.y_bp == W5_OUT_Y
    assert raw.input_nl is None
    b1, f1 = raw.linear.unit_root_residuals()
    assert abs(b1) < 1e-12 and abs(f1) < 1e-12
    assert raw.linear.has_common_unit_root()


def test_wiener5_cancelled_poles_gain_stability():
    m = paper_model("wiener", 5)
    lin = m.linear
    assert len(lin.b) == 4 and len(lin.f) == 4
    poles = lin.poles()
    np.testing.assert_allclose(np.abs(poles.imag), 0.0, atol=1e-9)
    np.testing.assert_allclose(np.sort(poles.real), np.sort([0.942, -0.967, -0.590, -0.121]), atol=1e-3)
    assert lin.is_stable()
    assert not lin.has_unit_pole(5e-3)
    assert lin.dc_gain() == pytest.approx(-0.192, abs=1e-3)
    # the cancellation removes exactly the pole at z = 1
    raw_poles = paper_model("wiener", 5, cancel_unit_root=False).linear.poles()
    assert np.min(np.abs(raw_poles - 1.0)) < 1e-6
    np.testing.assert_allclose(np.sort_complex(raw_poles[np.abs(raw_poles - 1.0) > 1e-6]), np.sort_complex(poles), atol=1e-9)


def test_wiener5_steady_state_map_hits_breakpoints():
    m = paper_model("wiener", 5)
    g = m.linear.steady_state_gain()
    volts = np.array([0.0, 0.479, 0.776, 1.193])
    # linear output lands on the output breakpoints (reversed order)
    np.testing.assert_allclose(g * volts, W5_OUT_X[::-1], atol=1e-3)
    np.testing.assert_allclose(m.steady_state(volts), W5_OUT_Y[::-1], atol=0.01)
    assert m.steady_state(1.193) == pytest.approx(2.834, abs=0.01)


def test_wiener5_simulation_settles_to_steady_state():
    m = paper_model("wiener", 5)
    y, _ = m.simulate(np.full(3000, 0.776))
    assert y[-1] == pytest.approx(m.steady_state(0.776), abs=1e-6)
    # the as-printed model (pole-zero pair at z = 1) ends at the same level here
    y_raw, _ = paper_model("wiener", 5, cancel_unit_root=False).simulate(np.full(3000, 0.776))
    assert y_raw[-1] == pytest.approx(y[-1], abs=1e-3)


def test_table_rows_and_flags():
    table = paper_model_table()
    assert len(table) == 16
    assert [(r["kind"], r["order"]) for r in table] == ALL_KEYS
    for r in table:
        assert r["usable"] is True, r
        assert r["stable"] and r["max_abs_pole"] < 1.0
        assert math.isfinite(r["dc_gain"])
        assert r["max_abs_pole"] == pytest.approx(max(abs(p) for p in r["poles"]))
        assert isinstance(r["reason"], str) and "\n" not in r["reason"]
    by_key = {(r["kind"], r["order"]): r for r in table}
    # orders 2 Wiener / Hammerstein-Wiener carry no unit root; order 4 H-W carries two
    no_root = {("wiener", 2), ("hammerstein-wiener", 2)}
    for key, r in by_key.items():
        expected = 0 if key in no_root else (2 if key == ("hammerstein-wiener", 4) else 1)
        assert r["unit_roots_cancelled"] == expected, key
        assert r["unit_root_cancelled"] == (expected > 0)
    w5 = by_key[("wiener", 5)]
    assert w5["dc_gain"] == pytest.approx(-0.192, abs=1e-3)
    assert w5["max_abs_pole"] == pytest.approx(0.967, abs=1e-3)


def test_table_flags_unusable_models_when_not_cancelled():
    table = paper_model_table(cancel_unit_root=False)
    usable = {(r["kind"], r["order"]) for r in table if r["usable"]}
    assert usable == {("wiener", 2), ("hammerstein-wiener", 2)}
    for r in table:
        if not r["usable"]:
            assert "z = 1" in r["reason"]
            assert not math.isfinite(r["dc_gain"])


@pytest.mark.parametrize("kind, order", ALL_KEYS)
def test_static_force_rises_with_voltage(kind, order):
    m = paper_model(kind, order)
    volts = np.linspace(*INPUT_RANGE_V, 25)
    force = m.steady_state(volts)
    assert np.all(np.diff(force) > 0)
    assert -0.1 < force[0] < 0.7
    assert 1.9 < force[-1] < 3.2


@pytest.mark.parametrize("kind, order", ALL_KEYS)
def test_models_bounded_on_square_wave(kind, order):
    m = paper_model(kind, order)
    t = np.arange(2000) * SAMPLE_TIME_S
    u = np.where(np.sin(2 * np.pi * 0.2 * t) >= 0, 1.0, 0.2)
    y, _ = m.simulate(u, state=m.rest_state(0.2))
    assert np.all(np.isfinite(y))
    assert np.max(np.abs(y)) < 20.0


@pytest.mark.parametrize(
    "kind, order, match",
    [
        ("narx", 5, "allowed: 'linear', 'hammerstein', 'wiener', 'hammerstein-wiener'"),
        ("Wiener", 5, "allowed"),
        ("wiener", 6, "one of 2, 3, 4, 5"),
        ("wiener", 1, "one of 2, 3, 4, 5"),
        ("wiener", 5.0, "one of 2, 3, 4, 5"),
        ("wiener", True, "one of 2, 3, 4, 5"),
    ],
)
def test_bad_kind_or_order(kind, order, match):
    with pytest.raises(ValueError, match=match) as info:
        paper_model(kind, order)
    assert "\n" not in str(info.value)


def test_transcription_decisions_recorded():
    locations = [d.location for d in TRANSCRIPTION_DECISIONS]
    b1_rows = [loc for loc in locations if loc.startswith("Appendix 2") and loc.endswith(", b1")]
    assert len(b1_rows) == 12
    assert all(d.read_as and d.reason and d.printed for d in TRANSCRIPTION_DECISIONS)


def test_the_two_readings_of_the_papers_delay_differ_by_one_sample():
    """The paper prints no nk: nk = 0 (its notation read literally) and nk = 1 (MATLAB's
    convention, the default) give the same model shifted by one 10 ms sample."""
    import numpy as np
    from ebraille_sim.estimation.registry import load_estimator
    m1, m0 = load_estimator("paper:wiener:5"), load_estimator("paper:wiener:5:nk0")
    assert (m1.linear.nk, m0.linear.nk) == (1, 0) and load_estimator("paper:wiener:5:nk1").linear.nk == 1
    u = np.concatenate([np.zeros(5), np.linspace(0.0, 1.0, 200)])
    y1, y0 = m1.simulate(u)[0], m0.simulate(u)[0]
    np.testing.assert_allclose(y1[1:], y0[:-1], atol=1e-12)
    assert abs(y1[100] - y0[100]) > 1e-3
    for bad in ("paper:wiener:5:nk2", "paper:wiener:5:delay"):
        with pytest.raises(ValueError, match="nk0"):
            load_estimator(bad)
    with pytest.raises(ValueError, match="nk must be one of 0, 1"):
        paper_model("wiener", 5, nk=3)


def test_the_delay_of_an_estimator_name_is_chosen_in_one_place():
    from ebraille_sim.estimation.registry import delay_of, delay_readings, load_estimator, with_delay
    assert delay_of("paper:wiener:5") == 1 and delay_of("paper:hammerstein:3:nk0") == 0
    assert delay_of("paper:wiener:5@1000") is None and delay_of("models/wiener-5.json") is None
    assert delay_readings("paper:wiener:5") == {0: "paper:wiener:5:nk0", 1: "paper:wiener:5:nk1"}
    assert delay_readings("paper:wiener:5:nk0@1000") == {}
    # re-discretised at 1 kHz the block carries no delay: both readings are one model
    a, b = load_estimator("paper:wiener:5:nk0@1000"), load_estimator("paper:wiener:5@1000")
    assert (a.linear.b, a.linear.f, a.linear.nk) == (b.linear.b, b.linear.f, b.linear.nk)
    for bad in (2, -1, 0.5, True, "1"):
        with pytest.raises(ValueError, match="nk must be 0 or 1"):
            with_delay("paper:wiener:5", bad)
    with pytest.raises(ValueError, match="no input delay to choose"):
        with_delay("paper:wiener:5@1000", 0)


@pytest.mark.parametrize("suffix", ["nk2", "nk-1", "nk1.5", "nk", "1"])
def test_a_delay_outside_the_two_readings_is_one_error_line_naming_the_key(tmp_path, capsys, suffix):
    from ebraille_sim.cli import main
    f = tmp_path / "bad.toml"
    f.write_text(f'name = "bad"\n[estimator]\nmodel = "paper:wiener:5:{suffix}"\n')
    assert main(["run", str(f), "--duration", "0.5", "--out", str(tmp_path / "o"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and "[estimator] model" in err[0] and suffix in err[0]
    assert not (tmp_path / "o").exists()


def test_a_firmware_preset_carries_either_reading_and_the_shipped_one_is_matlabs():
    from ebraille_sim.estimation.presets import get_firmware
    from ebraille_sim.estimation.registry import delay_of, load_estimator
    shipped = get_firmware("paper_100hz")
    assert delay_of(shipped.estimator["model"]) == 1 and "nk = 1" in shipped.description
    assert delay_of(get_firmware("fast_1khz").estimator["model"]) is None
    import pathlib
    import tempfile
    with tempfile.TemporaryDirectory() as d:
        p = pathlib.Path(d) / "literal.toml"
        p.write_text('name = "literal"\n[estimator]\nmodel = "paper:wiener:5:nk0"\nantialias_cutoff_hz = 20.0\n')
        fw = get_firmware(str(p))
    assert load_estimator(fw.estimator["model"]).linear.nk == 0
