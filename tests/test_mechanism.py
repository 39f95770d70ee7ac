"""The pymunk mechanism (ebraille_sim.plant.mechanism): physics, cross-validation with the lumped plant,
determinism, the off-centre press, inputs and pictures."""
from __future__ import annotations

import math

import numpy as np
import pytest

import controllers
from ebraille_sim.physics.drivetrain import mesh_force, shaft_to_rack_per_m
from ebraille_sim.plant.loop import Plant
from ebraille_sim.plant.mechanism import (MechanismParams, PymunkPlant, check_mechanism_step, draw_snapshot,
                                          mesh_flank, recording, write_animation)
from ebraille_sim.scenarios.mechanism_section import build_inputs, load_mechanism_scenario, validate_section
from ebraille_sim.physics.params import STANDARD_GRAVITY_M_PER_S2, DeviceParams
from ebraille_sim.scenarios.runner import run_scenario
from ebraille_sim.scenarios.spec import ScenarioError

STANDARD = ["steady_60wpm", "steady_90wpm", "steady_120wpm", "setpoint_steps", "contact_onset"]
BOUND = 0.05          # true-force RMS difference between the backends, fraction of the setpoint


def _rms_difference(scenario, duration_s, **kw):
    a = run_scenario(scenario, duration_s=duration_s)
    b = run_scenario(scenario, duration_s=duration_s, backend="pymunk", **kw)
    d = a.trace["force_true_n"] - b.trace["force_true_n"]
    return math.sqrt(float(np.mean(d ** 2))) / float(np.mean(a.trace["setpoint_n"])), a, b


def _closed_loop(plant, setpoint_n, steps):
    ctrl = controllers.make("pid")
    ctrl.reset(force_est_n=float(plant.force_est_n[0]), setpoint_n=setpoint_n, command_v=0.0)
    for _ in range(steps):
        plant.advance(ctrl.update(float(plant.force_est_n[0]), setpoint_n, plant.control_dt_s,
                                  float(plant.motor_current_a[0])))


# ---------------------------------------------------------------- cross-validation

@pytest.mark.parametrize("scenario", STANDARD)
def test_backends_agree_on_standard_scenarios_short(scenario):
    """First 4.5 s of every standard scenario (onset, reading and the first setpoint step)."""
    rel, _, b = _rms_difference(scenario, 4.5)
    assert rel <= BOUND, f"{scenario}: true-force RMS difference {rel:.1%} of the setpoint"
    assert b.metrics["peak_force_n"] < 3.0


@pytest.mark.slow
@pytest.mark.parametrize("scenario", STANDARD)
def test_backends_agree_on_standard_scenarios_full_length(scenario):
    """Full length.  Where the friction-limited loop is chaotic (the 2 N stretch of
    setpoint_steps: stick-slip events at different instants), the lumped plant differs from
    itself by about 6 % between its 10 kHz and 20 kHz steps; there the mechanism must
    stay within that reproducibility of the reference model."""
    import dataclasses

    from ebraille_sim.scenarios.spec import load_scenario
    rel, a, _ = _rms_difference(scenario, None)
    spec = load_scenario(scenario)
    fine = dataclasses.replace(spec.device, rates=dataclasses.replace(spec.device.rates, physics_rate_hz=20000.0))
    a20 = run_scenario(dataclasses.replace(spec, device=fine))
    d = a.trace["force_true_n"] - a20.trace["force_true_n"]
    own = math.sqrt(float(np.mean(d ** 2))) / float(np.mean(a.trace["setpoint_n"]))
    assert rel <= max(BOUND, 1.1 * own), (f"{scenario}: true-force RMS difference {rel:.1%} of the setpoint "
                                          f"(lumped 10 vs 20 kHz: {own:.1%})")


def test_without_2d_effects_the_mechanism_reproduces_the_lumped_plant_closely(monkeypatch):
    """No mesh offset (no binding): what remains is the step size and the rack/board split."""
    import ebraille_sim.plant.loop as loop
    import ebraille_sim.plant.mechanism as mechanism

    class NoOffsetPlant(PymunkPlant):
        @classmethod
        def from_devices(cls, devices, seeds, board_pos_m=None, models=None):
            return super().from_devices(devices, seeds, board_pos_m, models, mesh_offset_m=0.0)

    monkeypatch.setattr(mechanism, "NoOffsetPlant", NoOffsetPlant, raising=False)
    monkeypatch.setitem(loop.PLANT_BACKENDS, "pymunk_no_offset", "ebraille_sim.plant.mechanism:NoOffsetPlant")
    a = run_scenario("setpoint_steps", duration_s=4.5)
    b = run_scenario("setpoint_steps", duration_s=4.5, backend="pymunk_no_offset")
    d = a.trace["force_true_n"] - b.trace["force_true_n"]
    assert math.sqrt(float(np.mean(d ** 2))) / float(np.mean(a.trace["setpoint_n"])) <= 0.01


