"""compute_metrics in one pass gives the numbers of the per-character implementation, exactly."""
import numpy as np
import pytest

from ebraille_sim.scenarios import metrics as M
from ebraille_sim.scenarios.runner import run_scenario


def _reference_settling(t_s, force_n, setpoint_n, band_fraction, hold_s=M.SETTLE_HOLD_S):
    touch = np.nonzero(np.asarray(force_n) > M.CONTACT_THRESHOLD_N)[0]
    if touch.size == 0:
        return None
    ok = M.in_band(force_n, setpoint_n, band_fraction)
    dt = t_s[1] - t_s[0] if len(t_s) > 1 else 0.0
    need = max(1, int(round(hold_s / dt))) if dt > 0 else 1
    run = 0
    for k in range(touch[0], len(ok)):
        run = run + 1 if ok[k] else 0
        if run >= need:
            return float(t_s[k - need + 1] - t_s[touch[0]])
    return None


def _reference_char_fraction(trace, band_fraction):
    """The per-character loop (one pass over the trace per character)."""
    ci = np.asarray(trace["char_index"])
    ok = M.in_band(trace["force_true_n"], trace["setpoint_n"], band_fraction)
    chars = np.unique(ci[ci >= 0])
    if not chars.size:
        return None
    good = sum(1 for c in chars if np.mean(ok[ci == c]) >= M.CHAR_IN_BAND_REQUIRED)
    return good / chars.size


@pytest.mark.parametrize("name, duration", [("steady_90wpm", 6.0), ("refresh_60wpm", 6.0),
                                            ("setpoint_steps", 8.0), ("tremor_90wpm", 5.0)])
def test_metrics_equal_the_per_character_implementation(name, duration):
    res = run_scenario(name, duration_s=duration, seed=2)
    tr = res.trace
    band = res.spec.setpoint.band_fraction
    m = res.metrics
    if res.spec.reading.mode != "refresh":
        assert m["char_in_band_fraction"] == _reference_char_fraction(tr, band)
    assert m["settling_time_s"] == _reference_settling(tr["t_s"], tr["force_true_n"], tr["setpoint_n"], band)
    assert m["characters"] > 5 and m["char_in_band_fraction"] is not None


def test_synthetic_traces_cover_every_branch():
    rng = np.random.default_rng(0)
    for case in range(60):
        n = int(rng.integers(1, 400))
        t = (np.arange(n) + 1) * 1e-2
        sp = np.full(n, 1.0)
        f = 1.0 + rng.normal(0, [0.01, 0.1, 0.5][case % 3], n)
        f[: int(rng.integers(0, n + 1))] = 0.0                     # contact late or never
        ci = np.sort(rng.integers(-1, int(rng.integers(0, 30)) + 1, n))
        ci[rng.random(n) < 0.1] = -1
        tr = {"t_s": t, "force_true_n": f, "force_est_n": f, "setpoint_n": sp, "energy_j": np.zeros(n),
              "char_index": ci}
        m = M.compute_metrics(tr, 0.5, 0.1)
        assert m["char_in_band_fraction"] == _reference_char_fraction(tr, 0.1)
        assert M.settling_time(t, f, sp, 0.1, hold_s=0.05) == _reference_settling(t, f, sp, 0.1, hold_s=0.05)
        assert m["settling_time_s"] == _reference_settling(t, f, sp, 0.1)


@pytest.mark.parametrize("name, duration", [("steady_90wpm", 8.0), ("refresh_60wpm", 6.0), ("everyday_session", 20.0)])
def test_compiled_legibility_pass_equals_the_whole_run_evaluation(name, duration):
    from ebraille_sim.scenarios import legibility as L
    res = run_scenario(name, duration_s=duration, seed=4)
    tr = res.trace
    ci = tr["char_index"]
    if res.spec.reading.mode == "refresh":
        from ebraille_sim.scenarios.inputs import refresh_phases
        ci = np.where(refresh_phases(res.spec, res.schedule, tr["t_s"])[1], ci, -1)
    got = L.legibility_metrics(tr["force_true_n"], tr["setpoint_n"], ci, res.schedule.cells)
    for key, params in (("legible_char_fraction", L.DEFAULT), ("legible_char_fraction_cv", L.CONSTANT_VOLTAGE)):
        whole = L.character_legibility(tr["force_true_n"], tr["setpoint_n"], ci, res.schedule.cells, params)
        assert got[key] == whole["legible_char_fraction"] == res.metrics[key], key
    assert got["legible_char_fraction"] is not None


def test_in_band_in_chunks_equals_the_whole_array_expression():
    rng = np.random.default_rng(5)
    n = 3 * M.IN_BAND_CHUNK + 17
    sp = np.repeat(rng.uniform(0.2, 2.0, n // 1000 + 1), 1000)[:n]
    f = sp * rng.normal(1.0, 0.1, n)
    f[::97] = sp[::97] * 1.1                                   # on the band's edge
    whole = np.abs(f - sp) <= 0.1 * sp
    got = M.in_band(f, sp, 0.1)
    assert got.dtype == bool and got.shape == (n,) and np.array_equal(got, whole)
    assert 0.5 < got.mean() < 0.8
    assert np.array_equal(M.in_band(f[:10], 1.0, 0.1), np.abs(f[:10] - 1.0) <= 0.1)   # a scalar setpoint


def test_error_metrics_in_place_give_the_bits_of_the_plain_expressions():
    rng = np.random.default_rng(6)
    n = 5000
    t = (np.arange(n) + 1) * 1e-3
    sp = np.full(n, 1.0)
    f = 1.0 + rng.normal(0, 0.05, n)
    fe = f + rng.normal(0, 0.02, n)
    tr = {"t_s": t, "force_true_n": f, "force_est_n": fe, "setpoint_n": sp, "energy_j": np.zeros(n),
          "char_index": np.full(n, -1)}
    m = M.compute_metrics(tr, 1.0, 0.1)
    read = t >= 1.0
    err = f[read] - sp[read]
    assert m["force_rmse_n"] == float(np.sqrt(np.mean(err ** 2)))
    assert m["force_mae_n"] == float(np.mean(np.abs(err)))
    assert m["estimate_rmse_n"] == float(np.sqrt(np.mean((fe[read] - f[read]) ** 2)))
