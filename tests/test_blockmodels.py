"""Tests of ebraille_sim.estimation.blockmodels."""

import json
import math

import numpy as np
import pytest

from ebraille_sim.estimation.blockmodels import BlockModel, LinearBF, PiecewiseLinear, fitness


# ---------------------------------------------------------------------------
# PiecewiseLinear
# ---------------------------------------------------------------------------
@pytest.fixture
def pl():
    # segments: slope 2 on [0, 1], slope 0.5 on [1, 3]
    return PiecewiseLinear((0.0, 1.0, 3.0), (0.0, 2.0, 3.0))


def test_piecewise_interpolation_by_hand(pl):
    assert pl(0.5) == pytest.approx(1.0)
    assert pl(1.0) == pytest.approx(2.0)
    assert pl(2.0) == pytest.approx(2.5)
    assert pl(3.0) == pytest.approx(3.0)


def test_piecewise_linear_extrapolation_by_hand(pl):
    assert pl(-1.0) == pytest.approx(-2.0)  # 0 + 2 * (-1 - 0)
    assert pl(5.0) == pytest.approx(4.0)  # 3 + 0.5 * (5 - 3)


def test_piecewise_vectorised_shape(pl):
    x = np.array([[-1.0, 0.5], [2.0, 5.0]])
    y = pl(x)
    assert isinstance(y, np.ndarray) and y.shape == (2, 2)
    np.testing.assert_allclose(y, [[-2.0, 1.0], [2.5, 4.0]])
    assert isinstance(pl(0.5), float)


def test_piecewise_slope_at(pl):
    np.testing.assert_allclose(pl.slope_at([-5.0, 0.5, 1.0, 2.0, 3.0, 9.0]), [2, 2, 0.5, 0.5, 0.5, 0.5])


def test_piecewise_inverse_increasing(pl):
    np.testing.assert_allclose(pl.inverse([-2.0, 1.0, 2.5, 4.0]), [-1.0, 0.5, 2.0, 5.0])


def test_piecewise_inverse_decreasing():
    dec = PiecewiseLinear((-0.2, 0.0), (2.0, 0.0))  # slope -10
    assert dec.inverse(1.0) == pytest.approx(-0.1)
    assert dec.inverse(3.0) == pytest.approx(-0.3)  # extrapolated
    x = np.linspace(-1.0, 1.0, 11)
    np.testing.assert_allclose(dec.inverse(dec(x)), x, atol=1e-12)


def test_piecewise_inverse_rejects_non_monotone():
    with pytest.raises(ValueError, match="monotone"):
        PiecewiseLinear((0.0, 1.0, 2.0), (0.0, 1.0, 0.0)).inverse(0.5)
    with pytest.raises(ValueError, match="monotone"):
        PiecewiseLinear((0.0, 1.0, 2.0), (0.0, 1.0, 1.0)).inverse(0.5)


@pytest.mark.parametrize(
    "x, y, match",
    [
        ((0.0, 1.0), (0.0,), "differ in length"),
        ((0.0,), (0.0,), "at least 2"),
        ((0.0, 0.0), (0.0, 1.0), "strictly increasing"),
        ((1.0, 0.0), (0.0, 1.0), "strictly increasing"),
        ((0.0, math.nan), (0.0, 1.0), "finite"),
        ((0.0, 1.0), (0.0, math.inf), "finite"),
        ((0.0, "a"), (0.0, 1.0), "real numbers"),
    ],
)
def test_piecewise_validation_one_line(x, y, match):
    with pytest.raises(ValueError, match=match) as info:
        PiecewiseLinear(x, y)
    assert "\n" not in str(info.value)


def test_piecewise_is_frozen(pl):
    with pytest.raises(Exception):
        pl.x_bp = (0.0, 1.0)


# ---------------------------------------------------------------------------
# LinearBF
# ---------------------------------------------------------------------------
@pytest.fixture
def lin():
    # x[n] = 0.5 u[n-1] + 0.25 u[n-2] + 0.5 x[n-1] - 0.1 x[n-2]
    return LinearBF(b=(0.5, 0.25), f=(-0.5, 0.1), nk=1)


def test_linear_coefficient_arrays(lin):
    assert lin.numerator().tolist() == [0.0, 0.5, 0.25]
    assert lin.denominator().tolist() == [1.0, -0.5, 0.1]
    assert lin.order == 2


