"""One supervisor period, compiled: :func:`supervise_begin` before the inner controller,
:func:`supervise_end` after it (the loop engine composes them, :mod:`ebraille_sim.plant.engine`)."""
from __future__ import annotations

import math

from controllers.compiled import py_max as _pymax, py_min as _pymin
from controllers.supervisor.buffers import (_append, _at, _pop_front, _slide, _win_full, _win_lo, _win_push,
                                           _win_range)
from controllers.supervisor.detectors import _detect, _envelope_cap, _event, _motion, _safe, _slew, _trip
from controllers.supervisor.layout import CF, EVENT, FAULT, MODE, SV
from ebraille_sim.base.compiled import njit

@njit(cache=True, _nrt=False, error_model="numpy")
def supervise_begin(sv, cfg, f, sp, dt, cur):
    """First half of one supervised period: detectors, contact tracking, the safe states.

    Parameters
    ----------
    sv, cfg : ndarray of float64
        The state and configuration arrays of :meth:`Supervisor.compiled`.
    f : float
        Force estimate, N.
    sp : float
        Setpoint, N.
    dt : float
        Control period, s (at least the configuration's ``min_dt_s``).
    cur : float
        Measured motor current, A; NaN (or any non-finite value) when there is none.

    Returns
    -------
    code : int
        0: the command is ``u`` and the inner controller is not called.  1: call the inner
        controller with ``(f, sp_inner, dt, current)`` and pass its command to
        :func:`supervise_end`.  2: contact regained; resume the inner controller from 0 V with
        ``force_est_n=f, setpoint_n=sp_inner`` (:func:`controllers.compiled.controller_resume`: a
        bumpless reset with its integrator not below 0 V); the command is ``u`` (0 V).
    u : float
        Command, V (NaN for code 1).
    sp_inner : float
        Setpoint for the inner controller, N (clipped to :attr:`SupervisorConfig.setpoint_max_n`).
    """
    sv[SV.t] += dt
    t = sv[SV.t]
    has_cur = math.isfinite(cur)
    if not has_cur:
        cur = math.nan
    else:
        sv[SV.theta] = _pymax(0.0, sv[SV.theta] + (cur * cur - cfg[CF.rated_current_sq_a2]) * dt)
        _motion(sv, cfg, cur, dt)
    if sv[SV.mode] == MODE.retract or sv[SV.mode] == MODE.hold:
        return 0, _safe(sv, cfg, cur, dt), math.nan
    # detectors that latch
    if not math.isfinite(f) or f > cfg[CF.out_of_range_n]:
        _trip(sv, cfg, FAULT.fsr_out_of_range)
        return 0, _safe(sv, cfg, cur, dt), math.nan
    if sv[SV.theta] > cfg[CF.i2t_limit_a2s]:
        _trip(sv, cfg, FAULT.motor_overcurrent)
        return 0, _safe(sv, cfg, cur, dt), math.nan
    _win_push(sv, cfg, SV.est_win_t0, CF.est_win_span, t, f, True)
    if not has_cur:
        # the command window (the stuck rule without a current measurement) lags by the
        # estimator's response: a command that moved within the last ``stuck_response_s``
        # cannot have shown in the estimate yet
        _append(sv, cfg, SV.cmd_delay_head, CF.cmd_delay_base, t, sv[SV.u_prev])
        while True:
            k = _at(sv, cfg, SV.cmd_delay_head, CF.cmd_delay_base, 0)
            if not sv[k] <= t - cfg[CF.stuck_response_s]:
                break
            t_old, u_old = sv[k], sv[k + 1]
            _pop_front(sv, cfg, SV.cmd_delay_head, CF.cmd_delay_base)
            _win_push(sv, cfg, SV.cmd_win_t0, CF.cmd_win_span, t_old, u_old, True)
    sp_now = sp if math.isfinite(sp) else 0.0
    if sp_now < sv[SV.sp_last] - 1e-9:
        sv[SV.fall_t] = t                  # the setpoint fell: an intended release
    sv[SV.sp_last] = sp_now
    _win_push(sv, cfg, SV.sp_win_t0, CF.sp_win_span, t, sp_now, True)
    moving = (not has_cur) or abs(sv[SV.u_prev] - cfg[CF.motor_resistance_ohm] * cur) > cfg[CF.stuck_emf_v]
    # without a current measurement only: with one, the travel the back-EMF integral gives
    # decides (:func:`_detect`); ``u - R i`` of one period reads as motion inside the
    # gearhead's friction band and during a command step, where the board does not move
    if (not has_cur and moving and not math.isnan(sv[SV.cmd_win_t0]) and sv[SV.in_contact] != 0.0
            and _win_full(sv, cfg, SV.est_win_t0, CF.est_win_span, t)
            and _win_lo(sv, cfg, SV.est_win_t0, CF.est_win_span) > cfg[CF.contact_lost_n]
            and _win_range(sv, cfg, SV.est_win_t0, CF.est_win_span) < cfg[CF.stuck_tolerance_n]
            and _win_range(sv, cfg, SV.cmd_win_t0, CF.cmd_win_span) > cfg[CF.stuck_command_v]):
        _trip(sv, cfg, FAULT.fsr_stuck)
        return 0, _safe(sv, cfg, cur, dt), math.nan
    if has_cur and sv[SV.mode] == MODE.run:
        cause = _detect(sv, cfg, f, cur, dt)
        if cause != 0:
            _trip(sv, cfg, cause)
            return 0, _safe(sv, cfg, cur, dt), math.nan
    # contact tracking
    f_then = sv[_slide(sv, cfg, SV.drop_hist_head, CF.drop_hist_base, t, f, cfg[CF.drop_window_s]) + 1]
    if sv[SV.mode] == MODE.run:
        if f > cfg[CF.contact_on_n]:
            sv[SV.in_contact] = 1.0
        # an intended release (the setpoint fell, or asks for no contact) is not a loss
        released = _win_range(sv, cfg, SV.sp_win_t0, CF.sp_win_span)
        fell = t - sv[SV.fall_t] <= cfg[CF.release_window_s]
        lost = ((f < cfg[CF.contact_lost_n] and sp > cfg[CF.contact_on_n] and not fell)
                or (f_then - f > cfg[CF.drop_n] + _pymax(released, 0.0) and f < cfg[CF.drop_keep_fraction] * f_then
                    and sv[SV.u_prev] > 0.0
                    and t - sv[SV.cut_t] > cfg[CF.drop_window_s]))
        if sv[SV.in_contact] != 0.0 and lost:
            sv[SV.mode] = MODE.freeze
            sv[SV.freeze_t0] = t
            sv[SV.contact_travel_m] = math.nan       # the compression check starts again at the next contact
            sv[SV.contact_travel_set] = 0.0
            sv[SV.loss_travel_m] = sv[SV.travel_m]
            sv[SV.approach_end_t] = 0.0
            _event(sv, cfg, EVENT.contact_lost, 0.0)
    if sv[SV.mode] == MODE.freeze:
        since = t - sv[SV.freeze_t0]
        if f > cfg[CF.contact_on_n] and f >= f_then and since > cfg[CF.backoff_s]:
            sv[SV.mode] = MODE.run
            sv[SV.approach_end_t] = 0.0
            _event(sv, cfg, EVENT.contact_regained, 0.0)
            sv[SV.u_prev] = 0.0
            return 2, 0.0, _pymin(sp, cfg[CF.sp_max_n])
        if since > cfg[CF.contact_loss_timeout_s]:
            if not has_cur:
                _trip(sv, cfg, FAULT.contact_lost)
                return 0, _safe(sv, cfg, cur, dt), math.nan
            # the finger did not come back by itself (a strap slip away from the board, a finger
            # lifted and put down further away): re-approach at the speed whose push and impact stay
            # at the top setpoint, over the travel a slip within the budget can have opened, within
            # twice the time that travel takes; no contact there latches (an open sensor, a finger gone)
            limit_m = sv[SV.loss_travel_m] + cfg[CF.reapproach_travel_m]
            if sv[SV.approach_end_t] == 0.0:
                sv[SV.approach_end_t] = t + 2.0 * _pymax(limit_m - sv[SV.travel_m], 0.0) / cfg[
                    CF.reapproach_speed_m_per_s]
                _event(sv, cfg, EVENT.reapproach, 0.0)
            elif sv[SV.travel_m] > limit_m or t > sv[SV.approach_end_t]:
                _trip(sv, cfg, FAULT.contact_lost)
                return 0, _safe(sv, cfg, cur, dt), math.nan
            u = _envelope_cap(sv, cfg, _slew(sv, cfg, cfg[CF.reapproach_v], dt), cur)
            sv[SV.u_prev] = u
            return 0, u, math.nan
        u = -cfg[CF.retract_v] if since <= cfg[CF.backoff_s] else 0.0
        sv[SV.u_prev] = u
        return 0, u, math.nan
    return 1, math.nan, _pymin(sp, cfg[CF.sp_max_n])


