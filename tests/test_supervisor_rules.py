"""The safety supervisor's rules, one closed-form case each (controllers.supervisor).

Each case drives :class:`controllers.supervisor.Supervisor` around an inner controller that
returns a chosen command, with hand-made estimates, setpoints and currents, and checks the
command, mode, fault and events against numbers worked out by hand from the rule (in the
module docstring) and the nominal unit's own drive constants (:func:`unit_constants`).

Most cases run at a control period of ``DT = 1/1024 s``: a binary fraction, so the
supervisor's clock ``k DT`` is exact and a rule's time limit falls between two known periods
(``0.5 s`` is not crossed at 512 periods but at 513: ``512 DT = 0.5`` is not above it).
"""
import math

import pytest

from controllers.supervisor import EVENT_CAPACITY, Supervisor, SupervisorConfig

DT = 2.0 ** -10


def unit_constants() -> dict:
    """The drive constants of the nominal unit itself, as an exact calibration with no margins
    would store them (the firmware's own are :func:`controllers.supervisor.config.device_limits`):
    the cases are worked out by hand with these round numbers."""
    from controllers.supervisor.config import ESTIMATOR_PERIOD_S, _design_reader, _speed_limit
    from ebraille_sim.physics import limits
    from ebraille_sim.physics.fingertip import tangent_stiffness_n_per_m
    from ebraille_sim.physics.params import DeviceParams
    dev = DeviceParams()
    b = limits.drive_bounds(dev)
    rb, rm = _design_reader()
    keys = ("push_force_per_a_n", "friction_current_a", "weight_n", "back_emf_v_s_per_m", "pinion_mass_kg",
            "board_mass_kg", "gear_efficiency")
    return {**{k: b[k] for k in keys}, "motor_resistance_ohm": dev.motor.resistance_ohm,
            "stall_current_a": dev.driver_supply_v / dev.motor.resistance_ohm,
            "guide_static_n": dev.drivetrain.guide_coulomb_n * dev.drivetrain.guide_breakaway_ratio,
            "speed_hold_s": 0.5 * math.pi * math.sqrt(b["impact_mass_kg"] / tangent_stiffness_n_per_m(0.2, rb, rm)),
            "stuck_travel_m": 2.0 * dev.drivetrain.backlash_m + ESTIMATOR_PERIOD_S * _speed_limit(b, rb, rm)}


UNIT = unit_constants()
C = SupervisorConfig(**UNIT)
R, K_E = C.motor_resistance_ohm, C.back_emf_v_s_per_m          # 21.2 ohm, 105.47 V s/m


class Fixed:
    """Inner controller: returns ``u``; records the setpoints it is given and its resets."""
    name = "fixed"

    def __init__(self, u):
        self.u = u
        self.seen = []
        self.resets = []

    def reset(self, *, force_est_n, setpoint_n, command_v=0.0):
        self.resets.append((force_est_n, setpoint_n, command_v))

    def update(self, force_est_n, setpoint_n, dt_s, motor_current_a=None):
        self.seen.append(setpoint_n)
        return self.u


def make(u, *, f0=1.0, command_v=0.0, **config):
    sup = Supervisor(Fixed(u), SupervisorConfig(**{**UNIT, **config}))
    sup.reset(force_est_n=f0, setpoint_n=1.0, command_v=command_v)
    return sup


def jit(k: int, f: float) -> float:
    """``f`` plus 3 mN every other period: sensor noise above the 2 mN stuck tolerance."""
    return f + 3e-3 * (k % 2)


def drive(sup, n, f, sp=1.0, cur=None, dt=DT):
    """``n`` periods; ``f``, ``sp`` and ``cur`` are values or functions of the period index."""
    out = []
    for k in range(n):
        fk = f(k) if callable(f) else f
        ik = cur(sup, k) if callable(cur) else cur
        out.append(sup.update(fk, sp(k) if callable(sp) else sp, dt, ik))
    return out


def settle(sup, f, sp=1.0, cur=None):
    """200 periods (195 ms) in contact at ``f``: with the jitter, then the last 40 at ``f`` exactly
    (shorter than the stuck rule's 100 ms window).  A reset leaves no previous setpoint, so the
    first one counts as a fall: for release_window_s = 150 ms an estimate below contact_lost_n
    is not a loss and the travel reference follows the estimate at once."""
    drive(sup, 200, lambda k: jit(k, f) if k < 160 else f, sp=sp, cur=cur)


def stalled(sup, k):
    """The current of a motor that does not move: the last command over R (no back-EMF)."""
    return sup.u_prev / R


def at_speed(v, i):
    """Make the last applied command the one that drives current ``i`` at rack speed ``v``:
    back-EMF ``u - R i = k_E v`` (the hand-made input of the current rules)."""
    def cur(sup, k):
        sup.u_prev = R * i + K_E * v
        return i
    return cur


