"""Tests of ebraille_sim.identification.bench: profiles, the simulated instruments, conditioning, CSV input."""

import math

import numpy as np
import pytest

from ebraille_sim.identification import bench as B
from ebraille_sim.physics.fsr import static_resistance, static_voltage


@pytest.fixture(scope="module")
def square():
    return B.run_profile(B.PAPER_PROFILES["square_0.2hz"], seed=7)


# ---------------------------------------------------------------------------
# profiles
# ---------------------------------------------------------------------------
def test_chirp_schedule_is_the_papers():
    f, dwell = B.chirp_schedule()
    np.testing.assert_allclose(f[:8], np.arange(2, 10) * 0.1)
    np.testing.assert_allclose(f[8:], np.arange(1, 21))
    cycles = f * dwell
    np.testing.assert_allclose(cycles, np.round(cycles), atol=1e-9)   # whole cycles per step
    assert np.all(cycles >= 2 - 1e-9) and np.all(dwell >= 1.0)
    assert B.PAPER_PROFILES["chirp"].duration_s == pytest.approx(2 * np.sum(1 / f[:8]) + 2.0 + 19.0)


@pytest.mark.parametrize("name", list(B.PAPER_PROFILES))
def test_profiles_span_the_tactile_range(name):
    bench = B.BenchParams()
    pr = B.PAPER_PROFILES[name]
    t = np.arange(int(pr.duration_s * 1000)) * 1e-3
    f, exc = B.profile_signal(pr, t, bench)
    if pr.shape in ("chirp", "triangle"):
        assert f[0] == pytest.approx(bench.min_force_n)
    else:
        assert f[0] > bench.min_force_n
    assert f.min() >= bench.min_force_n - 1e-12 and f.max() <= bench.max_force_n + 1e-12
    assert f.max() == pytest.approx(bench.max_force_n, abs=1e-3)
    assert np.all(exc >= 0.1)


def test_chirp_is_phase_continuous_and_steps_in_frequency():
    bench = B.BenchParams()
    t = np.arange(int(B.PAPER_PROFILES["chirp"].duration_s * 1000)) * 1e-3
    f, exc = B.profile_signal(B.PAPER_PROFILES["chirp"], t, bench)
    assert np.max(np.abs(np.diff(f))) < 2.8 * 2 * np.pi * 20 * 1e-3   # no jumps at the steps
    assert exc[0] == pytest.approx(0.2) and exc[-1] == pytest.approx(20.0)
    assert np.all(np.diff(exc) >= 0)


def test_step_profile_climbs_and_returns():
    bench = B.BenchParams()
    t = (np.arange(6) + 0.5) * 10.0
    f, _ = B.profile_signal(B.PAPER_PROFILES["step_0.1hz"], t, bench)
    span = bench.max_force_n - bench.min_force_n
    np.testing.assert_allclose(f, bench.min_force_n + span * np.array([1, 2, 3, 2, 1, 0]) / 3)


def test_bad_profile_is_rejected():
    with pytest.raises(ValueError, match="unknown profile shape 'saw'"):
        B.Profile("x", "saw")
    with pytest.raises(ValueError, match="frequency_hz > 0"):
        B.Profile("x", "square", 0.0, 3)


# ---------------------------------------------------------------------------
# the recording
# ---------------------------------------------------------------------------
def test_record_is_100_hz_detrended_at_the_preload(square):
    assert square.dt_s == 0.01
    np.testing.assert_allclose(np.diff(square.time_s), 0.01)
    n0 = square.baseline_samples
    assert n0 == 200
    assert abs(np.mean(square.force_n[:n0])) < 2e-3 and abs(np.mean(square.voltage_v[:n0])) < 2e-3
    # the offsets are the preload (quantised to the actuator's 1.5 um steps) and its voltage
    bench = B.BenchParams()
    k = bench.film.stiffness_n_per_m(0.2)
    preload = round(bench.min_force_n / k / 1.5e-6) * 1.5e-6 * k
    # held in displacement, the preload relaxes a little towards the film's relaxed stiffness
    assert square.force_offset_n == pytest.approx(preload, abs=0.03)
    v_pre = static_voltage(preload, bench.device.fsr, bench.device.circuit)
    assert square.voltage_offset_v == pytest.approx(v_pre, rel=0.1)


def test_voltage_rises_with_force(square):
    hi = square.force_n > 2.0
    lo = (square.force_n < 0.2) & (square.time_s > 3.0)
    assert square.voltage_v[hi].mean() > square.voltage_v[lo].mean() + 0.8
    assert np.corrcoef(square.voltage_v, square.force_n)[0, 1] > 0.95