def test_linear_impulse_response_by_hand(lin):
    y, _ = lin.simulate([1.0, 0.0, 0.0, 0.0, 0.0])
    # y0 = 0; y1 = 0.5; y2 = 0.25 + 0.5*0.5 = 0.5; y3 = 0.5*0.5 - 0.1*0.5 = 0.2;
    # y4 = 0.5*0.2 - 0.1*0.5 = 0.05
    np.testing.assert_allclose(y, [0.0, 0.5, 0.5, 0.2, 0.05], atol=1e-15)


def test_linear_step_response_by_hand(lin):
    y, _ = lin.simulate(np.ones(4))
    # y1 = 0.5; y2 = 0.75 + 0.25 = 1.0; y3 = 0.75 + 0.5 - 0.05 = 1.2
    np.testing.assert_allclose(y, [0.0, 0.5, 1.0, 1.2], atol=1e-15)


def test_linear_poles_zeros_gain(lin):
    p = lin.poles()
    np.testing.assert_allclose(np.abs(p), [math.sqrt(0.1)] * 2)
    np.testing.assert_allclose(sorted(p.imag), [-math.sqrt(0.0375), math.sqrt(0.0375)])
    np.testing.assert_allclose(lin.zeros(), [-0.5])
    assert lin.dc_gain() == pytest.approx(0.75 / 0.6)
    assert lin.steady_state_gain() == pytest.approx(0.75 / 0.6)
    assert lin.is_stable()
    assert not lin.has_unit_pole()


def test_linear_instability_and_integrator():
    assert not LinearBF(b=(1.0,), f=(-1.5,)).is_stable()
    integ = LinearBF(b=(1.0,), f=(-1.0,))
    assert integ.has_unit_pole()
    assert integ.dc_gain() == math.inf
    assert LinearBF(b=(-1.0,), f=(-1.0,)).dc_gain() == -math.inf
    assert not integ.is_stable()


def test_linear_dc_gain_zero_over_zero_raises():
    with pytest.raises(ValueError, match="0/0"):
        LinearBF(b=(1.0, -1.0), f=(-1.0,)).dc_gain()


def test_linear_validation():
    with pytest.raises(ValueError, match="nk"):
        LinearBF(b=(1.0,), nk=-1)
    with pytest.raises(ValueError, match="nk"):
        LinearBF(b=(1.0,), nk=1.5)
    with pytest.raises(ValueError, match="at least 1"):
        LinearBF(b=())
    with pytest.raises(ValueError, match="finite"):
        LinearBF(b=(1.0,), f=(math.nan,))


def test_cancel_unit_root_exact_quotient():
    # B = (2 - z^-1)(1 - z^-1), F = (1 - 0.5 z^-1)(1 - z^-1)
    lin = LinearBF(b=(2.0, -3.0, 1.0), f=(-1.5, 0.5), nk=2)
    assert lin.has_common_unit_root()
    red = lin.cancel_unit_root()
    assert red.b == (2.0, -1.0)
    assert red.f == (-0.5,)
    assert red.nk == 2
    np.testing.assert_allclose(red.poles(), [0.5])
    # the pole set loses exactly the pole at z = 1
    np.testing.assert_allclose(np.sort(lin.poles().real), [0.5, 1.0])


def test_cancel_unit_root_drops_small_remainder():
    lin = LinearBF(b=(2.0, -3.0, 1.0004), f=(-1.5, 0.5))
    assert lin.cancel_unit_root(tol=1e-5) is lin  # remainder too large: unchanged
    red = lin.cancel_unit_root(tol=1e-3)
    np.testing.assert_allclose(red.b, (2.0, -1.0), atol=1e-15)
    np.testing.assert_allclose(red.f, (-0.5,), atol=1e-15)


def test_cancel_unit_root_needs_both_factors():
    integ = LinearBF(b=(1.0, 0.5), f=(-1.0,))
    assert integ.cancel_unit_root(tol=1e-3) is integ


def test_cancelled_model_has_same_response():
    lin = LinearBF(b=(2.0, -3.0, 1.0), f=(-1.5, 0.5), nk=1)
    red = lin.cancel_unit_root()
    rng = np.random.default_rng(1)
    u = rng.standard_normal(300)
    y_full, _ = lin.simulate(u)
    y_red, _ = red.simulate(u)
    np.testing.assert_allclose(y_full, y_red, atol=1e-9)
    assert red.dc_gain() == pytest.approx(1.0 / 0.5)
    assert lin.steady_state_gain() == pytest.approx(2.0)


