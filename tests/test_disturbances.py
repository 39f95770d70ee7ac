"""Disturbance profiles: validation, the physics of each profile, and their closed-loop effect."""
import dataclasses
import math

import numpy as np
import pytest

from ebraille_sim.scenarios import disturbances as D
from ebraille_sim.scenarios import faults as F
from ebraille_sim.scenarios import mechanism_section as M
from ebraille_sim.physics.params import DeviceParams
from ebraille_sim.scenarios.runner import run_scenario
from ebraille_sim.scenarios.spec import ScenarioError, parse_scenario

DT = 1e-3
T = np.arange(0, 60_000) * DT          # 60 s at the control rate
NOMINAL = DeviceParams()


def profiles(section, t=T, seed=0, device=NOMINAL):
    return D.build_inputs(D.validate_section("test", section), t, np.random.default_rng(seed), device)


# ---------------------------------------------------------------- validation

@pytest.mark.parametrize("section, fragment", [
    ({"wind": {}}, ("unknown key 'wind' in [disturbances]; allowed: battery, fsr_drift, fsr_temperature, "
                    "orientation, pressing, strap_slip, tremor")),
    ({"tremor": {"rms": 1e-5}}, "unknown key 'rms' in [disturbances.tremor]; allowed: band_hz, rms_m, transmission"),
    ({"tremor": {"rms_m": 0.01}}, "[disturbances.tremor] rms_m = 0.01 is out of range [0, 0.0002]"),
    ({"tremor": {"band_hz": [12, 8]}}, "band_hz must have low < high"),
    ({"tremor": {"band_hz": [8]}}, "band_hz must be a pair"),
    ({"strap_slip": {"at_s": 3.0}}, "at_s must be a list of times"),
    ({"battery": {"cells_series": 1.5}}, "cells_series must be a whole number"),
    ({"battery": {"soc_start": "full"}}, "soc_start must be a number"),
    ({"orientation": {"at_s": 5.0, "return_at_s": 5.2}}, "return_at_s = 5.2 must be at least"),
    ({"fsr_temperature": {"skin_c": math.inf}}, "skin_c must be finite"),
    ({"tremor": {"band_hz": [10.0, 10.000001]}}, "band_hz = [10, 10.000001] is 1e-06 Hz wide, narrower than 0.01 Hz"),
    ({"pressing": {"band_hz": [0.5, 0.505]}}, "needs a record of 4/width = 800 s"),
])
def test_bad_sections_give_one_line_errors(section, fragment):
    with pytest.raises(ScenarioError) as exc:
        D.validate_section("f.toml", section)
    msg = str(exc.value)
    assert fragment in msg and "\n" not in msg and msg.startswith("f.toml: ")


def test_scenario_parser_delegates_to_the_module():
    with pytest.raises(ScenarioError, match=r"x.toml: unknown key 'gust' in \[disturbances\]"):
        parse_scenario({"name": "x", "disturbances": {"gust": {}}}, source="x.toml")
    spec = parse_scenario({"name": "x", "disturbances": {"tremor": {"rms_m": 2e-5}}})
    assert spec.sections["disturbances"]["tremor"].rms_m == 2e-5


def test_every_parameter_has_unit_range_and_tagged_source():
    rows = D.parameter_table()
    assert {r[0] for r in rows} == set(D.KINDS)
    for kind, key, default, unit, rng, source in rows:
        assert unit and rng.startswith("[")
        assert any(tag in source for tag in ("[R]", "[D]", "[E]", "[M]")), (kind, key, source)


# ---------------------------------------------------------------- profiles

def _band_power_fraction(x, lo, hi):
    f = np.fft.rfftfreq(len(x), DT)
    p = np.abs(np.fft.rfft(x)) ** 2
    return p[(f >= lo) & (f <= hi)].sum() / p.sum()


def test_tremor_has_the_stated_rms_and_band():
    mode, x = profiles({"tremor": {"rms_m": 20e-6}})["finger_pos_m"]
    assert mode == "add"
    assert np.std(x) == pytest.approx(20e-6, rel=1e-9)
    assert _band_power_fraction(x, 8.0, 12.0) > 0.999
    _, y = profiles({"tremor": {"rms_m": 20e-6, "transmission": 0.25}})["finger_pos_m"]
    np.testing.assert_allclose(y, 0.25 * x)


