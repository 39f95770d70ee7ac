"""Ring buffers and running-extreme windows inside the supervisor's state array (compiled).

A ring's head and count are state slots and its first index and capacity configuration
slots, all whole numbers held as floats; the helpers read them into integers once per
operation and write back what changed."""
from __future__ import annotations

import math

from ebraille_sim.base.compiled import njit

@njit(cache=True, inline="always")
def _slot(first, cap, h, i):
    """Index in ``sv`` of the time of entry ``i`` (0: front) of a ring whose entries start at
    ``first``, with capacity ``cap`` and head ``h``.

    The head is below the capacity and ``i`` at most the count, so the ring wraps at most once:
    a compare and a subtraction stand for the remainder."""
    j = h + i
    if j >= cap:
        j -= cap
    return first + 2 * j


@njit(cache=True, inline="always")
def _at(sv, cfg, head, base, i):
    """Index in ``sv`` of the time of entry ``i`` (0: front) of the ring at slots ``head``/``base``."""
    return _slot(int(cfg[base]), int(cfg[base + 1]), int(sv[head]), i)


@njit(cache=True, inline="always")
def _put(sv, head, first, cap, h, n, t, x):
    """Append ``(t, x)`` behind the ``n`` entries of the ring at state slot ``head`` (its head ``h``)."""
    if n >= cap:
        raise ValueError("supervisor window full: the control period is below the shortest it was sized for")
    k = _slot(first, cap, h, n)
    sv[k] = t
    sv[k + 1] = x
    sv[head + 1] = n + 1


@njit(cache=True, inline="always")
def _append(sv, cfg, head, base, t, x):
    _put(sv, head, int(cfg[base]), int(cfg[base + 1]), int(sv[head]), int(sv[head + 1]), t, x)


@njit(cache=True, inline="always")
def _pop_front(sv, cfg, head, base):
    j = int(sv[head]) + 1
    sv[head] = 0 if j >= int(cfg[base + 1]) else j
    sv[head + 1] -= 1.0


@njit(cache=True, inline="always")
def _cut_front(sv, head, first, cap, cut):
    """Drop the front entries older than ``cut`` (a window emptied this way is a configuration error)."""
    h, n = int(sv[head]), int(sv[head + 1])
    if n > 0 and not sv[first + 2 * h] < cut:
        return
    while True:
        if n <= 0:
            sv[head], sv[head + 1] = h, n
            raise ValueError("supervisor window empty: stuck_response_s must not exceed stuck_window_s")
        if not sv[first + 2 * h] < cut:
            break
        h = 0 if h + 1 >= cap else h + 1
        n -= 1
    sv[head], sv[head + 1] = h, n


@njit(cache=True, inline="always")
def _slide(sv, cfg, head, base, t, x, span):
    """Append ``(t, x)`` to the queue at slots ``head``/``base`` and drop the front entries older
    than ``t - span``; the index in ``sv`` of the time of the front entry left."""
    first, cap, h = int(cfg[base]), int(cfg[base + 1]), int(sv[head])
    _put(sv, head, first, cap, h, int(sv[head + 1]), t, x)
    k = first + 2 * h
    if sv[k] < t - span:
        n = int(sv[head + 1])
        while sv[k] < t - span:
            h = 0 if h + 1 >= cap else h + 1
            n -= 1
            k = first + 2 * h
        sv[head], sv[head + 1] = h, n
    return k


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
    lo_first, lo_cap, hi_first, hi_cap = int(cfg[wc + 1]), int(cfg[wc + 2]), int(cfg[wc + 3]), int(cfg[wc + 4])
    lo_head, lo_n, hi_head, hi_n = int(sv[lo]), int(sv[lo + 1]), int(sv[hi]), int(sv[hi + 1])
    k = _slot(hi_first, hi_cap, hi_head, hi_n - 1)
    if hi_n > 0 and sv[k + 1] == x:
        sv[k] = t
        sv[k + 1] = x
        if keep_min:
            k = _slot(lo_first, lo_cap, lo_head, lo_n - 1)
            sv[k] = t
            sv[k + 1] = x
    else:
        if keep_min:
            while lo_n > 0 and sv[_slot(lo_first, lo_cap, lo_head, lo_n - 1) + 1] >= x:
                lo_n -= 1
            sv[lo + 1] = lo_n
        while hi_n > 0 and sv[_slot(hi_first, hi_cap, hi_head, hi_n - 1) + 1] <= x:
            hi_n -= 1
        sv[hi + 1] = hi_n
        if keep_min:
            _put(sv, lo, lo_first, lo_cap, lo_head, lo_n, t, x)
        _put(sv, hi, hi_first, hi_cap, hi_head, hi_n, t, x)
    cut = t - cfg[wc]
    if keep_min:
        _cut_front(sv, lo, lo_first, lo_cap, cut)
    _cut_front(sv, hi, hi_first, hi_cap, cut)


@njit(cache=True, inline="always")
def _win_lo(sv, cfg, w, wc):
    return sv[int(cfg[wc + 1]) + 2 * int(sv[w + 1]) + 1]


@njit(cache=True, inline="always")
def _win_hi(sv, cfg, w, wc):
    return sv[int(cfg[wc + 3]) + 2 * int(sv[w + 3]) + 1]


@njit(cache=True, inline="always")
def _win_range(sv, cfg, w, wc):
    return _win_hi(sv, cfg, w, wc) - _win_lo(sv, cfg, w, wc)


@njit(cache=True, inline="always")
def _win_full(sv, cfg, w, wc, t):
    return not math.isnan(sv[w]) and t - sv[w] >= cfg[wc]
