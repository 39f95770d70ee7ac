"""The random numbers of a drawn device, a drawn episode and a run's inputs, in compiled calls.

A seed (any NumPy ``SeedSequence`` or :class:`~ebraille_sim.base.seeds.SeedNode`) gives one
64-bit key, its first state word (:func:`key_of`); every random number drawn from it is a
fixed function of ``(key, stream, index)`` (SplitMix64 hashing, the counter-based scheme of
the sensor noise, :mod:`ebraille_sim.physics.noise`): no generator is made and no draw
depends on how many came before it in another stream.  One call of :func:`draw_numbers`
draws all of them:

==========  ======================================================  ===================
stream      numbers                                                 used by
==========  ======================================================  ===================
reader      3 uniforms: pulp b, m, relaxation c0                    the device draw
FSR unit    1 standard normal (k), 3 uniforms (n, hysteresis,       the device draw
            creep)
motor       2 standard normals (R, kM)                              the device draw
drive       3 uniforms: gear efficiency, guide friction, backlash   the device draw
board       7 uniforms: shunt, gain, offset, calibration load,      the device draw
            the calibration table's three other loads
episode     the run seed (52 bits), then the episode's uniforms     the episode draw
==========  ======================================================  ===================

:func:`~ebraille_sim.scenarios.population.sample_device` (a population sweep's reader) and
:meth:`~ebraille_sim.scenarios.episodes.EpisodeDistribution.draw` (an env episode, and a
scenario run of its spec) both draw through :func:`device_numbers` and
:func:`episode_numbers`: the reader of a seed is the same device in a sweep and in an episode
of that seed.  Uniforms lie in [0, 1) (53 bits); a standard normal is Box-Muller of two
uniforms of its stream.

A run's seed (the spec's ``seed``, an integer) gives its key the same way (:func:`run_numbers`,
one compiled call): the sensor noise's seed (stream ``sensor``) and the states of the two NumPy
generators (PCG64) that draw the reading's dwell jitter (stream ``reading``) and the
disturbances (stream ``inputs``; each disturbance kind draws from a child generator seeded
with a hash of that generator's seed and the kind's index, :func:`child_generator`).
:func:`ebraille_sim.scenarios.inputs.build_run_inputs` makes them for the scenario runner and
the env alike.

Examples
--------
>>> from ebraille_sim.base.seeds import SeedNode
>>> u, z = device_numbers(SeedNode(7))
>>> len(u), len(z), all(0.0 <= x < 1.0 for x in u)
(16, 3, True)
>>> device_numbers(SeedNode(7)) == (u, z)
True
"""
from __future__ import annotations

import math

import numpy as np
from numpy.random.bit_generator import ISpawnableSeedSequence

from ebraille_sim.base.compiled import njit
from ebraille_sim.physics.noise import splitmix64

__all__ = ["BOARD_NUMBERS", "DEVICE_NUMBERS", "DEVICE_UNIFORM_NUMBERS", "RUN_STREAMS", "STREAMS", "StreamSeed", "child_generator", "device_numbers",
           "draw_numbers", "episode_numbers", "generator_of", "key_of", "run_numbers"]

STREAMS = ("reader", "fsr", "motor", "drive", "board", "episode")
"""The streams of a seed's key, in the order of their numbers (module table)."""
(_READER, _FSR, _MOTOR, _DRIVE, _BOARD, _EPISODE) = range(len(STREAMS))
RUN_STREAMS = ("sensor", "reading", "inputs")
"""The streams of a run seed's key (module docstring)."""
_SENSOR, _READING, _INPUTS = range(len(STREAMS), len(STREAMS) + len(RUN_STREAMS))
_RUN_KEY = np.uint64(0x5851F42D4C957F2D)

