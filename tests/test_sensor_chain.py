"""FSR forward model, ADC, anti-alias filter and the in-loop estimator against analytic cases."""
import dataclasses
import math

import numpy as np
import pytest
import scipy.signal

from ebraille_sim.plant import kernel
from ebraille_sim.estimation.calibration import calibrate_r2, loading_branch_factor, static_error_table
from ebraille_sim.physics.fsr import static_resistance, static_voltage
from ebraille_sim.physics.fsr import FAULT_OPEN, FAULT_SHORT, FAULT_STUCK, FAULT_VALUE
from ebraille_sim.plant.layout import N_INPUT, P, S, U
from ebraille_sim.plant.lumped import initial_state, pack_params
from ebraille_sim.estimation.paper_models import paper_model
from ebraille_sim.physics.params import FSRS, CircuitParams, DeviceParams, EstimatorParams, FSRParams, RateParams


def _sensor(fsr=FSRParams(), circuit=CircuitParams(), estimator=EstimatorParams(), rates=RateParams(), seed=0,
            scatter=False):
    """A device's packed sensor chain at rest; without ``scatter`` the film's press-to-press draw is
    off (the laws here are checked on the central press; the draw has its own test in test_laws)."""
    if not scatter:
        fsr = dataclasses.replace(fsr, press_repeatability=0.0)
    dev = DeviceParams(fsr=fsr, circuit=circuit, estimator=estimator, rates=rates)
    p = pack_params(dev, seed)
    s = initial_state(dev, p)
    u = np.zeros(N_INPUT)
    u[U["driver_supply_v"]] = 6.0
    return dev, s, p, u


def _hold(s, p, u, force_n, seconds, rates=RateParams()):
    n = int(round(seconds * rates.physics_rate_hz))
    kernel.advance_sensor_only(s, p, u, force_n, n)


def _resistance_from(v, circuit):
    return circuit.r2_ohm * (circuit.supply_v - v) / v


def test_divider_voltage_at_a_known_resistance():
    c = CircuitParams(r2_ohm=10e3, supply_v=5.0)
    assert c.divider_v(10e3) == pytest.approx(2.5, abs=1e-15)
    assert c.divider_v(30e3) == pytest.approx(1.25, abs=1e-15)
    # nominal FSR at 1 N is 10 kOhm (power law k at 1 N)
    # (the turn-on region leaves 1/(1 + 0.1^4) of the law at 1 N)
    assert static_resistance(1.0, FSRS["nominal"]) == pytest.approx(1 / (1 / 10e3 / (1 + 1e-4) + 1e-7), rel=1e-12)


def test_adc_reads_the_static_divider_voltage_without_noise_or_memory_effects():
    fsr = FSRParams(noise_v_rms=0.0, hysteresis_fraction=0.0, creep_per_decade=0.0)
    c = CircuitParams()
    dev, s, p, u = _sensor(fsr=fsr, circuit=c)
    for f in (0.3, 1.0, 2.5):
        _hold(s, p, u, f, 0.05)
        v = static_voltage(f, fsr, c)
        assert s[S["fsr_voltage_v"]] == pytest.approx(math.floor(v / c.adc_lsb_v) * c.adc_lsb_v, abs=1e-12)


def test_hysteresis_loop_has_the_datasheet_width():
    fsr = FSRParams(noise_v_rms=0.0, creep_per_decade=0.0, hysteresis_fraction=0.10)
    c = CircuitParams(adc_bits=20)
    dev, s, p, u = _sensor(fsr=fsr, circuit=c)
    for f in np.linspace(0.0, 3.0, 61):          # load to 3 N
        _hold(s, p, u, float(f), 0.02)
    for f in np.linspace(3.0, 1.0, 41):          # unload to 1 N
        _hold(s, p, u, float(f), 0.02)
    r_down = _resistance_from(s[S["fsr_voltage_v"]], c)
    dev, s, p, u = _sensor(fsr=fsr, circuit=c)
    for f in np.linspace(0.0, 1.0, 21):          # fresh unit loaded to 1 N
        _hold(s, p, u, float(f), 0.02)
    r_up = _resistance_from(s[S["fsr_voltage_v"]], c)
    assert (r_up - r_down) / r_up == pytest.approx(0.10, abs=0.003)
    # loading branch factor: F_eff = F (1 - h)^(1/(2n))
    assert loading_branch_factor(fsr) == pytest.approx(0.9 ** (1 / (2 * 0.9)), rel=1e-12)


