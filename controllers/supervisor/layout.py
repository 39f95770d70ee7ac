"""The supervisor's state and configuration arrays: named slots (:data:`SV`, :data:`CF`), the
ring buffers' places, modes, faults and events, and the packing of a configuration."""
from __future__ import annotations

import collections
import functools
import math
import operator

import numpy as np

from controllers.supervisor.envelope import ENVELOPE_POINTS, _envelope_table

MIN_CONTROL_PERIOD_S = 1e-4
"""Shortest control period the detector windows are sized for, s: the nominal 10 kHz physics
step [E] (the control rate is a whole fraction of the physics rate; the shipped scenarios
control at 1 kHz).  A shorter period is a one-line error at :meth:`Supervisor.update`."""

MAX_WINDOW_SAMPLES = 1 << 15
"""Most samples one detector window is sized for [E]: a window longer than
``MAX_WINDOW_SAMPLES * MIN_CONTROL_PERIOD_S`` (3.3 s) raises the shortest period accepted to
its span over this count, so that a long window does not take megabytes."""

EVENT_CAPACITY = 256
"""Events the state array records after a reset; later ones are counted (the last entry of
:attr:`Supervisor.events` says how many were not recorded)."""

MODES = ("run", "freeze", "retract", "hold")
"""Modes by code (the ``mode`` slot of the state array)."""

FAULTS = ("fsr_out_of_range", "fsr_stuck", "motor_overcurrent", "contact_lost", "controller_nonfinite",
          "fsr_implausible", "fsr_no_contact", "motor_stalled")
"""Fault causes; the ``fault`` slot holds 0 (none) or the cause's position here plus one."""

_EVENT_TEXTS = ("fault {}: retract", "contact lost: freeze", "contact regained: resume",
                "non-finite command: hold", "finite command again: resume", "retracted: hold",
                "contact not back: re-approach")
_EVENT_NAMES = ("fault", "contact_lost", "contact_regained", "nonfinite", "finite_again", "retracted",
                "reapproach")

_WINDOWS = ("est_win", "cmd_win", "sp_win", "speed_win")
"""Running min and max windows: the estimate (stuck rule), the delayed command (stuck rule
without a current), the setpoint (release) and the rack speed (held peak: only its maximum is
kept; its minimum's deque stays empty and the start of its ring holds the detectors' cached
compressions, :func:`_soft_compression_m`)."""
_QUEUES = ("cmd_delay", "drop_hist")
"""Plain time-ordered queues: the command delayed by ``stuck_response_s`` and the recent
estimates of the drop rule."""

_STATE_SCALARS = ("mode", "fault", "t", "u_prev", "theta", "nan_s", "in_contact", "freeze_t0", "retract_t0",
                  "moving_s", "speed", "accel", "travel_m", "stuck_ref_n", "stuck_travel_m", "contact_travel_m",
                  "contact_travel_set", "cut_t", "sp_last", "fall_t", "stall_s", "implausible_s", "current_limit_a",
                  "last_f", "loss_travel_m", "approach_end_t", "searching", "event_count", "events_dropped", "first_dropped_t")
_CFG_SCALARS = ("force_cap_n", "cap_margin_n", "sp_max_n", "slew_v_per_s", "rated_current_sq_a2", "i2t_limit_a2s",
                "motor_resistance_ohm", "driver_supply_v", "back_emf_v_s_per_m", "powered_current_a",
                "moving_speed_m_per_s", "stuck_tolerance_n", "contact_lost_n", "contact_on_n", "stuck_travel_m",
                "soft_b_n_per_m", "soft_m_per_m", "release_window_s", "travel_follow_s", "implausible_n",
                "first_contact_travel_m", "end_stop_travel_m", "contact_current_a", "stall_fraction", "current_limit_a", "stall_time_s",
                "push_force_per_a_n", "breakaway_friction_n", "push_weight_n", "guide_static_n", "impact_mass_kg",
                "implausible_s", "out_of_range_n", "stuck_response_s", "stuck_emf_v", "stuck_command_v",
                "drop_window_s", "drop_n", "drop_keep_fraction", "backoff_s", "contact_loss_timeout_s", "retract_v", "watchdog_timeout_s",
                "reapproach_v", "reapproach_travel_m", "reapproach_speed_m_per_s", "search_travel_m",
                "retract_s", "retract_moving_s", "max_retract_s", "min_dt_s", "events_base", "events_cap",
                "envelope_n", "envelope_base", "state_len", "sense_error_a", "sense_gain_error_max")