def test_content_above_40_hz_is_removed(square):
    for x, raw, off in ((square.voltage_v, square.raw_voltage_v, square.voltage_offset_v),
                        (square.force_n, square.raw_force_n, square.force_offset_n)):
        d = raw - off                       # detrended, before the filter
        line = d[0] + (d[-1] - d[0]) * np.arange(d.size) / (d.size - 1)
        freqs = np.fft.rfftfreq(x.size, square.dt_s)
        before = np.abs(np.fft.rfft(d - line))
        after = np.abs(np.fft.rfft(x - line))
        assert np.max(before[freqs > 40.0]) > 1e-3 * np.max(before)       # there was some
        assert np.max(after[freqs > 40.0]) < 1e-9 * np.max(after)
        np.testing.assert_allclose(after[freqs < 40.0], before[freqs < 40.0], rtol=1e-9, atol=1e-9)


def test_load_cell_noise_and_resolution(square):
    lc = B.LoadCellParams()
    raw = square.raw_force_n[:square.baseline_samples]
    assert np.std(raw) == pytest.approx(lc.noise_n_rms, rel=0.25)
    np.testing.assert_allclose(raw / lc.resolution_n, np.round(raw / lc.resolution_n), atol=1e-6)


def test_film_is_the_standard_linear_solid_fitted_to_table3_stiffness():
    ke, k1, tau = B.fit_standard_linear_solid()
    np.testing.assert_allclose((ke, k1, tau), B.SLS_FIT_TABLE3, rtol=2e-3)
    film = B.FilmParams()
    k = film.stiffness_n_per_m(np.array(B.TABLE3_FREQUENCIES_HZ))
    assert np.max(np.abs(k / np.mean(B.TABLE3_STIFFNESS_N_PER_M, axis=0) - 1)) < 0.008
    # causal: the storage stiffness rises monotonically, the damping falls, and it is kN s/m
    f = np.logspace(-3, 2, 50)
    assert np.all(np.diff(film.stiffness_n_per_m(f)) > 0) and np.all(np.diff(film.damping_n_s_per_m(f)) < 0)
    assert film.damping_n_s_per_m(0.25) > 1000.0


def test_film_force_in_the_time_domain_is_the_complex_stiffness():
    film = B.FilmParams(mass_kg=0.0)
    dt, f = 1e-3, 0.25
    t = np.arange(int(40 / dt)) * dt
    y = 1e-5 * np.sin(2 * np.pi * f * t)
    force = film.force_n(y, np.zeros_like(y), dt)
    sel = t > 20.0
    x = np.column_stack([np.sin(2 * np.pi * f * t), np.cos(2 * np.pi * f * t)])[sel]
    a, b = np.linalg.lstsq(x, force[sel] - force[sel].mean(), rcond=None)[0]
    assert a / 1e-5 == pytest.approx(film.stiffness_n_per_m(f), rel=2e-3)
    assert b / 1e-5 / (2 * np.pi * f) == pytest.approx(film.damping_n_s_per_m(f), rel=0.02)