def _path_conductance(s, fsr, c):
    return 1 / _resistance_from(s[S["fsr_voltage_v"]], c) - 1 / fsr.standoff_resistance_ohm


def test_conductance_rises_under_a_constant_force_by_one_to_five_percent_per_decade():
    fsr = FSRParams(noise_v_rms=0.0, hysteresis_fraction=0.0)
    c = CircuitParams(adc_bits=24)
    dev, s, p, u = _sensor(fsr=fsr, circuit=c)
    _hold(s, p, u, 1.5, 0.1)
    g = [_path_conductance(s, fsr, c)]
    for seconds in (0.9, 9.0, 90.0):              # to 1, 10 and 100 s of load
        _hold(s, p, u, 1.5, seconds)
        g.append(_path_conductance(s, fsr, c))
    per_decade = np.diff(g) / np.asarray(g[:-1])
    assert np.all(per_decade > 0.01) and np.all(per_decade < 0.05)        # Interlink: < 5 %/decade
    # the hereditary law, held from a recovered film, is the static helper's
    assert g[-1] == pytest.approx(1 / static_resistance(1.5, fsr, load_time_s=100.0)
                                  - 1 / fsr.standoff_resistance_ohm, rel=2e-3)


def test_creep_recovers_after_unloading_and_remembers_a_short_pause():
    fsr = FSRParams(noise_v_rms=0.0, hysteresis_fraction=0.0)
    c = CircuitParams(adc_bits=24)
    dev, s, p, u = _sensor(fsr=fsr, circuit=c)
    _hold(s, p, u, 1.5, 0.05)
    g_fresh = _path_conductance(s, fsr, c)
    _hold(s, p, u, 1.5, 300.0)
    g_crept = _path_conductance(s, fsr, c)
    _hold(s, p, u, 0.0, 1.0)                      # short pause: most of the creep remains
    _hold(s, p, u, 1.5, 0.05)
    g_short = _path_conductance(s, fsr, c)
    _hold(s, p, u, 0.0, 1500.0)                   # long rest: recovered but for the slow terms (0.2 %)
    _hold(s, p, u, 1.5, 0.05)
    g_rest = _path_conductance(s, fsr, c)
    assert g_crept / g_fresh - 1 > 0.05
    assert g_short / g_fresh - 1 > 0.04
    assert g_rest / g_fresh == pytest.approx(1.0, abs=3e-3)


def test_creep_makes_the_dc_gain_exceed_the_10_hz_gain_by_5_to_32_percent():
    from ebraille_sim.physics.fsr import creep_frequency_response
    fsr = FSRParams(noise_v_rms=0.0, hysteresis_fraction=0.0)
    h0, h10 = creep_frequency_response(0.0, fsr), creep_frequency_response(10.0, fsr)
    boost = abs(h0) / abs(h10) - 1.0
    assert 0.05 <= boost <= 0.32                  # published dynamic FSR models: 5-32 %
    # the kernel's small-signal response at 10 Hz after a long preload is the analytic one
    c = CircuitParams(adc_bits=24)
    dev, s, p, u = _sensor(fsr=fsr, circuit=c)
    _hold(s, p, u, 1.5, 1000.0)
    t = np.arange(2000) * 1e-3
    g = np.empty(t.size)
    for i, ti in enumerate(t):
        _hold(s, p, u, 1.5 + 0.01 * math.sin(2 * math.pi * 10.0 * ti), 1e-3)
        g[i] = _path_conductance(s, fsr, c)
    x = np.column_stack([np.ones_like(t), np.sin(2 * np.pi * 10 * t), np.cos(2 * np.pi * 10 * t)])
    coef = np.linalg.lstsq(x[1000:], g[1000:], rcond=None)[0]
    amp = math.hypot(coef[1], coef[2])
    # the creep terms slower than the 1000 s preload have not filled: the operating point is the
    # film crept for 1000 s, and around it a 10 Hz change sees |H(10 Hz)| of the law's slope
    from ebraille_sim.physics.fsr import creep_gain
    g_held = 1 / static_resistance(1.5, fsr, load_time_s=1001.0) - 1 / fsr.standoff_resistance_ohm
    slope = fsr.exponent * g_held / (1.5 * creep_gain(1001.0, fsr))    # d G / d F_c at that point
    assert amp / 0.01 / slope == pytest.approx(abs(h10), rel=0.03)


