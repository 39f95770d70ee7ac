"""CSV bodies formatted in compiled code, with the bytes of Python's ``%.9g`` and ``%d``.

:func:`csv_body` writes the rows of a table of float, integer and text columns as the
``csv`` module's default dialect writes them (``\\r\\n`` line ends; the text cells given
already quoted).  A float is written as ``"%.9g" % v`` writes it: nine significant digits,
correctly rounded (ties to even) from the exact binary value, trailing zeros dropped, the
exponent form below ``1e-4``.  The digits come from exact integer arithmetic: ``|v| * 10**k``
as a 128-bit product of the significand and ``5**k`` (``k <= 27``), shifted by the binary
exponent, the remainder compared with one half.  Values outside what that covers
(``|v| >= 1e9``, ``0 < |v| < 1e-19``) make :func:`csv_body` return None, and the caller
formats the table in Python; zeros, infinities and NaN are written as Python writes them.

What it buys (``python benchmarks/bench_replicas.py``, the Python formatting of
:func:`ebraille_sim.tools.report.write_trace_csv` in its place in the same run, 2-core
machine): trace.csv of a 60 s steady_90wpm run (67,633 rows) in 79 ms against 210 ms, for a
run that simulates in 125 ms; the bytes are the same.
"""
from __future__ import annotations

import math

import numpy as np

from ebraille_sim.base.compiled import njit

__all__ = ["csv_body", "FLOAT", "INT", "TEXT"]

FLOAT, INT, TEXT = 0, 1, 2
"""Column kinds of :func:`csv_body`."""

_MAX_K = 27
"""Largest power of ten the digits are scaled by (``5**27 < 2**63``)."""

_MASK32 = np.uint64(0xFFFFFFFF)


_POW5 = np.array([5 ** k for k in range(_MAX_K + 1)], dtype=np.uint64)
"""``5**k`` for ``k = 0 .. _MAX_K``."""


@njit(cache=True)
def _mul_64x64(a, b):
    """The 128-bit product of two uint64 below 2**63, as ``(high, low)`` words."""
    a_lo = a & _MASK32
    a_hi = a >> np.uint64(32)
    b_lo = b & _MASK32
    b_hi = b >> np.uint64(32)
    lo_lo = a_lo * b_lo
    cross = a_hi * b_lo + a_lo * b_hi
    hi_hi = a_hi * b_hi
    lo = lo_lo + (cross << np.uint64(32))
    carry = np.uint64(1) if lo < lo_lo else np.uint64(0)
    hi = hi_hi + (cross >> np.uint64(32)) + carry
    return hi, lo


@njit(cache=True)
def _scaled_digits(m, e2, k):
    """``round_half_even(m * 2**e2 * 10**k)`` for ``0 <= k <= _MAX_K``; -1 when it is 2**63 or more."""
    hi, lo = _mul_64x64(m, _POW5[k])
    s = -(e2 + k)                                  # the product times 2**-s
    if s <= 0:
        if hi != np.uint64(0) or s < -62 or (lo >> np.uint64(63 + s)) != np.uint64(0):
            return -1
        return np.int64(lo << np.uint64(-s))
    if s < 64:
        if (hi >> np.uint64(s)) != np.uint64(0):
            return -1
        q = (lo >> np.uint64(s)) | (hi << np.uint64(64 - s))
        rem = lo & ((np.uint64(1) << np.uint64(s)) - np.uint64(1))
        half = np.uint64(1) << np.uint64(s - 1)
        up = rem > half or (rem == half and (q & np.uint64(1)) == np.uint64(1))
    elif s < 128:
        q = hi >> np.uint64(s - 64)
        rem_hi = hi & ((np.uint64(1) << np.uint64(s - 64)) - np.uint64(1)) if s > 64 else np.uint64(0)
        if s == 64:
            up = lo > (np.uint64(1) << np.uint64(63)) or (lo == (np.uint64(1) << np.uint64(63))
                                                         and (q & np.uint64(1)) == np.uint64(1))
        else:
            half_hi = np.uint64(1) << np.uint64(s - 65)
            above = rem_hi > half_hi or (rem_hi == half_hi and lo != np.uint64(0))
            tie = rem_hi == half_hi and lo == np.uint64(0)
            up = above or (tie and (q & np.uint64(1)) == np.uint64(1))
    else:
        return 0
    if q >= np.uint64(1) << np.uint64(62):
        return -1
    return np.int64(q) + (1 if up else 0)


@njit(cache=True)
def _put_nonfinite(buf, pos, x):
    """``nan``, ``inf`` or ``-inf`` (Python writes no sign on a NaN)."""
    if math.isnan(x):
        buf[pos], buf[pos + 1], buf[pos + 2] = 110, 97, 110
        return pos + 3
    if x < 0.0:
        buf[pos] = 45
        pos += 1
    buf[pos], buf[pos + 1], buf[pos + 2] = 105, 110, 102
    return pos + 3


@njit(cache=True)
def _put_int(buf, pos, v):
    if v < 0:
        buf[pos] = 45                              # "-"
        pos += 1
        v = -v
    n = 1
    t = v
    while t >= 10:
        t //= 10
        n += 1
    for i in range(n - 1, -1, -1):
        buf[pos + i] = 48 + v % 10
        v //= 10
    return pos + n