# ---------------------------------------------------------------- shaping

def test_slew_rate_limit():
    """600 V/s: a 10 V step request gives 0.6 V after 1 ms, then 0.6 V more every 1 ms until
    10 V at the 17th period (16 x 0.6 = 9.6); down again at the same rate."""
    sup = make(10.0, f0=0.0)
    out = drive(sup, 18, 0.0, dt=1e-3)
    assert out[0] == pytest.approx(0.6, rel=1e-12)
    assert out[:16] == pytest.approx([0.6 * (k + 1) for k in range(16)], rel=1e-12)
    assert out[16:] == [10.0, 10.0]
    sup.inner.u = -10.0
    assert drive(sup, 2, 0.0, dt=1e-3) == pytest.approx([9.4, 8.8], rel=1e-12)
    sup = make(10.0, f0=0.0)
    assert drive(sup, 3, 0.0) == [0.5859375, 1.171875, 1.7578125]          # 600/1024 V a period, exactly


def test_force_cap_setpoint_clip_and_soft_zone_scaling():
    """The inner setpoint is clipped to 3.0 - 0.3 = 2.7 N, or below it to the slip cap (2.675 N for
    the default 0.1 mm slip, tests/test_body_motion.py).  In the
    soft zone [2.7, 3.0] N a push
    is scaled by 1 - v, v = (f - 2.7) / 0.3: 2 V at 2.85 N (v = 0.5) gives 1 V, at 2.775 N
    (v = 0.25) 1.5 V; a pull is not scaled; at or above 3.0 N the command is -retract_v = -2 V."""
    sup = make(2.0, f0=0.5, slew_v_per_s=1e6)
    drive(sup, 4, lambda k: jit(k, 0.5), sp=3.5)
    assert sup.inner.seen[-1] == min(3.0 - 0.3, sup.config.slip_setpoint_cap_n)
    assert drive(sup, 1, 2.7) == [2.0]
    assert drive(sup, 1, 2.85) == pytest.approx([1.0], rel=1e-9)
    assert drive(sup, 1, 2.775) == pytest.approx([1.5], rel=1e-9)
    sup.inner.u = -1.0
    assert drive(sup, 1, 2.85) == [-1.0]
    sup.inner.u = 2.0
    assert drive(sup, 1, 3.0) == [-2.0]
    assert drive(sup, 1, 3.9) == [-2.0]
    assert sup.fault is None and sup.mode == "run"
    assert drive(sup, 1, 2.0) == [2.0]


def test_watchdog_holds_zero_resumes_bumplessly_and_latches_after_the_timeout():
    """A NaN command from 1.5 V slews to 0 V (0.6 V a ms: 0.9, 0.3, 0); a finite command again
    resumes from the held 0 V (the inner controller reset to 0 V, then 0.6 V a ms); NaN for
    more than 0.5 s latches: 512 periods of 1/1024 s are 0.5 s, the 513th trips."""
    sup = make(math.nan, command_v=1.5)
    out = drive(sup, 4, lambda k: jit(k, 1.0), dt=1e-3)
    assert out == pytest.approx([0.9, 0.3, 0.0, 0.0], abs=1e-12)
    assert sup.events == [(0.001, "non-finite command: hold")]
    sup.inner.u = 2.0
    out = drive(sup, 2, lambda k: jit(k, 1.0), dt=1e-3)
    assert out == pytest.approx([0.0, 0.6], abs=1e-12)
    assert sup.inner.resets[-1] == (1.0, 1.0, 0.0)
    assert sup.events[-1] == (0.005, "finite command again: resume")
    sup = make(math.inf)
    drive(sup, 512, lambda k: jit(k, 1.0))
    assert sup.fault is None and sup.nan_s == 0.5
    drive(sup, 1, 1.0)
    assert sup.fault == "controller_nonfinite" and sup.mode == "retract"
    assert sup.events[-1] == (round(513 * DT, 6), "fault controller_nonfinite: retract")


