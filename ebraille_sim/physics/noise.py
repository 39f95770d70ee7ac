"""Counter-based Gaussian noise: the same (seed, index) always gives the same number.

Sensor noise is drawn inside the compiled loop without any hidden generator state: the
``k``-th sample of a device with seed ``s`` is a pure function of ``(s, k)`` (SplitMix64
hashing, Steele et al. 2014, then Box-Muller).  A batch of devices therefore produces
exactly the same noise as the same devices run one by one, in any order.
"""
from __future__ import annotations

import math

import numpy as np
from ebraille_sim.base.compiled import njit

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_INV53 = 1.0 / 9007199254740992.0

STATE_SLOTS = ("sensor_count",)
"""State slot of the sample counter that indexes the noise sequence."""

OWNED_STATE_SLOTS = STATE_SLOTS
"""Every state slot this module declares (see :mod:`ebraille_sim.plant.layout`)."""


@njit(cache=True, inline="always")
def splitmix64(x):
    z = x + _GOLDEN
    z = (z ^ (z >> np.uint64(30))) * _M1
    z = (z ^ (z >> np.uint64(27))) * _M2
    return z ^ (z >> np.uint64(31))


@njit(cache=True)
def normal_at(seed, index):
    """Standard normal number for integer-valued floats ``seed`` and ``index``."""
    key = splitmix64(np.uint64(seed)) ^ (np.uint64(index) * _GOLDEN)
    z1 = splitmix64(key)
    z2 = splitmix64(z1)
    u1 = (float(z1 >> np.uint64(11)) + 1.0) * _INV53
    u2 = float(z2 >> np.uint64(11)) * _INV53
    return math.sqrt(-2.0 * math.log(u1)) * math.cos(2.0 * math.pi * u2)


@njit(cache=True, inline="always")
def noise_v(rms_v, seed, index):
    """Gaussian noise sample ``index`` of a device with ``seed``, scaled to ``rms_v`` (V)."""
    return rms_v * normal_at(seed, index)


def seed_from(seed_sequence: np.random.SeedSequence) -> float:
    """A 52-bit seed (exact in float64) from a NumPy ``SeedSequence``."""
    return float(int(seed_sequence.generate_state(1, dtype=np.uint64)[0]) >> 12)