# ---------------------------------------------------------------- determinism

def test_same_seed_gives_the_same_trajectory_exactly():
    a = run_scenario("contact_onset", duration_s=1.0, backend="pymunk", seed=5)
    b = run_scenario("contact_onset", duration_s=1.0, backend="pymunk", seed=5)
    for col in ("force_true_n", "force_est_n", "fsr_voltage_v", "command_v", "board_pos_m", "energy_j"):
        assert np.array_equal(a.trace[col], b.trace[col]), col
    c = run_scenario("contact_onset", duration_s=1.0, backend="pymunk", seed=6)
    assert not np.array_equal(a.trace["fsr_voltage_v"], c.trace["fsr_voltage_v"])


# ---------------------------------------------------------------- physics

def test_mesh_spring_is_the_lumped_mesh_law():
    """The DampedSpring set for tooth contact gives k (dx -+ b), zero in the gap: mesh_force.

    Its damping is the mesh damping plus k h (backward Euler of the spring), only in contact."""
    plant = PymunkPlant.from_devices([DeviceParams()], seeds=[1])
    m = plant.mechanisms[0]
    spring = m.dampers[0]
    b, k = m.half_gap, m.k_mesh
    assert [mesh_flank(dx, b) for dx in (-2 * b, -b, 0.0, b, 2 * b)] == [-1, 0, 0, 0, 1]
    for dx in np.linspace(-4 * b, 4 * b, 41):
        side = mesh_flank(dx, b)
        m._mesh_state(spring._constraint, side)
        # Chipmunk's default spring force, k (rest_length - dist), at dist = L_REF - dx
        got = spring.stiffness * (spring.rest_length - (m.L_REF - dx))
        assert got == pytest.approx(mesh_force.py_func(dx, 0.0, b, k, 0.0), abs=1e-9)
        assert spring.damping == (pytest.approx(m.c_mesh + k * m.h) if side else 0.0)


def test_open_loop_travel_matches_the_lumped_drive_train():
    """No finger: 2 V for 0.1 s.  Motor, reflected inertia, back-EMF and friction agree."""
    dev = DeviceParams()
    out = {}
    for cls in (Plant, PymunkPlant):
        plant = cls.from_devices([dev], seeds=[1])
        plant.set_finger(0.02)
        for _ in range(100):
            plant.advance(2.0)
        out[cls.__name__] = (float(plant.board_pos_m[0]), float(plant.motor_current_a[0]))
    (xl, il), (xp, ip) = out["Plant"], out["PymunkPlant"]
    assert xp == pytest.approx(xl, rel=0.03)
    assert ip == pytest.approx(il, rel=0.03)
    # steady speed of the reflected motor: (V - R i) / (kE N/r)
    g = shaft_to_rack_per_m(dev.drivetrain.gear_ratio, dev.drivetrain.pinion_radius_m)
    plant = PymunkPlant.from_devices([dev], seeds=[1])
    plant.set_finger(0.02)
    for _ in range(60):
        plant.advance(2.0)
    v = plant.mechanisms[0].pinion.velocity.y
    i = plant.mechanisms[0].current_a
    v_model = (2.0 - dev.motor.resistance_ohm * i) / (dev.motor.back_emf_v_s_per_rad * g)
    assert v == pytest.approx(v_model, rel=0.01)


def test_end_stop_holds_the_board_at_full_travel():
    """Driven at 6 V into the stop, the board never passes full travel, on arrival (period
    117) or during the hold (the end stop is the lumped ``end_stop`` law applied after each
    pymunk step; pymunk's slide joints let it overshoot 0.17 mm past the stop on arrival)."""
    dev = DeviceParams()
    plant = PymunkPlant.from_devices([dev], seeds=[1])
    plant.set_finger(0.02)
    xs = []
    for _ in range(400):
        plant.advance(6.0)
        xs.append(plant.board_pos_m[0])
    assert max(xs) <= dev.drivetrain.travel_max_m + 5e-6
    assert min(xs[200:]) == pytest.approx(dev.drivetrain.travel_max_m, abs=5e-6)


def test_jammed_motor_locks_the_pinion():
    plant = PymunkPlant.from_devices([DeviceParams()], seeds=[1])
    plant.set_finger(0.02)
    plant.set_input("motor_jammed", 1.0)
    for _ in range(50):
        plant.advance(6.0)
    assert abs(plant.mechanisms[0].pinion.position.y) < 1e-9


