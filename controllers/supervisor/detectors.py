"""The supervisor's detectors, events and safe states (compiled): what one period checks and
what a latched fault does."""
from __future__ import annotations

import math

from controllers.compiled import py_max as _pymax, py_min as _pymin
from controllers.supervisor.buffers import _win_hi, _win_push
from controllers.supervisor.layout import CF, EVENT, FAULT, MODE, SV
from ebraille_sim.base.compiled import njit
from ebraille_sim.physics import limits
from ebraille_sim.physics.fingertip import compression_at_force_m

@njit(cache=True)
def _event(sv, cfg, code, value):
    n = int(sv[SV.event_count])
    if n < int(cfg[CF.events_cap]):
        k = int(cfg[CF.events_base]) + 3 * n
        sv[k] = sv[SV.t]
        sv[k + 1] = code
        sv[k + 2] = value
        sv[SV.event_count] = n + 1
    else:
        if sv[SV.events_dropped] == 0.0:
            sv[SV.first_dropped_t] = sv[SV.t]
        sv[SV.events_dropped] += 1.0


@njit(cache=True)
def _trip(sv, cfg, cause):
    if sv[SV.fault] == 0.0:
        sv[SV.fault] = cause
        sv[SV.mode] = MODE.retract
        sv[SV.retract_t0] = sv[SV.t]
        sv[SV.moving_s] = 0.0
        _event(sv, cfg, EVENT.fault, cause)


@njit(cache=True, inline="always")
def _slew(sv, cfg, u, dt):
    du = cfg[CF.slew_v_per_s] * dt
    return _pymin(_pymax(u, sv[SV.u_prev] - du), sv[SV.u_prev] + du)


@njit(cache=True)
def _safe(sv, cfg, cur, dt):
    """Command of the latched safe state: retract, then hold at 0 V."""
    if sv[SV.mode] == MODE.retract:
        el = sv[SV.t] - sv[SV.retract_t0]
        if math.isnan(cur):
            done = el >= cfg[CF.retract_s]
        else:
            stalled = abs(cur) > 0.6 * cfg[CF.retract_v] / cfg[CF.motor_resistance_ohm]
            if not stalled and el > 0.01:
                sv[SV.moving_s] += dt
            done = (sv[SV.moving_s] >= cfg[CF.retract_moving_s] and stalled) or el >= cfg[CF.max_retract_s]
        if done:
            sv[SV.mode] = MODE.hold
            _event(sv, cfg, EVENT.retracted, 0.0)
        else:
            u = _slew(sv, cfg, -cfg[CF.retract_v], dt)
            sv[SV.u_prev] = u
            return u
    u = _slew(sv, cfg, 0.0, dt)
    sv[SV.u_prev] = u
    return u


@njit(cache=True, inline="always")
def _motion(sv, cfg, cur, dt):
    """Rack speed from the back-EMF of the last period, travel integral, held peak speed."""
    vs = cfg[CF.driver_supply_v]
    u = _pymin(_pymax(sv[SV.u_prev], -vs), vs)
    v = limits.rack_speed_from_emf_m_per_s(u, cur, cfg[CF.motor_resistance_ohm], cfg[CF.back_emf_v_s_per_m], 1.0)
    sv[SV.accel] = (v - sv[SV.speed]) / dt
    sv[SV.speed] = v
    if abs(cur) > cfg[CF.powered_current_a]:     # an unpowered motor (a cut supply) reads its command as speed
        sv[SV.travel_m] = _pymax(0.0, sv[SV.travel_m] + v * dt)
    _win_push(sv, cfg, SV.speed_win_t0, CF.speed_win_span, sv[SV.t], v, False)


