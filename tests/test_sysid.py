"""Tests of ebraille_sim.identification.sysid: recovery of known block-oriented systems, conventions, errors."""

import math

import numpy as np
import pytest

from ebraille_sim.estimation import blockmodels
from ebraille_sim.estimation import paper_models
from ebraille_sim.identification import sysid
from ebraille_sim.estimation.blockmodels import BlockModel, LinearBF, PiecewiseLinear

# A well-conditioned fifth-order block: poles and zeros apart, every mode excited.
TRUE_POLES = np.array([0.92, 0.7 + 0.5j, 0.7 - 0.5j, -0.5 + 0.3j, -0.5 - 0.3j])
TRUE_F = tuple(np.real(np.poly(TRUE_POLES))[1:])
TRUE_B = (1.0, -0.6, 0.4, -0.2, 0.3)
TRUE_LIN = LinearBF(TRUE_B, TRUE_F, nk=1)


def _input(n, seed):
    """Random levels in 0-1.2 V held 1-5 samples (a broadband excitation)."""
    rng = np.random.default_rng(seed)
    return np.repeat(rng.uniform(0.0, 1.2, n), rng.integers(1, 6, n))[:n]


def _noisy(model, u, seed, rel=0.002):
    y = sysid.simulate(model, u)
    return y + rel * np.std(y) * np.random.default_rng(seed).standard_normal(y.size)


@pytest.fixture(scope="module")
def wiener_truth():
    g = TRUE_LIN.dc_gain()
    out = PiecewiseLinear((0.0, 0.35 * g, 0.7 * g, 1.0 * g), (0.0, 0.6, 1.6, 3.0))
    return BlockModel(TRUE_LIN, None, out, dt_s=0.01)


@pytest.fixture(scope="module")
def hammerstein_truth():
    inl = PiecewiseLinear((0.0, 0.4, 0.8, 1.2), (0.0, 0.3, 1.0, 2.5))
    return BlockModel(TRUE_LIN, inl, None, dt_s=0.01)


@pytest.fixture(scope="module")
def wiener_fit(wiener_truth):
    u = _input(6000, 1)
    return sysid.fit_report("wiener", u, _noisy(wiener_truth, u, 2), 5, seed=3, n_starts=2, max_nk=2)


@pytest.fixture(scope="module")
def hammerstein_fit(hammerstein_truth):
    u = _input(6000, 4)
    return sysid.fit_report("hammerstein", u, _noisy(hammerstein_truth, u, 5), 5, seed=3, n_starts=2, max_nk=2)


# ---------------------------------------------------------------------------
# fitness (eq. 7) and re-exports
# ---------------------------------------------------------------------------
def test_fitness_is_eq7():
    y = np.array([1.0, 2.0, 3.0, 4.0])
    yh = np.array([1.0, 2.0, 3.0, 5.0])
    # ||yh - y|| = 1, ||y - mean|| = sqrt(5)
    assert sysid.fitness(y, yh) == pytest.approx(100.0 * (1.0 - 1.0 / math.sqrt(5.0)), abs=1e-12)
    assert sysid.fitness(y, y) == 100.0
    assert sysid.fitness(y, np.full(4, 2.5)) == pytest.approx(0.0, abs=1e-12)
    assert sysid.fitness(y, -y) < 0.0
    assert sysid.fitness is blockmodels.fitness


def test_paper_models_reexported_and_loadable():
    assert sysid.paper_model is paper_models.paper_model
    for kind in sysid.KINDS:
        for order in sysid.ORDERS:
            m = sysid.paper_model(kind, order)
            assert isinstance(m, BlockModel) and m.kind == kind
            assert sysid.simulate(m, np.linspace(0.0, 1.0, 50)).shape == (50,)


def test_paper_fitness_table_matches_paper_best():
    assert sysid.PAPER_FITNESS["wiener"][5]["chirp"] == 93.46
    assert sysid.PAPER_FITNESS["wiener"][5]["triangle_0.1hz"] == 87.25
    assert sysid.PAPER_FITNESS["linear"][2]["chirp"] == 78.79
    assert sysid.PAPER_FITNESS["hammerstein-wiener"][5]["triangle_0.1hz"] == 75.93