def _record(kind: str, names, start: int = 0):
    """A read-only record of indices (a named tuple): compiled code reads its fields as constants."""
    return collections.namedtuple(kind, names)(*range(start, start + len(names)))


# A window is five consecutive state slots (t0, lo head, lo count, hi head, hi count) and five
# consecutive configuration slots (span, lo base, lo capacity, hi base, hi capacity); a queue
# is two of each (head, count; base, capacity).  The compiled helpers index from the first.
SV = _record("SupervisorStateSlots", _STATE_SCALARS
             + tuple(f"{w}_{s}" for w in _WINDOWS for s in ("t0", "lo_head", "lo_count", "hi_head", "hi_count"))
             + tuple(f"{q}_{s}" for q in _QUEUES for s in ("head", "count")))
"""Slots of the supervisor's state array (the ring buffers and the events follow them)."""
CF = _record("SupervisorConfigSlots", _CFG_SCALARS
             + tuple(f"{w}_{s}" for w in _WINDOWS for s in ("span", "lo_base", "lo_cap", "hi_base", "hi_cap"))
             + tuple(f"{q}_{s}" for q in _QUEUES for s in ("base", "cap")))
"""Slots of the supervisor's configuration array (the speed envelope table follows them)."""
MODE = _record("SupervisorModes", MODES)
FAULT = _record("SupervisorFaults", FAULTS, start=1)
EVENT = _record("SupervisorEvents", _EVENT_NAMES)
_N_HEADER = len(SV)


def _window_capacity(span_s: float, min_dt_s: float) -> int:
    """Entries a window or queue over ``span_s`` can hold at periods >= ``min_dt_s`` (with rounding margin)."""
    return int(max(span_s, 0.0) / min_dt_s * (1.0 + 1e-6)) + 4


