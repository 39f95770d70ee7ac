"""NumPy's seed sequences with their hashing compiled: the same words in a fraction of the time.

A :class:`numpy.random.SeedSequence` hashes its entropy and spawn key into a pool of 32-bit
words when it is made, and hashes the pool again for every state it generates; both run
element by element in NumPy's own code, about 5 us each.  The env and the population
sweeps spawn a child per episode or reader and take its first state word as the key of
:mod:`ebraille_sim.scenarios.draws`, so :class:`SeedNode` computes the same pool and
the same words (NumPy's documented algorithm, ``SeedSequence.mix_entropy`` and
``generate_state``) in one compiled call each, and only when asked.  A node is a
``SeedSequence`` for every purpose of NumPy's generators (``numpy.random.default_rng(node)``,
``PCG64(node)``, ``Generator.spawn``): it has the same ``entropy``, ``spawn_key``,
``pool_size``, ``n_children_spawned``, ``pool``, :meth:`~SeedNode.generate_state` and
:meth:`~SeedNode.spawn`, and the generators made from it draw the same numbers
(``tests/test_seeds.py`` compares them with NumPy's over many entropies and keys).

What it buys (``python benchmarks/bench_replicas.py``, NumPy's ``SeedSequence`` in its place in
the same run, 2-core machine at a load average of about 7): an episode's key (a child spawned
and its first word) 2.8 us against 8.4 us, about one env step of a reset; a seed of three
children and their generators 8.8 us against 34 us.  Since an episode's numbers come from one
compiled call on one key, the whole reset's difference (685 us with nodes, 673 us with NumPy's
sequences) is within the reset figure's noise.

Examples
--------
>>> import numpy as np
>>> a = SeedNode(7).spawn(2)[1]
>>> b = np.random.SeedSequence(7).spawn(2)[1]
>>> a.generate_state(4).tolist() == b.generate_state(4).tolist()
True
>>> float(np.random.default_rng(a).random()) == float(np.random.default_rng(b).random())
True
"""
from __future__ import annotations

import numpy as np
from numpy.random.bit_generator import ISpawnableSeedSequence

from ebraille_sim.base.compiled import entry_point, njit

__all__ = ["SeedNode", "child_seed", "default_rng"]

_INIT_A = 0x43b0d7e5
_MULT_A = 0x931e8875
_INIT_B = 0x8b51f9dd
_MULT_B = 0x58f38ded
_MIX_MULT_L = 0xca01f9dd
_MIX_MULT_R = 0x4973f715
_M32 = 0xFFFFFFFF


@njit(cache=True)
def _pool_of(entropy, pool_size):
    """The pool of a seed sequence from its assembled entropy words (``mix_entropy``)."""
    mixer = np.zeros(pool_size, dtype=np.uint64)
    h = np.uint64(_INIT_A)
    n = entropy.shape[0]
    m32 = np.uint64(_M32)
    for i in range(pool_size):
        v = np.uint64(entropy[i]) if i < n else np.uint64(0)
        v = (v ^ h) & m32
        h = (h * np.uint64(_MULT_A)) & m32
        v = (v * h) & m32
        mixer[i] = v ^ (v >> np.uint64(16))
    for i_src in range(pool_size):
        for i_dst in range(pool_size):
            if i_src != i_dst:
                v = (mixer[i_src] ^ h) & m32
                h = (h * np.uint64(_MULT_A)) & m32
                v = (v * h) & m32
                v = v ^ (v >> np.uint64(16))
                r = (np.uint64(_MIX_MULT_L) * mixer[i_dst] - np.uint64(_MIX_MULT_R) * v) & m32
                mixer[i_dst] = r ^ (r >> np.uint64(16))
    for i_src in range(pool_size, n):
        for i_dst in range(pool_size):
            v = (np.uint64(entropy[i_src]) ^ h) & m32
            h = (h * np.uint64(_MULT_A)) & m32
            v = (v * h) & m32
            v = v ^ (v >> np.uint64(16))
            r = (np.uint64(_MIX_MULT_L) * mixer[i_dst] - np.uint64(_MIX_MULT_R) * v) & m32
            mixer[i_dst] = r ^ (r >> np.uint64(16))
    return mixer.astype(np.uint32)


@njit(cache=True)
def _state_of(pool, n_words):
    """``n_words`` 32-bit words generated from ``pool`` (``generate_state``)."""
    out = np.empty(n_words, dtype=np.uint32)
    h = np.uint64(_INIT_B)
    m32 = np.uint64(_M32)
    n = pool.shape[0]
    for i in range(n_words):
        v = (np.uint64(pool[i % n]) ^ h) & m32
        h = (h * np.uint64(_MULT_B)) & m32
        v = (v * h) & m32
        out[i] = v ^ (v >> np.uint64(16))
    return out