# ---------------------------------------------------------------------------
# recovery of known systems
# ---------------------------------------------------------------------------
def test_wiener_recovery(wiener_truth, wiener_fit):
    m = wiener_fit.model
    u_val = _input(3000, 99)
    assert sysid.fitness(sysid.simulate(wiener_truth, u_val), sysid.simulate(m, u_val)) >= 98.0
    assert sysid.match_poles(m.linear.poles(), TRUE_POLES) <= 0.02
    assert wiener_fit.nk == 1        # searched, not given
    assert m.kind == "wiener" and len(m.output_nl.x_bp) == 4


def test_wiener_recovers_the_static_map(wiener_truth, wiener_fit):
    u = np.linspace(0.05, 1.15, 12)
    np.testing.assert_allclose(wiener_fit.model.steady_state(u), wiener_truth.steady_state(u), atol=0.02)


def test_hammerstein_recovery(hammerstein_truth, hammerstein_fit):
    m = hammerstein_fit.model
    u_val = _input(3000, 98)
    assert sysid.fitness(sysid.simulate(hammerstein_truth, u_val), sysid.simulate(m, u_val)) >= 98.0
    assert sysid.match_poles(m.linear.poles(), TRUE_POLES) <= 0.02
    assert hammerstein_fit.nk == 1
    # input map: the kinks at 0.4 and 0.8 V are found
    np.testing.assert_allclose(m.input_nl.x_bp[1:3], (0.4, 0.8), atol=0.01)


def test_linear_output_error_recovery():
    lin = LinearBF((0.5, 0.3), (-1.2, 0.5), nk=2)
    m0 = BlockModel(lin, None, None, dt_s=0.01)
    u = _input(3000, 7) - 0.6
    m = sysid.fit("linear", u, _noisy(m0, u, 8), 2, seed=0)
    assert m.linear.nk == 2
    np.testing.assert_allclose(m.linear.f, lin.f, atol=0.01)
    np.testing.assert_allclose(m.linear.b, lin.b, atol=0.01)


def test_hammerstein_wiener_fit_reaches_the_noise_floor():
    inl = PiecewiseLinear((0.0, 0.4, 0.8, 1.2), (0.0, 0.3, 1.0, 2.5))
    lin = LinearBF((1.0, -0.5), (-1.1, 0.3), nk=1)
    g = lin.dc_gain()
    out = PiecewiseLinear((0.0, 0.5 * g, 1.5 * g, 2.5 * g), (0.0, 1.0, 1.6, 2.0))
    truth = BlockModel(lin, inl, out, dt_s=0.01)
    u = _input(5000, 11)
    m = sysid.fit("hammerstein-wiener", u, _noisy(truth, u, 12, rel=0.001), 2, seed=1)
    u_val = _input(2000, 13)
    assert sysid.fitness(sysid.simulate(truth, u_val), sysid.simulate(m, u_val)) >= 98.0


# ---------------------------------------------------------------------------
# conventions
# ---------------------------------------------------------------------------
def test_largest_b_coefficient_fixed_at_plus_one(wiener_fit, hammerstein_fit):
    for m in (wiener_fit.model, hammerstein_fit.model):
        b = np.asarray(m.linear.b)
        assert b[np.argmax(np.abs(b))] == 1.0
        assert np.max(np.abs(b)) == 1.0


def test_fix_b_index_keeps_the_transfer_function(wiener_truth):
    u = _input(2000, 21)
    y = sysid.simulate(wiener_truth, u)
    a = sysid.fit("wiener", u, y, 5, nk=1, n_starts=1, seed=0)
    b = sysid.fit("wiener", u, y, 5, nk=1, n_starts=1, seed=0, fix_b=2)
    assert b.linear.b[2] == 1.0
    np.testing.assert_allclose(sysid.simulate(a, u), sysid.simulate(b, u), atol=1e-9)


def test_identified_models_are_stable(wiener_fit, hammerstein_fit):
    for m in (wiener_fit.model, hammerstein_fit.model):
        assert m.linear.is_stable()
        assert np.max(np.abs(m.linear.poles())) < 1.0 - sysid.DEFAULT_MARGIN


