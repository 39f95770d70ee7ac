"""Electrode-skin contact, stimulation intensity and the legibility metric."""
import dataclasses
import math

import numpy as np
import pytest

from ebraille_sim.scenarios import legibility as L
from ebraille_sim.scenarios.braille import text_to_cells
from ebraille_sim.scenarios.runner import run_scenario
from ebraille_sim.scenarios.spec import parse_scenario

P = L.LegibilityParams()


def test_hertz_contact_radius():
    e_star = P.pulp_modulus_pa / (1 - P.poisson_ratio ** 2)
    for f in (0.2, 1.0, 3.0):
        a = float(L.contact_radius_m(f))
        assert 4 * e_star * a ** 3 / (3 * P.pulp_radius_m) == pytest.approx(f)
    assert float(L.contact_radius_m(0.0)) == 0.0
    assert float(L.contact_radius_m(8.0)) == pytest.approx(2 * float(L.contact_radius_m(1.0)))


def test_overlap_area_against_sampling():
    rng = np.random.default_rng(1)
    r = 0.6e-3
    for d, a in ((0.0, 2e-3), (2.6e-3, 3.0e-3), (3.0e-3, 2.5e-3), (5e-3, 1e-3)):
        exact = float(L._overlap_area(np.array([d]), r, np.array([a]))[0])
        pts = rng.uniform(-r, r, size=(200_000, 2))
        pts = pts[np.hypot(*pts.T) <= r]
        inside = np.hypot(pts[:, 0] + d, pts[:, 1]) <= a
        assert exact == pytest.approx(np.mean(inside) * math.pi * r * r, abs=0.01 * math.pi * r * r)


def test_coverage_grows_from_the_centre_row_outwards():
    cov = L.coverage(np.array([0.2, 0.5, 1.0]))
    assert cov.shape == (3, 6)
    centre, corner = [1, 4], [0, 2, 3, 5]                 # dots 2, 5 sit 1.2 mm from the centre
    assert np.all(cov[0, centre] == 1.0) and np.all(cov[0, corner] == 0.0)
    assert np.all((cov[1, corner] > 0.3) & (cov[1, corner] < 0.9))
    assert np.all(cov[2] == 1.0)


def test_impedance_law():
    assert float(L.impedance_ohm(0.0)) == P.impedance_touch_ohm
    z_fz = P.impedance_pressed_ohm + (P.impedance_touch_ohm - P.impedance_pressed_ohm) / math.e
    assert float(L.impedance_ohm(P.impedance_force_scale_n)) == pytest.approx(z_fz)
    assert float(L.impedance_ohm(50.0)) == pytest.approx(P.impedance_pressed_ohm)


def test_constant_current_is_nominal_until_the_compliance_limit():
    r = L.relative_intensity(np.array([1.0, 2.0, 0.3]), 1.0)
    assert np.all(r[0] == 1.0) and np.all(r[1] == 1.0)              # more force: same current density
    z = float(L.impedance_ohm(0.3))
    assert r[2, 1] == pytest.approx(P.compliance_v / z / P.current_a)   # centre electrode, compliance-limited


def test_a_peeling_electrode_feels_stronger_under_constant_current():
    high = dataclasses.replace(P, compliance_v=2000.0)
    r = L.relative_intensity(np.array([0.5]), 1.0, high)[0]
    phi = L.coverage(np.array([0.5]), high)[0]
    np.testing.assert_allclose(r[[0, 2, 3, 5]], 1.0 / phi[[0, 2, 3, 5]])
    assert np.all(r[[0, 2, 3, 5]] > 1.4)


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
    force[n + 20:n + 60] = 0.6                          # 40 % of "b" at 60 % force: dots fade
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
