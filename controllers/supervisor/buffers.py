"""Ring buffers and running-extreme windows inside the supervisor's state array (compiled)."""
from __future__ import annotations

import math

from ebraille_sim.base.compiled import njit

@njit(cache=True, inline="always")
def _at(sv, cfg, head, base, i):
    """Index in ``sv`` of the time of entry ``i`` (0: front) of the ring at slots ``head``/``base``.

    The head is below the capacity and ``i`` at most the count, so the ring wraps at most once:
    a compare and a subtraction stand for the remainder."""
    j = int(sv[head]) + i
    cap = int(cfg[base + 1])
    if j >= cap:
        j -= cap
    return int(cfg[base]) + 2 * j


@njit(cache=True, inline="always")
def _append(sv, cfg, head, base, t, x):
    n = int(sv[head + 1])
    if n >= int(cfg[base + 1]):
        raise ValueError("supervisor window full: the control period is below the shortest it was sized for")
    k = _at(sv, cfg, head, base, n)
    sv[k] = t
    sv[k + 1] = x
    sv[head + 1] = n + 1


@njit(cache=True, inline="always")
def _pop_front(sv, cfg, head, base):
    j = int(sv[head]) + 1
    sv[head] = 0 if j >= int(cfg[base + 1]) else j
    sv[head + 1] -= 1.0


@njit(cache=True, inline="always")
def _cut_front(sv, cfg, head, base, cut):
    """Drop the front entries older than ``cut`` (a window emptied this way is a configuration error)."""
    while True:
        if sv[head + 1] <= 0.0:
            raise ValueError("supervisor window empty: stuck_response_s must not exceed stuck_window_s")
        if sv[_at(sv, cfg, head, base, 0)] < cut:
            _pop_front(sv, cfg, head, base)
        else:
            break


@njit(cache=True, inline="always")
def _win_push(sv, cfg, w, wc, t, x, keep_min):
    """Running min/max push (monotonic deques) of the window at state slot ``w``, config slot ``wc``.

    The back of both deques is the last value pushed: a push leaves it there and a cut never
    reaches it (its time is the newest).  The deques are strictly monotonic, so the same value
    again pops just that entry from each and appends ``(t, x)`` in its place: that is done by
    writing the entry.  ``keep_min`` false keeps only the running maximum (a window whose
    minimum no rule reads; its minimum's deque is left empty)."""
    if math.isnan(sv[w]):
        sv[w] = t
    lo, hi = w + 1, w + 3
    if sv[hi + 1] > 0.0 and sv[_at(sv, cfg, hi, wc + 3, int(sv[hi + 1]) - 1) + 1] == x:
        k = _at(sv, cfg, hi, wc + 3, int(sv[hi + 1]) - 1)
        sv[k] = t
        sv[k + 1] = x
        if keep_min:
            k = _at(sv, cfg, lo, wc + 1, int(sv[lo + 1]) - 1)
            sv[k] = t
            sv[k + 1] = x
    else:
        if keep_min:
            while sv[lo + 1] > 0.0 and sv[_at(sv, cfg, lo, wc + 1, int(sv[lo + 1]) - 1) + 1] >= x:
                sv[lo + 1] -= 1.0
        while sv[hi + 1] > 0.0 and sv[_at(sv, cfg, hi, wc + 3, int(sv[hi + 1]) - 1) + 1] <= x:
            sv[hi + 1] -= 1.0
        if keep_min:
            _append(sv, cfg, lo, wc + 1, t, x)
        _append(sv, cfg, hi, wc + 3, t, x)
    cut = t - cfg[wc]
    if keep_min:
        _cut_front(sv, cfg, lo, wc + 1, cut)
    _cut_front(sv, cfg, hi, wc + 3, cut)


@njit(cache=True, inline="always")
def _win_lo(sv, cfg, w, wc):
    return sv[_at(sv, cfg, w + 1, wc + 1, 0) + 1]


@njit(cache=True, inline="always")
def _win_hi(sv, cfg, w, wc):
    return sv[_at(sv, cfg, w + 3, wc + 3, 0) + 1]


@njit(cache=True, inline="always")
def _win_range(sv, cfg, w, wc):
    return _win_hi(sv, cfg, w, wc) - _win_lo(sv, cfg, w, wc)


@njit(cache=True, inline="always")
def _win_full(sv, cfg, w, wc, t):
    return not math.isnan(sv[w]) and t - sv[w] >= cfg[wc]


