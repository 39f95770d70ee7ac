"""Each law of the lumped plant against an analytic case."""
import math

import numpy as np
import pytest

from ebraille_sim.physics.drivetrain import reflected
from ebraille_sim.physics.fingertip import relaxation_function
from ebraille_sim.plant.layout import S
from ebraille_sim.plant.lumped import Plant
from ebraille_sim.physics.params import (DRIVETRAINS, FINGERS, FSRS, MOTORS, CircuitParams, DeviceParams,
                                 DriveTrainParams, EstimatorParams, FingerParams, RateParams, describe, source_of)

FAULHABER = MOTORS["faulhaber_0816_006sr"]


def test_motor_stall_torque_and_no_load_speed_match_datasheet():
    # datasheet: stall 1.13 mN m, no-load 13 500 rpm, mechanical time constant 6.5 ms
    assert FAULHABER.stall_torque_at(6.0) == pytest.approx(1.13e-3, rel=0.01)
    rpm = FAULHABER.no_load_speed_at(6.0) * 60 / (2 * math.pi)
    assert rpm == pytest.approx(13500, rel=0.005)
    assert FAULHABER.mechanical_time_constant_s == pytest.approx(6.5e-3, rel=0.02)
    assert FAULHABER.electrical_time_constant_s == pytest.approx(10.2e-6, rel=0.02)


@pytest.mark.parametrize("name", sorted(MOTORS))
def test_every_motor_preset_is_consistent_with_its_stall_torque(name):
    m = MOTORS[name]
    assert m.stall_torque_at(m.nominal_voltage_v) == pytest.approx(m.stall_torque_nm, rel=0.08)
    assert source_of(m, "resistance_ohm").startswith("[")


@pytest.mark.parametrize("preset", [*MOTORS.values(), *FINGERS.values(), *DRIVETRAINS.values(), *FSRS.values(),
                                    CircuitParams(), RateParams(), EstimatorParams()])
def test_every_preset_value_carries_a_unit_and_a_source_tag(preset):
    for name, value, unit, source in describe(preset):
        if name == "name":
            continue
        assert unit, f"{type(preset).__name__}.{name} has no unit"
        assert source.startswith("[") or source.startswith("seed paper"), f"{name}: {source!r}"


def test_reflected_quantities_at_the_rack():
    r = reflected(FAULHABER, DriveTrainParams())
    # parameters table 2.4: 3.4 kg, 525 N s/m, 0.87 N Coulomb, ~55 mm/s
    assert r["mass_kg"] == pytest.approx(3.41, rel=0.01)
    assert r["back_emf_damping_n_s_per_m"] == pytest.approx(525, rel=0.01)
    assert r["coulomb_n"] == pytest.approx(0.87, rel=0.01)
    assert r["no_load_speed_m_per_s"] * 1e3 == pytest.approx(55.2, rel=0.01)


def _plant(device, finger_pos_m=0.05, seed=0):
    plant = Plant.from_devices([device], seeds=[seed])
    plant.set_finger(finger_pos_m)
    return plant


def test_jammed_motor_current_follows_the_exact_armature_transient():
    dev = DeviceParams(rates=RateParams(control_rate_hz=100_000, sensor_rate_hz=100_000, physics_rate_hz=100_000))
    plant = _plant(dev)
    plant.set_input("motor_jammed", 1.0)
    plant.advance(6.0)                       # one 10 us step at stall
    tau = FAULHABER.electrical_time_constant_s
    i_stall = 6.0 / FAULHABER.resistance_ohm
    assert plant.motor_current_a[0] == pytest.approx(i_stall * (1 - math.exp(-1e-5 / tau)), rel=1e-9)
    for _ in range(100):
        plant.advance(6.0)
    assert plant.motor_current_a[0] == pytest.approx(i_stall, rel=1e-9)   # 0.283 A = V/R