def test_pressing_is_slow():
    _, x = profiles({"pressing": {}})["finger_pos_m"]
    assert np.std(x) == pytest.approx(0.1e-3, rel=0.05)
    assert _band_power_fraction(x, 0.1, 1.0) > 0.999


def test_noise_record_beyond_the_memory_bound_is_refused_before_allocating():
    t = np.arange(10) * 1e-6                         # a 1 MHz control rate
    with pytest.raises(ValueError, match=r"band \[0.1, 1\] Hz needs a record of 40 s .* = 4e\+07 samples at 1e\+06 Hz"):
        D.band_limited_noise(t, 0.1, 1.0, 1e-4, np.random.default_rng(0))
    with pytest.raises(ValueError, match="is empty"):
        D.band_limited_noise(np.arange(10) * 1e-3, 5.0, 5.0, 1e-4, np.random.default_rng(0))
    # the bound sits above every shipped band at the 1 kHz control rate: 4/0.1 Hz = 40 s = 4e4 samples
    assert D.MAX_NOISE_RECORD_SAMPLES > 4.0 / D.MIN_BAND_WIDTH_HZ / 1e-3


def test_noise_record_shorter_than_the_band_period_keeps_its_rms_on_average():
    t = np.arange(500) * DT                      # 0.5 s, shorter than one period at 0.1 Hz
    vals = [np.std(D.band_limited_noise(t, 0.1, 1.0, 1.0, np.random.default_rng(s))) for s in range(40)]
    assert 0.0 < np.mean(vals) < 1.0             # a short window sees part of a slow process
    with pytest.raises(ValueError, match="Nyquist"):
        D.band_limited_noise(t, 100.0, 600.0, 1.0, np.random.default_rng(0))


def test_noise_is_scaled_to_its_rms_over_the_record():
    """The RMS taken from the spectrum (Parseval) is the record's: a run as long as the record
    has the RMS asked for, to round-off, whether the record has an even or odd length."""
    for n in (1440, 1215):                       # records of their own length (2^5 3^2 5 and 3^5 5)
        x = D.band_limited_noise(np.arange(n) * 5e-3, 8.0, 12.0, 1e-4, np.random.default_rng(n))
        assert x.size == n and np.std(x) == pytest.approx(1e-4, rel=1e-12)
        assert abs(np.mean(x)) < 1e-18


def test_noise_records_have_fast_lengths():
    """A run of a prime number of periods synthesises its noise over the next record whose
    length has no prime factor above 5, and keeps the RMS asked for over it."""
    assert [D.fast_length(n) for n in (1, 7, 1399, 1441, 8000, 8001)] == [1, 8, 1440, 1458, 8000, 8100]
    x = D.band_limited_noise(np.arange(1399) * 5e-3, 8.0, 12.0, 1e-4, np.random.default_rng(3))
    y = D.band_limited_noise(np.arange(1440) * 5e-3, 8.0, 12.0, 1e-4, np.random.default_rng(3))
    assert np.array_equal(x, y[:1399]) and np.std(y) == pytest.approx(1e-4, rel=1e-12)


def test_strap_slips_are_minimum_jerk_steps():
    _, x = profiles({"strap_slip": {"at_s": [10.0, 20.0], "displacement_m": 0.2e-3, "duration_s": 0.04}})[
        "finger_pos_m"]
    k = lambda t: int(round(t / DT))
    assert x[k(9.99)] == 0.0
    assert x[k(10.02)] == pytest.approx(0.1e-3, rel=1e-9)          # half-way at mid-slip
    assert x[k(15.0)] == pytest.approx(0.2e-3)
    assert x[-1] == pytest.approx(0.4e-3)
    assert np.all(np.diff(x) >= 0)