def test_temperature_offset_shifts_resistance_by_the_coefficient():
    fsr = FSRParams(noise_v_rms=0.0, hysteresis_fraction=0.0, creep_per_decade=0.0)
    c = CircuitParams(adc_bits=24)
    dev, s, p, u = _sensor(fsr=fsr, circuit=c)
    u[U["fsr_temp_offset_k"]] = 60.0             # 25 -> 85 C: datasheet -15 %
    _hold(s, p, u, 1.0, 0.05)
    r = _resistance_from(s[S["fsr_voltage_v"]], c)
    g_path = 1 / r - 1 / fsr.standoff_resistance_ohm
    assert 1 / g_path / 10e3 == pytest.approx(0.85, abs=1e-3)


def test_sensor_noise_has_the_stated_rms_and_is_reproducible():
    fsr = FSRParams(noise_v_rms=2e-3, hysteresis_fraction=0.0, creep_per_decade=0.0)
    c = CircuitParams(adc_bits=24)
    vals = []
    dev, s, p, u = _sensor(fsr=fsr, circuit=c, seed=11)
    _hold(s, p, u, 1.0, 0.05)
    for _ in range(4000):
        _hold(s, p, u, 1.0, 0.001)
        vals.append(s[S["fsr_voltage_v"]])
    vals = np.array(vals)
    assert vals.std() == pytest.approx(2e-3, rel=0.05)
    dev, s2, p2, u2 = _sensor(fsr=fsr, circuit=c, seed=11)
    _hold(s2, p2, u2, 1.0, 0.05)
    again = []
    for _ in range(4000):
        _hold(s2, p2, u2, 1.0, 0.001)
        again.append(s2[S["fsr_voltage_v"]])
    np.testing.assert_array_equal(vals, np.array(again))


@pytest.mark.parametrize("fault,expected", [(FAULT_OPEN, 0.0), (FAULT_SHORT, 5.0 - 5.0 / 1024)])
def test_open_and_short_faults_read_the_rails(fault, expected):
    dev, s, p, u = _sensor(fsr=FSRParams(noise_v_rms=0.0))
    u[U["fsr_fault"]] = fault
    _hold(s, p, u, 1.0, 0.01)
    assert s[S["fsr_voltage_v"]] == pytest.approx(expected, abs=1e-12)


def test_stuck_fault_repeats_the_last_code():
    dev, s, p, u = _sensor()
    _hold(s, p, u, 1.0, 0.05)
    v = s[S["fsr_voltage_v"]]
    u[U["fsr_fault"]] = FAULT_STUCK
    _hold(s, p, u, 2.5, 0.05)
    assert s[S["fsr_voltage_v"]] == v


def test_paper_wiener_estimator_at_a_steady_input():
    """0.776 V held: the fifth-order Wiener reads its second breakpoint, 1.496 N (the model alone:
    the creep compensation, which acts on the divider voltage, is off)."""
    dev, s, p, u = _sensor(fsr=FSRParams(noise_v_rms=0.0), circuit=CircuitParams(adc_bits=24),
                           estimator=EstimatorParams(creep_compensation=False))
    u[U["fsr_fault"]] = FAULT_VALUE
    u[U["fsr_fault_value"]] = 0.776 + s[S["tare_v"]]
    _hold(s, p, u, 0.0, 3.0)
    assert s[S["force_est_n"]] == pytest.approx(1.496, abs=2e-3)
    model = paper_model("wiener", 5)
    assert s[S["force_est_n"]] == pytest.approx(float(model.steady_state(0.776)), abs=1e-4)


