"""Tests of ebraille_sim.identification.dma: the virtual DMA against Table 3 and the eq. 6 model."""

import math

import numpy as np
import pytest

from ebraille_sim.identification import bench as B
from ebraille_sim.identification import dma as D

IDEAL = D.ideal_instruments()


@pytest.fixture(scope="module")
def ideal_dma():
    return D.dma_test(IDEAL, cycles=3, seed=1)


@pytest.fixture(scope="module")
def real_dma():
    return D.dma_test(B.BenchParams(), cycles=3, seed=1)


def test_ideal_instruments_remove_noise_and_quantisation_only():
    bench = B.BenchParams()
    ideal = D.ideal_instruments(bench)
    assert ideal.load_cell.noise_n_rms == 0.0 and ideal.load_cell.resolution_n == 0.0
    assert ideal.actuator.resolution_m == 0.0 and ideal.actuator.displacement_resolution_m == 0.0
    assert ideal.film == bench.film and ideal.device == bench.device
    assert ideal.actuator.servo_natural_hz == bench.actuator.servo_natural_hz


def test_estimate_kc_on_a_known_element():
    f, k, c, m = 0.375, 1.0e5, 4.0, 0.05
    w = 2 * math.pi * f
    t = np.arange(1600) * 0.005                     # 3 cycles at 200 Hz
    y = 1.2e-5 * np.sin(w * t + 0.3) + 2.0e-5
    velocity = 1.2e-5 * w * np.cos(w * t + 0.3)
    acceleration = -1.2e-5 * w * w * np.sin(w * t + 0.3)
    force = 0.2 + k * y + c * velocity + m * acceleration
    r = D.estimate_kc(y, force, 0.005, f, mass_kg=m)
    assert r["stiffness_n_per_m"] == pytest.approx(k, rel=1e-9)
    assert r["damping_n_s_per_m"] == pytest.approx(c, rel=1e-6)
    assert r["damping_loop_n_s_per_m"] == pytest.approx(c, rel=1e-3)
    assert r["amplitude_m"] == pytest.approx(1.2e-5, rel=1e-9)


def test_ideal_dma_measures_the_causal_film_within_5_percent_of_table3_stiffness(ideal_dma):
    rows = D.table3_comparison(ideal_dma)
    assert [r["frequency_hz"] for r in rows] == list(B.TABLE3_FREQUENCIES_HZ)
    film = IDEAL.film
    for r in rows:
        assert abs(r["k_rel_test1"]) < 0.05 and abs(r["k_rel_test2"]) < 0.05
        # measured from the time-domain run, not looked up: it is the film's complex stiffness
        assert r["k_virtual"] == pytest.approx(film.stiffness_n_per_m(r["frequency_hz"]), rel=0.01)
        assert r["c_virtual"] == pytest.approx(film.damping_n_s_per_m(r["frequency_hz"]), rel=0.05)
        # a causal film's damping is three orders above the printed N s/m
        assert r["c_virtual"] > 300 * r["c_test1"]
        assert r["c_loop"] == pytest.approx(r["c_virtual"], rel=0.05)


def test_table3_damping_cannot_come_from_a_causal_material():
    c = np.mean(B.TABLE3_DAMPING_N_S_PER_M, axis=0)
    k = np.mean(B.TABLE3_STIFFNESS_N_PER_M, axis=0)
    bound = D.causal_stiffness_rise_bound_n_per_m(B.TABLE3_FREQUENCIES_HZ, c)
    assert bound == pytest.approx(8.6, abs=0.2)                     # N/m
    assert k[-1] - k[0] > 1000 * bound                              # 9.49 kN/m printed
    assert c[-1] > c[-2]                                            # and the printed c rises at 0.5 Hz
    # the bound holds for a causal film: its stiffness rise is within int c dw
    film = B.FilmParams()
    f = np.linspace(0.125, 0.5, 400)
    rise = film.stiffness_n_per_m(0.5) - film.stiffness_n_per_m(0.125)
    assert rise <= D.causal_stiffness_rise_bound_n_per_m(f, film.damping_n_s_per_m(f))


def test_realistic_bench_resolves_k_but_not_the_printed_c(real_dma):
    for r in D.table3_comparison(real_dma):
        assert abs(r["k_rel_test1"]) < 0.05 and abs(r["k_rel_test2"]) < 0.05
        # the causal film's loss (kN s/m) is resolved, at three orders above Table 3's
        assert r["c_virtual"] > 300 * r["c_test1"]


def test_implied_damping_is_kilonewton_seconds_per_metre():
    c = D.implied_damping_n_s_per_m(B.TABLE3_FREQUENCIES_HZ, np.mean(B.TABLE3_STIFFNESS_N_PER_M, axis=0))
    slope = np.polyfit(np.log(B.TABLE3_FREQUENCIES_HZ), np.mean(B.TABLE3_STIFFNESS_N_PER_M, axis=0), 1)[0]
    np.testing.assert_allclose(c * 2 * np.pi * np.array(B.TABLE3_FREQUENCIES_HZ), 0.5 * np.pi * slope)
    assert np.all(c > 1000.0)
    assert np.all(c / np.mean(B.TABLE3_DAMPING_N_S_PER_M, axis=0) > 500.0)


@pytest.fixture(scope="module")
def records():
    return B.run_profiles(B.PAPER_PROFILES.values(), seed=0)


def test_eq6_amplitude_on_the_chirp_matches_the_paper(records):
    m = D.fit_second_order(records["chirp"])
    # the bench's divider and FSR give the paper's scale: A = 2.258e-5 (k in N/m, V in volts)
    assert m.amplitude == pytest.approx(D.PAPER_A, rel=0.05)
    z = m.regressor(records["chirp"].voltage_v, records["chirp"].excitation_hz, 0.01)
    a_ls = float(z @ records["chirp"].force_n) / float(z @ z)
    assert m.amplitude == pytest.approx(a_ls, rel=1e-12)


def test_eq6_scores_every_profile_below_a_nonlinear_model(records):
    from ebraille_sim.identification import sysid

    table = D.second_order_table(records, D.fit_second_order(records["chirp"]))
    assert list(table) == list(B.PAPER_PROFILES)
    w2 = sysid.fit("wiener", records["chirp"].voltage_v, records["chirp"].force_n, 2, nk=0, n_starts=1)
    for name, rec in records.items():
        assert 50.0 < table[name] < sysid.fitness(rec.force_n, sysid.simulate(w2, rec.voltage_v))


def test_eq6_needs_excitation_frequencies(records):
    import dataclasses

    rec = dataclasses.replace(records["chirp"], excitation_hz=None)
    with pytest.raises(ValueError, match="no excitation frequencies"):
        D.fit_second_order(rec)


def test_bad_dma_arguments():
    with pytest.raises(ValueError, match="frequencies_hz"):
        D.dma_test(IDEAL, frequencies_hz=(0.0,))
    with pytest.raises(ValueError, match="cycles must be an int >= 1"):
        D.dma_test(IDEAL, cycles=0)
    with pytest.raises(ValueError, match="at least 3 distinct"):
        D.fit_dma_polynomials([0.1, 0.2], [1.0, 2.0], [1.0, 2.0])