BOARD_NUMBERS = 7
"""Uniforms of the board stream (the length of
:data:`~ebraille_sim.scenarios.population.BOARD_UNIFORMS`)."""
DEVICE_UNIFORM_NUMBERS = 9 + BOARD_NUMBERS
"""Uniforms of a device: reader 3, FSR unit 3, drive train 3, board :data:`BOARD_NUMBERS`."""
DEVICE_NUMBERS = DEVICE_UNIFORM_NUMBERS + 3
"""Numbers of a device at the start of :func:`draw_numbers`' output: its 16 uniforms (reader,
FSR unit, drive train, board, in the order of
:data:`~ebraille_sim.scenarios.population.DEVICE_UNIFORMS` and
:data:`~ebraille_sim.scenarios.population.BOARD_UNIFORMS`), then its 3 normals (FSR k,
motor R, motor kM)."""

_STREAM_MULT = np.uint64(0x94D049BB133111EB)
_INDEX_MULT = np.uint64(0x9E3779B97F4A7C15)
_INV53 = 1.0 / 9007199254740992.0


@njit(cache=True, inline="always")
def _word(key, stream, index):
    """The 64-bit word ``index`` of ``stream`` of ``key``."""
    base = splitmix64(key ^ (np.uint64(stream + 1) * _STREAM_MULT))
    return splitmix64(base + np.uint64(index) * _INDEX_MULT)


@njit(cache=True, inline="always")
def _uniform(key, stream, index):
    """Uniform on [0, 1): the top 53 bits of word ``index``."""
    return float(_word(key, stream, index) >> np.uint64(11)) * _INV53


@njit(cache=True, inline="always")
def _normal(key, stream, index):
    """Standard normal from words ``index`` and ``index + 1`` (Box-Muller)."""
    u1 = (float(_word(key, stream, index) >> np.uint64(11)) + 1.0) * _INV53       # (0, 1]
    u2 = float(_word(key, stream, index + 1) >> np.uint64(11)) * _INV53
    return math.sqrt(-2.0 * math.log(u1)) * math.cos(2.0 * math.pi * u2)


@njit(cache=True)
def draw_numbers(key, n_episode_uniforms, out):
    """Every number of the key ``key[0]`` (a uint64 array, :func:`key_of`) into ``out``
    (float64, length ``DEVICE_NUMBERS + 1 + n_episode_uniforms``): the device's 16 uniforms and
    3 normals (:data:`DEVICE_NUMBERS`), the run seed (an integer below 2**52, exact as a
    float), the episode's uniforms."""
    k = key[0]
    for i in range(3):                                      # reader: pulp b, m, c0
        out[i] = _uniform(k, _READER, i)
    for i in range(3):                                      # FSR unit: n, hysteresis, creep (after k's normal)
        out[3 + i] = _uniform(k, _FSR, 2 + i)
    for i in range(3):                                      # drive train: efficiency, guide friction, backlash
        out[6 + i] = _uniform(k, _DRIVE, i)
    for i in range(BOARD_NUMBERS):                          # board: shunt, gain, offset, calibration loads
        out[9 + i] = _uniform(k, _BOARD, i)
    n = DEVICE_UNIFORM_NUMBERS
    out[n] = _normal(k, _FSR, 0)                            # FSR k
    out[n + 1] = _normal(k, _MOTOR, 0)                      # motor R
    out[n + 2] = _normal(k, _MOTOR, 2)                      # motor kM
    out[DEVICE_NUMBERS] = float(_word(k, _EPISODE, 0) >> np.uint64(12))
    for i in range(n_episode_uniforms):
        out[DEVICE_NUMBERS + 1 + i] = _uniform(k, _EPISODE, 1 + i)


def key_of(seed_sequence) -> np.ndarray:
    """The 64-bit key of a seed sequence: its first state word (``generate_state(1, uint64)``,
    an array of one uint64)."""
    return seed_sequence.generate_state(1, np.uint64)


def episode_numbers(seed_sequence, n_episode_uniforms: int) -> tuple[list, list, int, list]:
    """``(u, z, run_seed, v)`` of a seed in one compiled call: the device's uniforms ``u`` and
    normals ``z`` (:func:`device_numbers`), the run seed and ``n_episode_uniforms`` uniforms ``v``."""
    out = np.empty(DEVICE_NUMBERS + 1 + n_episode_uniforms)
    draw_numbers(key_of(seed_sequence), n_episode_uniforms, out)
    x = out.tolist()
    n = DEVICE_UNIFORM_NUMBERS
    return x[:n], x[n:DEVICE_NUMBERS], int(x[DEVICE_NUMBERS]), x[DEVICE_NUMBERS + 1:]