def test_same_seed_same_model_exactly(wiener_truth):
    u = _input(1500, 31)
    y = _noisy(wiener_truth, u, 32)
    a = sysid.fit("wiener", u, y, 3, n_starts=3, seed=5, max_nk=1)
    b = sysid.fit("wiener", u, y, 3, n_starts=3, seed=5, max_nk=1)
    assert a.to_dict() == b.to_dict()


def test_model_saves_and_loads_as_in_loop_estimator(tmp_path, wiener_fit):
    from ebraille_sim.estimation.registry import load_estimator
    from ebraille_sim.plant.lumped import pack_params
    from ebraille_sim.physics.params import DeviceParams

    path = tmp_path / "w5.json"
    wiener_fit.model.save(path)
    m = load_estimator(str(path))
    assert m.to_dict() == wiener_fit.model.to_dict()
    p = pack_params(DeviceParams(), 1.0, m)
    assert np.all(np.isfinite(p))


@pytest.mark.parametrize("kind", sysid.KINDS)
def test_shift_operating_point_is_exact(kind):
    m = sysid.paper_model(kind, 5)
    c, d = 0.11, 0.15
    shifted = sysid.shift_operating_point(m, c, d)
    u = 0.5 + 0.3 * np.sin(np.linspace(0.0, 20.0, 400))
    expected = m.simulate(u - c, m.rest_state(-c))[0] + d
    got = shifted.simulate(u, shifted.rest_state(0.0))[0]
    np.testing.assert_allclose(got, expected, atol=1e-12)
    assert shifted.kind == ("wiener" if kind == "linear" else kind)


def test_match_poles_pairs_best():
    assert sysid.match_poles([0.5, 0.9], [0.91, 0.52]) == pytest.approx(0.02)
    with pytest.raises(ValueError, match="size"):
        sysid.match_poles([0.5], [0.5, 0.6])


# ---------------------------------------------------------------------------
# bad input: one-line errors naming the problem
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("args, kwargs, match", [
    (("cubic", np.ones(500), np.ones(500), 2), {}, "unknown model kind"),
    (("wiener", np.arange(500.0), np.arange(400.0), 2), {}, "differ in length"),
    (("wiener", np.r_[np.arange(499.0), np.nan], np.arange(500.0), 2), {}, "u must be finite; sample 499"),
    (("wiener", np.arange(500.0), np.ones(500), 2), {}, "constant record"),
    (("wiener", np.arange(50.0), np.sin(np.arange(50.0)), 5), {}, "too few"),
    (("wiener", np.arange(500.0), np.sin(np.arange(500.0)), 0), {}, "order must be an int"),
    (("wiener", np.arange(500.0), np.sin(np.arange(500.0)), 2), {"fix_b": 7}, "fix_b"),
    (("wiener", np.arange(500.0), np.sin(np.arange(500.0)), 2), {"n_breakpoints": 1}, "n_breakpoints"),
    (("wiener", np.arange(500.0), np.sin(np.arange(500.0)), 2, -1), {}, "nk must be"),
])
def test_bad_input_is_rejected(args, kwargs, match):
    with pytest.raises(ValueError, match=match) as exc:
        sysid.fit(*args, **kwargs)
    assert "\n" not in str(exc.value)


def test_unknown_option_is_rejected():
    with pytest.raises(TypeError, match="n_strats"):
        sysid.fit("wiener", np.arange(500.0), np.sin(np.arange(500.0)), 2, n_strats=3)


# ---------------------------------------------------------------------------
# the identify command
# ---------------------------------------------------------------------------
@pytest.fixture(scope="module")
def csv_records(tmp_path_factory):
    from ebraille_sim.identification import bench

    d = tmp_path_factory.mktemp("csv")
    recs = bench.run_profiles([bench.PAPER_PROFILES["square_0.2hz"], bench.PAPER_PROFILES["triangle_0.25hz"]], seed=2)
    paths = []
    for name, rec in recs.items():
        paths.append(d / f"{name}.csv")
        rec.to_csv(paths[-1])
    return paths


