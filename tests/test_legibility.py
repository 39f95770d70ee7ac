"""Electrode-skin contact, stimulation intensity and the legibility metric."""
import dataclasses
import math

import numpy as np
import pytest

from ebraille_sim.scenarios import legibility as L
from ebraille_sim.scenarios.braille import Cell, text_to_cells
from ebraille_sim.scenarios.runner import run_scenario
from ebraille_sim.scenarios.spec import parse_scenario

P = L.LegibilityParams()


def test_contact_area_follows_the_measured_power_law():
    for f in (0.2, 1.0, 3.0):
        area = float(L.contact_area_m2(f))
        assert area == pytest.approx(P.contact_area_1n_m2 * f ** P.contact_area_exponent, rel=1e-12)
        assert math.pi * float(L.contact_radius_m(f)) ** 2 == pytest.approx(area, rel=1e-12)
    assert float(L.contact_area_m2(8.0)) == pytest.approx(2 * float(L.contact_area_m2(1.0)))    # n = 1/3
    assert float(L.contact_area_m2(0.0)) == 0.0 == float(L.contact_radius_m(-1.0))


def test_overlap_area_against_sampling():
    rng = np.random.default_rng(1)
    r = 0.6e-3
    for d, a in ((0.0, 2e-3), (2.6e-3, 3.0e-3), (3.0e-3, 2.5e-3), (5e-3, 1e-3)):
        exact = float(L._overlap_area(np.array([d]), r, np.array([a]))[0])
        pts = rng.uniform(-r, r, size=(200_000, 2))
        pts = pts[np.hypot(*pts.T) <= r]
        inside = np.hypot(pts[:, 0] + d, pts[:, 1]) <= a
        assert exact == pytest.approx(np.mean(inside) * math.pi * r * r, abs=0.01 * math.pi * r * r)


def _force_for_radius(a, params=P):
    """Force (N) at which the contact disc has radius ``a`` (m)."""
    return (math.pi * a * a / params.contact_area_1n_m2) ** (1.0 / params.contact_area_exponent)


def test_coverage_grows_from_the_centre_row_outwards():
    r = 0.5 * P.electrode_diameter_m
    corner = math.hypot(0.5 * P.pitch_m, P.pitch_m)                       # 2.68 mm from the centre
    f_in, f_out = _force_for_radius(corner + r), _force_for_radius(corner - r)
    assert 0.03 < f_in < 0.04 and 0.002 < f_out < 0.003                 # full from 39 mN: well below reading forces
    cov = L.coverage(np.array([0.9 * f_out, 0.5 * (f_in + f_out), 1.001 * f_in, 0.2, 1.0]))
    assert cov.shape == (5, 6)
    centre, corners = [1, 4], [0, 2, 3, 5]                              # dots 2, 5 sit 1.2 mm from the centre
    assert np.all(cov[0, centre] == 1.0) and np.all(cov[0, corners] == 0.0)
    assert np.all((cov[1, corners] > 0.2) & (cov[1, corners] < 0.8))
    assert np.all(cov[2:] == 1.0)


def test_impedance_law():
    for f in (0.2, 1.0, 3.0):
        p = f / float(L.contact_area_m2(f))
        z = P.impedance_pressed_ohm + P.impedance_interface_ohm * P.reference_pressure_pa / p
        assert float(L.impedance_ohm(f)) == pytest.approx(z, rel=1e-12)
    assert float(L.impedance_ohm(1.0)) == pytest.approx(80e3, rel=1e-12)       # p(1 N) = p_ref
    z_touch = float(L.impedance_ohm(P.touch_force_n))
    assert float(L.impedance_ohm(0.0)) == z_touch == float(L.impedance_ohm(-1.0)) and z_touch > 1e6
    z = L.impedance_ohm(np.linspace(0.0, 5.0, 501))
    assert np.all(np.diff(z[1:]) < 0) and z[-1] > P.impedance_pressed_ohm


