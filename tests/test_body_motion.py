"""The wearer's own motion: the relative-motion budget of a strapped frame, the setpoint's room
for a strap slip, and a CI-sized sample of the body-motion matrix (ebraille_sim.tools.body_motion)."""
from __future__ import annotations

import dataclasses
import math
import pathlib

import pytest

from controllers.supervisor import Supervisor, SupervisorConfig
from controllers.supervisor.motion import slip_peak_force_n, slip_setpoint_cap_n
from ebraille_sim.physics.fingertip import compression_at_force_m, elastic_force, relaxation_function
from ebraille_sim.physics.params import FINGERS
from ebraille_sim.scenarios.disturbances import body_motion_budget, strap_transmission
from ebraille_sim.scenarios.spec import ScenarioError, parse_scenario

ROOT = pathlib.Path(__file__).resolve().parent.parent


def _matrix():
    from ebraille_sim.tools import body_motion
    return body_motion


def test_strap_transmission_is_the_relative_motion_of_base_excitation():
    """|r^2 / (1 - r^2 + 2 j zeta r)|: at r = 1 it is 1/(2 zeta); far below resonance r^2; far above 1.
    A 15 g frame on 5 N/mm resonates at sqrt(5000/0.015)/(2 pi) = 91.9 Hz."""
    fn = math.sqrt(5e3 / 0.015) / (2 * math.pi)
    assert fn == pytest.approx(91.89, abs=0.01)
    assert strap_transmission(fn, 0.015, 5e3, 0.2) == pytest.approx(1 / 0.4, rel=1e-9)
    assert strap_transmission(fn / 100, 0.015, 5e3, 0.2) == pytest.approx(1e-4, rel=1e-3)
    assert strap_transmission(100 * fn, 0.015, 5e3, 0.2) == pytest.approx(1.0, rel=1e-3)
    r = 12.0 / fn
    assert strap_transmission(12.0, 0.015, 5e3, 0.2) == pytest.approx(r * r / math.hypot(1 - r * r, 0.4 * r), rel=1e-12)


def test_the_budget_takes_the_finger_motion_through_the_strap():
    """Tremor: the worst transmission over 8-12 Hz on the softest strap (5 N/mm), 0.0173, times the
    200 um largest finger tremor: 3.5 um RMS at the gap, three sigma (10 um) inside the
    supervisor's 45 um allowance.  Lifts: 2 m a / k = 2 x 15 g x 20 m/s^2 / 5 N/mm = 0.12 mm."""
    b = body_motion_budget()
    assert b["tremor_transmission_max"] == pytest.approx(strap_transmission(12.0, 0.015, 5e3), rel=1e-12)
    assert b["tremor_transmission_max"] == pytest.approx(0.01733, abs=1e-5)
    assert b["tremor_gap_rms_max_m"] == pytest.approx(3.465e-6, rel=1e-3)
    assert 3 * b["tremor_gap_rms_max_m"] < SupervisorConfig().finger_motion_m
    assert b["pressing_transmission_max"] == pytest.approx(strap_transmission(1.0, 0.015, 5e3), rel=1e-12)
    assert b["lift_depth_max_m"] == pytest.approx(0.12e-3, rel=1e-12)
    assert b["lift_move_min_s"] == pytest.approx(0.5 * math.pi * math.sqrt(0.015 / 20e3), rel=1e-12)
    assert b["slip_toward_max_m"] <= b["slip_depth_max_m"]
    stiffer = body_motion_budget(strap_stiffness_n_per_m=(10e3, 20e3))
    assert stiffer["tremor_transmission_max"] < b["tremor_transmission_max"]


@pytest.mark.parametrize("table,message", [
    ({"tremor": {"rms_m": 0.3e-3}}, "[disturbances.tremor] rms_m = 0.0003 is out of range [0, 0.0002]"),
    ({"pressing": {"rms_m": 1e-3}}, "[disturbances.pressing] rms_m = 0.001 is out of range [0, 0.0007]"),
    ({"strap_slip": {"at_s": [1.0], "duration_s": 0.005}},
     "[disturbances.strap_slip] duration_s = 0.005 is out of range [0.01, 5]"),
])
def test_the_schema_refuses_motions_no_wearer_produces(table, message):
    with pytest.raises(ScenarioError) as exc:
        parse_scenario({"name": "x", "disturbances": table}, source="x.toml")
    assert message in str(exc.value) and "\n" not in str(exc.value)


def test_slip_peak_force_without_the_mesh_is_the_hereditary_integral():
    """A held board, no mesh: the fully relaxed pulp (Fe0 = F/c0) compressed at constant speed v
    over T peaks at F + int_0^T G(T - s) dFe/ds ds (the QLV law in closed form, by quadrature)."""
    fi = FINGERS["stiff"]
    F, slip, T = 2.0, 0.1e-3, 0.02
    b, m, c0 = fi.stiffness_b_n_per_m, fi.exponent_m_per_m, fi.relax_weight_inf
    d0 = compression_at_force_m(F / c0, b, m)
    n = 4000
    total = 0.0
    for k in range(n):
        s = (k + 0.5) * T / n
        rate = (b + m * elastic_force(d0 + slip * s / T, b, m)) * slip / T
        total += float(relaxation_function(T - s, fi)) * rate * T / n
    assert slip_peak_force_n(F, slip, T, fi) == pytest.approx(F + total, rel=2e-3)
    assert slip_peak_force_n(F, 0.0, T, fi) == pytest.approx(F, abs=1e-12)