def test_strap_seats_after_its_maximum_offset():
    from ebraille_sim.scenarios.disturbances import StrapSlip
    t = np.arange(0.0, 3600.0, 0.01)
    x = StrapSlip(rate_per_min=2.0, displacement_m=0.1e-3).inputs(t, np.random.default_rng(1), None)["finger_pos_m"][1]
    assert x.max() == pytest.approx(1e-3) and x[-1] == pytest.approx(1e-3)   # 120 slips would add 12 mm
    assert np.all(np.diff(x) >= 0)
    k = int(np.argmax(x >= 1e-3 - 1e-12))
    assert 0.0 < t[k] < 1200.0 and np.all(x[k:] == x[-1])                   # seated: no further slips
    back = StrapSlip(at_s=(1.0, 2.0, 3.0), displacement_m=-0.5e-3, max_offset_m=1.2e-3).inputs(
        t[:500], np.random.default_rng(0), None)["finger_pos_m"][1]
    assert back[-1] == pytest.approx(-1.2e-3)                                 # both directions
    with pytest.raises(ValueError, match="max_offset_m"):
        profiles({"strap_slip": {"rate_per_min": 2.0, "max_offset_m": -1e-3}})


def test_poisson_slips_follow_the_rate_and_the_seed():
    counts = []
    for seed in range(30):
        _, x = profiles({"strap_slip": {"rate_per_min": 6.0, "displacement_m": 1e-4}}, seed=seed)["finger_pos_m"]
        counts.append(round(x[-1] / 1e-4))
    assert 4.5 < np.mean(counts) < 7.5                              # 6 per minute over 60 s
    a = profiles({"strap_slip": {"rate_per_min": 6.0}}, seed=3)["finger_pos_m"][1]
    b = profiles({"strap_slip": {"rate_per_min": 6.0}}, seed=3)["finger_pos_m"][1]
    np.testing.assert_array_equal(a, b)


def test_orientation_reverses_gravity_and_returns():
    mode, g = profiles({"orientation": {"from_deg": 0.0, "to_deg": 180.0, "at_s": 5.0, "duration_s": 1.0,
                                        "return_at_s": 20.0}})["gravity_along_m_per_s2"]
    assert mode == "set"
    k = lambda t: int(round(t / DT))
    assert g[k(4.0)] == pytest.approx(-9.81)
    assert g[k(5.5)] == pytest.approx(0.0, abs=1e-9)               # 90 deg at mid-move
    assert g[k(10.0)] == pytest.approx(9.81)
    assert g[k(30.0)] == pytest.approx(-9.81)


def test_orientation_starts_from_the_device_posture():
    dev = dataclasses.replace(DeviceParams(), gravity_m_per_s2=9.81 * math.cos(math.radians(60)))
    _, g = profiles({"orientation": {"to_deg": 60.0, "at_s": 1.0}}, device=dev)["gravity_along_m_per_s2"]
    np.testing.assert_allclose(g, -dev.gravity_m_per_s2)


def test_fsr_warms_with_its_time_constant():
    mode, u = profiles({"fsr_temperature": {"start_c": 18.0, "skin_c": 31.0, "reference_c": 25.0,
                                            "tau_s": 20.0}})["fsr_temp_offset_k"]
    assert mode == "set"
    assert u[0] == pytest.approx(-7.0)
    assert u[20_000] == pytest.approx(-7.0 + 13.0 * (1 - math.exp(-1)))
    assert u[-1] == pytest.approx(-7.0 + 13.0 * (1 - math.exp(-T[-1] / 20.0)))


@pytest.mark.parametrize("reference_c", [25.0, 45.0])
def test_session_offset_reproduces_the_creep_law_exactly(reference_c):
    """Warm (+5 K) and cold (-15 K: the temperature law's cold side) runs of a session 1 h in."""
    dev = DeviceParams()
    fsr = dev.fsr
    _, u = profiles({"fsr_drift": {"session_offset_s": 3600.0}, "fsr_temperature": {
        "start_c": 30.0, "skin_c": 30.0, "reference_c": reference_c}})["fsr_temp_offset_k"]
    from ebraille_sim.physics.fsr import held_resistance_factor, temperature_scale
    creep = lambda t: held_resistance_factor(t, fsr)
    kernel_scale = creep(T) * temperature_scale(u, fsr)          # what the kernel applies
    wanted = creep(3600.0 + T) * temperature_scale(np.full(T.size, 30.0 - reference_c), fsr)
    np.testing.assert_allclose(kernel_scale, wanted, rtol=1e-12)