def test_constant_current_is_nominal_until_the_compliance_limit():
    r = L.relative_intensity(np.array([1.0, 2.0, 0.2, 0.1]), 1.0)
    assert np.all(r[0] == 1.0) and np.all(r[1] == 1.0)              # more force: same current density
    for k, f in ((2, 0.2), (3, 0.1)):                                # V_c / Z(F) < I_0 below 0.27 N
        z = float(L.impedance_ohm(f))
        np.testing.assert_allclose(r[k], P.compliance_v / z / P.current_a, rtol=1e-12)
    f_limit = ((P.impedance_interface_ohm / (P.compliance_v / P.current_a - P.impedance_pressed_ohm))
               ** 1.5)                                               # Z(F) = V_c / I_0 with k = 1, n = 1/3
    assert f_limit == pytest.approx(0.269, abs=1e-3)
    assert np.all(L.relative_intensity(np.array([1.001 * f_limit]), 1.0) == 1.0)
    assert np.all(L.relative_intensity(np.array([0.999 * f_limit]), 1.0) < 1.0)


def test_a_peeling_electrode_feels_stronger_under_constant_current():
    high = dataclasses.replace(P, compliance_v=1e5)
    f = np.array([0.02])                                            # corners partly inside the patch
    r = L.relative_intensity(f, 1.0, high)[0]
    phi = L.coverage(f, high)[0]
    assert np.all((phi[[0, 2, 3, 5]] > 0.3) & (phi[[0, 2, 3, 5]] < 0.9))
    np.testing.assert_allclose(r[[0, 2, 3, 5]], 1.0 / phi[[0, 2, 3, 5]])
    assert np.all(r[[0, 2, 3, 5]] > 1.1) and np.all(r[[1, 4]] == 1.0)


def test_constant_voltage_follows_the_impedance():
    cv = L.CONSTANT_VOLTAGE
    f = np.array([0.8, 1.0, 1.3])
    r = L.relative_intensity(f, 1.0, cv)
    np.testing.assert_allclose(r[:, 1], L.impedance_ohm(1.0, cv) / L.impedance_ohm(f, cv))


def test_character_legibility_counts_dropouts_and_skips_spaces():
    cells = text_to_cells("ab c")                         # a, b, space, c
    n = 100
    ci = np.repeat(np.arange(4), n)
    force = np.ones(4 * n)
    sp = np.ones(4 * n)
    out = L.character_legibility(force, sp, ci, cells, L.CONSTANT_VOLTAGE)
    assert out["legible_char_fraction"] == 1.0 and set(out["legible_by_char"]) == {0, 1, 3}
    force[n + 20:n + 60] = 0.4                          # 40 % of "b" at 40 % force: dots fade
    out = L.character_legibility(force, sp, ci, cells, L.CONSTANT_VOLTAGE)
    assert out["legible_char_fraction"] == pytest.approx(2 / 3)
    assert out["legible_by_char"][1] == pytest.approx(0.6)
    force[:] = 1.0
    force[2 * n:3 * n] = 0.0                            # losing contact on the space does not matter
    assert L.character_legibility(force, sp, ci, cells)["legible_char_fraction"] == 1.0
    empty = L.character_legibility(force, sp, np.full(4 * n, -1), cells)
    assert empty["legible_char_fraction"] is None


def test_run_reports_legibility_beside_the_force_metrics():
    res = run_scenario("contact_onset")
    for k in L.METRIC_NAMES:
        assert k in res.metrics
    assert res.metrics["legible_char_fraction"] == 1.0
    lost = parse_scenario({"name": "x", "duration_s": 8.0, "seed": 2, "reading": {"wpm": 90},
                           "finger": {"gap_m": 1e-3},
                           "disturbances": {"strap_slip": {"at_s": [4.0], "displacement_m": 1.5e-3}}})
    m = run_scenario(lost).metrics
    assert m["contact_loss_count"] >= 1
    assert m["legible_char_fraction"] < 1.0 and m["legible_char_fraction_cv"] < 1.0


