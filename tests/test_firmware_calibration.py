"""The supervisor knows the drive only through its datasheet, the designer's margins and the
end-of-line calibration that reads the unit through the board's own current chain.

``controllers.supervisor.config.device_limits`` is ``firmware_limits(datasheet_device(d),
calibrate_drive(d))``; these tests check that nothing else of the unit reaches it, that the
calibration's numbers are within the bounds the firmware assumes for them, and that the
envelope built from them bounds the push of every unit within the tolerances.
"""
from __future__ import annotations

import dataclasses
import itertools

import numpy as np

import pytest

from controllers.supervisor import SupervisorConfig
from controllers.supervisor.config import GUIDE_COULOMB_MAX_N, datasheet_device, device_limits, firmware_limits
from ebraille_sim.base.seeds import SeedNode
from ebraille_sim.estimation.calibration import (CALIBRATION_CONVERSIONS, FORCE_GAUGE_TOLERANCE,
                                                 SPEED_REFERENCE_TOLERANCE, calibrate_device, calibrate_drive,
                                                 steady_estimate)
from ebraille_sim.estimation.registry import cached_model
from ebraille_sim.physics import limits
from ebraille_sim.physics.current_sense import averaged_error_a, mean_error_a, mean_reading_a
from ebraille_sim.physics.params import CurrentSenseParams, DeviceParams, FINGERS, FSRS
from ebraille_sim.scenarios.population import BOARD_UNIFORMS, sample_devices

NOMINAL = DeviceParams()


def _unit(r=1.0, k=1.0, eta=0.6, guide=0.1, shunt=0.0, gain=0.0, offset=0.0, backlash=0.1e-3):
    """A unit of the nominal parts with its own constants (scales of R and kM = kE, absolute
    gear efficiency, guide friction, backlash; the current chain's errors as fractions of their
    bounds)."""
    m, d, cs = NOMINAL.motor, NOMINAL.drivetrain, NOMINAL.current_sense
    motor = dataclasses.replace(m, resistance_ohm=m.resistance_ohm * r, torque_constant_nm_per_a=m.torque_constant_nm_per_a * k,
                                back_emf_v_s_per_rad=m.back_emf_v_s_per_rad * k)
    drive = dataclasses.replace(d, gear_efficiency=eta, guide_coulomb_n=guide, backlash_m=backlash)
    chain = dataclasses.replace(cs, shunt_error=shunt * cs.shunt_tolerance, gain_error=gain * cs.gain_error_max,
                                offset_v=offset * cs.offset_max_v)
    return dataclasses.replace(NOMINAL, motor=motor, drivetrain=drive, current_sense=chain)


CORNERS = [_unit(r, k, eta, guide, s, s, o)
           for r, k, eta, guide, s, o in itertools.product((0.85, 1.15), (0.91, 1.09), (0.5, 0.7), (0.05, 0.3),
                                                            (-1.0, 1.0), (-1.0, 1.0))]
"""Units at the corners of the tolerances: R +/-15 %, kM = kE +/-9 % (3 sigma of the population),
gear efficiency 0.5-0.7, guide friction 0.05-0.3 N, the chain's gain and offset errors at their bounds."""


def test_the_supervisor_constants_are_the_datasheet_and_the_calibration():
    drawn = sample_devices(424242, 6)
    sheets = {(datasheet_device(d).motor, datasheet_device(d).drivetrain, datasheet_device(d).current_sense)
              for d in drawn}
    nominal_sheet = datasheet_device(NOMINAL)
    assert sheets == {(nominal_sheet.motor, nominal_sheet.drivetrain, nominal_sheet.current_sense)}
    for d in drawn:
        assert device_limits(d) == firmware_limits(datasheet_device(d), calibrate_drive(d))
    # what the calibration does not see does not reach the supervisor: the reader, the FSR unit
    other = dataclasses.replace(_unit(), finger=FINGERS["soft"], fsr=FSRS[sorted(FSRS)[-1]])
    assert device_limits(other) == device_limits(_unit())
    assert datasheet_device(_unit(backlash=0.2e-3)).drivetrain == datasheet_device(_unit()).drivetrain
    # a unit with another gear efficiency changes only what its calibration measured
    a, b = device_limits(_unit(eta=0.6)), device_limits(_unit(eta=0.7))
    assert {k for k in a if a[k] != b[k]} == {"push_force_per_a_n", "friction_current_a", "gear_efficiency",
                                              "speed_hold_s", "stuck_travel_m", "motor_resistance_ohm",
                                              "stall_current_a", "back_emf_v_s_per_m"}