def test_pulp_relaxes_like_the_lumped_qlv_law():
    """Pinion jammed, finger stepped 1 mm into the board: the same relaxation as the lumped
    plant (both apply the same exponential + Prony law)."""
    dev = DeviceParams()
    res = {}
    for cls in (Plant, PymunkPlant):
        plant = cls.from_devices([dev], seeds=[1], board_pos_m=2e-3)
        plant.set_input("motor_jammed", 1.0)
        plant.set_finger(1e-3)
        f = []
        for _ in range(2000):
            plant.advance(0.0)
            f.append(float(plant.contact_force_n[0]))
        res[cls.__name__] = np.array(f)
    lum, mec = res["Plant"], res["PymunkPlant"]
    # after the board has settled on the jammed mesh (the gap impact differs for ~20 ms)
    for k in (50, 200, 1999):
        assert mec[k] == pytest.approx(lum[k], rel=0.02)
    assert mec[-1] < 0.75 * mec[50]         # the 70 ms and 1.4 s modes relax


def test_bushing_side_loads_are_the_mesh_moment():
    """Each rack's two bushings carry the couple of the mesh force at the tooth offset:
    |N_top| + |N_bottom| = 2 |F_mesh| e / L_b."""
    plant = PymunkPlant.from_devices([DeviceParams()], seeds=[1])
    plant.set_finger(1e-3)
    _closed_loop(plant, 1.0, 1500)
    m, geo = plant.mechanisms[0], plant.mech
    for i in range(2):
        expect = 2.0 * abs(m.mesh_force_n[i]) * geo.mesh_offset_m / geo.bushing_length_m
        assert m.side_load_n[i] == pytest.approx(expect, rel=0.05)


def _held_press(offset_m: float, periods: int) -> PymunkPlant:
    """The default device pressed ``offset_m`` off centre, the loop holding a 1 N estimate for ``periods``."""
    plant = PymunkPlant.from_devices([DeviceParams()], seeds=[1])
    plant.set_finger(1e-3)
    plant.set_pose(press_offset_m=offset_m)
    _closed_loop(plant, 1.0, periods)
    return plant


def test_offcentre_press_tilts_the_board_and_shifts_load_and_friction_to_the_near_rack():
    geo = MechanismParams()
    res = {}
    for off in (0.0, 4e-3):
        plant = _held_press(off, 2000)
        m = plant.mechanisms[0]
        res[off] = (m.tilt_rad, list(m.mesh_force_n), list(m.rack_friction_limit_n), float(plant.contact_force_n[0]))
    tilt0, _, lim0, _ = res[0.0]
    tilt, fm, lim, f = res[4e-3]
    assert abs(tilt0) < 5e-5
    # rack B (the side of the press) carries more and its mesh deflects more: B side lower
    assert fm[1] > fm[0]
    k = 0.5 * DeviceParams().drivetrain.mesh_stiffness_n_per_m
    assert tilt == pytest.approx(-(fm[1] - fm[0]) / k / geo.rod_spacing_m, rel=0.15)
    # lever rule for the press alone: dF = 2 F x / s
    assert fm[1] - fm[0] == pytest.approx(2 * f * 4e-3 / geo.rod_spacing_m, rel=0.3)
    assert lim[1] > lim0[1] and lim[0] < lim0[0]


def test_press_over_the_board_edge_reads_low_and_the_loop_overloads_the_finger():
    """A strip beyond the board edge carries nothing; the two loaded strips conduct in
    parallel, which reads less than the same force spread evenly (n < 1).  The loop holds
    the same estimate (1.001 N) as on a centred press, so the finger carries more: 0.992 N
    against 0.972 N centred after 3 s (ratio 1.020).  The static strip law alone predicts
    1.046 (the sum over the equivalent force); the sensor's hysteresis and creep states,
    which follow the equivalent force's history, take part of it back.  Without the strip
    law the ratio would be 1."""
    true_n = {}
    for offset_m in (0.0, 9e-3):
        plant = _held_press(offset_m, 3000)
        assert float(plant.force_est_n[0]) == pytest.approx(1.0, abs=0.01)
        true_n[offset_m] = float(plant.contact_force_n[0])
    fc = plant.mechanisms[0].fc
    assert fc[2] == 0.0 and fc[0] > 0.0 and fc[1] > 0.0
    n = DeviceParams().fsr.exponent
    share = 1.0 / len(fc)
    f_eq = (share ** (1 - n) * sum(f ** n for f in fc if f > 0)) ** (1 / n)
    assert f_eq < 0.97 * sum(fc)
    static_ratio = sum(fc) / f_eq
    assert static_ratio > 1.03
    # same estimate, more force on the finger (measured 1.020), never more than the static law
    assert 1.015 * true_n[0.0] < true_n[9e-3] < static_ratio * true_n[0.0]