def test_in_loop_estimator_equals_the_reference_pipeline():
    """Anti-alias biquad at the sensor rate, decimation, BlockModel.simulate, two-sample mean
    (creep compensation off: its own tests are below)."""
    c = CircuitParams(adc_bits=24)
    dev, s, p, u = _sensor(fsr=FSRParams(noise_v_rms=0.0), circuit=c, estimator=EstimatorParams(creep_compensation=False))
    rng = np.random.default_rng(5)
    n = 3000
    v_in = 0.6 + 0.3 * np.sin(np.arange(n) * 2 * np.pi * 2.0 / 1000) + 0.01 * rng.standard_normal(n)
    u[U["fsr_fault"]] = FAULT_VALUE
    est = []
    for k in range(n):
        u[U["fsr_fault_value"]] = v_in[k]
        kernel.advance_sensor_only(s, p, u, 0.0, 10)    # one sensor sample per call
        est.append(s[S["force_est_n"]])
    est = np.array(est)
    lsb = c.adc_lsb_v
    vq = np.floor(v_in / lsb) * lsb - s[S["tare_v"]]
    b, a = scipy.signal.butter(2, 20.0, fs=1000.0)
    y_aa = scipy.signal.lfilter(b, a, vq)
    dec = y_aa[9::10]
    model = paper_model("wiener", 5)
    f_model, _ = model.simulate(dec)
    f_avg = 0.5 * (f_model + np.concatenate([[float(model.steady_state(0.0))], f_model[:-1]]))
    f_avg = np.maximum(f_avg, 0.0)
    np.testing.assert_allclose(est[9::10], f_avg, rtol=0, atol=1e-9)


def test_divider_calibration_reproduces_the_default_r2():
    r2 = calibrate_r2(paper_model("wiener", 5), FSRS["nominal"], CircuitParams())
    assert r2 == pytest.approx(CircuitParams().r2_ohm, rel=0.01)
    rows = static_error_table(paper_model("wiener", 5), FSRS["nominal"], CircuitParams())
    at1 = next(r for r in rows if r["force_n"] == 1.0)
    assert abs(at1["rel_error_at_60s"]) < 0.05


def _held_estimates(fsr, estimator, force_n, times_s=(2.0, 10.0, 30.0, 60.0)):
    """Estimates at ``times_s`` of a force held from a recovered film (24-bit ADC)."""
    dev, s, p, u = _sensor(fsr=fsr, circuit=CircuitParams(adc_bits=24), estimator=estimator)
    out, t0 = [], 0.0
    for t in times_s:
        _hold(s, p, u, force_n, t - t0)
        t0 = t
        out.append(s[S["force_est_n"]])
    return np.array(out)


@pytest.mark.parametrize("force_n", [0.5, 1.0, 2.0])
def test_creep_compensation_inverts_the_creep_of_a_sensor_with_its_parameters(force_n):
    """A held force on a sensor whose creep equals the firmware's nominal law: compensated to the
    un-crept film (reference hold ~0), the estimate equals the one of a sensor without creep to
    1e-3 relative at 2-60 s (6e-4: the prediction runs on the estimate, not the film's force) (that one's static error, up to 14 %, is the estimator's own); without
    the compensation the creep makes it read 9-15 % higher and drift by > 2.5 % from 2 to 60 s."""
    nominal = FSRParams(noise_v_rms=0.0)
    comp = _held_estimates(nominal, EstimatorParams(creep_compensation=True, creep_reference_hold_s=1e-6), force_n)
    # the creep-free film keeps the nominal film's play operators (the loop the creep does not make)
    from ebraille_sim.physics.fsr import play_loop_fraction
    no_creep = _held_estimates(dataclasses.replace(nominal, creep_per_decade=0.0,
                                                   hysteresis_fraction=play_loop_fraction(nominal)),
                               EstimatorParams(creep_compensation=False), force_n)
    crept = _held_estimates(nominal, EstimatorParams(creep_compensation=False), force_n)
    np.testing.assert_allclose(comp, no_creep, rtol=1e-3)
    assert np.all(crept / no_creep > 1.06)
    assert crept[-1] / crept[0] - 1.0 > 0.025