def test_the_gear_mesh_gives_way_and_lowers_the_peak():
    fi = FINGERS["stiff"]
    rigid = slip_peak_force_n(2.6, 0.1e-3, 0.02, fi)
    soft = slip_peak_force_n(2.6, 0.1e-3, 0.02, fi, 3e4)
    stiff = slip_peak_force_n(2.6, 0.1e-3, 0.02, fi, 1e5)
    assert rigid == pytest.approx(3.7007, abs=1e-3) and soft == pytest.approx(3.4072, abs=1e-3)
    assert soft < stiff < rigid


def test_the_setpoint_leaves_room_for_the_budgeted_slip():
    """The cap is the largest setpoint whose slip peak stays at the safe force (to 1 mN); the
    default 0.1 mm over 20 ms behind the nominal 30 N/mm mesh caps at 2.675 N, a loose strap's
    0.3 mm at 1.61 N; the supervisor passes the inner controller no more than that."""
    c = SupervisorConfig()
    fi = dataclasses.replace(FINGERS["stiff"], stiffness_b_n_per_m=c.reader_b_n_per_m,
                             exponent_m_per_m=c.reader_m_per_m)
    cap = c.slip_setpoint_cap_n
    assert cap == pytest.approx(2.675, abs=2e-3)
    assert slip_peak_force_n(cap, c.slip_headroom_m, c.slip_time_s, fi, c.mesh_stiffness_n_per_m) <= c.safe_force_n
    assert slip_peak_force_n(cap + 2e-3, c.slip_headroom_m, c.slip_time_s, fi,
                             c.mesh_stiffness_n_per_m) > c.safe_force_n
    assert slip_setpoint_cap_n(3.5, 0.3e-3, 0.02, fi, 3e4) == pytest.approx(1.612, abs=2e-3)
    loose = SupervisorConfig(slip_headroom_m=0.3e-3)

    class Inner:
        seen = []

        def reset(self, **kw):
            pass

        def update(self, f, sp, dt, cur=None):
            self.seen.append(sp)
            return 0.0
    sup = Supervisor(Inner(), loose)
    sup.reset(force_est_n=1.0, setpoint_n=1.0)
    sup.update(1.0, 3.0, 1e-3)
    assert Inner.seen[-1] == pytest.approx(loose.slip_setpoint_cap_n) and Inner.seen[-1] < 1.62


def test_a_slip_room_that_leaves_no_reading_force_is_refused_in_one_line():
    with pytest.raises(ValueError) as exc:
        SupervisorConfig(slip_headroom_m=2e-3)
    assert "slip_headroom_m" in str(exc.value) and "\n" not in str(exc.value)


def test_body_motion_matrix_sample_inside_the_budget_stays_below_the_safe_force():
    """The CI sample of the matrix (every motion inside the budget, stiff reader, high-k unit, 3 N
    asked, both firmwares) keeps the true force at or below 3.5 N."""
    mx = _matrix()
    devs = mx.readers(0)
    ms = mx.motions()
    for motion, fw, sp, fsr, reader in mx.cells(quick=True):
        if not ms[motion][2]:
            continue
        r = mx.run_cell(motion, fw, sp, fsr, devs[reader])
        assert r["peak_n"] <= mx.SAFE_N, (motion, fw, r)


def test_a_loose_strap_setting_holds_a_larger_slip():
    """0.3 mm toward the board in 20 ms at 3 N asked on the stiff reader: above 3.5 N with the
    default room (0.1 mm), at or below it with ``slip_headroom_m`` = 0.3 mm (setpoint 1.61 N)."""
    mx = _matrix()
    stiff = mx.readers(0)["stiff"]
    assert mx.run_cell("slip_0.3mm", "1khz", 3.0, "nominal", stiff)["peak_n"] > mx.SAFE_N
    loose = mx.run_cell("slip_0.3mm", "1khz", 3.0, "nominal", stiff, supervisor={"slip_headroom_m": 0.3e-3})
    assert loose["peak_n"] <= mx.SAFE_N


def test_the_reapproach_searches_the_budgets_slip_away():
    """The supervisor's ``slip_away_m`` is the budget's largest slip away from the board."""
    assert SupervisorConfig().slip_away_m == body_motion_budget()["slip_depth_max_m"]


@pytest.mark.parametrize("firmware", ["default", "1khz"])
def test_a_slip_away_from_the_board_resumes_in_band(firmware):
    """The budget's 0.5 mm strap slip away from the board at 1 N unloads the stiff reader's pulp
    entirely: the supervisor freezes and backs off, the finger does not come back by itself, and
    after ``contact_loss_timeout_s`` the board re-approaches and the loop resumes.  No fault latches
    and the force is in band over the last second of a 5.5 s run (a latched ``contact_lost`` would
    hold the board retracted for the rest of the session).  After the resume at 2.3 s the 100 Hz
    firmware takes 1.2-1.7 s to settle into band, depending on the noise's seed (nine seeds), the
    1 kHz firmware 0.9-1.4 s, so the window starts at 4.5 s."""
    import numpy as np
    from ebraille_sim.scenarios.runner import run_scenario
    bm = _matrix()
    spec = bm.cell_spec("slip_away_0.5mm", firmware, 1.0, duration_s=5.5)
    res = run_scenario(dataclasses.replace(spec, device=bm.readers(0)["stiff"]))
    texts = [e for _, e in res.supervisor["events"]]
    assert res.supervisor["fault"] is None
    assert texts == ["contact lost: freeze", "contact not back: re-approach", "contact regained: resume"]
    tr = res.trace
    late = tr["t_s"] > 4.5
    assert np.mean(np.abs(tr["force_true_n"][late] - 1.0) <= 0.1) == 1.0
    assert tr["force_true_n"].max() <= bm.SAFE_N
