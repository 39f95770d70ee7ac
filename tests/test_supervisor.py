"""Safety supervisor (controllers.supervisor) driven directly, without the plant."""
import math

import pytest

from controllers.supervisor import Supervisor, SupervisorConfig
from ebraille_sim.scenarios.supervision import validate_section, wrap_controller
from ebraille_sim.scenarios.spec import ScenarioError


class Const:
    """Inner controller returning a fixed command and recording the setpoints it saw."""
    name = "const"

    def __init__(self, u):
        self.u = u
        self.seen = []
        self.resets = 0

    def reset(self, *, force_est_n, setpoint_n, command_v=0.0):
        self.resets += 1

    def update(self, force_est_n, setpoint_n, dt_s, motor_current_a=None):
        self.seen.append(setpoint_n)
        return self.u


def run(sup, f, sp=1.0, n=1, cur=None, dt=1e-3, jitter=3e-3):
    """``n`` periods at the estimate ``f`` (plus an alternating jitter, as sensor noise gives)."""
    u = None
    for k in range(n):
        fk = f + (jitter if (k % 2 and f > 0.1) else 0.0) if math.isfinite(f) else f
        u = sup.update(fk, sp, dt, cur)
    return u


def test_setpoint_clipped_and_slew_limited():
    inner = Const(5.0)
    sup = Supervisor(inner)
    sup.reset(force_est_n=0.0, setpoint_n=1.0)
    u1 = sup.update(0.0, 3.5, 1e-3)
    assert inner.seen[-1] == pytest.approx(min(2.7, sup.config.slip_setpoint_cap_n))
    assert u1 == pytest.approx(0.6)                 # 600 V/s over 1 ms
    assert run(sup, 0.0, 3.5, n=20) == pytest.approx(5.0)


def test_soft_zone_scales_push_and_cap_retracts():
    sup = Supervisor(Const(2.0), SupervisorConfig(slew_v_per_s=1e6))
    sup.reset(force_est_n=0.5, setpoint_n=1.0)
    run(sup, 0.5, n=5)                               # in contact
    assert run(sup, 2.85) == pytest.approx(1.0)      # half-way through the 0.3 N soft zone
    assert run(sup, 3.05) == pytest.approx(-2.0)     # above the cap: pull back
    assert sup.fault is None
    assert run(sup, 2.0) == pytest.approx(2.0)


def test_watchdog_holds_then_resumes_or_latches():
    inner = Const(math.nan)
    sup = Supervisor(inner, SupervisorConfig(slew_v_per_s=1e6))
    sup.reset(force_est_n=1.0, setpoint_n=1.0)
    assert run(sup, 1.0, n=100) == 0.0
    inner.u = 1.5
    assert run(sup, 1.0) == 0.0 and inner.resets == 2   # bumpless restart from the held 0 V
    assert run(sup, 1.0) == pytest.approx(1.5)
    inner.u = math.inf
    run(sup, 1.0, n=600)
    assert sup.fault == "controller_nonfinite" and sup.mode in ("retract", "hold")


def test_i2t_trips_after_the_overload_time_at_stall_current():
    cfg = SupervisorConfig()
    sup = Supervisor(Const(6.0), cfg)
    sup.reset(force_est_n=1.0, setpoint_n=1.0)
    k = 0
    while sup.fault is None and k < 5000:
        sup.update(1.0 + 1e-3 * (k % 7), 1.0, 1e-3, cfg.stall_current_a)
        k += 1
    assert sup.fault == "motor_overcurrent"
    assert k * 1e-3 == pytest.approx(cfg.overload_time_s, abs=0.01)


def test_rated_current_never_trips():
    sup = Supervisor(Const(4.0))
    sup.reset(force_est_n=1.0, setpoint_n=1.0)
    for k in range(3000):
        sup.update(1.0 + 1e-3 * (k % 5), 1.0, 1e-3, 0.19)
    assert sup.fault is None