@njit(cache=True, inline="always")
def _interp_envelope(cfg, x):
    """Current limit at speed ``x`` from the envelope table: linear between the points (``bisect_right``)."""
    n = int(cfg[CF.envelope_n])
    b = int(cfg[CF.envelope_base])
    if x <= cfg[b]:
        return cfg[b + n]
    if x >= cfg[b + n - 1]:
        return cfg[b + 2 * n - 1]
    lo, hi = 0, n
    while lo < hi:
        mid = (lo + hi) // 2
        if x < cfg[b + mid]:
            hi = mid
        else:
            lo = mid + 1
    if lo >= n:                       # x is NaN: no interval holds it
        return math.nan
    x0, x1, y0, y1 = cfg[b + lo - 1], cfg[b + lo], cfg[b + n + lo - 1], cfg[b + n + lo]
    return y0 + (y1 - y0) * (x - x0) / (x1 - x0)


@njit(cache=True, inline="always")
def _envelope_cap(sv, cfg, u, cur):
    """Largest command that keeps the next period's current within the speed-dependent limit."""
    v_held = _pymax(_win_hi(sv, cfg, SV.speed_win_t0, CF.speed_win_span), 0.0)
    i_lim = _interp_envelope(cfg, v_held)
    sv[SV.current_limit_a] = i_lim
    vs = cfg[CF.driver_supply_v]
    u_applied = _pymin(_pymax(sv[SV.u_prev], -vs), vs)
    return _pymin(u, u_applied + cfg[CF.motor_resistance_ohm] * (i_lim - cur))


@njit(cache=True, inline="always")
def _rest_push_lower_edge_n(cfg, cur):
    """Least force (N) that the drive applies to the finger when nothing else takes it, for a
    current READ as ``cur``: the least true current that reading allows (the sensing chain's worst
    case, ``(cur - e_abs) / (1 + e_gain)``) through the steady push bound with break-away friction,
    the weight against the push and the guide rods' break-away friction (the lower edge of the
    friction band).  A sensor that reads a little high never accuses the FSR."""
    cur_lo = (cur - cfg[CF.sense_error_a]) / (1.0 + cfg[CF.sense_gain_error_max])
    return (limits.push_force_bound_n(cur_lo, cfg[CF.push_force_per_a_n], 1.0, 1.0, cfg[CF.breakaway_friction_n],
                                      cfg[CF.push_weight_n]) - cfg[CF.guide_static_n])


@njit(cache=True, inline="always")
def _soft_compression_m(sv, cfg, pair, force_n):
    """:func:`~ebraille_sim.physics.fingertip.compression_at_force_m` of ``force_n`` on the soft
    reader, through a one-entry cache: the ``pair``-th (force, compression) pair at the start of
    the speed window's unused minimum ring (:data:`_WINDOWS`).

    The estimate holds its value for an estimator period, so most periods ask for the force of
    the last call, and the law is computed again only when the force differs.  The pair depends
    on the configuration alone, so a reset keeps it; a ring of zeros holds the pair (0, 0), which
    is the law's value.  The callers' forces are positive or a sum with a positive margin, never
    a negative zero (which would compare equal to 0 with a compression of the other sign); a
    NaN never matches."""
    k = int(cfg[CF.speed_win_lo_base]) + 2 * pair
    if force_n != sv[k]:
        sv[k] = force_n
        sv[k + 1] = compression_at_force_m(force_n, cfg[CF.soft_b_n_per_m], cfg[CF.soft_m_per_m])
    return sv[k + 1]