def test_free_running_board_reaches_the_friction_limited_no_load_speed():
    """Steady speed from the force balance of motor, brush friction, gear loss, guide friction and gravity."""
    dt = DriveTrainParams(travel_max_m=0.2)              # long travel for the test
    dev = DeviceParams(drivetrain=dt)
    plant = _plant(dev, finger_pos_m=1.0)
    for _ in range(250):                                 # 0.25 s >> 6.5 ms time constant
        plant.advance(3.0)
    v_meas = plant.state[0][S.board_vel_m_per_s]
    g = dt.gear_ratio / dt.pinion_radius_m
    m = FAULHABER
    mu = dt.gear_loss_coefficient
    f_load = dt.guide_coulomb_n + dt.moving_mass_kg * 9.81     # guide Coulomb + weight (hand pad down)
    # kt g (V - ke g v)/R = Tf g + (1+mu)(f_load + c_g v)   -> solve for v
    kt, ke, r = m.torque_constant_nm_per_a, m.back_emf_v_s_per_rad, m.resistance_ohm
    a = kt * g * ke * g / r + (1 + mu) * dt.guide_viscous_n_s_per_m
    v_expected = (kt * g * 3.0 / r - m.friction_torque_nm * g - (1 + mu) * f_load) / a
    assert v_meas == pytest.approx(v_expected, rel=2e-3)


def test_pulp_compression_at_one_newton():
    f = FINGERS["nominal"]
    # instantaneous law: d = ln(1 + m F / b)/m = 1.40 mm for the nominal reader
    assert f.compression_at_m(1.0) * 1e3 == pytest.approx(1.40, abs=0.01)
    assert f.elastic_force_n(f.compression_at_m(1.0)) == pytest.approx(1.0, rel=1e-12)
    # fully relaxed: c0 Fe(d) = 1 N
    assert f.compression_at_m(1.0, relaxed=True) == pytest.approx(math.log1p(f.exponent_m_per_m / (
        f.relax_weight_inf * f.stiffness_b_n_per_m)) / f.exponent_m_per_m, rel=1e-12)
    assert FINGERS["soft"].compression_at_m(1.0) * 1e3 == pytest.approx(2.0, abs=0.02)
    assert FINGERS["stiff"].compression_at_m(1.0) * 1e3 == pytest.approx(0.9, abs=0.02)


def test_relaxation_weights_must_sum_to_one():
    with pytest.raises(ValueError, match="sum to 1"):
        FingerParams(relax_weight_inf=0.5)


def test_pulp_relaxes_with_the_prony_time_constants():
    """A held indentation step: F(t) = Fe(d) G(t), G = c0 + sum c_i exp(-t/tau_i)."""
    stiff_mesh = DriveTrainParams(mesh_stiffness_n_per_m=3e6, backlash_m=0.0, travel_max_m=0.01)
    rates = RateParams(control_rate_hz=1000, sensor_rate_hz=1000, physics_rate_hz=200_000)
    dev = DeviceParams(drivetrain=stiff_mesh, rates=rates)
    plant = Plant.from_devices([dev], seeds=[0], board_pos_m=2.0e-3)
    plant.set_input("motor_jammed", 1.0)
    plant.set_finger(0.6e-3)                              # 1.4 mm compression at t = 0
    d0 = 1.4e-3
    fe = FINGERS["nominal"].elastic_force_n(d0)
    times, forces = [], []
    for k in range(3000):
        plant.advance(0.0)
        times.append((k + 1) * 1e-3)
        forces.append(plant.contact_force_n[0])
    times, forces = np.array(times), np.array(forces)
    d = plant.board_pos_m[0] - 0.6e-3                  # the board yields by F/k_mesh (< 1 um)
    assert abs(d - d0) < 1e-6
    for t in (0.004, 0.07, 0.3, 1.4, 3.0):
        k = int(round(t / 1e-3)) - 1
        assert forces[k] == pytest.approx(fe * relaxation_function(times[k], FINGERS["nominal"]), rel=0.01)


def test_contact_force_is_zero_when_the_board_leaves_the_pulp():
    dev = DeviceParams()
    plant = Plant.from_devices([dev], seeds=[0])
    plant.set_finger(1.0e-3)
    for _ in range(300):
        plant.advance(2.0)
    assert plant.contact_force_n[0] > 0.5
    for _ in range(300):
        plant.advance(-6.0)
    assert plant.contact_force_n[0] == 0.0
    assert plant.board_pos_m[0] == pytest.approx(dev.drivetrain.travel_min_m)   # end stop holds


def test_drive_is_not_back_drivable_by_the_finger():
    """With no command the board must hold against a 1 N press (friction + gear loss)."""
    dev = DeviceParams()
    plant = Plant.from_devices([dev], seeds=[0])
    plant.set_finger(1.0e-3)
    while plant.contact_force_n[0] < 1.0:
        plant.advance(1.5)
    x0 = plant.board_pos_m[0]
    for _ in range(2000):
        plant.advance(0.0)
    assert plant.board_pos_m[0] == pytest.approx(x0, abs=0.15e-3)   # backlash only
    assert plant.contact_force_n[0] > 0.3