def test_params_reject_nonsense():
    with pytest.raises(ValueError, match="mode must be"):
        L.LegibilityParams(mode="pulsed")
    with pytest.raises(ValueError, match="dynamic_range must be > 1"):
        L.LegibilityParams(dynamic_range=1.0)
    with pytest.raises(ValueError, match="current_a must be finite and > 0"):
        L.LegibilityParams(current_a=-1.0)


# --- the compiled laws and pass against the numpy implementation they replaced ---

def _ref_contact_area_m2(force_n, params):
    f = np.asarray(force_n, dtype=float)
    return np.where(f > 0, params.contact_area_1n_m2 * np.where(f > 0, f, 1.0) ** params.contact_area_exponent, 0.0)


def _ref_contact_radius_m(force_n, params):
    return np.sqrt(_ref_contact_area_m2(force_n, params) / np.pi)


def _ref_overlap_area(d, r, a):
    d, a = np.broadcast_arrays(np.asarray(d, float), np.asarray(a, float))
    out = np.zeros(d.shape)
    small = np.minimum(r, a)
    inside = d <= np.abs(a - r)
    out[inside] = np.pi * small[inside] ** 2
    part = (~inside) & (d < a + r) & (a > 0)
    if np.any(part):
        dd, aa = d[part], a[part]
        c1 = np.clip((dd ** 2 + r ** 2 - aa ** 2) / (2 * dd * r), -1.0, 1.0)
        c2 = np.clip((dd ** 2 + aa ** 2 - r ** 2) / (2 * dd * aa), -1.0, 1.0)
        k = (-dd + r + aa) * (dd + r - aa) * (dd - r + aa) * (dd + r + aa)
        out[part] = r ** 2 * np.arccos(c1) + aa ** 2 * np.arccos(c2) - 0.5 * np.sqrt(np.maximum(k, 0.0))
    return out


def _ref_coverage(force_n, params):
    a = _ref_contact_radius_m(force_n, params)[..., None]
    d = np.hypot(*L.electrode_centres_m(params).T)
    r = 0.5 * params.electrode_diameter_m
    return _ref_overlap_area(np.broadcast_to(d, a.shape[:-1] + (6,)), r, np.broadcast_to(a, a.shape[:-1] + (6,))) \
        / (math.pi * r * r)


def _ref_impedance_ohm(force_n, params):
    f = np.maximum(np.asarray(force_n, dtype=float), params.touch_force_n)
    p = f / _ref_contact_area_m2(f, params)
    return params.impedance_pressed_ohm + params.impedance_interface_ohm \
        * (params.reference_pressure_pa / p) ** params.pressure_exponent


def _ref_current_a(force_n, phi, params, setpoint_n):
    z = _ref_impedance_ohm(force_n, params)[..., None]
    if params.mode == "constant_current":
        return np.minimum(params.current_a, params.compliance_v * phi / z)
    v0 = params.current_a * _ref_impedance_ohm(setpoint_n, params)[..., None]
    return v0 * phi / z


def _ref_relative_intensity(force_n, setpoint_n, params):
    force_n = np.asarray(force_n, dtype=float)
    setpoint_n = np.broadcast_to(np.asarray(setpoint_n, dtype=float), force_n.shape)
    phi = _ref_coverage(force_n, params)
    area = math.pi * (0.5 * params.electrode_diameter_m) ** 2
    i = _ref_current_a(force_n, phi, params, setpoint_n)
    j = np.divide(i, phi * area, out=np.zeros_like(i), where=phi > 1e-12)
    ones = np.ones(setpoint_n.shape + (1,))
    j_nom = _ref_current_a(setpoint_n, ones, params, setpoint_n) / area
    return j / j_nom