def test_current_and_speed_envelope():
    """At rest the command is capped where the current the board reads reaches the limit at
    rest: the true limit i_lim = (3.2476 - 0.0589) / 63.28 + 0.00825 = 58.64 mA, read through the
    worst-case sensor as i_lim (1 - 0.012) - 3.11 mA = 54.82 mA, R i = 1.1623 V.  Moving at v the
    cap is the back-EMF k_E v plus R i_read(v), with i_read(v) the sensed envelope at the highest
    speed of the last speed_hold_s (78 ms); above 1.05 times the 40.2 mm/s speed limit, a braking
    current -8.25 mA."""
    assert C.current_limit_a == pytest.approx((3.5 - (540 + 1448 * 3.5) * 45e-6 - 0.05886) / 63.2832
                                              + 0.034 / 4.12, rel=1e-6)
    i_rest = C.current_limit_a * (1.0 - 0.012) - 0.00311279296875
    assert C.sensed_limit_a(C.current_limit_a) == pytest.approx(i_rest, rel=1e-12)
    sup = make(6.0, slew_v_per_s=1e6)
    assert drive(sup, 3, lambda k: jit(k, 1.0), cur=stalled) == pytest.approx([R * i_rest] * 3, rel=1e-12)
    assert R * i_rest == pytest.approx(1.1623, abs=1e-4)
    v = C.speed_limit_m_per_s / 2                  # an envelope point: 20.1 mm/s, 29.0 mA true
    i_v = C.sensed_limit_a(C.current_for_force_a(C.drive_force_limit_n(v)))
    assert C.current_for_force_a(C.drive_force_limit_n(v)) == pytest.approx(0.0290, abs=1e-4)
    sup = make(6.0, command_v=3.0, slew_v_per_s=1e6)
    u = drive(sup, 1, 1.0, cur=(3.0 - K_E * v) / R)[0]
    assert u == pytest.approx(K_E * v + R * i_v, rel=1e-9)
    n_hold = int(C.speed_hold_s / DT)              # 79 periods (79.97): the speed is held for 78.1 ms
    assert n_hold == 79
    out = drive(sup, n_hold + 2, lambda k: jit(k + 1, 1.0), cur=stalled)
    assert out[:n_hold] == pytest.approx([R * i_v] * n_hold, rel=1e-9)
    assert out[n_hold:] == pytest.approx([R * i_rest] * 2, rel=1e-9)
    v = 1.2 * C.speed_limit_m_per_s
    sup = make(6.0, command_v=6.0, slew_v_per_s=1e6)
    u = drive(sup, 1, 1.0, cur=(6.0 - K_E * v) / R)[0]
    assert u == pytest.approx(K_E * v - R * C.friction_current_a, rel=1e-9)


def test_i2t_overcurrent():
    """theta = int (i^2 - 0.19^2) dt, kept >= 0, trips above (0.283^2 - 0.19^2) 0.5 s = 0.0220 A^2 s.
    At a current whose excess i^2 - I_rated^2 is the stall current's over 0.601, theta reaches
    the limit at 0.3005 s: at 1 ms periods the 301st trips, not the 300th.  A second at no
    current before does not bank credit (theta stays 0)."""
    assert C.i2t_limit_a2s == pytest.approx((0.283019 ** 2 - 0.19 ** 2) * 0.5, rel=1e-5)
    i = math.sqrt(C.rated_current_a ** 2 + (C.stall_current_a ** 2 - C.rated_current_a ** 2) / 0.601)
    sup = make(0.0)
    drive(sup, 1000, lambda k: jit(k, 1.0), cur=0.0, dt=1e-3)
    assert sup.theta == 0.0
    drive(sup, 300, lambda k: jit(k, 1.0), cur=i, dt=1e-3)
    assert sup.fault is None and sup.theta == pytest.approx(0.3 / 0.601 * (C.stall_current_a ** 2 - 0.19 ** 2))
    drive(sup, 1, 1.0, cur=i, dt=1e-3)
    assert sup.fault == "motor_overcurrent"


def test_rated_current_holds_theta_at_zero():
    sup = make(0.0)
    drive(sup, 2000, lambda k: jit(k, 1.0), cur=C.rated_current_a, dt=1e-3)
    assert sup.theta == 0.0 and sup.fault is None


# ---------------------------------------------------------------- contact loss

def test_contact_lost_freeze_back_off_hold_then_regained_resume():
    """In contact at 1 N, an estimate of 0.05 N (< 0.1 N) with the setpoint asking for contact
    freezes: -2 V while t - t0 <= 50 ms (periods 0..51: 51/1024 = 49.8 ms), then 0 V.  0.51 N within
    the back-off does not resume.  After it, 0.5 N right after 0.51 N is falling (the estimate
    30/1024 s earlier is higher, by 2 %): held until that is 0.5 N too (period 52 + 30 = 82); then the
    inner controller is reset to 0 V and takes over at the next period."""
    sup = make(1.0, slew_v_per_s=1e6)
    settle(sup, 1.0)
    t0 = sup.t + DT
    out = drive(sup, 1, 0.05)
    assert out == [-2.0] and sup.mode == "freeze" and sup.freeze_t0 == t0
    out += drive(sup, 51, 0.51)
    assert out == [-2.0] * 52 and sup.mode == "freeze"
    out = drive(sup, 30, 0.5)                      # periods 52..81
    assert out == [0.0] * 30 and sup.mode == "freeze"
    resets = len(sup.inner.resets)
    assert drive(sup, 1, 0.5) == [0.0] and sup.mode == "run"          # period 82
    assert sup.inner.resets[resets:] == [(0.5, 1.0, 0.0)]
    assert drive(sup, 1, 0.5) == [1.0]
    assert [e for _, e in sup.events] == ["contact lost: freeze", "contact regained: resume"]
    assert sup.events[0][0] == round(t0, 6) and sup.events[1][0] == round(t0 + 82 * DT, 6)