def test_stuck_reading_with_moving_command_latches_without_a_current_measurement():
    sup = Supervisor(Const(0.0), SupervisorConfig(slew_v_per_s=1e6))
    sup.reset(force_est_n=1.0, setpoint_n=1.0)
    run(sup, 1.0, n=200, cur=None, jitter=0.0)
    sup.inner.u = 1.0                                # command jumps, reading frozen at 1.0 N
    run(sup, 1.0, n=40, cur=None, jitter=0.0)
    assert sup.fault is None                         # within the estimator's response: not yet
    run(sup, 1.0, n=20, cur=None, jitter=0.0)
    assert sup.fault == "fsr_stuck"
    assert run(sup, 1.0, cur=0.01) == pytest.approx(-2.0)


def test_stuck_reading_with_jammed_motor_is_left_to_i2t():
    sup = Supervisor(Const(0.0), SupervisorConfig(slew_v_per_s=1e6))
    sup.reset(force_est_n=1.0, setpoint_n=1.0)
    run(sup, 1.0, n=200, cur=0.0, jitter=0.0)
    sup.inner.u = 1.0
    for _ in range(50):                                          # stalled: i = u/R, no back-EMF
        sup.update(1.0, 1.0, 1e-3, sup.u_prev / 21.2)
    assert sup.fault is None


def test_out_of_range_and_nonfinite_estimate_latch():
    for f in (4.5, math.nan):
        sup = Supervisor(Const(1.0))
        sup.reset(force_est_n=1.0, setpoint_n=1.0)
        run(sup, 1.0, n=10)
        run(sup, f)
        assert sup.fault == "fsr_out_of_range"


def test_contact_loss_freezes_then_resumes_on_contact():
    inner = Const(1.0)
    sup = Supervisor(inner, SupervisorConfig(slew_v_per_s=1e6))
    sup.reset(force_est_n=1.0, setpoint_n=1.0)
    run(sup, 1.0, n=50)
    assert run(sup, 0.0) == pytest.approx(-2.0)      # back off
    assert sup.mode == "freeze"
    assert run(sup, 0.0, n=100) == 0.0               # then hold
    assert run(sup, 0.8, n=2) == pytest.approx(1.0)  # contact again: resume
    assert sup.mode == "run" and sup.fault is None


def test_contact_loss_timeout_latches_then_holds_after_retract():
    sup = Supervisor(Const(1.0))
    sup.reset(force_est_n=1.0, setpoint_n=1.0)
    run(sup, 1.0, n=50)
    run(sup, 0.0, n=700)
    assert sup.fault == "contact_lost"
    run(sup, 0.0, n=700)                             # no current measurement: fixed retract time
    assert sup.mode == "hold" and run(sup, 0.0) == 0.0


def test_disabled_supervisor_passes_through():
    sup = Supervisor(Const(math.nan), SupervisorConfig(enabled=False))
    assert math.isnan(sup.update(1.0, 1.0, 1e-3))


@pytest.mark.parametrize("section,msg", [
    ({"force_cap": 3.0}, "unknown key 'force_cap' in \\[supervisor\\]"),
    ({"force_cap_n": -1.0}, "force_cap_n must be > 0, got -1.0"),
    ({"retract_v": float("nan")}, "retract_v must be finite, got nan"),
    ({"cap_margin_n": 5.0}, "cap_margin_n"),
    ({"enabled": 1}, "enabled must be true or false"),
    ({"force_cap_n": 100.0, "out_of_range_n": 200.0}, "force_cap_n = 100 N is above the 4 N safe limit"),
    ({"force_cap_n": 4.01, "out_of_range_n": 5.0}, "above the 4 N safe limit"),
])
def test_validate_section_errors(section, msg):
    with pytest.raises(ScenarioError, match=msg):
        validate_section("x.toml", section)