def test_drift_needs_a_temperature_coefficient():
    dev = dataclasses.replace(DeviceParams(), fsr=dataclasses.replace(DeviceParams().fsr, temperature_coeff_per_k=0.0))
    with pytest.raises(ScenarioError, match="negative temperature_coeff_per_k"):
        profiles({"fsr_drift": {}}, device=dev)


def test_battery_thevenin_model_and_cutoff():
    b = D.Battery(soc_start=0.5, load_current_a=0.1, r0_ohm=0.4, r1_ohm=0.2, tau1_s=10.0, capacity_mah=100.0)
    v = b.supply_v(np.array([0.0, 10.0, 1000.0]))
    assert v[0] == pytest.approx(float(D.li_ion_ocv_v(0.5)) - 0.04)
    soc10 = 0.5 - 0.1 * 10 / 360.0
    assert v[1] == pytest.approx(float(D.li_ion_ocv_v(soc10)) - 0.04 - 0.02 * (1 - math.exp(-1)))
    two = dataclasses.replace(b, cells_series=2).supply_v(np.array([0.0]))
    assert two[0] == pytest.approx(2 * v[0])
    _, s = profiles({"battery": {"soc_start": 0.004}})["driver_supply_v"]
    cut = int(np.argmax(s == 0.0))
    assert 20_000 < cut < 40_000 and np.all(s[cut:] == 0.0) and np.all(s[:cut] >= 3.0)


def test_kinds_draw_from_independent_streams():
    a = profiles({"tremor": {}})["finger_pos_m"][1]
    b = profiles({"tremor": {}, "strap_slip": {"rate_per_min": 3.0}, "pressing": {}}, seed=0)
    _, slip = profiles({"strap_slip": {"rate_per_min": 3.0}})["finger_pos_m"]
    _, press = profiles({"pressing": {}})["finger_pos_m"]
    np.testing.assert_allclose(b["finger_pos_m"][1], a + slip + press, atol=1e-15)


# ---------------------------------------------------------------- closed loop

def _spec(dist, duration=12.0, seed=5):
    return parse_scenario({"name": "d", "seed": seed, "duration_s": duration, "reading": {"wpm": 90},
                           "finger": {"gap_m": 1e-3}, "disturbances": dist})


def test_a_slip_away_from_the_board_drops_the_force_then_the_loop_recovers():
    res = run_scenario(_spec({"strap_slip": {"at_s": [6.0], "displacement_m": 0.3e-3}}), supervised=False)
    t, f, fe = res.trace["t_s"], res.trace["force_true_n"], res.trace["force_est_n"]
    before = f[(t > 5.0) & (t < 6.0)].mean()
    assert before == pytest.approx(1.0, abs=0.08)          # the estimate's bias under hereditary creep
    assert f[(t > 6.0) & (t < 6.2)].min() < 0.8                    # 0.3 mm at ~1.5 N/mm
    # the loop restores the estimate; the true force settles on the FSR's other hysteresis
    # branch, within the 10 % hysteresis of the sensor
    assert fe[t > 10.0].mean() == pytest.approx(1.0, abs=0.02)
    assert f[t > 10.0].mean() == pytest.approx(1.0, abs=0.10)


def test_same_seed_same_trace_with_random_disturbances():
    spec = _spec({"tremor": {}, "pressing": {}, "strap_slip": {"rate_per_min": 4.0}}, duration=4.0)
    a, b = run_scenario(spec), run_scenario(spec)
    np.testing.assert_array_equal(a.trace["force_true_n"], b.trace["force_true_n"])
    c = run_scenario(spec, seed=6)
    assert not np.array_equal(a.trace["force_true_n"], c.trace["force_true_n"])