def test_cancel_unit_roots_repeats():
    # two (1 - z^-1) factors in both B and F (ascending powers of z^-1)
    b = np.convolve([1.0, -2.0, 1.0], [3.0, 1.0])
    f = np.convolve([1.0, -2.0, 1.0], [1.0, -0.25])
    lin = LinearBF(b=tuple(b), f=tuple(f[1:]))
    assert lin.b == (3.0, -5.0, 1.0, 1.0)
    red, count = lin.cancel_unit_roots()
    assert count == 2
    np.testing.assert_allclose(red.b, (3.0, 1.0))
    np.testing.assert_allclose(red.f, (-0.25,))
    once, count1 = lin.cancel_unit_roots(max_count=1)
    assert count1 == 1 and len(once.b) == 3


def test_linear_simulate_state_shape_checked(lin):
    with pytest.raises(ValueError, match="shape"):
        lin.simulate([1.0], zi=[0.0])


def test_normalised():
    lin = LinearBF(b=(-2.0, 4.0, 1.0), f=(-0.3,), nk=1)
    norm, gain = lin.normalised()
    assert gain == 4.0
    assert norm.b == (-0.5, 1.0, 0.25)
    assert norm.f == lin.f and norm.nk == 1
    u = np.random.default_rng(0).standard_normal(50)
    np.testing.assert_allclose(gain * norm.simulate(u)[0], lin.simulate(u)[0], atol=1e-12)
    norm0, gain0 = lin.normalised(index=0)
    assert gain0 == -2.0 and norm0.b[0] == 1.0
    with pytest.raises(ValueError, match="zero"):
        LinearBF(b=(0.0, 1.0)).normalised(index=0)


# ---------------------------------------------------------------------------
# BlockModel
# ---------------------------------------------------------------------------
def _hw_model():
    lin = LinearBF(b=(0.3, -0.1, 0.05), f=(-0.6, 0.08), nk=1)
    inl = PiecewiseLinear((0.0, 0.5, 1.2), (0.0, 0.4, 1.5))
    onl = PiecewiseLinear((-0.2, 0.3, 1.0, 2.0), (0.1, 0.5, 2.0, 2.2))
    return BlockModel(lin, inl, onl, dt_s=0.01, name="test hw")


def test_block_model_kinds():
    lin = LinearBF(b=(1.0,))
    nl = PiecewiseLinear.identity()
    assert BlockModel(lin, None, None, 0.01).kind == "linear"
    assert BlockModel(lin, nl, None, 0.01).kind == "hammerstein"
    assert BlockModel(lin, None, nl, 0.01).kind == "wiener"
    assert BlockModel(lin, nl, nl, 0.01).kind == "hammerstein-wiener"


def test_block_model_validation():
    with pytest.raises(ValueError, match="dt_s"):
        BlockModel(LinearBF(b=(1.0,)), None, None, dt_s=0.0)
    with pytest.raises(ValueError, match="linear"):
        BlockModel((1.0,), None, None, dt_s=0.01)
    with pytest.raises(ValueError, match="input_nl"):
        BlockModel(LinearBF(b=(1.0,)), (0, 1), None, dt_s=0.01)


def test_block_model_evaluation_order():
    m = _hw_model()
    u = np.array([0.2, 0.9, 1.4, -0.3, 0.7])
    w = m.input_nl(u)
    x, _ = m.linear.simulate(w)
    np.testing.assert_array_equal(m.simulate(u)[0], m.output_nl(x))


def test_streaming_equals_whole_exactly():
    m = _hw_model()
    u = np.random.default_rng(7).uniform(-0.5, 1.5, 1001)
    y_all, s_all = m.simulate(u)
    y1, s1 = m.simulate(u[:377])
    y2, s2 = m.simulate(u[377:], state=s1)
    np.testing.assert_array_equal(np.concatenate([y1, y2]), y_all)
    np.testing.assert_array_equal(s2, s_all)
    # sample-by-sample streaming as well
    state, ys = None, []
    for v in u[:50]:
        y, state = m.simulate([v], state)
        ys.append(y[0])
    np.testing.assert_array_equal(ys, y_all[:50])