def test_wrap_controller_uses_the_section():
    sup = wrap_controller(validate_section("x.toml", {"force_cap_n": 2.0, "cap_margin_n": 0.2}), Const(1.0), 1e-3)
    assert isinstance(sup, Supervisor) and sup.config.force_cap_n == 2.0


def test_motor_limits_follow_the_device():
    from ebraille_sim.physics.params import MOTORS, TACTILE_FORCE_MAX_N, DeviceParams
    nominal = SupervisorConfig()
    assert nominal == SupervisorConfig.for_device(DeviceParams())
    # the resistance is the one the at-rest calibration measured through the current chain
    assert nominal.motor_resistance_ohm == pytest.approx(21.2, rel=0.015)
    assert nominal.stall_current_a == 6.0 / nominal.motor_resistance_ohm and nominal.rated_current_a == 0.19
    assert nominal.force_cap_n == TACTILE_FORCE_MAX_N
    for name, motor in MOTORS.items():
        dev = DeviceParams(motor=motor, driver_supply_v=motor.nominal_voltage_v)
        c = SupervisorConfig.for_device(dev)
        assert c.motor_resistance_ohm == pytest.approx(motor.resistance_ohm, rel=0.015)
        assert c.stall_current_a == pytest.approx(motor.nominal_voltage_v / motor.resistance_ohm, rel=0.015)
        assert 0 < c.rated_current_a < c.stall_current_a
    maxon = DeviceParams(motor=MOTORS["maxon_dcx6m_3v"], driver_supply_v=3.0)
    r_maxon = SupervisorConfig.for_device(maxon).motor_resistance_ohm
    assert r_maxon == pytest.approx(8.9, rel=0.015)
    sup = wrap_controller({"force_cap_n": 2.0, "cap_margin_n": 0.2}, Const(1.0), 1e-3, device=maxon)
    assert sup.config.motor_resistance_ohm == r_maxon and sup.config.force_cap_n == 2.0
    assert SupervisorConfig.for_device(maxon, envelope_overrides={"motor_resistance_ohm": 9.5}).motor_resistance_ohm == 9.5


def test_the_policy_is_settable_and_the_drive_envelope_comes_from_the_device():
    import dataclasses

    from controllers.supervisor import ENVELOPE_KEYS, POLICY_KEYS, device_limits
    from ebraille_sim.physics.params import DRIVETRAINS, DeviceParams
    names = [f.name for f in dataclasses.fields(SupervisorConfig)]
    assert sorted(POLICY_KEYS + ENVELOPE_KEYS) == sorted(names) and not set(POLICY_KEYS) & set(ENVELOPE_KEYS)
    assert set(device_limits(DeviceParams())) == set(ENVELOPE_KEYS)
    assert {"board_mass_kg", "reader_b_n_per_m", "push_force_per_a_n", "mesh_stiffness_n_per_m"} <= set(ENVELOPE_KEYS)
    for key in ("board_mass_kg", "motor_resistance_ohm"):
        with pytest.raises(ValueError, match=f"^{key} is not a supervisor setting: it is derived from \\[device\\]"):
            SupervisorConfig.for_device(DeviceParams(), **{key: 1.0})
        with pytest.raises(ScenarioError, match=f"^x.toml: \\[supervisor\\] {key} is not a setting: the supervisor "
                                                f"derives it from \\[device\\]"):
            validate_section("x.toml", {key: 1.0})
    # the mesh stiffness the slip cap assumes is the device's drive train's, as the firmware's datasheet has it
    stiff = dataclasses.replace(DRIVETRAINS["planetary_64"], mesh_stiffness_n_per_m=6e4)
    c = SupervisorConfig.for_device(DeviceParams(drivetrain=stiff))
    assert c.mesh_stiffness_n_per_m == 6e4 and SupervisorConfig().mesh_stiffness_n_per_m == 3e4
    assert c.slip_setpoint_cap_n < SupervisorConfig().slip_setpoint_cap_n       # a stiffer mesh leaves less room
    with pytest.raises(ValueError, match="unknown key 'force_cap_n' in the drive envelope"):
        SupervisorConfig.for_device(DeviceParams(), envelope_overrides={"force_cap_n": 2.0})