def _pack(c) -> np.ndarray:
    """The configuration array of ``c``: derived constants, buffer layout, speed envelope."""
    spans = {"est_win": c.stuck_window_s, "cmd_win": c.stuck_window_s - c.stuck_response_s,
             "sp_win": c.release_window_s, "speed_win": c.speed_hold_s,
             "cmd_delay": c.stuck_response_s, "drop_hist": c.drop_window_s}
    min_dt = max(MIN_CONTROL_PERIOD_S, max(spans.values()) / MAX_WINDOW_SAMPLES)
    vals = {
        "force_cap_n": c.force_cap_n, "cap_margin_n": c.cap_margin_n, "sp_max_n": c.setpoint_max_n,
        "slew_v_per_s": c.slew_v_per_s, "rated_current_sq_a2": c.rated_current_a ** 2,
        "i2t_limit_a2s": c.i2t_limit_a2s, "motor_resistance_ohm": c.motor_resistance_ohm,
        "driver_supply_v": c.driver_supply_v, "back_emf_v_s_per_m": c.back_emf_v_s_per_m,
        "powered_current_a": c.powered_current_a, "moving_speed_m_per_s": c.moving_speed_m_per_s,
        "stuck_tolerance_n": c.stuck_tolerance_n, "contact_lost_n": c.contact_lost_n,
        "contact_on_n": c.contact_on_n, "stuck_travel_m": c.stuck_travel_m, "soft_b_n_per_m": c.soft_b_n_per_m,
        "soft_m_per_m": c.soft_m_per_m, "release_window_s": c.release_window_s,
        "travel_follow_s": c.travel_follow_s, "implausible_n": c.implausible_n,
        "first_contact_travel_m": c.first_contact_travel_m, "end_stop_travel_m": c.end_stop_travel_m,
        "contact_current_a": c.current_for_force_a(c.contact_on_n),
        "sense_error_a": c.sense_error_a, "sense_gain_error_max": c.sense_gain_error_max,
        "stall_fraction": c.stall_fraction, "current_limit_a": c.sensed_limit_a(c.current_limit_a),
        "stall_time_s": c.stall_time_s,
        "push_force_per_a_n": c.push_force_per_a_n,
        "breakaway_friction_n": c.friction_breakaway_ratio * c.friction_current_a * c.push_force_per_a_n,
        "push_weight_n": -c.weight_n, "guide_static_n": c.guide_static_n, "impact_mass_kg": c.impact_mass_kg,
        "implausible_s": c.implausible_s, "out_of_range_n": c.out_of_range_n,
        "stuck_response_s": c.stuck_response_s, "stuck_emf_v": c.stuck_emf_v,
        "stuck_command_v": c.stuck_command_v, "drop_window_s": c.drop_window_s, "drop_n": c.drop_n,
        "drop_keep_fraction": c.drop_keep_fraction,
        "backoff_s": c.backoff_s, "contact_loss_timeout_s": c.contact_loss_timeout_s, "retract_v": c.retract_v,
        "reapproach_v": c.reapproach_command_v, "reapproach_travel_m": c.reapproach_travel_m,
        "reapproach_speed_m_per_s": c.reapproach_speed_m_per_s, "search_travel_m": c.search_travel_m,
        "watchdog_timeout_s": c.watchdog_timeout_s, "retract_s": c.retract_s,
        "retract_moving_s": c.retract_moving_s, "max_retract_s": c.max_retract_s, "min_dt_s": min_dt,
        "events_cap": EVENT_CAPACITY, "envelope_n": ENVELOPE_POINTS, "envelope_base": len(CF),
    }
    pos = _N_HEADER
    for w, span_key, lo_base, lo_cap, hi_base, hi_cap in _WINDOW_KEYS:
        cap = _window_capacity(spans[w], min_dt)
        vals[span_key] = spans[w]
        vals[lo_base], vals[lo_cap] = pos, cap
        pos += 2 * cap
        vals[hi_base], vals[hi_cap] = pos, cap
        pos += 2 * cap
    for q, base_key, cap_key in _QUEUE_KEYS:
        cap = _window_capacity(spans[q], min_dt)
        vals[base_key], vals[cap_key] = pos, cap
        pos += 2 * cap
    vals["events_base"] = pos
    vals["state_len"] = pos + 3 * EVENT_CAPACITY
    cfg = np.empty(len(CF) + 2 * ENVELOPE_POINTS)
    cfg[:len(CF)] = _config_values(vals)
    _envelope_table(c, cfg[len(CF):])
    return cfg


_WINDOW_KEYS = tuple((w, f"{w}_span", f"{w}_lo_base", f"{w}_lo_cap", f"{w}_hi_base", f"{w}_hi_cap") for w in _WINDOWS)
_QUEUE_KEYS = tuple((q, f"{q}_base", f"{q}_cap") for q in _QUEUES)
_config_values = operator.itemgetter(*CF._fields)
"""The keys :func:`_pack` fills for the windows and queues, and the getter of its values in the
order of :data:`CF` (made once)."""


def _initial_state(c) -> np.ndarray:
    """The header of the state array after a reset (the ring buffers are empty by their counts):
    :func:`_reset_header` with the configuration's current limit."""
    h = _reset_header().copy()
    h[SV.current_limit_a] = c.sensed_limit_a(c.current_limit_a)
    return h


@functools.lru_cache(maxsize=1)
def _reset_header() -> np.ndarray:
    """The slots of a reset state header that no configuration changes (read-only, made once:
    every supervisor a reset makes starts from a copy)."""
    h = np.zeros(_N_HEADER)
    for name in ("stuck_ref_n", "contact_travel_m", "first_dropped_t") + tuple(f"{w}_t0" for w in _WINDOWS):
        h[getattr(SV, name)] = math.nan
    h[SV.cut_t] = -math.inf
    h[SV.sp_last] = math.inf
    h[SV.fall_t] = -math.inf
    h.flags.writeable = False
    return h


# ---- compiled period --------------------------------------------------------------------------

