"""Shared timing helper of the benchmark scripts."""
from __future__ import annotations

import time


def best_of(fn, repeat: int):
    """Run ``fn`` ``repeat`` times; return (shortest wall time in s, last result)."""
    best, out = float("inf"), None
    for _ in range(max(1, repeat)):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out