def test_contact_loss_timeout_latches():
    """No contact for more than 0.6 s after the freeze latches ``contact_lost`` when there is no
    current measurement (no travel to bound a re-approach by): 614/1024 = 0.5996 s, 615/1024 =
    0.6006 s.  The retract then slews at 600/1024 V a period to -2 V."""
    sup = make(1.0)
    settle(sup, 1.0)
    drive(sup, 615, 0.05)                          # periods 0..614 after the loss
    assert sup.mode == "freeze" and sup.fault is None
    assert drive(sup, 4, 0.05) == [-0.5859375, -1.171875, -1.7578125, -2.0]
    assert sup.fault == "contact_lost"


def test_reapproach_speed_is_where_its_push_and_impact_reach_the_top_setpoint():
    """The re-approach command ``kE v + R I_f`` pushes a held pulp with ``P kE v / R + m_b g`` (eq. 1
    at the current ``u / R``); the board arriving at ``v`` may drive at most the force whose impact
    peaks at the top setpoint (eq. 2-3).  The two meet at the re-approach speed; the travel it
    searches is the 0.5 mm slip, the soft reader's compression at 0.2 N, 50 ms at that speed and
    ``stuck_travel_m``."""
    from ebraille_sim.physics import limits
    from ebraille_sim.physics.fingertip import compression_at_force_m
    for c in (C, SupervisorConfig()):
        v = c.reapproach_speed_m_per_s
        u = c.reapproach_command_v
        assert u == pytest.approx(c.back_emf_v_s_per_m * v + c.motor_resistance_ohm * c.friction_current_a, rel=1e-12)
        push = c.push_force_per_a_n * c.back_emf_v_s_per_m * v / c.motor_resistance_ohm + c.weight_n
        assert c.push_force_n(u / c.motor_resistance_ohm) == pytest.approx(push, rel=1e-9)
        e = limits.impact_energy_j(v, c.pinion_mass_kg, c.board_mass_kg, c.gear_efficiency)
        room = limits.drive_force_for_impact_n(e, c.setpoint_max_n, c.reader_b_n_per_m, c.reader_m_per_m)
        assert push == pytest.approx(room, abs=2e-3)
        assert c.reapproach_travel_m == pytest.approx(
            0.5e-3 + compression_at_force_m(0.2, c.soft_b_n_per_m, c.soft_m_per_m) + 0.05 * v + c.stuck_travel_m,
            rel=1e-12)
    firmware = SupervisorConfig()
    assert firmware.reapproach_speed_m_per_s == pytest.approx(6.35e-3, abs=0.01e-3)
    assert firmware.reapproach_command_v == pytest.approx(0.818, abs=1e-3)
    assert firmware.reapproach_travel_m == pytest.approx(2.29e-3, abs=0.01e-3)


def _lost_for_the_timeout(cur=None):
    """In contact at 1 N, then 0.05 N for 615 periods (0.6006 s): frozen, the timeout just passed."""
    sup = make(1.0, slew_v_per_s=1e6)
    settle(sup, 1.0)
    drive(sup, 615, 0.05, cur=cur)
    assert sup.mode == "freeze" and sup.fault is None
    return sup


def test_contact_not_back_reapproaches_and_resumes_on_contact():
    """With a current measurement the timeout does not latch: the board re-approaches at the
    re-approach command (the envelope's cap lies above it) and a contact resumes the inner
    controller from 0 V.  Without the rule ``contact_lost`` would latch here."""
    sup = _lost_for_the_timeout(cur=stalled)
    v = C.reapproach_speed_m_per_s
    out = drive(sup, 20, 0.05, cur=at_speed(v, C.friction_current_a))
    assert out == [pytest.approx(C.reapproach_command_v, rel=1e-12)] * 20
    assert sup.mode == "freeze" and sup.fault is None
    assert sup.travel_m == pytest.approx(20 * v * DT, rel=1e-9)
    resets = len(sup.inner.resets)
    assert drive(sup, 1, 0.25, cur=at_speed(v, C.friction_current_a)) == [0.0] and sup.mode == "run"
    assert sup.inner.resets[resets:] == [(0.25, 1.0, 0.0)]
    assert drive(sup, 1, 0.25) == [1.0]
    assert [e for _, e in sup.events] == ["contact lost: freeze", "contact not back: re-approach",
                                          "contact regained: resume"]