def test_force_cap_limit_is_the_tactile_maximum_plus_one_newton():
    from controllers.supervisor import FORCE_CAP_LIMIT_N
    from ebraille_sim.physics.params import TACTILE_FORCE_MAX_N
    assert FORCE_CAP_LIMIT_N == TACTILE_FORCE_MAX_N + 1.0 == 4.0
    assert SupervisorConfig(force_cap_n=4.0, out_of_range_n=5.0).force_cap_n == 4.0


# ---------------------------------------------------------------- drive bounds (physics.limits)
def test_push_force_bound_is_eta_km_n_over_r_less_friction_plus_weight():
    from ebraille_sim.physics import limits
    kt, g, eta, tf, w = 4.12e-3, 25600.0, 0.6, 0.034e-3, 0.0589
    assert limits.push_force_bound_n(0.05, kt, g, eta, tf, w) == pytest.approx(0.6 * (105.472 * 0.05 - 0.8704) + w,
                                                                              rel=1e-12)
    i = limits.current_for_push_force_a(3.0, kt, g, eta, tf, w)
    assert limits.push_force_bound_n(i, kt, g, eta, tf, w) == pytest.approx(3.0, rel=1e-12)
    assert i == pytest.approx(((3.0 - w) / 0.6 / g + tf) / kt, rel=1e-12)


def test_speed_from_back_emf_and_impact_energy():
    from ebraille_sim.physics import limits
    assert limits.rack_speed_from_emf_m_per_s(2.0, 0.05, 21.2, 4.116e-3, 25600.0) == pytest.approx(
        (2.0 - 1.06) / 4.116e-3 / 25600.0, rel=1e-12)
    e = limits.impact_energy_j(0.01, 3.4, 0.006, 0.6)
    assert e == pytest.approx(0.5 * (0.6 * 3.4 + 0.006) * 1e-4, rel=1e-12)
    assert limits.speed_for_energy_m_per_s(e, 3.4, 0.006, 0.6) == pytest.approx(0.01, rel=1e-12)


def test_pulp_energy_is_the_integral_of_the_elastic_law():
    from scipy.integrate import quad

    from ebraille_sim.physics import limits
    from ebraille_sim.physics.fingertip import elastic_force
    b, m = 264.0, 1246.0
    for d in (0.3e-3, 1.4e-3, 2.2e-3):
        ref = quad(lambda x: elastic_force(x, b, m), 0.0, d)[0]
        assert limits.elastic_energy_j(d, b, m) == pytest.approx(ref, rel=1e-9)
    assert limits.elastic_energy_j(-1e-3, b, m) == 0.0
    # absorbed energy above a drive of 1 N up to 3 N, against a direct integral
    d0, d1 = math.log1p(m * 1.0 / b) / m, math.log1p(m * 3.0 / b) / m
    ref = quad(lambda x: elastic_force(x, b, m) - 1.0, d0, d1)[0]
    assert limits.absorbed_energy_j(1.0, 3.0, b, m) == pytest.approx(ref, rel=1e-9)
    # the drive force that a given impact allows inverts it
    assert limits.drive_force_for_impact_n(ref, 3.0, b, m) == pytest.approx(1.0, rel=1e-9)
    assert limits.drive_force_for_impact_n(0.0, 3.0, b, m) == 3.0
    assert limits.drive_force_for_impact_n(1.0, 3.0, b, m) < 0.0          # too much energy: brake