@njit(cache=True)
def _put_g9(buf, pos, x, digits):
    """Write ``"%.9g" % x`` (``digits``: scratch of 9 integers); returns the new position, or
    -1 where the value is not covered."""
    if not math.isfinite(x):
        return _put_nonfinite(buf, pos, x)
    if math.copysign(1.0, x) < 0.0:
        buf[pos] = 45
        pos += 1
        x = -x
    if x == 0.0:
        buf[pos] = 48
        return pos + 1
    if x >= 1e9 or x < 1e-19:
        return -1
    m, e2 = math.frexp(x)                          # x = m * 2**e2, 0.5 <= m < 1
    mi = np.uint64(m * 9007199254740992.0)         # exact: 53 significant bits
    e2 -= 53
    e10 = int(math.floor(math.log10(x)))
    d = np.int64(-1)
    found = False
    for _ in range(3):                             # the estimate of the exponent is off by one at most
        k = 8 - e10
        if k < 0 or k > _MAX_K:
            return -1
        d = _scaled_digits(mi, e2, k)
        if d < 0:
            return -1
        if d >= 1000000000:
            e10 += 1
        elif d < 100000000:
            e10 -= 1
        else:
            found = True
            break
    if not found:
        return -1
    for i in range(8, -1, -1):
        digits[i] = d % 10
        d //= 10
    nd = 9
    while nd > 1 and digits[nd - 1] == 0:
        nd -= 1
    if e10 < -4:                                   # exponent form: d.ddde-XX
        buf[pos] = 48 + digits[0]
        pos += 1
        if nd > 1:
            buf[pos] = 46
            pos += 1
            for i in range(1, nd):
                buf[pos] = 48 + digits[i]
                pos += 1
        buf[pos] = 101                             # "e"
        buf[pos + 1] = 45
        pos += 2
        ex = -e10
        if ex < 10:
            buf[pos] = 48
            pos += 1
        return _put_int(buf, pos, ex)
    if e10 < 0:                                    # 0.000ddd
        buf[pos] = 48
        buf[pos + 1] = 46
        pos += 2
        for _ in range(-e10 - 1):
            buf[pos] = 48
            pos += 1
        for i in range(nd):
            buf[pos] = 48 + digits[i]
            pos += 1
        return pos
    for i in range(e10 + 1):                       # integer part, then the fraction if any
        buf[pos] = 48 + (digits[i] if i < nd else 0)
        pos += 1
    if nd > e10 + 1:
        buf[pos] = 46
        pos += 1
        for i in range(e10 + 1, nd):
            buf[pos] = 48 + digits[i]
            pos += 1
    return pos


@njit(cache=True)
def _body(n, kinds, slots, floats, ints, text_index, text_bytes, text_offsets, buf):
    """Write the ``n`` rows into ``buf``; the number of bytes written, or -1 (a float not covered)."""
    digits = np.empty(9, np.int64)
    pos = 0
    for r in range(n):
        for j in range(kinds.shape[0]):
            if j:
                buf[pos] = 44                      # ","
                pos += 1
            kind = kinds[j]
            if kind == 0:
                pos = _put_g9(buf, pos, floats[r, slots[j]], digits)
                if pos < 0:
                    return -1
            elif kind == 1:
                pos = _put_int(buf, pos, ints[r, slots[j]])
            else:
                t = text_index[r]
                for b in range(text_offsets[t], text_offsets[t + 1]):
                    buf[pos] = text_bytes[b]
                    pos += 1
        buf[pos] = 13
        buf[pos + 1] = 10
        pos += 2
    return pos


def csv_body(columns: list) -> bytes | None:
    """The CSV rows of ``columns``, UTF-8 bytes, or None where a number is not covered (a
    float of the ranges above, the most negative 64-bit integer).

    Parameters
    ----------
    columns : list of (kind, values)
        At least one column: :data:`FLOAT` with a float array, :data:`INT` with an integer
        array, or :data:`TEXT` (at most one) with ``(index, texts)``: the cell of row ``r`` is
        ``texts[index[r]]``, written as it is (quoted already where it needs to be).  All of
        one length.
    """
    kinds = np.array([k for k, _ in columns], dtype=np.int64)
    first_kind, first = columns[0]
    n = len(first[0]) if first_kind == TEXT else len(first)
    fl = [np.asarray(v, dtype=np.float64) for k, v in columns if k == FLOAT]
    it = [np.asarray(v, dtype=np.int64) for k, v in columns if k == INT]
    if any(a.size and a.min() == np.iinfo(np.int64).min for a in it):
        return None
    slots = np.zeros(len(columns), dtype=np.int64)
    nf = ni = 0
    texts_width = 0
    text_index = np.zeros(n if any(k == TEXT for k, _ in columns) else 0, dtype=np.int64)
    encoded = [b""]
    for j, (kind, values) in enumerate(columns):
        if kind == FLOAT:
            slots[j], nf = nf, nf + 1
        elif kind == INT:
            slots[j], ni = ni, ni + 1
        else:
            index, texts = values
            text_index = np.ascontiguousarray(index, dtype=np.int64)
            encoded = [t.encode("utf-8") for t in texts]
            texts_width = max((len(e) for e in encoded), default=0)
    floats = np.column_stack(fl) if fl else np.zeros((n, 0))
    ints = np.column_stack(it) if it else np.zeros((n, 0), dtype=np.int64)
    text_bytes = np.frombuffer(b"".join(encoded), dtype=np.uint8) if any(encoded) else np.zeros(1, np.uint8)
    text_offsets = np.cumsum([0] + [len(e) for e in encoded]).astype(np.int64)
    width = 16 * nf + 20 * ni + texts_width + len(columns) + 2
    buf = np.empty(max(n * width, 1), dtype=np.uint8)
    used = _body(n, kinds, slots, np.ascontiguousarray(floats), np.ascontiguousarray(ints), text_index,
                 text_bytes, text_offsets, buf)
    return None if used < 0 else buf[:used].tobytes()