def test_steady_state_and_rest_state():
    m = _hw_model()
    g = 0.25 / 0.48
    assert m.linear.steady_state_gain() == pytest.approx(g)
    for u0 in (0.0, 0.3, 1.0, 1.6):
        expected = m.output_nl(g * m.input_nl(u0))
        assert m.steady_state(u0) == pytest.approx(expected)
        y, _ = m.simulate(np.full(20, u0), state=m.rest_state(u0))
        np.testing.assert_allclose(y, expected, atol=1e-12)
    np.testing.assert_allclose(m.steady_state(np.array([0.0, 1.0])), [m.steady_state(0.0), m.steady_state(1.0)])


def test_steady_state_of_integrator_raises():
    m = BlockModel(LinearBF(b=(1.0,), f=(-1.0,)), None, None, 0.01)
    with pytest.raises(ValueError, match="integrates"):
        m.steady_state(1.0)


def test_json_round_trip_exact(tmp_path):
    lin = LinearBF(b=(0.1 + 0.2, 1.0 / 3.0, -1e-17), f=(-0.7, 2.0 / 7.0), nk=3)
    inl = PiecewiseLinear((0.1, 0.7, 1.3), (math.pi, math.e, 1.0 / 9.0))
    m = BlockModel(lin, inl, None, dt_s=0.01, name="round trip")
    d = m.to_dict()
    assert d["kind"] == "hammerstein" and d["nk"] == 3 and d["dt_s"] == 0.01
    assert json.loads(json.dumps(d)) == d
    assert BlockModel.from_dict(json.loads(json.dumps(d))) == m
    path = tmp_path / "model.json"
    m.save(path)
    assert BlockModel.load(path) == m
    m2 = _hw_model()
    m2.save(path)
    assert BlockModel.load(path) == m2


def test_load_errors_are_one_line(tmp_path):
    with pytest.raises(FileNotFoundError, match="not found") as info:
        BlockModel.load(tmp_path / "missing.json")
    assert "\n" not in str(info.value)
    bad = tmp_path / "bad.json"
    bad.write_text("{not json", encoding="utf-8")
    with pytest.raises(ValueError, match="is not valid JSON") as info:
        BlockModel.load(bad)
    assert "\n" not in str(info.value)
    d = _hw_model().to_dict()
    d["gain"] = 2.0
    bad.write_text(json.dumps(d), encoding="utf-8")
    with pytest.raises(ValueError, match="unknown key.*gain") as info:
        BlockModel.load(bad)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize(
    "mutate, match",
    [
        (lambda d: d.pop("b"), "missing key.*b"),
        (lambda d: d.update(kind="wiener"), "disagrees"),
        (lambda d: d.update(format="other"), "format"),
        (lambda d: d.update(version=99), "version"),
        (lambda d: d["output_nl"].update(extra=1), "unknown key.*output_nl"),
        (lambda d: d["input_nl"].update(x_bp=[1.0, 0.0, 2.0]), "input_nl.*strictly increasing"),
        (lambda d: d.update(nk=-1), "nk"),
    ],
)
def test_from_dict_rejects(mutate, match):
    d = _hw_model().to_dict()
    mutate(d)
    with pytest.raises(ValueError, match=match):
        BlockModel.from_dict(d)


def test_kernel_arrays_layout():
    m = _hw_model()
    k = m.kernel_arrays()
    assert k["order"] == 3
    assert k["num"].tolist() == [0.0, 0.3, -0.1, 0.05]
    assert k["den"].tolist() == [1.0, -0.6, 0.08, 0.0]
    for key in ("num", "den", "in_x", "in_y", "out_x", "out_y"):
        assert k[key].dtype == np.float64
    assert k["in_x"].tolist() == [0.0, 0.5, 1.2]
    assert k["out_y"].tolist() == [0.1, 0.5, 2.0, 2.2]
    lin_only = BlockModel(LinearBF(b=(1.0,), f=(-0.5, 0.1, 0.2)), None, None, 0.01).kernel_arrays()
    assert lin_only["num"].tolist() == [1.0, 0.0, 0.0, 0.0]
    assert lin_only["in_x"].tolist() == [-1.0, 1.0] and lin_only["out_y"].tolist() == [-1.0, 1.0]