def test_derived_limits_of_the_default_device():
    c = SupervisorConfig()
    # the calibrated push per ampere with its margins: above the unit's 63.28 N/A, by at most 4 %
    assert 1.0 < c.push_force_per_a_n / (0.6 * 4.12e-3 * 64 / 2.5e-3) < 1.04
    assert c.envelope_force_n == pytest.approx(3.5 - (540 + 1448 * 3.5) * 45e-6, rel=1e-12)  # 3.25 N
    assert c.current_limit_a == pytest.approx(0.0566, abs=2e-4)           # 58.6 mA with the unit's truth
    assert c.speed_limit_m_per_s == pytest.approx(0.0395, abs=5e-4)       # 40.2 mm/s with the unit's truth
    assert c.current_limit_a < c.rated_current_a < c.stall_current_a
    assert c.drive_force_limit_n(0.0) == pytest.approx(c.envelope_force_n)
    assert 1.8 < c.drive_force_limit_n(0.014) < 2.0                        # the 14 mm/s approach
    from ebraille_sim.physics.params import DRIVETRAINS, MOTORS, DeviceParams
    pololu = SupervisorConfig.for_device(DeviceParams(motor=MOTORS["pololu_lp_6v"],
                                                      drivetrain=DRIVETRAINS["pololu_100"]))
    assert 1.0 < pololu.push_force_per_a_n / (0.51 * 4.15e-3 * 100.37 / 2.5e-3) < 1.04
    # the friction the line measured (T_f/kM = its 20 mA no-load current, and the guide rods), less
    # what may be lost in service
    assert 0.7 * 0.02 < pololu.friction_current_a < 0.02
    assert pololu.current_limit_a == pytest.approx(
        (pololu.envelope_force_n - pololu.weight_n) / pololu.push_force_per_a_n + pololu.friction_current_a, rel=1e-12)
    with pytest.raises(ValueError, match="safe_force_n = 4.5 N is above the 4 N"):
        SupervisorConfig(safe_force_n=4.5)


def consistent(sup, f, sp, n, u_free=None, dt=1e-3):
    """``n`` periods of a stalled motor (current u/R) or a free one (no-load current)."""
    c = sup.config
    for _ in range(n):
        cur = sup.u_prev / c.motor_resistance_ohm if u_free is None else c.friction_current_a
        sup.update(f, sp, dt, cur)


def test_envelope_limits_the_command_to_the_current_limit_at_rest():
    sup = Supervisor(Const(6.0))
    sup.reset(force_est_n=1.0, setpoint_n=1.0)
    consistent(sup, 1.0, 1.0, 100)
    c = sup.config
    # the limit applies to the board's reading of the current, derated by the chain's worst case
    assert sup.u_prev == pytest.approx(c.motor_resistance_ohm * c.sensed_limit_a(c.current_limit_a), rel=1e-6)


def test_envelope_brakes_above_the_speed_limit():
    sup = Supervisor(Const(6.0), SupervisorConfig(slew_v_per_s=1e6))
    sup.reset(force_est_n=0.0, setpoint_n=1.0, command_v=6.0)
    c = sup.config
    fast = 1.2 * c.speed_limit_m_per_s * c.back_emf_v_s_per_m       # back-EMF of a board above the limit
    u = sup.update(0.0, 1.0, 1e-3, (6.0 - fast) / c.motor_resistance_ohm)
    assert u < fast                                                   # current reversed: braking


def test_setpoint_release_is_not_a_contact_loss_but_a_real_drop_is():
    sup = Supervisor(Const(0.5), SupervisorConfig(slew_v_per_s=1e6))
    sup.reset(force_est_n=1.0, setpoint_n=1.0)
    run(sup, 1.0, n=100)
    run(sup, 0.6, sp=0.4, n=5)                    # the setpoint fell by 0.6 N: the estimate follows
    assert sup.mode == "run"
    run(sup, 0.6, sp=0.4, n=300)
    run(sup, 0.2, sp=0.4, n=5)                    # a fall of 0.4 N with no release asked for
    assert sup.mode == "freeze"