@pytest.mark.parametrize("force_n", [0.5, 1.0, 2.0])
def test_compensated_estimate_is_the_calibration_holds_at_every_hold_time(force_n):
    """With the default reference (the 20-s calibration hold) the estimate of a held force is the
    static estimate after 20 s (estimation.calibration.steady_estimate) from 2 s to 60 s, within
    3e-4 relative; an individual sensor with another exponent (FSRS high_k, n = 0.95 against the
    nominal 0.9) keeps a residual drift below 0.3 % where it drifts 2.9 % uncompensated."""
    from ebraille_sim.estimation.calibration import steady_estimate
    nominal = FSRParams(noise_v_rms=0.0)
    est = _held_estimates(nominal, EstimatorParams(), force_n)
    ref = steady_estimate(paper_model("wiener", 5), force_n, nominal, CircuitParams(adc_bits=24), 20.0)
    np.testing.assert_allclose(est, ref, rtol=3e-4)
    high_k = dataclasses.replace(FSRS["high_k"], noise_v_rms=0.0)
    comp = _held_estimates(high_k, EstimatorParams(), force_n)
    bare = _held_estimates(high_k, EstimatorParams(creep_compensation=False), force_n)
    assert abs(comp[-1] / comp[0] - 1.0) < 3e-3
    assert bare[-1] / bare[0] - 1.0 > 0.025


def test_creep_compensation_is_deterministic_and_switchable():
    """Same seed, same estimates to the bit; the flag off leaves the estimate of the bare model and
    its states untouched (the firmware's creep states stay at zero)."""
    runs = []
    for _ in range(2):
        dev, s, p, u = _sensor(fsr=FSRParams(), seed=7)
        _hold(s, p, u, 1.2, 3.0)
        runs.append(s.copy())
    np.testing.assert_array_equal(runs[0], runs[1])
    assert runs[0][S["comp_creep_4_n"]] > 0.0
    dev, s, p, u = _sensor(fsr=FSRParams(), seed=7, estimator=EstimatorParams(creep_compensation=False))
    _hold(s, p, u, 1.2, 3.0)
    assert all(s[S[f"comp_creep_{j}_n"]] == 0.0 for j in range(5))
    assert s[S["fsr_voltage_v"]] == runs[0][S["fsr_voltage_v"]]          # the sensor itself is the same
    assert s[S["force_est_n"]] != runs[0][S["force_est_n"]]


@pytest.mark.parametrize("comp", [False, True])
def test_hysteresis_compensation_removes_the_unloading_branch_error(comp):
    """A noiseless nominal film pressed to 1.6 N, held, then let down to 1.0 N: uncompensated the
    estimate reads the unloading branch (about 10 % high); compensated, the two readings differ
    by no more than the deadband can hold each of them off the input (one deadband below the
    rising press, one above the falling one), converted to force by the divider's slope at
    1 N.  Creep compensation is on in both, as on the device."""
    est = EstimatorParams(hysteresis_compensation=comp)
    fsr_q = FSRParams(noise_v_rms=0.0)
    dev, s, p, u = _sensor(fsr=fsr_q, estimator=est)
    _hold(s, p, u, 1.0, 3.0)
    direct = s[S["force_est_n"]]
    dev, s, p, u = _sensor(fsr=fsr_q, estimator=est)
    for f in np.linspace(0.0, 1.6, 50):
        _hold(s, p, u, f, 0.02)
    for f in np.linspace(1.6, 1.0, 50):
        _hold(s, p, u, f, 0.02)
    _hold(s, p, u, 1.0, 2.0)
    rel = s[S["force_est_n"]] / direct - 1.0
    if comp:
        slope_v_per_n = (static_voltage(1.01, fsr_q, dev.circuit) - static_voltage(0.99, fsr_q, dev.circuit)) / 0.02
        deadband_n = est.hysteresis_deadband_lsb * dev.circuit.adc_lsb_v / slope_v_per_n
        assert abs(rel) <= 2.0 * deadband_n / 1.0
    else:
        assert rel > 0.06