def test_reapproach_latches_beyond_its_travel_and_after_its_time():
    """No contact within ``reapproach_travel_m`` of travel beyond the board's place at the loss
    latches ``contact_lost`` (the finger is gone, or an open sensor reads none); so does a board
    that stops on the way (a pulp pressed blind, a jam) once twice the travel's time at the
    re-approach speed has passed."""
    v, i = C.reapproach_speed_m_per_s, C.friction_current_a
    n = C.reapproach_travel_m / (v * DT)
    assert 0.05 < n % 1.0 < 0.95
    sup = _lost_for_the_timeout(cur=stalled)
    drive(sup, int(n), 0.05, cur=at_speed(v, i))
    assert sup.fault is None
    drive(sup, 1, 0.05, cur=at_speed(v, i))
    assert sup.fault == "contact_lost" and sup.mode == "retract"
    m = 2.0 * C.reapproach_travel_m / (v * DT)
    assert 0.05 < m % 1.0 < 0.95
    sup = _lost_for_the_timeout(cur=stalled)
    drive(sup, 1 + int(m), 0.05, cur=stalled)
    assert sup.fault is None and sup.travel_m == 0.0
    drive(sup, 1, 0.05, cur=stalled)
    assert sup.fault == "contact_lost"


def test_setpoint_release_widens_the_drop():
    """A drop is a loss when the estimate falls by more than 0.3 N within 30 ms to below half its
    value then, while pushing.  A setpoint fall of 1 N within 150 ms widens that to 1.3 N: from
    2 N, 0.72 N (a fall of 1.28 N) is a release, 0.68 N (1.32 N) a loss.  Without the release
    0.9 N from 2 N (1.1 N) is one."""
    def case(f_end, sp_end):
        sup = make(0.5, f0=2.0, slew_v_per_s=1e6)
        settle(sup, 2.0, sp=2.0)
        drive(sup, 5, f_end, sp=sp_end)
        return sup.mode
    assert case(0.72, 1.0) == "run"
    assert case(0.68, 1.0) == "freeze"
    assert case(0.9, 2.0) == "freeze"


def test_drop_within_the_window_against_a_slow_fall():
    """A linear fall from 1 N of s per period (estimate 1 - s k at period k) shows a drop of 30 s
    within the 30 ms window (30/1024 s holds, 31/1024 s does not).  s = 0.0102 N: 0.306 N > 0.3 N,
    a loss once 1 - s k is below half of 1 - s (k - 30), i.e. below 30 s = 0.306 N: k > 68.04,
    period 69.  s = 0.0098 N (0.294 N) is no loss, down to 0.12 N."""
    def case(s):
        sup = make(0.5, slew_v_per_s=1e6)
        settle(sup, 1.0)
        for k in range(1, int((1.0 - 0.12) / s) + 1):
            drive(sup, 1, 1.0 - s * k)
            if sup.mode == "freeze":
                return k
    assert case(0.0102) == 69
    assert case(0.0098) is None


def test_drop_keep_fraction_and_drop_size():
    """From 0.62 N, 0.308 N is a loss (a drop of 0.312 N > 0.3 N, below 0.31 N); from 0.58 N,
    0.285 N is not (a drop of 0.295 N); from 1 N, 0.55 N is not (above half of 1 N)."""
    def case(f0, f1):
        sup = make(0.5, f0=f0, slew_v_per_s=1e6)
        settle(sup, f0)
        drive(sup, 1, f1)
        return sup.mode
    assert case(0.62, 0.308) == "freeze"
    assert case(0.58, 0.285) == "run"
    assert case(1.0, 0.55) == "run"
    assert case(1.0, 0.45) == "freeze"


def test_low_estimate_is_a_loss_only_while_the_setpoint_asks_for_contact():
    """0.05 N with the setpoint at 0.15 N (not above contact_on_n = 0.2 N) is no loss; after a
    setpoint fall (1.0 -> 0.5 N) not for 150 ms (153/1024 s is past it, 153 periods later)."""
    sup = make(0.0, slew_v_per_s=1e6)
    settle(sup, 1.0)
    drive(sup, 50, 0.05, sp=0.15)
    assert sup.mode == "run"
    sup = make(0.0, slew_v_per_s=1e6)
    settle(sup, 1.0)
    drive(sup, 1, 1.0, sp=0.5)                       # the fall: at period 0
    drive(sup, 153, 0.05, sp=0.5)                     # periods 1..153: 153/1024 = 0.1494 s
    assert sup.mode == "run"
    drive(sup, 1, 0.05, sp=0.5)                       # 154/1024 = 0.1504 s > 0.15 s
    assert sup.mode == "freeze"