def test_a_partial_unloading_is_not_a_contact_loss_but_a_fall_toward_no_load_is():
    """A strap slip drops the estimate by more than drop_n within drop_window_s but leaves the
    finger loaded (1.0 -> 0.65 N); a lost contact takes it toward the no-load reading."""
    for end_n, lost in ((0.65, False), (0.55, False), (0.45, True), (0.2, True)):
        sup = Supervisor(Const(0.5), SupervisorConfig(slew_v_per_s=1e6))
        sup.reset(force_est_n=1.0, setpoint_n=1.0)
        run(sup, 1.0, n=100)
        run(sup, end_n, n=5)
        assert (sup.mode == "freeze") is lost, end_n
    with pytest.raises(ValueError, match="drop_keep_fraction = 1.5 must be at most 1"):
        SupervisorConfig(drop_keep_fraction=1.5)

def test_stuck_estimate_while_the_board_travels_latches():
    sup = Supervisor(Const(0.7), SupervisorConfig(slew_v_per_s=1e6))
    sup.reset(force_est_n=1.0, setpoint_n=1.0)
    run(sup, 1.0, n=20)
    c = sup.config
    v = 2e-3                                      # the board moves at 2 mm/s, the estimate does not change
    # the design's largest backlash (0.2 mm) and one estimator period at the speed limit
    assert c.stuck_travel_m == pytest.approx(0.2e-3 + 0.01 * 0.04137, rel=1e-3)   # 0.61 mm
    for _ in range(250):
        sup.update(1.0, 1.0, 1e-3, (sup.u_prev - c.back_emf_v_s_per_m * v) / c.motor_resistance_ohm)
    assert sup.fault is None                      # 0.5 mm: within the backlash and one estimator period
    for _ in range(100):
        sup.update(1.0, 1.0, 1e-3, (sup.u_prev - c.back_emf_v_s_per_m * v) / c.motor_resistance_ohm)
    assert sup.fault == "fsr_stuck"


def test_motor_pushing_without_motion_or_contact_is_stopped():
    sup = Supervisor(Const(6.0))
    sup.reset(force_est_n=0.0, setpoint_n=1.0)
    consistent(sup, 0.0, 1.0, 400)
    assert sup.fault is None
    consistent(sup, 0.0, 1.0, 200)
    assert sup.fault == "motor_stalled" and any("motor_stalled" in e for _, e in sup.events)


def test_at_the_current_limit_a_push_the_estimate_accounts_for_is_a_hold_not_a_stall():
    """A board at rest at the current limit: a jam when the push at the lower edge of the friction
    band (2.39 N at the limit as the board reads it, 52.8 mA) exceeds the estimate by more than
    ``implausible_n``, a hold of a high force (creeping forward against the break-away friction)
    when the estimate shows it."""
    c = SupervisorConfig()
    i_read = c.sensed_limit_a(c.current_limit_a)
    f_rest = c.push_force_n(i_read, c.friction_breakaway_ratio, -c.weight_n) - c.guide_static_n
    assert f_rest == pytest.approx(2.39, abs=0.01)
    for f, fault in [(f_rest - c.implausible_n + 0.05, None), (1.0, "motor_stalled")]:
        sup = Supervisor(Const(6.0))
        sup.reset(force_est_n=f, setpoint_n=c.force_cap_n)
        consistent(sup, f, c.force_cap_n, 1000)                   # 1 s at the limit, no motion
        assert sup.fault == fault, (f, sup.events)
        if fault is None:
            assert sup.u_prev == pytest.approx(c.motor_resistance_ohm * i_read, rel=1e-6)
        else:
            assert sup.events[0][0] == pytest.approx(c.stall_time_s, abs=0.005)