def _held_estimates(section, creep_compensation=True, preload=True, seconds=20.0, device=None):
    """The sensor chain's estimate of a film pressed to 1 N at 0.3 s and held, at 2, 5, 10 and 19 s,
    with the inputs of ``section`` (the ``est_creep_preload`` input zeroed unless ``preload``), on
    ``device`` (default the nominal)."""
    from ebraille_sim.base.validation import replace_checked
    from ebraille_sim.plant import kernel
    from ebraille_sim.plant.layout import N_INPUT, S, U
    from ebraille_sim.plant.lumped import initial_state, pack_params
    base = NOMINAL if device is None else device
    dev = dataclasses.replace(base, estimator=replace_checked(base.estimator, creep_compensation=creep_compensation))
    t = np.arange(0, int(round(seconds / DT))) * DT
    prof = profiles(section, t=t, device=dev) if section else {}
    if not preload:
        prof.pop("est_creep_preload", None)
    p = pack_params(dev, 0)
    s = initial_state(dev, p)
    u = np.zeros(N_INPUT)
    u[U.driver_supply_v] = dev.driver_supply_v
    n_sub = int(round(dev.rates.physics_rate_hz * DT))
    out = {}
    for k in range(t.size):
        for name, (_, arr) in prof.items():
            u[U[name]] = arr[k]
        kernel.advance_sensor_only(s, p, u, 0.0 if t[k] < 0.3 else 1.0, n_sub)
        if k in (2000, 5000, 10000, 19000):
            out[k] = s[S.force_est_n]
    return np.array([out[k] for k in sorted(out)])


def test_a_session_preload_reads_like_a_fresh_film_when_the_firmware_followed_the_session():
    two_hours = {"fsr_drift": {"session_offset_s": 7200.0}}
    fresh = _held_estimates({})
    # the film crept for 2 h and the firmware's compensation advanced by the same session
    np.testing.assert_allclose(_held_estimates(two_hours), fresh, rtol=5e-3)
    # a firmware that had not followed it would read the crept film 6-9 % high (the creep goes on
    # for days: 2 h of it is 9-10 % more conductance than 2-19 s)
    stale = _held_estimates(two_hours, preload=False) / fresh
    assert np.all((stale > 1.055) & (stale < 1.095))
    # without any creep compensation the crept film reads high too
    raw = _held_estimates(two_hours, creep_compensation=False) / _held_estimates({}, creep_compensation=False)
    assert np.all(raw > 1.015)


def test_a_low_creep_unit_s_session_preload_follows_the_creep_its_bench_measured():
    """The firmware compensates a unit's creep with the creep per decade its bench measured; the
    session it followed is advanced by the same law.  A unit creeping 1.2 % per decade (the
    nominal film 2.75 %), bench-measured as such, 2 h into a session reads like a fresh film; the
    nominal film's law for the session alone read it 2.8-4.2 % low."""
    from ebraille_sim.base.validation import replace_checked
    slow = dataclasses.replace(NOMINAL, fsr=replace_checked(NOMINAL.fsr, creep_per_decade=0.012),
                               estimator=replace_checked(NOMINAL.estimator, creep_per_decade=0.012))
    two_hours = {"fsr_drift": {"session_offset_s": 7200.0}}
    fresh = _held_estimates({}, device=slow)
    np.testing.assert_allclose(_held_estimates(two_hours, device=slow), fresh, rtol=5e-3)


def test_tremor_raises_the_tracking_error():
    quiet = run_scenario(_spec({}, duration=10.0)).metrics["force_rmse_n"]
    shaky = run_scenario(_spec({"tremor": {"rms_m": 30e-6}}, duration=10.0)).metrics["force_rmse_n"]
    assert shaky > 1.4 * quiet


def _sections():
    """Every shipped scenario's delegate sections, one of each disturbance and fault kind, a
    mechanism section and drawn episodes."""
    import pathlib
    from ebraille_sim.scenarios.episodes import EpisodeDistribution
    from ebraille_sim.scenarios.spec import load_scenario
    specs = [load_scenario(p) for p in sorted(pathlib.Path(D.__file__).parents[2].joinpath("scenarios").glob("*.toml"))]
    specs += [EpisodeDistribution(battery_probability=p).draw(np.random.SeedSequence(s))
              for s in range(6) for p in (0.0, 1.0)]
    for spec in specs:
        yield spec.device, spec.sections
    yield DeviceParams(), {"disturbances": D.validate_section("t", {k: {} for k in D.KINDS})}
    yield DeviceParams(), {"faults": F.validate_section("t", [
        {"kind": k, "start_s": 0.1, "duration_s": 0.2, **({"value_v": 1.0} if k == "fsr_value" else {})}
        for k in F.KINDS])}
    yield DeviceParams(), {"mechanism": M.validate_section("t", {"press_offset_m": 1e-3})}


