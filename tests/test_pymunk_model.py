"""The pymunk model of one device (ebraille_sim.plant.pymunk.model): the mesh, motor, friction,
end stop and pulp laws against the lumped plant's, the rod side loads, the off-centre press."""
from __future__ import annotations

import numpy as np
import pytest

import controllers
from ebraille_sim.physics.drivetrain import mesh_force, shaft_to_rack_per_m
from ebraille_sim.physics.params import DeviceParams
from ebraille_sim.plant.lumped import Plant
from ebraille_sim.plant.pymunk.geometry import MechanismParams
from ebraille_sim.plant.pymunk.model import mesh_flank
from ebraille_sim.plant.pymunk.plant import PymunkPlant

def _closed_loop(plant, setpoint_n, steps):
    ctrl = controllers.make("pid")
    ctrl.reset(force_est_n=float(plant.force_est_n[0]), setpoint_n=setpoint_n, command_v=0.0)
    for _ in range(steps):
        plant.advance(ctrl.update(float(plant.force_est_n[0]), setpoint_n, plant.control_dt_s,
                                  float(plant.motor_current_a[0])))

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
    # same estimate, more force on the finger (measured 1.020), never more than the static law;
    # the turn-on region lowers a lightly loaded point's conductance by its factor T(f) < 1, which
    # the power-law bound widens by T^(-1/n) at the lightest loaded point
    from ebraille_sim.physics.fsr import turn_on_factor
    fsr = DeviceParams().fsr
    t_min = min(turn_on_factor(f, fsr.actuation_force_n, fsr.turn_on_steepness) for f in fc if f > 0)
    assert 1.015 * true_n[0.0] < true_n[9e-3] < static_ratio * t_min ** (-1.0 / n) * true_n[0.0]
