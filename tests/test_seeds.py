"""The compiled seed sequences give NumPy's words, generators and spawn order."""
import random

import numpy as np
import pytest

from ebraille_sim.base.seeds import SeedNode, child_seed, default_rng


def _cases(n=600):
    rnd = random.Random(5)
    for _ in range(n):
        e = rnd.choice([0, 1, rnd.getrandbits(31), rnd.getrandbits(63), rnd.getrandbits(64), rnd.getrandbits(128),
                        rnd.getrandbits(200)])
        key = tuple(rnd.choice([0, rnd.randrange(10), rnd.getrandbits(40)]) for _ in range(rnd.randrange(5)))
        yield e, key, rnd.choice([4, 5, 8]), rnd.randrange(1, 9)


def test_pool_and_states_equal_numpy_seed_sequences():
    for e, key, pool_size, n in _cases():
        a = np.random.SeedSequence(e, spawn_key=key, pool_size=pool_size)
        b = SeedNode(e, spawn_key=key, pool_size=pool_size)
        assert b.pool.tolist() == a.pool.tolist()
        assert b.generate_state(n).tolist() == a.generate_state(n).tolist()
        s64 = b.generate_state(n, np.uint64)
        assert s64.dtype == np.uint64 and s64.tolist() == a.generate_state(n, np.uint64).tolist()


def test_children_and_generators_equal_numpy_ones():
    for e, key, pool_size, _ in _cases(200):
        a = np.random.SeedSequence(e, spawn_key=key, pool_size=pool_size)
        b = SeedNode(e, spawn_key=key, pool_size=pool_size)
        for _ in range(2):
            ca, cb = a.spawn(3), b.spawn(3)
            assert [c.spawn_key for c in cb] == [c.spawn_key for c in ca]
            assert b.n_children_spawned == a.n_children_spawned
            ga, gb = np.random.default_rng(ca[2]), np.random.default_rng(cb[2])
            assert gb.bit_generator.state == ga.bit_generator.state
            assert gb.standard_normal(4).tolist() == ga.standard_normal(4).tolist()
            assert gb.spawn(1)[0].random() == ga.spawn(1)[0].random()


def test_default_rng_of_an_int_is_numpys():
    rnd = random.Random(11)
    for seed in [0, 1, 2**31 - 1, 2**31, 2**63 - 1] + [rnd.getrandbits(31) for _ in range(100)]:
        ours, numpys = default_rng(seed), np.random.default_rng(seed)
        assert ours.bit_generator.state == numpys.bit_generator.state
        assert ours.standard_normal((3, 2)).tolist() == numpys.standard_normal((3, 2)).tolist()
        assert ours.random() == numpys.random()


def test_child_seed_leaves_the_parent_unspawned_and_falls_back_for_other_entropy():
    parent = np.random.SeedSequence(77, spawn_key=(2,))
    c = child_seed(parent, 4)
    assert isinstance(c, SeedNode) and parent.n_children_spawned == 0
    assert c.generate_state(4).tolist() == parent.spawn(5)[4].generate_state(4).tolist()
    listed = np.random.SeedSequence([1, 2, 3])
    c = child_seed(listed, 1)
    assert isinstance(c, np.random.SeedSequence)
    assert c.generate_state(2).tolist() == listed.spawn(2)[1].generate_state(2).tolist()
    assert SeedNode.of(parent).seed_sequence().pool.tolist() == parent.pool.tolist()


@pytest.mark.parametrize("args", [(-1, ()), (1, (-2,)), (3, (), 2)])
def test_bad_seed_nodes_are_one_line_errors(args):
    e, key, *pool = args
    with pytest.raises(ValueError, match="SeedNode needs"):
        SeedNode(e, spawn_key=key, pool_size=pool[0] if pool else 4)


def test_spawned_children_hash_their_parents_words_and_index_as_numpy_does():
    for e, key, pool_size, n in _cases(300):
        a = np.random.SeedSequence(e, spawn_key=key, pool_size=pool_size)
        b = SeedNode(e, spawn_key=key, pool_size=pool_size)
        a.spawn(2), b.spawn(2)
        for ca, cb in zip(a.spawn(3), b.spawn(3)):
            assert (cb._prefix is not None) == (max(key + (5,)) <= 0xFFFFFFFF)
            assert cb.generate_state(n, np.uint64).tolist() == ca.generate_state(n, np.uint64).tolist()
            assert cb.pool.tolist() == ca.pool.tolist()
            assert cb.generate_state(n).tolist() == ca.generate_state(n).tolist()
    big = SeedNode(9, spawn_key=(2**40,)).spawn(2)              # a key word of two words: no shared prefix
    ref = np.random.SeedSequence(9, spawn_key=(2**40,)).spawn(2)
    assert all(c._prefix is None for c in big)
    assert [c.generate_state(4, np.uint64).tolist() for c in big] == [c.generate_state(4, np.uint64).tolist() for c in ref]