@njit(cache=True, inline="always")
def _detect(sv, cfg, f, cur, dt):
    """The detectors that need the motor current; the fault code, or 0."""
    v = sv[SV.speed]
    moving = abs(v) > cfg[CF.moving_speed_m_per_s]
    in_contact = sv[SV.in_contact] != 0.0
    # a stuck code: the estimate does not change while the board travels
    if f > cfg[CF.contact_lost_n] and in_contact:
        if not abs(f - sv[SV.stuck_ref_n]) <= cfg[CF.stuck_tolerance_n]:
            sv[SV.stuck_ref_n] = f
            sv[SV.stuck_travel_m] = 0.0
        elif abs(cur) > cfg[CF.powered_current_a]:    # a powered motor: an unpowered one (a cut supply)
            # draws no current and its command reads as speed
            sv[SV.stuck_travel_m] += v * dt
            if abs(sv[SV.stuck_travel_m]) > cfg[CF.stuck_travel_m]:
                return FAULT.fsr_stuck
    else:
        sv[SV.stuck_ref_n] = math.nan
    # travel since the first contact against the compression the estimate allows on the soft reader
    if in_contact:
        if sv[SV.contact_travel_set] == 0.0:
            sv[SV.contact_travel_m] = sv[SV.travel_m]
            sv[SV.contact_travel_set] = 1.0
        elif f > cfg[CF.contact_on_n]:
            # the reference follows where the pulp's surface must be for the estimate shown,
            # at once on an intended release (the setpoint fell: the back-EMF integral's drift
            # over many presses in refresh mode does not add up) and slowly otherwise (the
            # finger drifts, presses and the strap slips over a session: only a fast mismatch,
            # a board running into the finger while the reading stays low, trips)
            target = sv[SV.travel_m] - _soft_compression_m(sv, cfg, 0, f)
            if sv[SV.t] - sv[SV.fall_t] <= cfg[CF.release_window_s]:
                sv[SV.contact_travel_m] = _pymax(sv[SV.contact_travel_m], target)
            else:
                sv[SV.contact_travel_m] = sv[SV.contact_travel_m] + (target - sv[SV.contact_travel_m]) * _pymin(
                    1.0, dt / cfg[CF.travel_follow_s])
        allowed = (_soft_compression_m(sv, cfg, 1, _win_hi(sv, cfg, SV.est_win_t0, CF.est_win_span)
                                       + cfg[CF.implausible_n]) + cfg[CF.stuck_travel_m])
        if sv[SV.travel_m] - sv[SV.contact_travel_m] > allowed:
            return FAULT.fsr_implausible
    # no contact within the travel the gap allows
    if not in_contact and sv[SV.travel_m] > cfg[CF.first_contact_travel_m]:
        return FAULT.fsr_no_contact
    # pushing and not moving: with no contact seen, or at the current limit with a push that does
    # not reach the finger (the lower edge of the friction band at rest above the estimate) short of
    # the far end stop (there the finger lies beyond the board's reach, not behind a jam): a
    # motor creeping a held force forward against the full break-away friction also sits at the
    # limit, and its estimate accounts for the push
    if not moving and ((f < cfg[CF.contact_on_n] and cur > cfg[CF.contact_current_a])
                       or (cur > cfg[CF.stall_fraction] * cfg[CF.current_limit_a]
                           and sv[SV.travel_m] < cfg[CF.end_stop_travel_m]
                           and _rest_push_lower_edge_n(cfg, cur) - _win_hi(sv, cfg, SV.est_win_t0, CF.est_win_span)
                           > cfg[CF.implausible_n])):
        sv[SV.stall_s] += dt
        if sv[SV.stall_s] > cfg[CF.stall_time_s]:
            return FAULT.motor_stalled
    else:
        sv[SV.stall_s] = 0.0
    # the force the current implies while the board moves forward, against the estimate
    if v > cfg[CF.moving_speed_m_per_s]:
        a = _pymax(sv[SV.accel], 0.0)
        # lower edge of the friction band: break-away friction, guide friction, weight against
        # the push, and the force that accelerates the rotor and the board
        f_lo = _rest_push_lower_edge_n(cfg, cur) - cfg[CF.impact_mass_kg] * a
        if f_lo - _win_hi(sv, cfg, SV.est_win_t0, CF.est_win_span) > cfg[CF.implausible_n]:
            sv[SV.implausible_s] += dt
            if sv[SV.implausible_s] > cfg[CF.implausible_s]:
                return FAULT.fsr_implausible
        else:
            sv[SV.implausible_s] = 0.0
    else:
        sv[SV.implausible_s] = 0.0
    return 0