@pytest.mark.parametrize("unit", CORNERS[::5])
def test_the_calibration_reads_the_unit_within_the_bounds_the_firmware_assumes(unit):
    cs = unit.current_sense
    cal = calibrate_drive(unit)
    e_gain = (1 + cs.shunt_error) * (1 + cs.gain_error) - 1
    i_rest = 1.0 / unit.motor.resistance_ohm
    e_r = (cs.gain_error_max + cs.shunt_tolerance) + averaged_error_a(cs, CALIBRATION_CONVERSIONS) / i_rest
    assert abs(cal.resistance_ohm / unit.motor.resistance_ohm - 1) <= e_r
    g = limits.shaft_to_rack_per_m(unit.drivetrain.gear_ratio, unit.drivetrain.pinion_radius_m)
    p_true = unit.drivetrain.gear_efficiency * unit.motor.torque_constant_nm_per_a * g
    i1, i2 = cal.test_currents_a
    slope = 2 * mean_error_a(cs, CALIBRATION_CONVERSIONS) / (i2 - i1)
    ratio = cal.push_force_per_a_n * (1 + e_gain) / p_true
    assert 1 - FORCE_GAUGE_TOLERANCE - slope <= ratio <= 1 + FORCE_GAUGE_TOLERANCE + slope
    ke_true = unit.motor.back_emf_v_s_per_rad * g
    assert abs(cal.back_emf_v_s_per_m / ke_true - 1) <= SPEED_REFERENCE_TOLERANCE + 0.005


@pytest.mark.parametrize("unit", CORNERS)
def test_the_envelope_bounds_the_push_of_every_unit_within_the_tolerances(unit):
    """The unit's push moving forward (eq. (1) of docs/safety.md with its true constants and its
    guide rods' friction against the push) is never above the firmware's, at any current; the
    impact's mass and the speed the firmware reads are never below the unit's; so the current
    limit at rest holds the unit below the envelope force."""
    c = SupervisorConfig.for_device(unit)
    m, d = unit.motor, unit.drivetrain
    g = limits.shaft_to_rack_per_m(d.gear_ratio, d.pinion_radius_m)
    p_true = d.gear_efficiency * m.torque_constant_nm_per_a * g
    assert p_true <= c.push_force_per_a_n
    assert d.gear_efficiency * m.friction_torque_nm * g + d.guide_coulomb_n >= c.friction_current_a * c.push_force_per_a_n
    assert d.gear_efficiency <= c.gear_efficiency
    assert m.back_emf_v_s_per_rad * g >= c.back_emf_v_s_per_m
    push = limits.push_force_bound_n(c.current_limit_a, m.torque_constant_nm_per_a, g, d.gear_efficiency,
                                     m.friction_torque_nm, unit.drivetrain.moving_mass_kg * unit.gravity_m_per_s2)
    assert push - d.guide_coulomb_n <= c.envelope_force_n
    # and the nominal drive still reaches the 2.7 N top setpoint with its guide friction, hand upright
    if unit is CORNERS[0]:
        n = SupervisorConfig()
        p = NOMINAL.drivetrain.gear_efficiency * NOMINAL.motor.torque_constant_nm_per_a * g
        top = p * (n.current_limit_a - NOMINAL.motor.friction_torque_nm / NOMINAL.motor.torque_constant_nm_per_a) \
            - NOMINAL.drivetrain.guide_coulomb_n - 0.059
        assert top > 2.7


def test_margins_lower_the_limits_against_the_units_truth():
    """The datasheet's constants with the margins give a lower current limit at rest than the
    nominal unit's truth, and the guide rods' largest friction is the one the firmware assumes."""
    c = SupervisorConfig()
    b = limits.drive_bounds(NOMINAL)
    true_limit = limits.current_for_push_force_a(c.envelope_force_n, b["push_force_per_a_n"], 1.0, 1.0,
                                                 b["friction_current_a"] * b["push_force_per_a_n"], b["weight_n"])
    assert 0.85 * true_limit < c.current_limit_a < true_limit
    assert c.guide_static_n == GUIDE_COULOMB_MAX_N * NOMINAL.drivetrain.guide_breakaway_ratio
    assert 0.98 * b["back_emf_v_s_per_m"] < c.back_emf_v_s_per_m < b["back_emf_v_s_per_m"]


@pytest.mark.parametrize("errors", [(0.0, 0.0, 0.0), (1.0, 1.0, 1.0), (-1.0, 1.0, -1.0), (1.0, -1.0, 1.0)])
def test_a_mean_reading_is_the_chain_gain_times_the_current_within_its_bound(errors):
    s, gn, o = errors
    cs = dataclasses.replace(CurrentSenseParams(), shunt_error=0.01 * s, gain_error=0.002 * gn, offset_v=25e-6 * o)
    gain = (1 + cs.shunt_error) * (1 + cs.gain_error)
    bound = averaged_error_a(cs, CALIBRATION_CONVERSIONS)
    worst = 0.0
    for k in range(60):
        i = -0.06 + 0.12 * k / 59 + 0.37e-3 * k / 59          # codes at every fraction of a step
        worst = max(worst, abs(mean_reading_a(cs, i, 1000.0 + k, CALIBRATION_CONVERSIONS) - gain * i))
    assert worst <= bound
    assert worst > 0.1 * bound                                  # the bound is not loose by orders


