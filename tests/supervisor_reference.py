"""Test-only reference: a verbatim copy of the pure-Python :class:`controllers.supervisor.Supervisor`.

The package's supervisor keeps its state in arrays and runs its period in compiled code
(:func:`controllers.supervisor.supervise_begin` / :func:`~controllers.supervisor.supervise_end`).
This module keeps the implementation it replaced, unchanged (deques, bisect, Python floats),
so tests/test_supervisor_compiled.py can check that the compiled one gives the same commands,
modes, faults and events.  Test code, not package code.
"""
from __future__ import annotations

import bisect
import math
from collections import deque

from ebraille_sim.physics import limits
from ebraille_sim.physics.fingertip import compression_at_force_m

from controllers.base import check_dt
from controllers.supervisor import SupervisorConfig

__all__ = ["Supervisor"]


class _Window:
    """Running min and max over the last ``span_s`` seconds (monotonic deques)."""

    def __init__(self, span_s: float):
        self.span = span_s
        self.lo: deque = deque()
        self.hi: deque = deque()
        self.t0 = None

    def push(self, t: float, x: float) -> None:
        if self.t0 is None:
            self.t0 = t
        lo, hi = self.lo, self.hi
        while lo and lo[-1][1] >= x:
            lo.pop()
        while hi and hi[-1][1] <= x:
            hi.pop()
        item = (t, x)
        lo.append(item)
        hi.append(item)
        cut = t - self.span
        while lo[0][0] < cut:
            lo.popleft()
        while hi[0][0] < cut:
            hi.popleft()

    def full(self, t: float) -> bool:
        return self.t0 is not None and t - self.t0 >= self.span

    def range(self) -> float:
        return self.hi[0][1] - self.lo[0][1]