@njit(cache=True)
def _state64_of(pool, n_words):
    """``n_words`` 64-bit words generated from ``pool``: pairs of :func:`_state_of`'s words, the
    first the low half (NumPy's little-endian view)."""
    w = _state_of(pool, 2 * n_words)
    out = np.empty(n_words, dtype=np.uint64)
    for i in range(n_words):
        out[i] = np.uint64(w[2 * i]) | (np.uint64(w[2 * i + 1]) << np.uint64(32))
    return out


@njit(cache=True)
def _state_into(entropy, pool, out):
    """With ``entropy`` words, hash them into ``pool`` (its length the pool size; an empty
    ``entropy``: ``pool`` is already hashed); then :func:`_state64_of` of the pool into ``out``
    (none for an empty ``out``).  One compiled call for a new seed's generator state."""
    if entropy.shape[0] > 0:
        pool[:] = _pool_of(entropy, pool.shape[0])
    if out.shape[0] > 0:
        out[:] = _state64_of(pool, out.shape[0])


@njit(cache=True)
def _child_state_into(prefix, index, pool, out):
    """:func:`_state_into` of the entropy words ``prefix`` followed by the word ``index``: the
    words of a spawned child, whose prefix (its parent's padded entropy and key) its siblings share."""
    entropy = np.empty(prefix.shape[0] + 1, dtype=np.uint64)
    entropy[:-1] = prefix
    entropy[-1] = np.uint64(index)
    _state_into(entropy, pool, out)


_NO_WORDS = np.zeros(0, dtype=np.uint64)
_ENTRY: list = []
_CHILD_ENTRY: list = []


def _hash_into(entropy, pool, out) -> None:
    """:func:`_state_into` through its machine code for these argument types (compiled or
    loaded at the first call; no dispatch on each call)."""
    if not _ENTRY:
        _ENTRY.append(entry_point(_state_into, _NO_WORDS, np.zeros(4, dtype=np.uint32), _NO_WORDS))
    _ENTRY[0](entropy, pool, out)


def _child_hash_into(prefix, index: int, pool, out) -> None:
    """:func:`_child_state_into` through its machine code (as :func:`_hash_into`)."""
    if not _CHILD_ENTRY:
        _CHILD_ENTRY.append(entry_point(_child_state_into, _NO_WORDS, 0, np.zeros(4, dtype=np.uint32), _NO_WORDS))
    _CHILD_ENTRY[0](prefix, index, pool, out)


def _words(n: int, out: list) -> None:
    """Append the little-endian 32-bit words of the non-negative int ``n`` (one word for 0)."""
    if n == 0:
        out.append(0)
    while n > 0:
        out.append(n & _M32)
        n >>= 32