def _ref_legible_fraction(force_n, setpoint_n, char_index, cells, params):
    ci = np.asarray(char_index)
    sel = ci >= 0
    if not sel.any():
        return None
    masks = np.array([c.mask for c in cells], dtype=np.int64)
    idx = ci[sel]
    dots = ((masks[idx][:, None] >> np.arange(6)) & 1).astype(bool)
    ratio = _ref_relative_intensity(np.asarray(force_n)[sel], np.asarray(setpoint_n)[sel], params)
    lo, hi = params.band
    ok = np.all(((ratio >= lo) & (ratio <= hi)) | ~dots, axis=1)
    n_ok = np.bincount(idx, weights=ok.astype(float), minlength=len(cells))
    n_all = np.bincount(idx, minlength=len(cells))
    shown = np.unique(idx[dots.any(axis=1)])
    if shown.size == 0:
        return None
    return float(np.mean(n_ok[shown] / n_all[shown] >= LEGIBLE_REQUIRED))


LEGIBLE_REQUIRED = L.LEGIBLE_REQUIRED
OFFSET = dataclasses.replace(P, array_offset_x_m=1.5e-3, electrode_diameter_m=1.4e-3)    # another geometry
TIGHT_CV = dataclasses.replace(L.CONSTANT_VOLTAGE, dynamic_range=1.3, pressure_exponent=0.7,
                               contact_area_exponent=0.45)
OTHER_Z = dataclasses.replace(L.CONSTANT_VOLTAGE, pressure_exponent=0.7)   # default geometry, another impedance law


def _edge_forces(params):
    """Forces where the contact circle passes through an electrode centre or touches an
    electrode's edge from outside or inside, and zero/negative forces."""
    r = 0.5 * params.electrode_diameter_m
    radii = [a for d in np.unique(np.round(np.hypot(*L.electrode_centres_m(params).T), 15))
             for a in (d, d - r, d + r) if a > 0]
    return np.array([_force_for_radius(a, params) for a in radii]
                    + [0.0, -0.5, 1e-12, params.touch_force_n, 0.5 * params.touch_force_n])


def _random_reading(rng, n_cells, n):
    """Random cells (masks 0..63, some without raised dots) shown in runs of 40 samples with
    -1 gaps; forces near setpoints of 0.1-2 N (the corner electrodes leave the contact below
    0.04 N) except for a share of each character's samples (0-20 %, around the 10 % a
    character may lose) at random, zero, negative and edge forces."""
    masks = rng.integers(0, 64, n_cells)
    masks[rng.random(n_cells) < 0.2] = 0
    cells = [Cell(char="x", dots=tuple(k + 1 for k in range(6) if m >> k & 1), mask=int(m),
                  kind="letter" if m else "space") for m in masks]
    runs = n // 40 + 1
    ci = np.repeat(rng.integers(-1, n_cells, runs), 40)[:n]
    sp = np.repeat(rng.uniform(0.1, 2.0, runs), 40)[:n]
    f = sp * rng.normal(1.0, 0.04, n)
    bad = rng.random(n) < rng.uniform(0.0, 0.2, n_cells)[ci]
    f[bad] = rng.uniform(-0.2, 3.5, bad.sum())
    edge = bad & (rng.random(n) < 0.5)
    f[edge] = rng.choice(_edge_forces(P), edge.sum())
    return f, sp, ci, cells