def _reference_kernel(k, u):
    """Plain per-sample evaluator written from the documented order."""

    def pwl(xb, yb, v):
        n = len(xb)
        i = 0
        while i < n - 2 and v >= xb[i + 1]:
            i += 1
        return yb[i] + (yb[i + 1] - yb[i]) * (v - xb[i]) / (xb[i + 1] - xb[i])

    num, den, order = k["num"], k["den"], k["order"]
    z = np.zeros(order)
    out = []
    for v in u:
        w = pwl(k["in_x"], k["in_y"], v)
        x = num[0] * w + (z[0] if order else 0.0)
        for i in range(order - 1):
            z[i] = num[i + 1] * w - den[i + 1] * x + z[i + 1]
        if order:
            z[order - 1] = num[order] * w - den[order] * x
        out.append(pwl(k["out_x"], k["out_y"], x))
    return np.array(out)


@pytest.mark.parametrize("with_nl", [True, False])
def test_kernel_arrays_reproduce_simulate(with_nl):
    m = _hw_model()
    if not with_nl:
        m = BlockModel(m.linear, None, None, m.dt_s)
    u = np.random.default_rng(3).uniform(-0.6, 1.8, 200)
    np.testing.assert_allclose(_reference_kernel(m.kernel_arrays(), u), m.simulate(u)[0], rtol=0, atol=1e-12)


# ---------------------------------------------------------------------------
# fitness
# ---------------------------------------------------------------------------
def test_fitness_values():
    y = np.array([0.0, 1.0, 2.0, 5.0])
    assert fitness(y, y) == 100.0
    assert fitness(y, np.full_like(y, y.mean())) == pytest.approx(0.0, abs=1e-12)
    # ||err|| = 1, ||y - mean|| = sqrt(2)
    assert fitness([0.0, 1.0, 2.0], [0.0, 1.0, 1.0]) == pytest.approx((1 - 1 / math.sqrt(2)) * 100)
    assert fitness([0.0, 1.0, 2.0], [2.0, 1.0, 0.0]) == pytest.approx(-100.0)


def test_fitness_errors():
    with pytest.raises(ValueError, match="shape"):
        fitness([1.0, 2.0], [1.0])
    with pytest.raises(ValueError, match="constant"):
        fitness([1.0, 1.0], [1.0, 2.0])


# ---------------------------------------------------------------------------
# BlockModel.to_control
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("linear", [
    LinearBF(b=(-0.529, 0.471, -0.16, 0.179), f=(0.736, -0.822, -0.646, -0.065), nk=1),  # paper Wiener 5
    LinearBF(b=(0.2, 0.1, -0.05), f=(), nk=2),                                             # FIR, longer numerator
    LinearBF(b=(1.0,), f=(-1.6, 0.8), nk=0),                                               # resonant, no delay
])
def test_to_control_is_the_linear_block_of_the_model(linear):
    control = pytest.importorskip("control")
    model = BlockModel(linear, PiecewiseLinear((0.0, 1.0), (0.0, 2.0)), None, dt_s=0.01)
    tf = model.to_control()
    assert isinstance(tf, control.TransferFunction) and tf.dt == 0.01
    u = np.random.default_rng(7).standard_normal(400)
    x, _ = linear.simulate(u)                              # the model's own lfilter of the linear block
    y = control.forced_response(tf, U=u).outputs
    assert np.max(np.abs(y - x)) <= 1e-12 * max(1.0, np.max(np.abs(x)))
    assert control.dcgain(tf) == pytest.approx(linear.dc_gain(), rel=1e-12)
    # poles of the transfer function: those of F plus the ones at the origin from the padding
    p = np.sort_complex(tf.poles())
    expected = np.concatenate([linear.poles(), np.zeros(linear.order - len(linear.f))])
    np.testing.assert_allclose(p, np.sort_complex(expected), atol=1e-9)


def test_to_control_of_the_paper_model():
    control = pytest.importorskip("control")
    from ebraille_sim.estimation.registry import load_estimator
    m = load_estimator("paper:wiener:5")
    tf = m.to_control()
    u = np.random.default_rng(3).uniform(0.0, 1.2, 1000)          # detrended divider volts
    x, _ = m.linear.simulate(u)
    y = control.forced_response(tf, U=u).outputs
    assert tf.dt == m.dt_s == 0.01
    assert np.max(np.abs(y - x)) <= 1e-12 * np.max(np.abs(x))
    assert np.allclose(m.output_nl(y), m.simulate(u)[0], rtol=0, atol=1e-12)