def test_same_seed_same_record_exactly():
    a = B.run_profile(B.PAPER_PROFILES["triangle_0.25hz"], seed=3)
    b = B.run_profile(B.PAPER_PROFILES["triangle_0.25hz"], seed=3)
    c = B.run_profile(B.PAPER_PROFILES["triangle_0.25hz"], seed=4)
    for name in ("voltage_v", "force_n", "raw_voltage_v", "raw_force_n", "displacement_m"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert not np.array_equal(a.raw_force_n, c.raw_force_n)


def test_run_profiles_gives_each_profile_its_own_seed():
    recs = B.run_profiles([B.PAPER_PROFILES["square_0.2hz"], B.Profile("sq2", "square", 0.2, 6)], seed=5)
    assert not np.array_equal(recs["square_0.2hz"].raw_force_n, recs["sq2"].raw_force_n)
    with pytest.raises(ValueError, match="unique"):
        B.run_profiles([B.PAPER_PROFILES["chirp"]] * 2)


def test_constant_displacement_hold_raises_the_resistance_about_six_percent():
    rec = B.run_profile(B.HOLD_PROFILE, seed=2)
    creep = B.hold_creep(rec)
    # the paper: about +6 % in 30 min under constant displacement; the film and fixture
    # relax (the force falls) faster than the sensor's own creep raises its conductance
    assert creep["creep_fraction"] == pytest.approx(0.06, abs=0.01)
    n0 = rec.baseline_samples
    f_start, f_end = rec.true_force_n[n0 + 200], rec.true_force_n[-200]
    assert f_end < 0.85 * f_start
    # under the same force held constant the sensor's resistance would fall instead
    fsr = B.BenchParams().device.fsr
    assert static_resistance(f_start, fsr, load_time_s=1800.0) < static_resistance(f_start, fsr, load_time_s=2.0)


# ---------------------------------------------------------------------------
# conditioning
# ---------------------------------------------------------------------------
def test_lowpass_fft_is_zero_phase_brick_wall():
    n = 2000
    t = np.arange(n) * 0.01
    ramp = 0.3 * t                                    # removed exactly with the end-point line
    k = np.arange(n // 2 + 1)
    rng = np.random.default_rng(0)
    spec = rng.standard_normal(k.size) + 1j * rng.standard_normal(k.size)
    spec[0] = spec[-1] = 0.0
    periodic = np.fft.irfft(spec, n)                  # exactly periodic over the record
    periodic -= np.linspace(periodic[0], periodic[-1], n)   # ... and zero at both ends
    low = np.fft.irfft(np.where(np.fft.rfftfreq(n, 0.01) <= 40.0, np.fft.rfft(periodic), 0.0), n)
    y = B.lowpass_fft(ramp + periodic, 0.01, 40.0)
    np.testing.assert_allclose(y, ramp + low, atol=1e-12)     # zero phase: no shift, no lag


def test_condition_removes_the_baseline_mean():
    v = np.r_[np.full(100, 0.3), np.full(100, 1.3)]
    f = np.r_[np.full(100, 0.2), np.full(100, 3.0)]
    vc, fc, v0, f0, nb = B.condition(v, f, 0.01, 1.0, None)
    assert (v0, f0, nb) == (pytest.approx(0.3), pytest.approx(0.2), 100)
    np.testing.assert_allclose(vc[100:], 1.0)
    with pytest.raises(ValueError, match="longer than the record"):
        B.condition(v, f, 0.01, 5.0, None)


def test_bench_params_are_validated():
    with pytest.raises(ValueError, match="cutoff_hz 60"):
        B.BenchParams(cutoff_hz=60.0)
    with pytest.raises(ValueError, match="min_force_n"):
        B.BenchParams(min_force_n=3.0, max_force_n=1.0)
    with pytest.raises(ValueError, match="load-cell range"):
        B.BenchParams(max_force_n=30.0)
    with pytest.raises(ValueError, match="FilmParams.branch_tau_s must be > 0"):
        B.FilmParams(branch_tau_s=0.0)
    with pytest.raises(ValueError, match="noise_n_rms must be >= 0"):
        B.LoadCellParams(noise_n_rms=-1.0)


# ---------------------------------------------------------------------------
# recorded CSV data
# ---------------------------------------------------------------------------
def test_csv_round_trip(tmp_path, square):
    path = tmp_path / "sq.csv"
    square.to_csv(path)
    rec = B.load_csv(path)
    assert rec.name == "sq" and rec.dt_s == pytest.approx(0.01)
    np.testing.assert_allclose(rec.voltage_v, square.voltage_v, atol=1e-5)
    np.testing.assert_allclose(rec.force_n, square.force_n, atol=1e-5)


def _write(tmp_path, text, name="d.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


def _rows(n, dt=0.01, start=0):
    return "".join(f"{(start + i) * dt:.4f},{0.1 + 0.5 * math.sin(i / 7):.4f},{1 + math.sin(i / 7):.4f}\n"
                   for i in range(n))


@pytest.mark.parametrize("text, match", [
    ("time_s,voltage_v\n" + "0,1\n" * 200, "missing column\\(s\\) force_n"),
    ("time_s,voltage_v,force_n\n" + _rows(150) + "1.5,abc,2\n" + _rows(50, start=151),
     "line 152, column voltage_v: 'abc' is not a number"),
    ("time_s,voltage_v,force_n\n" + _rows(150) + "1.5,nan,2\n",
     "line 152, column voltage_v: value 'nan' is not finite"),
    ("time_s,voltage_v,force_n\n" + _rows(150) + "1.49,0.1,2\n", "time_s must increase strictly; line 152"),
    ("time_s,voltage_v,force_n\n" + _rows(150) + "1.6,0.1,2\n", "not uniformly sampled: step 0.11 s at line 152"),
    ("time_s,voltage_v,force_n\n" + _rows(20), "20 data row\\(s\\); at least 100"),
    ("time_s,voltage_v,force_n\n" + "".join(f"{i * 0.01},1,2\n" for i in range(300)), "constant"),
    ("time_s,voltage_v,force_n\n" + _rows(150) + "1.5,0.1\n", "line 152 has no force_n value"),
    ("", "empty file"),
])
def test_csv_errors_are_one_line(tmp_path, text, match):
    with pytest.raises(ValueError, match=match) as exc:
        B.load_csv(_write(tmp_path, text))
    assert "\n" not in str(exc.value)


def test_csv_missing_file_and_bad_cutoff(tmp_path):
    with pytest.raises(FileNotFoundError, match="CSV file not found"):
        B.load_csv(tmp_path / "nope.csv")
    p = _write(tmp_path, "time_s,voltage_v,force_n\n" + _rows(300))
    with pytest.raises(ValueError, match="cutoff_hz 80"):
        B.load_csv(p, cutoff_hz=80.0)
    rec = B.load_csv(p, baseline_s=0.0, cutoff_hz=None)      # extra options: no conditioning
    assert rec.voltage_offset_v == 0.0 and rec.force_offset_n == 0.0