def test_compiled_laws_equal_the_numpy_reference_on_random_and_edge_forces():
    rng = np.random.default_rng(7)
    for params in (P, L.CONSTANT_VOLTAGE, OFFSET, TIGHT_CV):
        f = np.concatenate([rng.uniform(-0.5, 4.0, 5000), _edge_forces(params)])
        sp = rng.uniform(0.2, 3.0, f.size)
        # the same libm transcendentals and operation order give the same bits on this build;
        # the tolerance only admits a SIMD arccos/exp in another numpy build
        np.testing.assert_allclose(L.contact_radius_m(f, params), _ref_contact_radius_m(f, params),
                                   rtol=1e-14, atol=0)
        np.testing.assert_allclose(L.impedance_ohm(f, params), _ref_impedance_ohm(f, params), rtol=1e-14, atol=0)
        np.testing.assert_allclose(L.coverage(f, params), _ref_coverage(f, params), rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(L.relative_intensity(f, sp, params), _ref_relative_intensity(f, sp, params),
                                   rtol=1e-12, atol=1e-12)
        assert L.relative_intensity(f.reshape(-1, 1), 1.0, params).shape == (f.size, 1, 6)
    d = rng.uniform(0, 5e-3, 2000)
    a = np.concatenate([rng.uniform(0, 5e-3, 1990), [0.0, 0.6e-3, 1e-3, 1e-3, 2e-3, 0.0, 0.6e-3, 1.6e-3, 0.4e-3, 3e-3]])
    d[-10:] = [0.0, 0.0, 0.4e-3, 1.6e-3, 1.4e-3, 0.6e-3, 1.2e-3, 1.0e-3, 1.0e-3, 2.4e-3]   # inside / tangent cases
    np.testing.assert_allclose(L._overlap_area(d, 0.6e-3, a), _ref_overlap_area(d, 0.6e-3, a), rtol=1e-12, atol=1e-18)
    assert float(L.contact_radius_m(0.0)) == 0.0 and np.all(L.coverage(np.array([0.0, -1.0])) == 0.0)


@pytest.mark.parametrize("seed", range(6))
def test_compiled_legibility_pass_equals_the_numpy_reference(seed):
    rng = np.random.default_rng(seed)
    f, sp, ci, cells = _random_reading(rng, int(rng.integers(1, 40)), int(rng.integers(1, 6000)))
    got = L.legibility_metrics(f, sp, ci, cells)
    assert got == {"legible_char_fraction": _ref_legible_fraction(f, sp, ci, cells, L.DEFAULT),
                   "legible_char_fraction_cv": _ref_legible_fraction(f, sp, ci, cells, L.CONSTANT_VOLTAGE)}
    # stimulators with another geometry are counted in their own pass, one with another
    # impedance law in the same pass gets its own impedance; order kept
    params = [OFFSET, L.DEFAULT, TIGHT_CV, OTHER_Z, OFFSET, L.CONSTANT_VOLTAGE]
    assert L._legible_fractions(f, sp, ci, cells, params) == \
        [_ref_legible_fraction(f, sp, ci, cells, p) for p in params]
    assert L._legible_fractions(f, sp, ci, cells, [TIGHT_CV]) == [_ref_legible_fraction(f, sp, ci, cells, TIGHT_CV)]
    for p in (L.DEFAULT, TIGHT_CV):
        assert L.character_legibility(f, sp, ci, cells, p)["legible_char_fraction"] == \
            _ref_legible_fraction(f, sp, ci, cells, p)


def test_legibility_pass_covers_the_threshold_and_the_edge_cases():
    cells = text_to_cells("ab c")                         # a, b, space, c
    n = 100
    ci = np.repeat(np.arange(4), n)
    sp = np.ones(4 * n)
    for bad, expected in ((10, 1.0), (11, 2 / 3)):         # 90 % of the window legible is enough, 89 % is not
        f = np.ones(4 * n)
        f[n:n + bad] = 0.4
        got = L.legibility_metrics(f, sp, ci, cells)
        assert got["legible_char_fraction_cv"] == pytest.approx(expected) == \
            _ref_legible_fraction(f, sp, ci, cells, L.CONSTANT_VOLTAGE)
        assert got["legible_char_fraction"] == 1.0
    none = {"legible_char_fraction": None, "legible_char_fraction_cv": None}
    assert L.legibility_metrics(np.ones(4 * n), sp, np.full(4 * n, -1), cells) == none      # nothing shown
    assert L.legibility_metrics(np.ones(n), sp[:n], np.full(n, 2), cells) == none           # only the space
    assert L.legibility_metrics(np.zeros(0), np.zeros(0), np.zeros(0, int), cells) == none  # empty run
    zero = L.legibility_metrics(np.zeros(4 * n), sp, ci, cells)                             # no contact at all
    assert zero == {"legible_char_fraction": 0.0, "legible_char_fraction_cv": 0.0}
    with pytest.raises(ValueError, match="refers to cell 4 but there are 4 cells"):
        L.legibility_metrics(np.ones(3), np.ones(3), np.array([0, 4, -1]), cells)
    with pytest.raises(ValueError, match="force_n has 3 samples but char_index has 2"):
        L.legibility_metrics(np.ones(3), np.ones(3), np.array([0, 1]), cells)


def test_legibility_pass_is_deterministic():
    rng = np.random.default_rng(11)
    f, sp, ci, cells = _random_reading(rng, 25, 20000)
    first = L.legibility_metrics(f, sp, ci, cells)
    assert all(L.legibility_metrics(f.copy(), sp.copy(), ci.copy(), cells) == first for _ in range(3))
    r = L.relative_intensity(f, sp, L.CONSTANT_VOLTAGE)
    assert np.array_equal(r, L.relative_intensity(f, sp, L.CONSTANT_VOLTAGE))
    assert np.array_equal(L.relative_intensity(f[::-1], sp[::-1], L.CONSTANT_VOLTAGE), r[::-1])  # per sample only


def test_laws_are_monotone_in_force():
    f = np.linspace(0.0, 5.0, 2001)
    area = L.contact_area_m2(f)
    assert area[0] == 0.0 and np.all(np.diff(area) > 0)
    cov = L.coverage(f)
    assert np.all(np.diff(cov, axis=0) >= 0) and np.all((cov >= 0) & (cov <= 1))
    cv = L.relative_intensity(f, 1.0, L.CONSTANT_VOLTAGE)[:, 1]      # centre dot, always covered above 0
    assert np.all(np.diff(cv[1:]) > 0)
    cc = L.relative_intensity(f, 1.0)
    assert np.all(np.diff(cc[1:, 1]) >= 0) and np.all(cc[f > 0.3] == 1.0)


def test_legible_force_ranges_at_a_1_n_setpoint():
    """Where the laws put the band edges: constant current from 0.144 N up (Z(F) = 212 kOhm),
    constant voltage 0.466-2.58 N (Z(F) = Z(1 N) DR^+-1/2)."""
    lo, hi = P.band
    for f, inside in ((0.143, False), (0.145, True), (4.0, True)):
        assert bool(np.all((L.relative_intensity(np.array([f]), 1.0) >= lo))) is inside
    cv = L.CONSTANT_VOLTAGE
    for f, inside in ((0.465, False), (0.468, True), (2.57, True), (2.59, False)):
        r = float(L.relative_intensity(np.array([f]), 1.0, cv)[0, 1])
        assert (lo <= r <= hi) is inside, f
    assert P.current_a / math.sqrt(P.dynamic_range) == pytest.approx(1.414e-3, rel=1e-3)   # implied threshold


def test_setpoint_and_forces_at_or_below_zero_stay_finite():
    r = L.relative_intensity(np.array([0.0, -1.0, 1.0, 1e-4]), np.array([1.0, 1.0, 0.0, 0.0]))
    assert np.all(np.isfinite(r)) and np.all(r[:2] == 0.0)
    r = L.relative_intensity(np.array([1.0, 1e-4]), 0.0, L.CONSTANT_VOLTAGE)
    assert np.all(np.isfinite(r))


def test_new_params_reject_nonsense():
    with pytest.raises(ValueError, match="contact_area_exponent must be < 1"):
        L.LegibilityParams(contact_area_exponent=1.0)
    with pytest.raises(ValueError, match="pressure_exponent must be finite and > 0"):
        L.LegibilityParams(pressure_exponent=0.0)
    with pytest.raises(ValueError, match="contact_area_1n_m2 must be finite and > 0"):
        L.LegibilityParams(contact_area_1n_m2=float("nan"))