# ---------------------------------------------------------------- sensor and motor faults

def test_fsr_out_of_range():
    """An estimate above 4 N (a shorted FSR reads ~15 N), or not finite, latches; 4 N itself does not."""
    for f, fault in ((4.0, None), (4.0 + 1e-9, "fsr_out_of_range"), (math.nan, "fsr_out_of_range"),
                     (math.inf, "fsr_out_of_range"), (-math.inf, "fsr_out_of_range")):
        sup = make(1.0, slew_v_per_s=1e6)
        drive(sup, 10, lambda k: jit(k, 1.0))
        u = drive(sup, 1, f)[0]
        assert sup.fault == fault, f
        assert u == -2.0                              # above the 3 N cap, or the retract
        if fault:
            assert sup.events == [(round(11 * DT, 6), "fault fsr_out_of_range: retract")]


def test_fsr_stuck_without_a_current_measurement():
    """Without a current: in contact, the estimate's range over 100 ms below 2 mN while the
    command of 50 ms earlier moved more than 0.25 V.  The inner command steps 0 -> 1 V after
    200 periods: period 201 commands 1 V, period 202 sees it as the last command, and 52
    periods later (52/1024 s >= 50 ms, 51/1024 s not) it reaches the delayed window: the trip
    is at period 254.  A range of 2.1 mN is not stuck; 1.9 mN is."""
    def case(jitter, n):
        sup = make(0.0, slew_v_per_s=1e6)
        drive(sup, 200, lambda k: 1.0 + jitter * (k % 2))
        sup.inner.u = 1.0
        drive(sup, n, lambda k: 1.0 + jitter * (k % 2))
        return sup
    assert case(0.0, 53).fault is None
    sup = case(0.0, 54)
    assert sup.fault == "fsr_stuck" and sup.events[0][0] == round(254 * DT, 6)
    assert case(1.9e-3, 60).fault == "fsr_stuck"
    assert case(2.1e-3, 300).fault is None