def _press_and_read(s, p, u, force_n, settle_s, samples):
    """A press from 0 to ``force_n`` in 50 ms, held ``settle_s``, then the estimate at each of
    ``samples`` further milliseconds of the hold."""
    for f in np.linspace(0.0, force_n, 50):
        _hold(s, p, u, f, 0.001)
    _hold(s, p, u, force_n, settle_s)
    out = []
    for _ in range(samples):
        _hold(s, p, u, force_n, 0.001)
        out.append(s[S["force_est_n"]])
    return out


def _fast_firmware(turn_lsb):
    return EstimatorParams(hysteresis_compensation=True, model="paper:wiener:5@1000", antialias_cutoff_hz=50.0,
                           hysteresis_turn_lsb=turn_lsb)


@pytest.mark.parametrize("seed", range(3))
def test_turn_test_reads_a_relaxation_the_deadband_holds_and_keeps_a_standing_force(seed):
    """On the 1 kHz firmware with its noise: a press to 1.15 N in 20 ms that relaxes to 1.0 N
    over 60 ms (the pulp at a standing board) is read more than 4 % high behind the plain
    deadband (5.1-5.6 %), more than a point less with the turn test (3.7-4.2 %: the creep's 3.2
    points of the film's 10 % loop are not the play loop the firmware inverts); at a standing 1.5 N after a 50 ms press the two
    estimates agree to 6 mN and the turn test's is as still (no noise ratchet)."""
    reads = {}
    for turn in (0.0, 1.75):
        dev, s, p, u = _sensor(estimator=_fast_firmware(turn), seed=seed)
        for f in np.linspace(0.0, 1.15, 20):
            _hold(s, p, u, f, 0.001)
        for f in np.linspace(1.15, 1.0, 60):
            _hold(s, p, u, f, 0.001)
        held = []
        for _ in range(100):
            _hold(s, p, u, 1.0, 0.001)
            held.append(s[S["force_est_n"]])
        dev, s, p, u = _sensor(estimator=_fast_firmware(turn), seed=seed)
        steady = _press_and_read(s, p, u, 1.5, 1.0, 2000)
        reads[turn] = (np.mean(held[-50:]), np.mean(steady), np.ptp(steady))
    assert reads[0.0][0] > 1.04
    assert reads[1.75][0] < min(1.045, reads[0.0][0] - 0.01)
    assert abs(reads[1.75][1] - reads[0.0][1]) < 0.006
    assert reads[1.75][2] <= max(reads[0.0][2], 0.001)


@pytest.mark.parametrize("seed", range(3))
def test_centring_reads_a_standing_press_one_narrowest_width_from_the_edge(seed):
    """On the 1 kHz firmware with its noise, a press to 1.0 N in 50 ms held for a second: the
    exact inverse reads the edge of the film's blind stretch it last crossed (the loading edge,
    or the unloading one where the turn test took the press's end for a turn), the centred one
    the middle of the stretch, one narrowest play width (ln N) away, to 5 %; the centring
    adds no noise of its own."""
    reads = {}
    for centre in (0.0, 0.05):
        est = dataclasses.replace(_fast_firmware(1.75), hysteresis_centre_time_s=centre)
        dev, s, p, u = _sensor(estimator=est, seed=seed)
        held = _press_and_read(s, p, u, 1.0, 0.5, 500)
        reads[centre] = (np.mean(held), np.ptp(held))
        w1 = p[P["comp_play_w0"]]
    moved = abs(math.log(reads[0.05][0] / reads[0.0][0]))
    assert moved == pytest.approx(w1, rel=0.05)
    assert reads[0.05][1] <= reads[0.0][1] + 0.001


def test_turn_test_refuses_a_follow_deadband_wider_than_the_deadband_in_one_line():
    EstimatorParams(hysteresis_deadband_lsb=0.3)                      # turn test off: not read
    with pytest.raises(ValueError, match="hysteresis_follow_lsb = 0.5 must not exceed") as exc:
        EstimatorParams(hysteresis_turn_lsb=1.75, hysteresis_deadband_lsb=0.3)
    assert "\n" not in str(exc.value)