class Supervisor:
    """Safety wrapper around a :class:`~controllers.base.Controller` (see the module docstring).

    Attributes
    ----------
    mode : str
        ``"run"``, ``"freeze"`` (contact lost), ``"retract"`` or ``"hold"``.
    fault : str or None
        Cause of the latched fault, if any.
    events : list of (float, str)
        Time since reset (s) and a short description of every mode change.
    """

    def __init__(self, inner, config: SupervisorConfig = SupervisorConfig()):
        if not isinstance(config, SupervisorConfig):
            raise TypeError(f"config must be a SupervisorConfig, got {type(config).__name__}")
        self.inner = inner
        self.config = config
        self.name = f"supervised({getattr(inner, 'name', type(inner).__name__)})"
        self._envelope = _envelope(config)
        self._clear()

    def _clear(self):
        c = self.config
        self.mode = "run"
        self.fault = None
        self.events = []
        self.t = 0.0
        self.u_prev = 0.0
        self.theta = 0.0
        self.nan_s = 0.0
        self.in_contact = False
        self.freeze_t0 = 0.0
        self.retract_t0 = 0.0
        self.moving_s = 0.0
        self.est_win = _Window(c.stuck_window_s)
        self.cmd_win = _Window(c.stuck_window_s - c.stuck_response_s)
        self.cmd_delay: deque = deque()
        self.drop_hist: deque = deque()
        self.sp_win = _Window(c.release_window_s)
        self.speed_win = _Window(c.speed_hold_s)
        self.speed = 0.0
        self.accel = 0.0
        self.travel_m = 0.0
        self.stuck_ref_n = math.nan
        self.stuck_travel_m = 0.0
        self.contact_travel_m = None
        self.cut_t = -math.inf
        self.sp_last = math.inf
        self.fall_t = -math.inf
        self.stall_s = 0.0
        self.implausible_s = 0.0
        self.current_limit_a = c.sensed_limit_a(c.current_limit_a)
        self.last_f = 0.0

    def reset(self, *, force_est_n: float, setpoint_n: float, command_v: float = 0.0) -> None:
        """Clear faults and detectors and reset the inner controller bumplessly."""
        self._clear()
        self.u_prev = float(command_v) if math.isfinite(command_v) else 0.0
        self.inner.reset(force_est_n=force_est_n, setpoint_n=min(setpoint_n, self._sp_max), command_v=command_v)

    @property
    def _sp_max(self) -> float:
        return self.config.force_cap_n - self.config.cap_margin_n

    def _event(self, text: str) -> None:
        self.events.append((round(self.t, 6), text))

    def _trip(self, cause: str) -> None:
        if self.fault is None:
            self.fault = cause
            self.mode = "retract"
            self.retract_t0 = self.t
            self.moving_s = 0.0
            self._event(f"fault {cause}: retract")

    def _slew(self, u: float, dt: float) -> float:
        du = self.config.slew_v_per_s * dt
        return min(max(u, self.u_prev - du), self.u_prev + du)

    def _motion(self, cur: float, dt_s: float) -> None:
        """Rack speed from the back-EMF of the last period, travel integral, held peak speed."""
        c = self.config
        u = min(max(self.u_prev, -c.driver_supply_v), c.driver_supply_v)
        v = limits.rack_speed_from_emf_m_per_s(u, cur, c.motor_resistance_ohm, c.back_emf_v_s_per_m, 1.0)
        self.accel = (v - self.speed) / dt_s
        self.speed = v
        if abs(cur) > c.powered_current_a:     # an unpowered motor (a cut supply) reads its command as speed
            self.travel_m = max(0.0, self.travel_m + v * dt_s)
        self.speed_win.push(self.t, v)

    def _envelope_cap(self, u: float, cur: float) -> float:
        """Largest command that keeps the next period's current within the speed-dependent limit."""
        c = self.config
        v_held = max(self.speed_win.hi[0][1], 0.0)
        i_lim = _interp(self._envelope, v_held)
        self.current_limit_a = i_lim
        u_applied = min(max(self.u_prev, -c.driver_supply_v), c.driver_supply_v)
        return min(u, u_applied + c.motor_resistance_ohm * (i_lim - cur))

    def _detect(self, f: float, sp: float, cur: float, dt_s: float) -> str | None:
        """The detectors that need the motor current; the cause of a fault, or None."""
        c = self.config
        v = self.speed
        moving = abs(v) > c.moving_speed_m_per_s
        # a stuck code: the estimate does not change while the board travels
        if f > c.contact_lost_n and self.in_contact:
            if not abs(f - self.stuck_ref_n) <= c.stuck_tolerance_n:
                self.stuck_ref_n = f
                self.stuck_travel_m = 0.0
            elif abs(cur) > c.powered_current_a:     # a powered motor: an unpowered one (a cut supply)
                # draws no current and its command reads as speed
                self.stuck_travel_m += v * dt_s
                if abs(self.stuck_travel_m) > c.stuck_travel_m:
                    return "fsr_stuck"
        else:
            self.stuck_ref_n = math.nan
        # travel since the first contact against the compression the estimate allows on the soft reader
        if self.in_contact:
            if self.contact_travel_m is None:
                self.contact_travel_m = self.travel_m
            elif f > c.contact_on_n:
                # the reference follows where the pulp's surface must be for the estimate shown,
                # at once on an intended release (the setpoint fell: the back-EMF integral's drift
                # over many presses in refresh mode does not add up) and slowly otherwise (the
                # finger drifts, presses and the strap slips over a session: only a fast mismatch,
                # a board running into the finger while the reading stays low, trips)
                target = self.travel_m - compression_at_force_m(f, c.soft_b_n_per_m, c.soft_m_per_m)
                if self.t - self.fall_t <= c.release_window_s:
                    self.contact_travel_m = max(self.contact_travel_m, target)
                else:
                    self.contact_travel_m += (target - self.contact_travel_m) * min(1.0, dt_s / c.travel_follow_s)
            allowed = (compression_at_force_m(self.est_win.hi[0][1] + c.implausible_n, c.soft_b_n_per_m,
                                              c.soft_m_per_m) + c.stuck_travel_m)
            if self.travel_m - self.contact_travel_m > allowed:
                return "fsr_implausible"
        # no contact within the travel the gap allows
        if not self.in_contact and self.travel_m > c.first_contact_travel_m:
            return "fsr_no_contact"
        # pushing and not moving: with no contact seen, or at the current limit with a push that
        # does not reach the finger (the lower edge of the friction band at rest above the estimate)
        f_rest = c.push_force_n(cur, c.friction_breakaway_ratio, -c.weight_n) - c.guide_static_n
        if not moving and ((f < c.contact_on_n and cur > c.current_for_force_a(c.contact_on_n))
                           or (cur > c.stall_fraction * c.sensed_limit_a(c.current_limit_a)
                               and f_rest - self.est_win.hi[0][1] > c.implausible_n)):
            self.stall_s += dt_s
            if self.stall_s > c.stall_time_s:
                return "motor_stalled"
        else:
            self.stall_s = 0.0
        # the force the current implies while the board moves forward, against the estimate
        if v > c.moving_speed_m_per_s:
            a = max(self.accel, 0.0)
            # lower edge of the friction band: break-away friction, guide friction, weight against
            # the push, and the force that accelerates the rotor and the board
            f_lo = (c.push_force_n(cur, c.friction_breakaway_ratio, -c.weight_n) - c.guide_static_n
                    - c.impact_mass_kg * a)
            if f_lo - self.est_win.hi[0][1] > c.implausible_n:
                self.implausible_s += dt_s
                if self.implausible_s > c.implausible_s:
                    return "fsr_implausible"
            else:
                self.implausible_s = 0.0
        else:
            self.implausible_s = 0.0
        return None

    def update(self, force_est_n: float, setpoint_n: float, dt_s: float, motor_current_a: float | None = None) -> float:
        """One period: run the detectors, then pass, shape or replace the inner command."""
        c = self.config
        if not 0.0 < dt_s < math.inf:
            check_dt(dt_s)
        if not c.enabled:
            return self.inner.update(force_est_n, setpoint_n, dt_s, motor_current_a)
        self.t += dt_s
        t = self.t
        f = float(force_est_n)
        cur = None if motor_current_a is None or not math.isfinite(motor_current_a) else float(motor_current_a)
        if cur is not None:
            self.theta = max(0.0, self.theta + (cur * cur - c.rated_current_a ** 2) * dt_s)
            self._motion(cur, dt_s)
        if self.mode in ("retract", "hold"):
            return self._safe(cur, dt_s)
        # detectors that latch
        if not math.isfinite(f) or f > c.out_of_range_n:
            self._trip("fsr_out_of_range")
            return self._safe(cur, dt_s)
        if self.theta > c.i2t_limit_a2s:
            self._trip("motor_overcurrent")
            return self._safe(cur, dt_s)
        self.est_win.push(t, f)
        if cur is None:
            # the command window (the stuck rule without a current measurement) lags by the
            # estimator's response: a command that moved within the last ``stuck_response_s``
            # cannot have shown in the estimate yet
            self.cmd_delay.append((t, self.u_prev))
            while self.cmd_delay[0][0] <= t - c.stuck_response_s:
                self.cmd_win.push(*self.cmd_delay.popleft())
        sp_in = float(setpoint_n)
        sp_now = sp_in if math.isfinite(sp_in) else 0.0
        if sp_now < self.sp_last - 1e-9:
            self.fall_t = t                  # the setpoint fell: an intended release
        self.sp_last = sp_now
        self.sp_win.push(t, sp_now)
        moving = cur is None or abs(self.u_prev - c.motor_resistance_ohm * cur) > c.stuck_emf_v
        # without a current measurement only: with one, the travel the back-EMF integral gives
        # decides (:meth:`_detect`); ``u - R i`` of one period reads as motion inside the
        # gearhead's friction band and during a command step, where the board does not move
        if (cur is None and moving and self.cmd_win.t0 is not None and self.in_contact and self.est_win.full(t) and self.est_win.lo[0][1] > c.contact_lost_n
                and self.est_win.range() < c.stuck_tolerance_n and self.cmd_win.range() > c.stuck_command_v):
            self._trip("fsr_stuck")
            return self._safe(cur, dt_s)
        if cur is not None and self.mode == "run":
            cause = self._detect(f, sp_in, cur, dt_s)
            if cause is not None:
                self._trip(cause)
                return self._safe(cur, dt_s)
        # contact tracking
        self.drop_hist.append((t, f))
        while self.drop_hist[0][0] < t - c.drop_window_s:
            self.drop_hist.popleft()
        f_then = self.drop_hist[0][1]
        if self.mode == "run":
            if f > c.contact_on_n:
                self.in_contact = True
            # an intended release (the setpoint fell, or asks for no contact) is not a loss
            released = self.sp_win.range()
            fell = t - self.fall_t <= c.release_window_s
            lost = ((f < c.contact_lost_n and sp_in > c.contact_on_n and not fell)
                    or (f_then - f > c.drop_n + max(released, 0.0) and f < c.drop_keep_fraction * f_then
                        and self.u_prev > 0.0
                        and t - self.cut_t > c.drop_window_s))
            if self.in_contact and lost:
                self.mode = "freeze"
                self.freeze_t0 = t
                self.contact_travel_m = None          # the compression check starts again at the next contact
                self._event("contact lost: freeze")
        if self.mode == "freeze":
            if f > c.contact_on_n and f >= f_then and t - self.freeze_t0 > c.backoff_s:
                self.mode = "run"
                self._event("contact regained: resume")
                self.inner.reset(force_est_n=f, setpoint_n=min(setpoint_n, self._sp_max), command_v=0.0)
                self.u_prev = 0.0
                return 0.0
            if t - self.freeze_t0 > c.contact_loss_timeout_s:
                self._trip("contact_lost")
                return self._safe(cur, dt_s)
            u = -c.retract_v if t - self.freeze_t0 <= c.backoff_s else 0.0
            self.u_prev = u
            return u
        # run: the inner controller, watchdog, cap, slew, current and speed envelope
        sp = min(sp_in, self._sp_max)
        u = self.inner.update(f, sp, dt_s, motor_current_a)
        if not math.isfinite(u):
            if self.nan_s == 0.0:
                self._event("non-finite command: hold")
            self.nan_s += dt_s
            if self.nan_s > c.watchdog_timeout_s:
                self._trip("controller_nonfinite")
                return self._safe(cur, dt_s)
            u = self._slew(0.0, dt_s)
            self.u_prev = u
            return u
        if self.nan_s > 0.0:
            self.nan_s = 0.0
            self._event("finite command again: resume")
            self.inner.reset(force_est_n=f, setpoint_n=sp, command_v=self.u_prev)
            u = self.u_prev
        u_inner = u
        lo = c.force_cap_n - c.cap_margin_n
        if f >= c.force_cap_n:
            u = -c.retract_v
        elif f > lo and u > 0.0:
            u *= 1.0 - (f - lo) / c.cap_margin_n
        u = self._slew(u, dt_s)
        if cur is not None:
            u = self._envelope_cap(u, cur)
        if u < u_inner - 1e-9:
            self.cut_t = t               # the supervisor held the push back: a drop that follows is its own
        self.u_prev = u
        return u

    def _safe(self, cur, dt_s) -> float:
        """Command of the latched safe state: retract, then hold at 0 V."""
        c = self.config
        if self.mode == "retract":
            el = self.t - self.retract_t0
            if cur is None:
                done = el >= c.retract_s
            else:
                stalled = abs(cur) > 0.6 * c.retract_v / c.motor_resistance_ohm
                if not stalled and el > 0.01:
                    self.moving_s += dt_s
                done = (self.moving_s >= c.retract_moving_s and stalled) or el >= c.max_retract_s
            if done:
                self.mode = "hold"
                self._event("retracted: hold")
            else:
                u = self._slew(-c.retract_v, dt_s)
                self.u_prev = u
                return u
        u = self._slew(0.0, dt_s)
        self.u_prev = u
        return u


def _envelope(c: SupervisorConfig) -> tuple[list[float], list[float]]:
    """Current limit against rack speed: (speeds, currents), from rest to beyond the speed limit.

    At each speed the drive force may not exceed :meth:`SupervisorConfig.drive_force_limit_n`;
    beyond :attr:`SupervisorConfig.speed_limit_m_per_s` the limit is a braking current.
    """
    v_max = c.speed_limit_m_per_s
    speeds = [v_max * k / 32 for k in range(33)]
    currents = [c.sensed_limit_a(c.current_for_force_a(max(c.drive_force_limit_n(v), 0.0))) for v in speeds]
    speeds.append(1.05 * v_max)
    currents.append(-c.friction_current_a)
    return speeds, currents


def _interp(table: tuple[list[float], list[float]], x: float) -> float:
    xs, ys = table
    if x <= xs[0]:
        return ys[0]
    if x >= xs[-1]:
        return ys[-1]
    k = bisect.bisect_right(xs, x)
    x0, x1, y0, y1 = xs[k - 1], xs[k], ys[k - 1], ys[k]
    return y0 + (y1 - y0) * (x - x0) / (x1 - x0)