def test_the_divider_calibration_reads_its_known_load_with_the_load_s_error():
    model = cached_model(NOMINAL.estimator.model)
    for err in (-0.02, 0.02):
        dev = calibrate_device(NOMINAL, load_error=err)
        assert steady_estimate(model, 1.0 + err, dev.fsr, dev.circuit, 20.0) == pytest.approx(1.0, abs=2e-3)
        assert steady_estimate(model, 1.0, dev.fsr, dev.circuit, 20.0) == pytest.approx(1.0 / (1 + err), rel=0.02)
    with pytest.raises(ValueError, match="load_error"):
        calibrate_device(NOMINAL, load_error=float("nan"))


def test_the_population_draws_the_chain_errors_within_their_bounds_on_a_fifth_seed_child():
    drawn = sample_devices(99, 40)
    cs0 = CurrentSenseParams()
    for name, bound in (("shunt_error", cs0.shunt_tolerance), ("gain_error", cs0.gain_error_max),
                        ("offset_v", cs0.offset_max_v)):
        v = [getattr(d.current_sense, name) for d in drawn]
        assert max(map(abs, v)) <= bound and min(v) < -0.5 * bound and max(v) > 0.5 * bound
    assert len(BOARD_UNIFORMS) == 7
    # the table's load errors come after the first four: those four draw as before
    u_b = np.random.default_rng(SeedNode(99).spawn(5)[4]).random(4)
    assert np.array_equal(np.random.default_rng(SeedNode(99).spawn(5)[4]).random(7)[:4], u_b)
    # the board's child is the fifth: the reader, FSR, motor and drive draws keep their children
    assert [c.spawn_key for c in SeedNode(5).spawn(5)[:4]] == [c.spawn_key for c in SeedNode(5).spawn(4)]


BAD = [("shunt_ohm", -0.05), ("adc_bits", 0), ("offset_v", 0.01), ("offset_max_v", 0.03),
       ("shunt_tolerance", -0.01), ("gain_error_max", -0.002), ("gain_error_max", 2.0), ("adc_noise_lsb", 1e9),
       ("zero_samples", 0), ("shunt_error", 0.02)]


@pytest.mark.parametrize("key,value", BAD)
def test_a_current_chain_parameter_out_of_range_is_one_line_in_the_api(key, value):
    with pytest.raises(ValueError) as e:
        DeviceParams(current_sense=CurrentSenseParams(**{key: value}))
    msg = str(e.value)
    assert "\n" not in msg and key in msg


@pytest.mark.parametrize("overrides,named", [
    ({"shunt_ohm": 10.0}, "shunt_ohm"), ({"adc_bits": 6}, "adc_bits"), ({"adc_bits": 7}, "adc_bits"),
    ({"gain_v_per_v": 1.0}, "gain_v_per_v")])
def test_a_chain_that_cannot_read_the_drive_is_one_line_in_the_api(overrides, named):
    with pytest.raises(ValueError) as e:
        SupervisorConfig.for_device(DeviceParams(current_sense=CurrentSenseParams(**overrides)))
    assert "\n" not in str(e.value) and named in str(e.value)


@pytest.mark.parametrize("line,named", [("shunt_ohm = -0.05", "shunt_ohm"), ("adc_bits = 0", "adc_bits"),
                                        ("offset_v = 0.01", "offset_v"), ("offset_max_v = 0.03", "offset_max_v"),
                                        ("shunt_tolerance = -0.01", "shunt_tolerance"),
                                        ("adc_bits = 6", "adc_bits"), ("shunt_ohm = 10.0", "shunt_ohm")])
def test_a_current_chain_parameter_out_of_range_is_one_line_at_the_cli(line, named, tmp_path, capsys):
    from ebraille_sim.cli import main
    path = tmp_path / "bad.toml"
    path.write_text(f'name = "bad"\ndescription = "x"\n[device.current_sense_overrides]\n{line}\n')
    before = sorted(p.name for p in tmp_path.iterdir())
    code = main(["run", str(path), "--duration", "0.2", "--out", str(tmp_path / "out"), "--no-plot", "-q"])
    cap = capsys.readouterr()
    lines = cap.err.splitlines()
    assert code == 2 and len(lines) == 1 and lines[0].startswith("error: ") and named in lines[0], cap.err
    assert "Traceback" not in cap.err and len(lines[0]) <= 300
    assert sorted(p.name for p in tmp_path.iterdir()) == before        # refused before any run or output