def test_identify_command_on_recorded_csv(tmp_path, csv_records, capsys):
    import json

    from ebraille_sim.cli import main

    out = tmp_path / "out"
    rc = main(["identify", "--csv", str(csv_records[0]), "--csv", str(csv_records[1]), "--kinds", "linear,wiener",
               "--orders", "2,3", "--quick", "--no-plots", "--no-load-voltage", "0.0007", "--out", str(out)])
    assert rc == 0
    table = json.loads((out / "fitness.json").read_text())
    assert set(table) == {"linear", "wiener"}
    assert set(table["wiener"]) == {"2", "3"}
    assert set(table["wiener"]["2"]) == {"square_0.2hz", "triangle_0.25hz"}
    assert table["wiener"]["3"]["square_0.2hz"] > 85.0
    md = (out / "fitness.md").read_text()
    assert "## Wiener" in md and "**" in md and "| Square (0.20 Hz) |" in md
    for kind in ("linear", "wiener"):
        for order in (2, 3):
            m = BlockModel.load(out / "models" / f"{kind}-{order}.json")
            assert m.kind == kind
            dev = BlockModel.load(out / "models" / f"{kind}-{order}-device.json")
            assert dev.kind == "wiener"
    assert not (out / "plots").exists() and not (out / "dma.md").exists()
    assert "Best model by mean fitness" in capsys.readouterr().out


def test_identify_in_parallel_gives_the_serial_models_and_plots_reuse_the_scoring_runs(tmp_path, csv_records):
    """``-j 2`` fits in two processes: the same fitness table as one process, bit for bit
    (each fit is seeded alone and anchored against rank-deficient steps); the plot shows the
    scoring simulation (its panel titles are the table's fitness values)."""
    import json

    from ebraille_sim.cli import main
    from ebraille_sim.commands.identify import FitPlotter, _envelope, identify_all
    from ebraille_sim.identification import bench
    from ebraille_sim.identification.sysid import fitness, simulate

    outs = {}
    for jobs in ("1", "2"):
        outs[jobs] = tmp_path / f"j{jobs}"
        assert main(["identify", "--csv", str(csv_records[0]), "--csv", str(csv_records[1]), "--kinds",
                     "linear,hammerstein", "--orders", "2,3", "--quick", "--out", str(outs[jobs]), "-j", jobs,
                     "--quiet"]) == 0
    t1, t2 = (json.loads((outs[j] / "fitness.json").read_text()) for j in ("1", "2"))
    assert t1.keys() == t2.keys()
    for kind in t1:
        for order in t1[kind]:
            assert t1[kind][order] == t2[kind][order]
    for name in ("linear-2", "hammerstein-3"):
        assert (outs["2"] / "plots" / f"{name}.png").stat().st_size > 10_000
    recs = {r.stem: bench.load_csv(r) for r in csv_records}
    sims: dict = {}
    models, table, _ = identify_all(recs, next(iter(recs)), ["linear"], [2], {"n_starts": 1, "max_nfev": 50},
                                    sims=sims)
    m = models[("linear", 2)]
    for name, rec in recs.items():
        np.testing.assert_array_equal(sims[("linear", 2)][name], simulate(m, rec.voltage_v))
        assert table["linear"][2][name] == fitness(rec.force_n, sims[("linear", 2)][name])
    plotter = FitPlotter(recs, {})
    plotter.draw(m, tmp_path / "p.png", sims[("linear", 2)])
    titles = [ax.get_title() for ax, *_ in plotter.panels]
    plotter.close()
    assert titles == [f"{name}: {table['linear'][2][name]:.2f} %" for name in recs]
    # the drawn envelope keeps every sample's extremes
    rec = next(iter(recs.values()))
    t_env, y_env = _envelope(rec.time_s, rec.force_n, 200)
    assert len(y_env) == 200 and y_env.max() == rec.force_n.max() and y_env.min() == rec.force_n.min()
    assert np.all(np.diff(t_env) >= 0)


def test_a_fit_does_not_depend_on_the_heap(csv_records):
    """A Hammerstein fit whose Jacobian is rank-deficient (breakpoint segments no sample
    reaches) gives the same model, bit for bit, however the process's memory was laid out
    before it; unanchored, Levenberg-Marquardt's steps along the null directions followed
    MINPACK's rounding and the fitness moved from run to run."""
    from ebraille_sim.identification import bench
    from ebraille_sim.identification.sysid import fit_report

    rec = bench.load_csv(csv_records[0])
    rng = np.random.default_rng(3)
    held, seen = [], set()
    for _ in range(6):
        held.append(np.empty(int(rng.integers(1, 5000))))
        r = fit_report("hammerstein", rec.voltage_v.copy(), rec.force_n.copy(), 3, dt_s=rec.dt_s, n_starts=1,
                       max_nfev=100, n_delay_candidates=1, seed=0)
        seen.add((r.fitness_pct, r.model.linear.b, r.model.linear.f))
    assert len(seen) == 1