@njit(cache=True, _nrt=False, error_model="numpy")
def supervise_end(sv, cfg, u, f, sp, dt, cur):
    """Second half of a period whose :func:`supervise_begin` gave code 1: shape the inner command.

    Parameters
    ----------
    sv, cfg : ndarray of float64
        As for :func:`supervise_begin`.
    u : float
        The inner controller's command, V (any value: a non-finite one is the watchdog's case).
    f, sp, dt, cur : float
        As passed to :func:`supervise_begin` in the same period.

    Returns
    -------
    code : int
        1: the command is finite again after a non-finite stretch; reset the inner controller
        with ``force_est_n=f, setpoint_n=sp_inner, command_v=reset_cmd``.  2: the search before
        the first contact (``search_gap_m``) found the finger; reset the inner controller from
        0 V with ``force_est_n=f, setpoint_n=sp_inner`` (a plain bumpless reset, the soft start of
        a session's first contact: unlike a regained contact its integrator may start below 0 V).
        0 otherwise.
    u : float
        Command, V.
    reset_cmd : float
        Command to reset the inner controller from (code 1), V; NaN otherwise.
    """
    if not math.isfinite(cur):
        cur = math.nan
    if not math.isfinite(u):
        if sv[SV.nan_s] == 0.0:
            _event(sv, cfg, EVENT.nonfinite, 0.0)
        sv[SV.nan_s] += dt
        if sv[SV.nan_s] > cfg[CF.watchdog_timeout_s]:
            _trip(sv, cfg, FAULT.controller_nonfinite)
            return 0, _safe(sv, cfg, cur, dt), math.nan
        u = _slew(sv, cfg, 0.0, dt)
        sv[SV.u_prev] = u
        return 0, u, math.nan
    code = 0
    reset_cmd = math.nan
    if sv[SV.nan_s] > 0.0:
        sv[SV.nan_s] = 0.0
        _event(sv, cfg, EVENT.finite_again, 0.0)
        code = 1
        reset_cmd = sv[SV.u_prev]
        u = sv[SV.u_prev]
    if not math.isnan(cur):
        if sv[SV.in_contact] == 0.0 and sv[SV.travel_m] > cfg[CF.search_travel_m]:
            # no contact yet beyond the search travel: the finger may be lifted and come back onto
            # the board at any moment, so search at the re-approach speed rather than let the
            # loop's integrator run the board on (its wind-up is dropped at the first contact)
            sv[SV.searching] = 1.0
            target = cfg[CF.reapproach_v] if math.isfinite(sp) and sp > cfg[CF.contact_on_n] else 0.0
            u = _envelope_cap(sv, cfg, _slew(sv, cfg, target, dt), cur)
            sv[SV.u_prev] = u
            return code, u, reset_cmd
        if sv[SV.searching] != 0.0:
            # the search found the finger: the loop starts from 0 V with a plain bumpless reset, the
            # soft start of a session's first contact (not the resume of a regained contact)
            sv[SV.searching] = 0.0
            sv[SV.u_prev] = 0.0
            return 2, 0.0, math.nan
    u_inner = u
    lo = cfg[CF.force_cap_n] - cfg[CF.cap_margin_n]
    if f >= cfg[CF.force_cap_n]:
        u = -cfg[CF.retract_v]
    elif f > lo and u > 0.0:
        u *= 1.0 - (f - lo) / cfg[CF.cap_margin_n]
    u = _slew(sv, cfg, u, dt)
    if not math.isnan(cur):
        u = _envelope_cap(sv, cfg, u, cur)
    if u < u_inner - 1e-9:
        sv[SV.cut_t] = sv[SV.t]            # the supervisor held the push back: a drop that follows is its own
    sv[SV.u_prev] = u
    return code, u, reset_cmd


# ---- Python wrapper -----------------------------------------------------------------------------