def test_fsr_stuck_by_travel_with_a_current_measurement():
    """With a current: in contact, the estimate within 2 mN of its reference while the powered
    motor moves the board more than stuck_travel_m = 2 x 0.1 mm + 10 ms x 42.07 mm/s = 0.6207 mm
    net.  At 2 mm/s (1.953 um a period of 1/1024 s) that is 317.8 periods: the reference is set
    at the second period in contact, the 318th period after it trips."""
    assert C.stuck_travel_m == pytest.approx(2 * 0.1e-3 + 0.01 * 0.04207, rel=1e-3)
    v, i = 2e-3, 0.024
    assert C.stuck_travel_m / (v * DT) == pytest.approx(317.8, abs=0.05)
    sup = make(0.0)
    drive(sup, 2 + 317, 1.0, cur=at_speed(v, i))
    assert sup.fault is None
    drive(sup, 1, 1.0, cur=at_speed(v, i))
    assert sup.fault == "fsr_stuck"
    sup = make(0.0)                                  # back and forth: the net travel stays small
    drive(sup, 2000, 1.0, cur=lambda s, k: at_speed(v if (k // 100) % 2 == 0 else -v, i)(s, k))
    assert sup.fault is None


def test_fsr_implausible_force_from_the_current():
    """Moving forward at 1 mm/s at i_lim = 58.64 mA the push at the lower edge of the friction band is
    63.28 x 0.05864 - 1.25 x 0.5222 - 0.0589 - 0.125 = 2.874 N, 2.37 N above the 0.503 N estimate
    (> 0.5 N).  The first moving period accelerates (1.02 m/s^2 x 2.05 kg = 2.1 N less), so the
    count starts at the second: more than 0.2 s is 205 periods (204/1024 = 0.1992 s), the trip
    at the 206th."""
    i, v = C.current_limit_a, 1e-3
    f_lo = C.push_force_n(i, C.friction_breakaway_ratio, -C.weight_n) - C.guide_static_n
    assert f_lo == pytest.approx(2.874, abs=2e-3)
    sup = make(0.0, f0=0.5)
    drive(sup, 1 + 204, lambda k: jit(k, 0.5), cur=at_speed(v, i))
    assert sup.fault is None
    drive(sup, 1, 0.5, cur=at_speed(v, i))
    assert sup.fault == "fsr_implausible"


def test_fsr_implausible_travel_beyond_the_soft_compression():
    """With the reference held (travel_follow_s huge), the board may travel past the first contact
    by the soft reader's compression at the recent estimate plus implausible_n, ln(1 + 1080 x
    1.003 / 141) / 1080 = 2.0012 mm, plus stuck_travel_m 0.6207 mm: 2.6219 mm.  At 20 mm/s
    (19.53 um a period) that is 134.2 periods: the 135th after the reference trips."""
    cfg = dict(travel_follow_s=1e9)
    allowed = math.log1p(1080 * 1.003 / 141) / 1080 + C.stuck_travel_m
    assert allowed == pytest.approx(2.6219e-3, abs=1e-7)
    v, i = 0.02, 0.01
    assert allowed / (v * DT) == pytest.approx(134.2, abs=0.05)
    sup = make(0.0, f0=0.5, **cfg)
    settle(sup, 0.5, cur=at_speed(0.0, i))          # in contact at rest, the reference at 0
    drive(sup, 134, lambda k: jit(k, 0.5), cur=at_speed(v, i))
    assert sup.fault is None
    drive(sup, 1, 0.5, cur=at_speed(v, i))
    assert sup.fault == "fsr_implausible"


def test_fsr_no_contact():
    """No estimate above 0.2 N within first_contact_travel_m = 2 mm + the soft reader's compression
    at 3.5 N (3.079 mm) = 5.079 mm of travel: at 10 mm/s (9.766 um a period) 520.1 periods; the
    521st trips."""
    assert C.first_contact_travel_m == pytest.approx(2e-3 + math.log1p(1080 * 3.5 / 141) / 1080, rel=1e-12)
    v, i = 0.01, 0.012
    assert C.first_contact_travel_m / (v * DT) == pytest.approx(520.09, abs=0.01)
    sup = make(0.0, f0=0.0)
    drive(sup, 520, 0.0, cur=at_speed(v, i))
    assert sup.fault is None
    drive(sup, 1, 0.0, cur=at_speed(v, i))
    assert sup.fault == "fsr_no_contact"


def test_motor_stalled():
    """Pushing without moving for more than 0.5 s (512 periods of 1/1024 s are 0.5 s): with no
    contact shown (0.05 N, the current above the 10.5 mA that pushes 0.2 N), or at the current
    limit (58.6 mA > 0.95 i_lim) with the push at the lower edge of the friction band, 2.874 N,
    more than 0.5 N above the 1.003 N estimate.  The first period draws no current (the command
    was 0 V): the count starts at the second, the trip is at period 2 + 512."""
    assert C.current_for_force_a(C.contact_on_n) == pytest.approx(0.01048, abs=1e-5)
    for f in (0.05, 1.0):
        sup = make(6.0, f0=f, slew_v_per_s=1e6)
        drive(sup, 513, lambda k: jit(k, f), cur=stalled)
        assert sup.fault is None and sup.stall_s == 0.5
        drive(sup, 1, f, cur=stalled)
        assert sup.fault == "motor_stalled"
    sup = make(6.0, f0=2.45, slew_v_per_s=1e6)     # 2.874 - 2.453 < 0.5 N: the estimate accounts for the push
    drive(sup, 1000, lambda k: jit(k, 2.45), cur=stalled)
    assert sup.fault is None


# ---------------------------------------------------------------- safe states and events

def test_safe_retract_and_hold_with_a_current_measurement():
    """Retract at -2 V (from 0 V, 600/1024 V a period: -0.586, -1.172, -1.758, -2) until the board
    has moved back for 50 ms and then stalls on the end stop (|i| > 0.6 x 2 / 21.2 = 56.6 mA).
    Motion counts from 10 ms after the trip (period 11: 11/1024 s); 50 ms of it is 52 periods
    (51.2), periods 11..62: a stall at period 63 ends the retract, one at 62 does not, and a
    stall on the way (period 20) is not motion (the end moves to 64).  Then hold: 0 V after the
    slew, the inner controller no longer called."""
    def case(stop, stalls=()):
        sup = make(0.0)
        drive(sup, 10, lambda k: jit(k, 1.0), cur=-0.01)
        u = drive(sup, 1, 5.0, cur=-0.01)                          # period 0: out of range
        calls = len(sup.inner.seen)
        u += drive(sup, stop, 5.0, cur=lambda s, k: -0.1 if k + 1 in stalls + (stop,) else -0.01)
        return sup, u, calls
    sup, u, calls = case(63)
    assert sup.fault == "fsr_out_of_range" and sup.mode == "hold"
    assert u[:5] == [-0.5859375, -1.171875, -1.7578125, -2.0, -2.0] and u[4:63] == [-2.0] * 59
    assert u[63] == -1.4140625
    assert sup.events[-1] == (round(sup.t, 6), "retracted: hold")
    assert drive(sup, 4, 5.0, cur=-0.1) == [-0.828125, -0.2421875, 0.0, 0.0]
    assert len(sup.inner.seen) == calls
    assert case(62)[0].mode == "retract"
    assert case(63, stalls=(20,))[0].mode == "retract"
    assert case(64, stalls=(20,))[0].mode == "hold"


def test_safe_retract_timing_without_a_current_and_at_most_max_retract_s():
    """Without a current the retract lasts retract_s = 0.6 s (615 periods: 615/1024 s >= 0.6 s);
    a jammed motor (stalled throughout) retracts for max_retract_s = 10 s (10240 periods)."""
    sup = make(1.0, slew_v_per_s=1e6)
    drive(sup, 10, lambda k: jit(k, 1.0))
    drive(sup, 1, math.nan)
    drive(sup, 614, 1.0)
    assert sup.mode == "retract" and sup.u_prev == -2.0
    assert drive(sup, 1, 1.0) == [0.0] and sup.mode == "hold"
    sup = make(1.0, slew_v_per_s=1e6)
    drive(sup, 10, lambda k: jit(k, 1.0), cur=0.0)
    drive(sup, 1, math.nan, cur=-0.1)
    drive(sup, 10239, 1.0, cur=-0.1)
    assert sup.mode == "retract"
    drive(sup, 1, 1.0, cur=-0.1)
    assert sup.mode == "hold"


def test_event_log_and_its_capacity():
    """With the back-off shorter than a period, 0.02 N and 1.01 N alternating after 200 periods in
    contact lose and regain contact every period: event k at period 201 + k.  The log keeps
    EVENT_CAPACITY = 256; of 300 events 44 are counted from event 256's time, 457/1024 s."""
    assert EVENT_CAPACITY == 256
    sup = make(1.0, backoff_s=0.5e-3)
    settle(sup, 1.0)
    drive(sup, 300, lambda k: 0.02 if k % 2 == 0 else 1.01)     # 1.01 N: not below any recent estimate
    ev = sup.events
    assert len(ev) == 257
    assert ev[:2] == [(round(201 * DT, 6), "contact lost: freeze"), (round(202 * DT, 6), "contact regained: resume")]
    assert ev[255] == (round(456 * DT, 6), "contact regained: resume")
    assert ev[256] == (round(457 * DT, 6), "event log full: 44 events from here on not recorded")
    sup.reset(force_est_n=1.0, setpoint_n=1.0)
    assert sup.events == []


def test_regained_contact_resumes_a_pid_with_its_integrator_not_below_zero():
    """The contact-loss case above with a real PID inside: a bumpless reset from 0 V at 0.5 N on
    a 1 N setpoint would start the integrator at ``-kp (b r - y)`` and the first command at 0 V;
    the resume raises the integrator to 0 V, so the first command is the proportional part
    ``kp b (1 - 0.5)`` and pushes towards the finger.  The session's start keeps the plain
    bumpless reset (its integrator below 0 V: the soft start of the approach)."""
    from controllers import PID, PIDConfig
    from controllers.compiled import PS
    cfg = PIDConfig(kp_v_per_n=2.0, ki_v_per_ns=10.0, kd_vs_per_n=0.0)
    sup = Supervisor(PID(cfg), SupervisorConfig(**{**UNIT, "slew_v_per_s": 1e6}))
    sup.reset(force_est_n=0.0, setpoint_n=1.0, command_v=0.0)
    state = sup.inner.compiled()[1]
    assert state[PS.integrator_v] == pytest.approx(-2.0 * cfg.setpoint_weight_p, rel=1e-12)
    settle(sup, 1.0)
    drive(sup, 1, 0.05)
    drive(sup, 51, 0.51)
    drive(sup, 30, 0.5)
    assert drive(sup, 1, 0.5) == [0.0] and sup.mode == "run"
    assert state[PS.integrator_v] == 0.0
    u = drive(sup, 1, 0.5)[0]
    assert u == pytest.approx(2.0 * cfg.setpoint_weight_p * 0.5 + 10.0 * DT * 0.0, abs=1e-9) and u > 0.0


def test_resume_keeps_an_integrator_that_starts_above_zero():
    """At an estimate above the setpoint the bumpless reset from 0 V starts the integrator above
    0 V; the resume leaves it there (the floor only raises)."""
    from controllers import make as make_controller
    from controllers.compiled import PS, resume_controller
    for name in ("pid", "pid_dob"):
        a, b = make_controller(name), make_controller(name)
        a.reset(force_est_n=1.4, setpoint_n=1.0, command_v=0.0)
        resume_controller(b, force_est_n=1.4, setpoint_n=1.0)
        assert a.compiled()[1][PS.integrator_v] > 0.0
        assert list(a.compiled()[1]) == list(b.compiled()[1])
        a.reset(force_est_n=0.3, setpoint_n=1.0, command_v=0.0)
        resume_controller(b, force_est_n=0.3, setpoint_n=1.0)
        assert a.compiled()[1][PS.integrator_v] < 0.0 == b.compiled()[1][PS.integrator_v]