def test_every_section_module_names_the_inputs_it_builds():
    import importlib
    from ebraille_sim.scenarios.spec import DELEGATES
    t = np.arange(200) * 1e-3
    seen = set()
    for device, sections in _sections():
        for key, section in sections.items():
            mod = importlib.import_module(DELEGATES[key])
            if not hasattr(mod, "build_inputs"):
                continue
            built = mod.build_inputs(section, t, np.random.default_rng(0), device)
            assert tuple(mod.driven_inputs(section)) == tuple(built), key
            seen.update(built)
    assert {"finger_pos_m", "driver_supply_v", "gravity_along_m_per_s2", "fsr_temp_offset_k", "est_creep_preload",
            "fsr_fault", "fsr_fault_value", "motor_jammed", "press_offset_m"} <= seen
    for kind in D.KINDS.values():
        if hasattr(kind, "inputs"):
            assert tuple(kind().inputs(t, np.random.default_rng(1), DeviceParams())) == kind.drives


def test_profiles_are_rows_of_one_table_with_the_values_of_separate_arrays():
    from ebraille_sim.scenarios.draws import generator_of, run_numbers
    from ebraille_sim.scenarios.inputs import build_run_inputs, profile_table
    from ebraille_sim.scenarios.spec import load_scenario
    spec = load_scenario("everyday_session")
    run = build_run_inputs(spec)
    n = run.n_steps
    assert list(run.profiles) == ["est_creep_preload", "finger_pos_m", "fsr_temp_offset_k"]
    assert profile_table(run.profiles, n) is not None                     # no copy for the loop
    # the same profiles as separate arrays, the finger's summed as constant + (pressing + slips)
    built = D.build_inputs(spec.sections["disturbances"], run.t_s[:n], generator_of(run_numbers(spec.seed)[2]),
                           spec.device)
    assert np.array_equal(run.profiles["finger_pos_m"], spec.finger.gap_m + built["finger_pos_m"][1])
    for name in ("est_creep_preload", "fsr_temp_offset_k"):
        assert np.array_equal(run.profiles[name], built[name][1])


def test_a_section_that_builds_an_input_it_did_not_name_is_refused(monkeypatch):
    from ebraille_sim.scenarios import mechanism_section
    from ebraille_sim.scenarios.inputs import build_run_inputs
    from ebraille_sim.scenarios.spec import ScenarioError, load_scenario
    spec = load_scenario("steady_90wpm")
    spec = dataclasses.replace(spec, sections={"mechanism": M.validate_section("t", {"press_offset_m": 1e-3})})
    assert "press_offset_m" in build_run_inputs(spec).profiles
    monkeypatch.setattr(mechanism_section, "driven_inputs", lambda section: ("press_offset_m",))
    with pytest.raises(ScenarioError, match="drives 'finger_tilt_rad', which its module's driven_inputs does not name"):
        build_run_inputs(spec)


def test_a_section_that_names_an_input_it_does_not_build_is_refused(monkeypatch):
    from ebraille_sim.scenarios import mechanism_section
    from ebraille_sim.scenarios.inputs import build_run_inputs
    from ebraille_sim.scenarios.spec import load_scenario
    spec = load_scenario("steady_90wpm")
    spec = dataclasses.replace(spec, sections={"mechanism": M.validate_section("t", {"press_offset_m": 1e-3})})
    names = mechanism_section.driven_inputs({})
    monkeypatch.setattr(mechanism_section, "driven_inputs", lambda section: names + ("motor_jammed",))
    with pytest.raises(ScenarioError, match="names 'motor_jammed' in driven_inputs but does not drive it"):
        build_run_inputs(spec)