@pytest.mark.parametrize("argv, match", [
    (["--csv", "MISSING.csv"], "CSV file not found"),
    (["--kinds", "wiener,cubic"], "--kinds: 'cubic' is not one of"),
    (["--orders", "2,x"], "--orders: 'x' is not valid"),
    (["--seed", "-1"], "argument --seed: a seed must lie in [0, 2**63)"),
    (["--no-load-voltage", "0.1"], "--no-load-voltage needs --csv"),
])
def test_identify_command_errors_are_one_line(tmp_path, argv, match, capsys):
    from ebraille_sim.cli import main

    rc = main(["identify", "--out", str(tmp_path / "o")] + argv)
    err = capsys.readouterr().err
    assert rc == 2
    assert err.startswith("error: ") and err.count("\n") == 1
    assert match in err
    assert not (tmp_path / "o").exists()


def test_identify_command_rejects_a_malformed_csv(tmp_path, capsys):
    from ebraille_sim.cli import main

    bad = tmp_path / "bad.csv"
    bad.write_text("time_s,voltage_v,force_n\n" + "".join(f"{i * 0.01:.2f},0.{i % 7},1\n" for i in range(150))
                   + "1.50,oops,1\n")
    assert main(["identify", "--csv", str(bad), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "line 152, column voltage_v: 'oops' is not a number" in err and err.count("\n") == 1


@pytest.mark.slow
def test_identify_command_on_the_virtual_bench(tmp_path):
    import json

    from ebraille_sim.cli import main

    out = tmp_path / "bench"
    assert main(["identify", "--quick", "--kinds", "wiener", "--orders", "5", "--out", str(out)]) == 0
    table = json.loads((out / "fitness.json").read_text())
    assert set(table["wiener"]["5"]) == set(sysid.PAPER_PROFILE_ORDER)
    assert table["wiener"]["5"]["chirp"] > 90.0
    for name in ("dma.md", "dma.json", "creep.json", "summary.json", "plots/wiener-5.png", "data/chirp.csv",
                 "models/wiener-5-device.json"):
        assert (out / name).is_file(), name
    creep = json.loads((out / "creep.json").read_text())
    assert 0.03 < creep["creep_fraction"] < 0.07



def test_nyquist_clearance_keeps_poles_off_z_minus_one():
    """A system with a pole at z = -0.99 is fitted exactly when the fitter may go there (the
    paper's MATLAB fits put poles within 0.04 of -1) and held 0.2 away with a clearance of
    0.2, at the cost of fitness; the default is the unconstrained fit."""
    from scipy.signal import lfilter

    from ebraille_sim.identification.sysid import fit_report

    u = np.random.default_rng(1).standard_normal(3000)
    y = lfilter([1.0, 0.5], np.poly([0.9, -0.99]), u)
    opts = dict(nk=0, n_starts=1, n_delay_candidates=1, max_nfev=100)
    free = fit_report("linear", u, y, 2, **opts)
    held = fit_report("linear", u, y, 2, nyquist_clearance=0.2, **opts)
    p_free = np.roots(np.concatenate([[1.0], free.model.linear.f]))
    p_held = np.roots(np.concatenate([[1.0], held.model.linear.f]))
    assert np.min(np.abs(p_free + 1.0)) == pytest.approx(0.01, abs=1e-4)
    assert free.fitness_pct > 99.9
    assert np.min(np.abs(p_held + 1.0)) >= 0.2 - 1e-9
    assert held.fitness_pct < 60.0
    assert np.max(np.abs(p_held)) < 1.0
    with pytest.raises(ValueError, match="nyquist_clearance"):
        fit_report("linear", u, y, 2, nyquist_clearance=1.0, **opts)


def test_chirp_dwell_holds_whole_cycles_and_the_default_is_unchanged():
    from ebraille_sim.identification import bench

    f0, d0 = bench.chirp_schedule()
    np.testing.assert_array_equal(d0, np.maximum(2.0 / f0, 1.0))
    f, d = bench.chirp_schedule(5.0)
    np.testing.assert_array_equal(f, f0)
    cycles = d * f
    np.testing.assert_allclose(cycles, np.round(cycles), atol=1e-9)
    assert np.all(d >= 5.0 - 1e-9) and np.all(d - 1.0 / f < 5.0 - 1e-9)   # the first whole count past 5 s
    assert bench.chirp_schedule(0.01)[1] == pytest.approx(1.0 / f0)          # at least one cycle
    p = bench.Profile("chirp", "chirp", chirp_dwell_s=5.0)
    assert p.duration_s == pytest.approx(float(np.sum(d)))
    force, exc = bench.profile_signal(p, np.arange(0.0, p.duration_s, 0.001), bench.BenchParams())
    assert exc[0] == pytest.approx(0.2) and exc[-1] == pytest.approx(20.0)
    with pytest.raises(ValueError, match="chirp_dwell_s applies to a chirp profile only"):
        bench.Profile("sq", "square", 0.2, 6, chirp_dwell_s=5.0)
    with pytest.raises(ValueError, match="chirp_dwell_s"):
        bench.Profile("chirp", "chirp", chirp_dwell_s=-1.0)


def test_identify_conditions_are_selectable_and_recorded(tmp_path, csv_records, capsys):
    import json

    from ebraille_sim.cli import main

    out = tmp_path / "nk1"
    assert main(["identify", "--csv", str(csv_records[0]), "--csv", str(csv_records[1]), "--kinds", "linear",
                 "--orders", "2", "--quick", "--no-plots", "--nk", "1", "--nyquist-clearance", "0.1",
                 "--out", str(out), "--quiet"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["fit_options"]["nk"] == 1 and summary["fit_options"]["nyquist_clearance"] == 0.1
    assert summary["models"]["linear-2"]["nk"] == 1
    rc = main(["identify", "--csv", str(csv_records[0]), "--chirp-dwell", "5", "--out", str(tmp_path / "x")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "--chirp-dwell sets the virtual bench's chirp" in err[0]


def test_fit_readings_tells_the_two_readings_of_the_delay_apart_on_the_same_data():
    """The paper prints no nk: both readings are fitted on one record, and the delay the data
    were made with fits better (a one-sample shift of a first-order block costs several points)."""
    u = np.repeat(np.random.default_rng(0).uniform(-0.5, 0.8, 300), 4)
    for true_nk in (0, 1):
        true = BlockModel(LinearBF((1.0,), (-0.6,), nk=true_nk), None,
                          PiecewiseLinear((-1.0, 0.0, 1.0, 2.0), (-0.5, 0.0, 2.0, 5.0)), dt_s=0.01)
        y = sysid.simulate(true, u)
        fits = sysid.fit_readings("wiener", u, y, 1, n_starts=1)
        assert list(fits) == [0, 1] and all(fits[k].nk == k for k in fits)
        assert fits[true_nk].fitness_pct > 99.9
        assert fits[1 - true_nk].fitness_pct < fits[true_nk].fitness_pct - 5.0
        assert fits[true_nk].fitness_by_nk == {true_nk: fits[true_nk].fitness_pct}
    with pytest.raises(TypeError, match="nks"):
        sysid.fit_readings("wiener", u, y, 1, nk=1)
    with pytest.raises(ValueError, match="none twice"):
        sysid.fit_readings("wiener", u, y, 1, nks=(1, 1))


def test_identify_reports_both_readings_of_the_delay(tmp_path, csv_records, capsys):
    import json

    from ebraille_sim.cli import main
    out = tmp_path / "r"
    assert main(["identify", "--csv", str(csv_records[0]), "--kinds", "linear", "--orders", "2", "--quick",
                 "--readings", "--no-plots", "--out", str(out), "--quiet"]) == 0
    r = json.loads((out / "summary.json").read_text())["models"]["linear-2"]["readings"]
    assert set(r) == {"0", "1"} and all(0 < r[k]["estimation_fitness"] <= 100 for k in r)
    assert "both readings" in (out / "fitness.md").read_text()
    capsys.readouterr()
    assert main(["identify", "--csv", str(csv_records[0]), "--readings", "--nk", "1", "--out",
                 str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and "--readings" in err[0]