class SeedNode(ISpawnableSeedSequence):
    """A seed sequence of integer ``entropy`` and ``spawn_key``, hashed by compiled code.

    Same arguments and attributes as :class:`numpy.random.SeedSequence` (entropy a
    non-negative int, spawn key a tuple of non-negative ints); the pool is computed when
    first needed.
    """

    __slots__ = ("entropy", "spawn_key", "pool_size", "n_children_spawned", "_pool", "_padded", "_prefix")

    def __init__(self, entropy: int, *, spawn_key: tuple = (), pool_size: int = 4, n_children_spawned: int = 0):
        if type(entropy) is not int:
            entropy = int(entropy)
        if entropy < 0 or any(k < 0 for k in spawn_key) or pool_size < 4:
            raise ValueError(f"SeedNode needs non-negative integers and a pool of at least 4 words, got "
                             f"entropy={entropy!r}, spawn_key={spawn_key!r}, pool_size={pool_size!r}")
        self.entropy = entropy
        self.spawn_key = tuple(spawn_key)
        self.pool_size = pool_size
        self.n_children_spawned = n_children_spawned
        self._pool = None
        self._padded = None
        self._prefix = None

    @classmethod
    def of(cls, seed_sequence) -> SeedNode:
        """A node with the entropy, key and spawn count of ``seed_sequence`` (a NumPy one or a node)."""
        return cls(seed_sequence.entropy, spawn_key=seed_sequence.spawn_key, pool_size=seed_sequence.pool_size,
                   n_children_spawned=seed_sequence.n_children_spawned)

    def _assembled(self) -> np.ndarray:
        """The entropy words and then the spawn key's, the entropy padded to the pool size
        when there is a key (``SeedSequence.get_assembled_entropy``)."""
        key = self.spawn_key
        if not key:
            words: list = []
            _words(self.entropy, words)
            return np.array(words, dtype=np.uint64)
        padded = self._padded
        if padded is None:
            padded = []
            _words(self.entropy, padded)
            padded.extend([0] * (self.pool_size - len(padded)))
            self._padded = padded
        if max(key) <= _M32:                           # one word each
            return np.array(padded + list(key), dtype=np.uint64)
        words = list(padded)
        for k in key:
            _words(k, words)
        return np.array(words, dtype=np.uint64)

    @property
    def pool(self) -> np.ndarray:
        """The hashed entropy, uint32 (``SeedSequence.pool``)."""
        if self._pool is None:
            self._pool = np.empty(self.pool_size, dtype=np.uint32)
            _hash_into(self._assembled(), self._pool, _NO_WORDS)
        return self._pool

    def generate_state(self, n_words: int, dtype=np.uint32) -> np.ndarray:
        """``n_words`` words of ``dtype`` (uint32 or uint64), as ``SeedSequence.generate_state``."""
        if dtype is np.uint64 or np.dtype(dtype) == np.uint64:
            out = np.empty(n_words, dtype=np.uint64)
            if self._pool is None:                      # the pool and the state in one call
                self._pool = np.empty(self.pool_size, dtype=np.uint32)
                if self._prefix is not None:            # a spawned child: its parent's words and its index
                    _child_hash_into(self._prefix, self.spawn_key[-1], self._pool, out)
                else:
                    _hash_into(self._assembled(), self._pool, out)
            else:
                _hash_into(_NO_WORDS, self._pool, out)
            return out
        if np.dtype(dtype) == np.uint32:
            return _state_of(self.pool, n_words)
        raise ValueError("only uint32 and uint64 are supported")

    def spawn(self, n_children: int) -> list[SeedNode]:
        """The next ``n_children`` children (spawn keys extended by their index), as ``SeedSequence.spawn``."""
        k0 = self.n_children_spawned
        if self._padded is None:
            self._padded = []
            _words(self.entropy, self._padded)
            self._padded.extend([0] * (self.pool_size - len(self._padded)))
        # the children's entropy words are these and then their index, when every key word is one
        # word: made once for all of them, shared (only the compiled hash reads it)
        prefix = None
        if max(self.spawn_key + (k0 + n_children,)) <= _M32:
            prefix = np.array(self._padded + list(self.spawn_key), dtype=np.uint64)
        out = []
        for i in range(k0, k0 + n_children):
            child = object.__new__(SeedNode)            # the parent's checked values, a new index
            child.entropy = self.entropy
            child.spawn_key = self.spawn_key + (i,)
            child.pool_size = self.pool_size
            child.n_children_spawned = 0
            child._pool = None
            child._padded = self._padded                 # the same entropy words, shared read-only
            child._prefix = prefix
            out.append(child)
        self.n_children_spawned = k0 + n_children
        return out

    def seed_sequence(self) -> np.random.SeedSequence:
        """The NumPy ``SeedSequence`` of the same entropy, key and spawn count."""
        return np.random.SeedSequence(self.entropy, spawn_key=self.spawn_key, pool_size=self.pool_size,
                                      n_children_spawned=self.n_children_spawned)

    def __repr__(self) -> str:
        return f"SeedNode(entropy={self.entropy}, spawn_key={self.spawn_key})"


def child_seed(parent, k: int):
    """Child ``k`` of the seed sequence ``parent`` (its spawn key extended by ``k``), leaving
    ``parent``'s spawn count as it was: a :class:`SeedNode` where the entropy and key are
    integers, else NumPy's ``SeedSequence``."""
    if type(parent.entropy) is int and all(type(i) is int for i in parent.spawn_key):
        return SeedNode(parent.entropy, spawn_key=parent.spawn_key + (k,), pool_size=parent.pool_size)
    return np.random.SeedSequence(parent.entropy, spawn_key=parent.spawn_key + (k,), pool_size=parent.pool_size)


def default_rng(seed: int) -> np.random.Generator:
    """``numpy.random.default_rng(seed)`` of a non-negative int ``seed``: the same PCG64 generator
    (the same numbers), its seed sequence a :class:`SeedNode` (2 us against NumPy's 5.5 us)."""
    return np.random.Generator(np.random.PCG64(SeedNode(seed)))
