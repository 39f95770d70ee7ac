"""NumPy's reductions of a 1-D float64 array, compiled, with NumPy's bits.

``numpy.std`` of a short array spends most of its time in Python (the mean, the deviations,
their squares and sum are separate NumPy calls, each with its dispatch).  :func:`std` is one
compiled call that performs the same floating-point operations in the same order:
``numpy.add.reduce`` of a contiguous array is NumPy's pairwise summation
(:func:`pairwise_sum`: blocks of at most 128 values summed with eight accumulators, longer
runs split in halves rounded down to a multiple of eight), the mean is that sum over ``n``, the
variance the same sum of the squared deviations over ``n``, the result its square root.
``tests/test_reset_cost.py`` compares both with NumPy's over many lengths and scales.

Examples
--------
>>> import numpy as np
>>> x = np.random.default_rng(0).standard_normal(1000)
>>> float(std(x)) == float(np.std(x))
True
"""
from __future__ import annotations

import math

import numpy as np

from ebraille_sim.base.compiled import njit

__all__ = ["pairwise_sum", "std"]


@njit(cache=True, inline="always")
def _term(a, i, mean, squared):
    """Value ``i`` of the run: ``a[i]``, or with ``squared`` its squared deviation from ``mean``."""
    if squared:
        d = a[i] - mean
        return d * d
    return a[i]


@njit(cache=True)
def _block_sum(a, lo, n, mean, squared):
    """The sum of the terms ``lo .. lo + n - 1`` (:func:`_term`), ``n <= 128``, as NumPy sums a
    block: one by one below 8 values, else with eight accumulators and the rest one by one."""
    if n < 8:
        res = 0.0
        for i in range(lo, lo + n):
            res += _term(a, i, mean, squared)
        return res
    r0, r1 = _term(a, lo, mean, squared), _term(a, lo + 1, mean, squared)
    r2, r3 = _term(a, lo + 2, mean, squared), _term(a, lo + 3, mean, squared)
    r4, r5 = _term(a, lo + 4, mean, squared), _term(a, lo + 5, mean, squared)
    r6, r7 = _term(a, lo + 6, mean, squared), _term(a, lo + 7, mean, squared)
    m = lo + n - n % 8
    i = lo + 8
    while i < m:
        r0 += _term(a, i, mean, squared)
        r1 += _term(a, i + 1, mean, squared)
        r2 += _term(a, i + 2, mean, squared)
        r3 += _term(a, i + 3, mean, squared)
        r4 += _term(a, i + 4, mean, squared)
        r5 += _term(a, i + 5, mean, squared)
        r6 += _term(a, i + 6, mean, squared)
        r7 += _term(a, i + 7, mean, squared)
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < lo + n:
        res += _term(a, i, mean, squared)
        i += 1
    return res


@njit(cache=True)
def _pairwise(a, lo, n, mean, squared):
    """The pairwise sum of the terms ``lo .. lo + n - 1`` (:func:`_term`)."""
    if n <= 128:
        return _block_sum(a, lo, n, mean, squared)
    runs_lo = np.empty(128, dtype=np.int64)
    runs_n = np.empty(128, dtype=np.int64)
    sums = np.empty(128)
    done = np.empty(128, dtype=np.int64)            # sums of a run's halves found so far
    runs_lo[0], runs_n[0], done[0] = lo, n, 0
    top = 0                                         # the run being split is runs_*[top]
    while True:
        r_lo, r_n = runs_lo[top], runs_n[top]
        if done[top] == 2:
            s = sums[2 * top] + sums[2 * top + 1]
            if top == 0:
                return s
            top -= 1
            sums[2 * top + done[top]] = s
            done[top] += 1
            continue
        n2 = r_n // 2
        n2 -= n2 % 8
        c_lo, c_n = (r_lo, n2) if done[top] == 0 else (r_lo + n2, r_n - n2)
        if c_n <= 128:
            sums[2 * top + done[top]] = _block_sum(a, c_lo, c_n, mean, squared)
            done[top] += 1
        else:
            top += 1
            runs_lo[top], runs_n[top], done[top] = c_lo, c_n, 0


@njit(cache=True)
def pairwise_sum(a, lo, n):
    """The sum of ``a[lo:lo + n]`` in the order of NumPy's pairwise summation (``np.add.reduce``
    of a contiguous float64 array, whose initial value 0 adds nothing): a run of more than 128
    values is the sum of its halves, the first ``n // 2`` rounded down to a multiple of 8.  The
    halves are walked with a stack of runs, not by recursion (a cached compiled function must
    not call itself)."""
    return _pairwise(a, lo, n, 0.0, False)


@njit(cache=True)
def std(x):
    """``numpy.std(x)`` of a 1-D float64 array with at least one value, bit for bit: the
    squared deviations are summed as they are computed, in NumPy's order."""
    n = x.shape[0]
    mean = _pairwise(x, 0, n, 0.0, False) / n
    return math.sqrt(_pairwise(x, 0, n, mean, True) / n)