def device_numbers(seed_sequence) -> tuple[list, list]:
    """The uniforms on [0, 1) and standard normals of the device of a seed (the lists
    :func:`~ebraille_sim.scenarios.population.device_from_variates` takes)."""
    u, z, _, _ = episode_numbers(seed_sequence, 0)
    return u, z


@njit(cache=True)
def _run_words(seed, out):
    """The run seed's words into ``out`` (uint64, 9): the sensor seed's word, then four words of
    the reading generator's state and four of the inputs generator's."""
    k = splitmix64(np.uint64(seed) ^ _RUN_KEY)
    out[0] = _word(k, _SENSOR, 0) >> np.uint64(12)
    for i in range(4):
        out[1 + i] = _word(k, _READING, i)
        out[5 + i] = _word(k, _INPUTS, i)


@njit(cache=True)
def _child_words(parent, k, out):
    """Four words of child ``k`` of a generator whose state and increment are the words ``parent``."""
    key = splitmix64(parent[0] ^ splitmix64(parent[1] ^ splitmix64(parent[2] ^ splitmix64(parent[3]))))
    for i in range(4):
        out[i] = _word(key, k, i)


class StreamSeed(ISpawnableSeedSequence):
    """A seed sequence whose state is four given 64-bit words: what a NumPy bit generator made
    from it (:func:`generator_of`) is seeded with, without hashing; its children
    (:meth:`spawn`) are hashes of the words and their index (:func:`_child_words`)."""

    __slots__ = ("words", "n_children_spawned")

    def __init__(self, words):
        self.words = np.ascontiguousarray(words, dtype=np.uint64)
        self.n_children_spawned = 0

    def generate_state(self, n_words: int, dtype=np.uint32) -> np.ndarray:
        """The first ``n_words`` words of ``dtype`` (uint64: the words; uint32: their halves)."""
        w = self.words if np.dtype(dtype) == np.uint64 else self.words.view(np.uint32)
        if n_words > w.size:
            raise ValueError(f"a StreamSeed holds {w.size} words of {np.dtype(dtype).name}, {n_words} asked")
        return w[:n_words].copy()

    def child(self, k: int) -> StreamSeed:
        """Child ``k`` (independent of how many were spawned)."""
        out = np.empty(4, dtype=np.uint64)
        _child_words(self.words, k, out)
        return StreamSeed(out)

    def spawn(self, n_children: int) -> list:
        k0 = self.n_children_spawned
        self.n_children_spawned = k0 + n_children
        return [self.child(k) for k in range(k0, k0 + n_children)]


def generator_of(words) -> np.random.Generator:
    """A NumPy ``Generator`` (PCG64) seeded with the four 64-bit ``words`` (a :class:`StreamSeed`)."""
    return np.random.Generator(np.random.PCG64(StreamSeed(words)))


def run_numbers(seed: int) -> tuple[float, np.ndarray, np.ndarray]:
    """``(sensor_seed, reading_words, inputs_words)`` of a run seed in one compiled call: the
    sensor noise's seed (an integer below 2**52 as a float) and the words of the reading's and
    the inputs' generators (:func:`generator_of`)."""
    out = np.empty(9, dtype=np.uint64)
    _run_words(np.uint64(seed), out)
    return float(out[0]), out[1:5], out[5:9]


def child_generator(rng: np.random.Generator, k: int) -> np.random.Generator:
    """Child ``k`` of the generator ``rng``: a generator of the same bit generator seeded with
    child ``k`` of ``rng``'s seed (:meth:`StreamSeed.child`, or a NumPy seed sequence's child,
    its spawn key extended by ``k``), whatever ``rng`` has drawn; ``rng`` is left as it was."""
    bits = rng.bit_generator
    parent = bits.seed_seq
    if type(parent) is StreamSeed:
        return type(rng)(type(bits)(parent.child(k)))
    from ebraille_sim.base.seeds import child_seed
    return type(rng)(type(bits)(seed=child_seed(parent, parent.n_children_spawned + k)))
