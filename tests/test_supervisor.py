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
    assert inner.seen[-1] == pytest.approx(2.7)
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


def test_stuck_reading_with_moving_motor_latches_and_retracts():
    sup = Supervisor(Const(0.0), SupervisorConfig(slew_v_per_s=1e6))
    sup.reset(force_est_n=1.0, setpoint_n=1.0)
    run(sup, 1.0, n=200, cur=0.0, jitter=0.0)
    sup.inner.u = 1.0                                # command jumps, reading frozen at 1.0 N
    run(sup, 1.0, n=5, cur=0.01, jitter=0.0)         # motor turns: u - R i = 0.79 V of back-EMF
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
    assert (nominal.motor_resistance_ohm, nominal.stall_current_a, nominal.rated_current_a) == (21.2, 6.0 / 21.2, 0.19)
    assert nominal.force_cap_n == TACTILE_FORCE_MAX_N
    for name, motor in MOTORS.items():
        dev = DeviceParams(motor=motor, driver_supply_v=motor.nominal_voltage_v)
        c = SupervisorConfig.for_device(dev)
        assert c.motor_resistance_ohm == motor.resistance_ohm
        assert c.stall_current_a == pytest.approx(motor.nominal_voltage_v / motor.resistance_ohm)
        assert 0 < c.rated_current_a < c.stall_current_a
    maxon = DeviceParams(motor=MOTORS["maxon_dcx6m_3v"], driver_supply_v=3.0)
    assert SupervisorConfig.for_device(maxon).motor_resistance_ohm == 8.9
    sup = wrap_controller({"force_cap_n": 2.0, "cap_margin_n": 0.2}, Const(1.0), 1e-3, device=maxon)
    assert sup.config.motor_resistance_ohm == 8.9 and sup.config.force_cap_n == 2.0
    assert SupervisorConfig.for_device(maxon, motor_resistance_ohm=9.5).motor_resistance_ohm == 9.5


def test_force_cap_limit_is_the_tactile_maximum_plus_one_newton():
    from controllers.supervisor import FORCE_CAP_LIMIT_N
    from ebraille_sim.physics.params import TACTILE_FORCE_MAX_N
    assert FORCE_CAP_LIMIT_N == TACTILE_FORCE_MAX_N + 1.0 == 4.0
    assert SupervisorConfig(force_cap_n=4.0, out_of_range_n=5.0).force_cap_n == 4.0