def test_backlash_dead_zone_delays_the_board_on_reversal():
    dt = DriveTrainParams(backlash_m=0.2e-3)
    dev = DeviceParams(drivetrain=dt)
    plant = Plant.from_devices([dev], seeds=[0], board_pos_m=2e-3)
    plant.set_finger(1.0)
    plant.set_input("gravity_along_m_per_s2", 0.0)
    for _ in range(50):
        plant.advance(1.0)
    xb0 = plant.board_pos_m[0]
    xp0 = plant.state[0][S.pinion_pos_m]
    moved_pinion = 0.0
    for _ in range(200):
        plant.advance(-1.0)
        moved_pinion = xp0 - plant.state[0][S.pinion_pos_m]
        if plant.board_pos_m[0] < xb0 - 1e-6:
            break
    # the pinion crossed the whole gap (0.2 mm) before the rack followed
    assert moved_pinion == pytest.approx(0.2e-3, abs=0.03e-3)


def test_physics_rate_too_low_for_the_stiff_contact_is_rejected():
    dev = DeviceParams(rates=RateParams(control_rate_hz=1000, sensor_rate_hz=1000, physics_rate_hz=1000))
    with pytest.raises(ValueError, match="physics_rate_hz 1000 is too low"):
        Plant.from_devices([dev], seeds=[0])


def test_rates_must_be_whole_multiples():
    with pytest.raises(ValueError, match="whole multiple"):
        RateParams(control_rate_hz=3000, physics_rate_hz=10000)
    with pytest.raises(ValueError, match="must be > 0"):
        RateParams(control_rate_hz=-1.0)
    with pytest.raises(ValueError, match="finite"):
        RateParams(control_rate_hz=float("nan"))


def test_batch_equals_single_devices_exactly():
    devs = [DeviceParams(), DeviceParams(finger=FINGERS["soft"]), DeviceParams(finger=FINGERS["stiff"])]
    batch = Plant.from_devices(devs, seeds=[1, 2, 3])
    batch.set_finger(1.0e-3)
    singles = [Plant.from_devices([d], seeds=[s]) for d, s in zip(devs, [1, 2, 3])]
    for p in singles:
        p.set_finger(1.0e-3)
    rng = np.random.default_rng(0)
    for _ in range(400):
        cmd = rng.uniform(-1, 3, size=3)
        batch.advance(cmd)
        for j, p in enumerate(singles):
            p.advance(cmd[j])
    for j, p in enumerate(singles):
        np.testing.assert_array_equal(batch.state[j], p.state[0])


def test_non_finite_command_is_rejected():
    plant = Plant.from_devices([DeviceParams()], seeds=[0])
    with pytest.raises(ValueError, match="command_v must be finite"):
        plant.advance(float("nan"))
    with pytest.raises(KeyError, match="unknown plant input"):
        plant.set_input("finger", 1.0)


def test_driver_saturates_at_the_supply():
    plant = Plant.from_devices([DeviceParams()], seeds=[0])
    plant.set_input("motor_jammed", 1.0)
    for _ in range(10):
        plant.advance(100.0)
    assert plant.motor_current_a[0] == pytest.approx(6.0 / 21.2, rel=1e-9)
    

def test_a_100_ms_tap_dissipates_about_81_percent_of_its_work():
    from ebraille_sim.physics.fingertip import tap_dissipated_fraction
    for name in ("soft", "nominal", "stiff"):
        frac = tap_dissipated_fraction(FINGERS[name])
        assert 0.70 <= frac <= 0.90                          # Jindrich et al. 2003: 81 %
    assert tap_dissipated_fraction(FINGERS["nominal"]) == pytest.approx(0.81, abs=0.01)
    # an elastic pulp (no relaxation) returns all of it
    import dataclasses
    elastic = dataclasses.replace(FINGERS["nominal"], relax_weight_inf=1.0, relax_weight_1=0.0,
                                  relax_weight_2=0.0, relax_weight_3=0.0)
    assert tap_dissipated_fraction(elastic) == pytest.approx(0.0, abs=1e-3)