def test_offcentre_scenario_runs_on_both_backends_and_shows_tilt():
    spec = load_mechanism_scenario("offcentre_press")
    with recording(every_s=0.05) as rec:
        b = run_scenario(spec, backend="pymunk", duration_s=8.0)
    t = np.array([f["t_s"] for f in rec.frames])
    tilt = np.array([f["tilt_rad"] for f in rec.frames])
    assert abs(np.mean(tilt[(t > 2.0) & (t < 3.0)])) < 1e-4
    assert np.mean(tilt[(t > 7.0) & (t < 8.0)]) < -5e-4
    a = run_scenario(spec, duration_s=8.0)
    assert np.isfinite(a.trace["force_true_n"]).all() and b.metrics["in_band_fraction"] > 0.8


# ---------------------------------------------------------------- inputs, checks, pictures

def test_step_check_rejects_a_too_coarse_rate_with_one_line():
    with pytest.raises(ValueError, match="physics_rate_hz 200 is too low") as exc:
        check_mechanism_step(DeviceParams(), MechanismParams(physics_rate_hz=200.0))
    assert "\n" not in str(exc.value)
    assert check_mechanism_step(DeviceParams(), MechanismParams()) == pytest.approx(0.41, abs=0.01)
    with pytest.raises(ValueError, match="physics_rate_hz 1000 is too low"):
        check_mechanism_step(DeviceParams(), MechanismParams(physics_rate_hz=1000.0))


def test_bad_options_and_inputs_give_one_line_errors():
    with pytest.raises(ValueError, match="unknown key 'rod_gap_m'.*allowed: .*rod_spacing_m"):
        PymunkPlant.from_devices([DeviceParams()], seeds=[1], rod_gap_m=1.0)
    with pytest.raises(ValueError, match="n_contacts"):
        MechanismParams(n_contacts=1)
    with pytest.raises(ValueError, match="whole multiple"):
        PymunkPlant.from_devices([DeviceParams()], seeds=[1], physics_rate_hz=3000.0)
    plant = PymunkPlant.from_devices([DeviceParams()], seeds=[1])
    plant.set_pose(finger_tilt_rad=float("nan"))
    with pytest.raises(ValueError, match="finger pose must be finite"):
        plant.advance(0.0)
    plant = PymunkPlant.from_devices([DeviceParams()], seeds=[1])
    with pytest.raises(ValueError, match="command_v must be finite"):
        plant.advance(float("inf"))


def test_scenario_section_is_validated_strictly():
    with pytest.raises(ScenarioError, match="unknown key 'offset' in \\[mechanism\\]; allowed: "):
        validate_section("x.toml", {"offset": 1.0})
    with pytest.raises(ScenarioError, match="press_offset_m = 0.1 is out of range"):
        validate_section("x.toml", {"press_offset_m": 0.1})
    with pytest.raises(ScenarioError, match="times must increase"):
        validate_section("x.toml", {"pose_steps": [[2.0, 0.0, 0.0], [1.0, 0.0, 0.0]]})
    sec = validate_section("x.toml", {"pose_steps": [[1.0, 0.004, 2.0]], "hand_roll_deg": 90.0})
    t = np.arange(0.0, 2.0, 0.5)
    inp = build_inputs(sec, t, None, DeviceParams())
    assert list(inp["press_offset_m"][1]) == [0.0, 0.0, 0.004, 0.004]
    assert inp["finger_tilt_rad"][1][-1] == pytest.approx(math.radians(2.0))
    assert inp["gravity_lateral_m_per_s2"][1][0] == pytest.approx(-STANDARD_GRAVITY_M_PER_S2)


def test_picture_is_an_rgb_array_that_follows_the_mechanism(tmp_path):
    plant = PymunkPlant.from_devices([DeviceParams()], seeds=[1])
    plant.set_finger(1e-3)
    img0 = plant.render()
    for _ in range(300):
        plant.advance(3.0)
    img1 = plant.render()
    assert img0.shape == (360, 480, 3) and img0.dtype == np.uint8
    assert np.abs(img0.astype(int) - img1.astype(int)).sum() > 1000
    out = write_animation([plant.snapshot(), plant.snapshot()], tmp_path / "m.gif", fps=10)
    assert out.exists() and out.stat().st_size > 0
    assert draw_snapshot(plant.snapshot(), size_px=(320, 240)).shape == (240, 320, 3)