def test_current_implying_more_force_than_the_estimate_latches():
    sup = Supervisor(Const(6.0))
    sup.reset(force_est_n=0.5, setpoint_n=1.0)
    c = sup.config
    v = 1e-3
    for _ in range(400):                          # moving at 1 mm/s at the current limit, estimate 0.5 N
        i = c.current_limit_a
        sup.u_prev = c.motor_resistance_ohm * i + c.back_emf_v_s_per_m * v
        sup.update(0.5 + 1e-3 * (sup.t * 1e3 % 3), 1.0, 1e-3, i)
        if sup.fault:
            break
    assert sup.fault == "fsr_implausible"


def test_travel_follows_a_force_loop_that_hunts_back_and_forth():
    """A loop hunting around its setpoint pushes the board forward at the current a push takes,
    and the finger pushes it back while the drive retracts at less than the motor's friction
    current: the travel integral comes back with the board.  Counting only the forward legs
    ratchets it by each leg's travel, into a false ``fsr_implausible`` within seconds.  A motor
    that draws no current (a cut supply) reads no travel, whatever its command."""
    sup = Supervisor(Const(0.0))
    sup.reset(force_est_n=1.0, setpoint_n=1.0)
    c = sup.config
    v, leg = 2e-3, 40                                   # 2 mm/s for 40 ms: 0.08 mm a leg
    legs = ((v, 0.024), (-v, -0.004))                   # forward at 24 mA, back at -4 mA
    assert c.powered_current_a < 0.004 < c.friction_current_a
    k = 0
    start = None
    for cycle in range(60):                             # 4.8 s of hunting
        for speed, i in legs:
            for _ in range(leg):
                sup.u_prev = c.motor_resistance_ohm * i + c.back_emf_v_s_per_m * speed
                sup.update(1.0 + (3e-3 if k % 2 else 0.0), 1.0, 1e-3, i)
                k += 1
        if cycle == 0:
            start = sup.travel_m
    assert sup.fault is None
    assert abs(sup.travel_m - start) < 0.05 * v * leg * 1e-3
    before = sup.travel_m
    for _ in range(100):                                # a cut supply: 0.6 V commanded, no current
        sup.u_prev = 0.6
        sup.update(1.0 + (3e-3 if k % 2 else 0.0), 1.0, 1e-3, 0.0)
        k += 1
    assert sup.travel_m == before


def test_a_board_hunting_inside_the_films_blind_stretch_is_not_a_stuck_sensor():
    """The hysteresis compensation holds its estimate still, to the bit, until the force has
    crossed the film's blind stretch after a reversal: a loop hunting inside it moves the board
    back and forth under an estimate that does not change.  The stuck rule counts the board's
    net travel, so that is not a stuck code; the same estimate while the board keeps moving one
    way is."""
    c = SupervisorConfig()
    v, leg = 2e-3, 40                                   # 0.08 mm a leg, 60 cycles: 9.6 mm back and forth
    legs = ((v, 0.024), (-v, -0.004))
    sup = Supervisor(Const(0.0))
    sup.reset(force_est_n=1.0, setpoint_n=1.0)
    for _ in range(60):
        for speed, i in legs:
            for _ in range(leg):
                sup.u_prev = c.motor_resistance_ohm * i + c.back_emf_v_s_per_m * speed
                sup.update(1.0, 1.0, 1e-3, i)
    assert sup.fault is None
    for k in range(1000):                               # then one way only: 2 mm/s
        sup.u_prev = c.motor_resistance_ohm * 0.024 + c.back_emf_v_s_per_m * v
        sup.update(1.0, 1.0, 1e-3, 0.024)
        if sup.fault:
            break
    assert sup.fault == "fsr_stuck"
    assert k * 1e-3 * v == pytest.approx(c.stuck_travel_m, abs=2 * v * 1e-3)


def test_supervisor_is_deterministic():
    def trace():
        sup = Supervisor(Const(6.0))
        sup.reset(force_est_n=0.0, setpoint_n=1.0)
        out = []
        for k in range(300):
            out.append(sup.update(0.3 * (k > 50), 1.0, 1e-3, sup.u_prev / 21.2 * 0.9))
        return out
    assert trace() == trace()
