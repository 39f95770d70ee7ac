"""The compiled home of the random numbers of devices, episodes and runs (scenarios/draws.py)."""
from __future__ import annotations

import numpy as np
from scipy import stats

from ebraille_sim.base.seeds import SeedNode
from ebraille_sim.scenarios.draws import (DEVICE_NUMBERS, StreamSeed, child_generator, device_numbers, episode_numbers,
                                          generator_of, run_numbers)


def test_a_seed_node_and_numpys_seed_sequence_give_the_same_numbers():
    for entropy, key in [(7, ()), (2**70 + 3, (1, 2)), (0, (5,))]:
        a = episode_numbers(SeedNode(entropy, spawn_key=key), 9)
        b = episode_numbers(np.random.SeedSequence(entropy, spawn_key=key), 9)
        assert a == b


def test_the_device_of_a_seed_is_the_device_part_of_its_episode_and_streams_do_not_shift():
    ss = SeedNode(11)
    u, z = device_numbers(ss)
    u2, z2, run_seed, v = episode_numbers(ss, 25)
    assert (u, z) == (u2, z2) and len(u) + len(z) == DEVICE_NUMBERS
    _, _, run_seed_short, v_short = episode_numbers(ss, 3)
    assert run_seed_short == run_seed and v_short == v[:3]       # more uniforms shift no earlier number
    assert 0 <= run_seed < 2**52 and float(run_seed) == run_seed


def test_uniforms_and_normals_have_their_distributions():
    rows = [episode_numbers(c, 4) for c in SeedNode(2024).spawn(3000)]
    u = np.array([r[0] for r in rows])                          # (3000, 13)
    z = np.array([r[1] for r in rows])                          # (3000, 3)
    v = np.array([r[3] for r in rows])
    for col in np.hstack([u, v]).T:
        assert 0.0 <= col.min() and col.max() < 1.0
        assert stats.kstest(col, "uniform").pvalue > 1e-4
    for col in z.T:
        assert stats.kstest(col, "norm").pvalue > 1e-4
    corr = np.corrcoef(np.hstack([u, z, v]).T)
    assert np.max(np.abs(corr - np.eye(corr.shape[0]))) < 0.1    # no two streams or indices alike


def test_run_streams_are_fixed_functions_of_the_seed_and_differ_between_streams():
    s1, r1, i1 = run_numbers(1)
    s2, r2, i2 = run_numbers(1)
    assert s1 == s2 and r1.tolist() == r2.tolist() and i1.tolist() == i2.tolist()
    assert 0 <= s1 < 2**52 and r1.tolist() != i1.tolist() and run_numbers(2)[0] != s1
    a, b = generator_of(i1), generator_of(i1)
    assert a.random(5).tolist() == b.random(5).tolist()


def test_children_are_independent_of_each_other_and_of_the_parents_draws_and_leave_it_as_it_was():
    g = generator_of(run_numbers(5)[2])
    state = g.bit_generator.state
    c0, c1 = child_generator(g, 0), child_generator(g, 1)
    assert g.bit_generator.state == state
    x0, x1 = c0.standard_normal(4000), c1.standard_normal(4000)
    g.random(7)                                                  # whatever the parent has drawn
    assert child_generator(g, 0).standard_normal(4000).tolist() == x0.tolist()
    assert abs(np.corrcoef(x0, x1)[0, 1]) < 0.06
    philox = child_generator(np.random.Generator(np.random.Philox(3)), 2)   # another bit generator: its seed's child
    want = np.random.Generator(np.random.Philox(np.random.SeedSequence(3, spawn_key=(2,))))
    assert philox.random(3).tolist() == want.random(3).tolist()


def test_a_stream_seed_gives_its_words_and_refuses_more():
    seed = StreamSeed(np.array([1, 2, 3, 2**64 - 1], dtype=np.uint64))
    assert seed.generate_state(2, np.uint64).tolist() == [1, 2]
    assert seed.generate_state(8, np.uint32).tolist()[-2:] == [2**32 - 1, 2**32 - 1]
    a, b = seed.spawn(2)
    assert a.words.tolist() == seed.child(0).words.tolist() and b.words.tolist() == seed.child(1).words.tolist()
    try:
        seed.generate_state(5, np.uint64)
    except ValueError as exc:
        assert "holds 4 words" in str(exc)
    else:
        raise AssertionError("five words of four were given")


def test_the_board_stream_draws_one_uniform_per_named_board_variate():
    from ebraille_sim.scenarios.draws import BOARD_NUMBERS, DEVICE_UNIFORM_NUMBERS
    from ebraille_sim.scenarios.population import BOARD_UNIFORMS, DEVICE_UNIFORMS
    assert BOARD_NUMBERS == len(BOARD_UNIFORMS)
    assert DEVICE_UNIFORM_NUMBERS == len(DEVICE_UNIFORMS) + len(BOARD_UNIFORMS)
