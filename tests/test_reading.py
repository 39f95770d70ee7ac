"""Tests for ebraille_sim.scenarios.reading and the built-in passages."""

import math

import numpy as np
import pytest

from ebraille_sim.scenarios.braille import text_to_cells
from ebraille_sim.scenarios.passages import list_passages, load_passage
from ebraille_sim.scenarios.reading import (
    ReadingSchedule,
    build_schedule,
    mean_dwell_s,
    realised_wpm,
)


@pytest.mark.parametrize("wpm, dwell", [(60, 0.2), (120, 0.1), (90, 60 / 450), (12, 1.0)])
def test_mean_dwell_from_wpm(wpm, dwell):
    sched = build_schedule("hello world", wpm)
    assert len(sched) == 11
    assert sched.dwell_s.shape == (11,)
    np.testing.assert_allclose(sched.dwell_s, dwell, rtol=0, atol=1e-15)
    assert mean_dwell_s(wpm) == pytest.approx(dwell, rel=1e-15)
    assert sched.wpm == wpm


def test_dwell_exact_values_at_60_and_120_wpm():
    assert build_schedule("a", 60).dwell_s[0] == 0.2
    assert build_schedule("a", 120).dwell_s[0] == 0.1


def test_signs_count_as_cells():
    sched = build_schedule("A1", 60)
    assert len(sched) == 4
    assert sched.t_end_s == pytest.approx(0.8, abs=1e-12)


def test_start_times_and_end_time():
    sched = build_schedule("abcd", 60, start_s=2.0)
    np.testing.assert_allclose(sched.start_s, [2.0, 2.2, 2.4, 2.6], atol=1e-12)
    assert sched.t_end_s == pytest.approx(2.8, abs=1e-12)
    assert sched.t_start_s == 2.0
    np.testing.assert_array_equal(sched.boundaries_s(), sched.start_s)


def test_index_at_exact_boundaries():
    sched = build_schedule("abc", 12)
    t = np.array([-1e-9, 0.0, 0.999999, 1.0, 2.0, 2.999999, 3.0, 10.0])
    np.testing.assert_array_equal(sched.index_at(t), [-1, 0, 0, 1, 2, 2, -1, -1])
    assert sched.index_at(1.0) == 1
    assert isinstance(sched.index_at(1.0), int)


def test_index_at_own_boundaries_for_every_cell():
    sched = build_schedule("The 42 bus, again!", 60, jitter_fraction=0.3,
                           rng=np.random.default_rng(3), word_pause_s=0.25)
    b = sched.boundaries_s()
    np.testing.assert_array_equal(sched.index_at(b), np.arange(len(sched)))
    assert sched.index_at(sched.t_end_s) == -1
    assert sched.index_at(np.nextafter(sched.t_end_s, -np.inf)) == len(sched) - 1
    assert sched.index_at(np.nextafter(b[0], -np.inf)) == -1


def test_index_at_keeps_shape_and_handles_nan():
    sched = build_schedule("ab", 24)
    out = sched.index_at(np.array([[0.1, 0.6], [np.nan, 1.0]]))
    assert out.shape == (2, 2)
    np.testing.assert_array_equal(out, [[0, 1], [-1, -1]])


def test_sum_of_dwells_equals_reading_time():
    sched = build_schedule(load_passage("default"), 90, start_s=5.0,
                           jitter_fraction=0.2, rng=np.random.default_rng(1),
                           word_pause_s=0.05, line_pause_s=0.4)
    assert math.isclose(sched.dwell_s.sum(), sched.t_end_s - 5.0, rel_tol=1e-12)
    np.testing.assert_allclose(np.diff(sched.start_s), sched.dwell_s[:-1], rtol=1e-9)


def test_jitter_is_deterministic_for_same_seed():
    text = "Reading at 100 wpm."
    a = build_schedule(text, 100, jitter_fraction=0.2, rng=np.random.default_rng(42))
    b = build_schedule(text, 100, jitter_fraction=0.2, rng=np.random.default_rng(42))
    c = build_schedule(text, 100, jitter_fraction=0.2, rng=np.random.default_rng(43))
    np.testing.assert_array_equal(a.dwell_s, b.dwell_s)
    np.testing.assert_array_equal(a.start_s, b.start_s)
    assert not np.array_equal(a.dwell_s, c.dwell_s)


def test_jitter_matches_formula_and_clipping():
    text = "abcdefghij" * 20
    mean = 0.2
    sched = build_schedule(text, 60, jitter_fraction=0.5, rng=np.random.default_rng(7))
    z = np.random.default_rng(7).standard_normal(len(text))
    expected = np.clip(mean * (1 + 0.5 * z), 0.5 * mean, 1.5 * mean)
    np.testing.assert_allclose(sched.dwell_s, expected, rtol=1e-15)
    assert sched.dwell_s.min() == pytest.approx(0.1)
    assert sched.dwell_s.max() == pytest.approx(0.3)


def test_jitter_requires_rng():
    with pytest.raises(ValueError, match="rng"):
        build_schedule("abc", 60, jitter_fraction=0.1)
    with pytest.raises(ValueError, match="Generator"):
        build_schedule("abc", 60, jitter_fraction=0.1, rng=42)


def test_word_and_line_pauses():
    sched = build_schedule("a b\nc", 60, word_pause_s=0.3, line_pause_s=1.0)
    np.testing.assert_allclose(sched.dwell_s, [0.2, 0.5, 0.2, 1.2, 0.2], atol=1e-12)
    assert sched.t_end_s == pytest.approx(2.3, abs=1e-12)
    assert sched.index_at(0.65) == 1
    assert sched.index_at(0.75) == 2
    assert sched.index_at(2.05) == 3
    assert sched.index_at(2.15) == 4


def test_pauses_not_added_to_letters_or_signs():
    sched = build_schedule("A1,", 60, word_pause_s=0.5, line_pause_s=0.5)
    np.testing.assert_array_equal(sched.dwell_s, [0.2] * 5)


def test_cells_input_equivalent_to_text():
    text = "Go 2 it"
    a = build_schedule(text, 75)
    b = build_schedule(text_to_cells(text), 75)
    assert a.cells == b.cells
    np.testing.assert_array_equal(a.start_s, b.start_s)


def test_realised_wpm():
    assert realised_wpm(build_schedule("hello", 60)) == pytest.approx(60.0, rel=1e-12)
    assert realised_wpm(build_schedule("hello world", 120)) == pytest.approx(120.0, rel=1e-12)
    sched = build_schedule("a b", 60, word_pause_s=0.4)
    assert realised_wpm(sched) == pytest.approx(36.0, rel=1e-12)
    with pytest.raises(ValueError):
        realised_wpm(build_schedule("", 60))


def test_empty_schedule():
    sched = build_schedule("", 60, start_s=1.5)
    assert len(sched) == 0
    assert sched.t_end_s == 1.5
    assert sched.index_at(1.5) == -1
    assert sched.start_s.shape == (0,)


def test_arrays_are_read_only():
    sched = build_schedule("ab", 60)
    assert isinstance(sched, ReadingSchedule)
    with pytest.raises(ValueError):
        sched.dwell_s[0] = 1.0
    with pytest.raises(AttributeError):
        sched.wpm = 10


@pytest.mark.parametrize("wpm", [0, -3, float("nan"), float("inf"), 1000.5, "fast", True, None])
def test_invalid_wpm(wpm):
    with pytest.raises(ValueError, match="wpm"):
        build_schedule("abc", wpm)


def test_invalid_wpm_message_names_value():
    with pytest.raises(ValueError, match=r"^wpm must be a positive finite number, got -3$"):
        build_schedule("abc", -3)
    with pytest.raises(ValueError, match=r"got 2000"):
        build_schedule("abc", 2000)


def test_wpm_limits_accepted():
    assert build_schedule("a", 1000).dwell_s[0] == pytest.approx(0.012)
    assert build_schedule("a", 0.5).dwell_s[0] == pytest.approx(24.0)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"word_pause_s": -0.1},
        {"line_pause_s": float("nan")},
        {"jitter_fraction": -0.2},
        {"start_s": float("inf")},
    ],
)
def test_invalid_options(kwargs):
    with pytest.raises(ValueError):
        build_schedule("a b", 60, **kwargs)


def test_untranscribable_text_raises():
    with pytest.raises(ValueError, match=r"'~' at position 2"):
        build_schedule("ab~", 60)


def test_passages_available_and_transcribable():
    names = list_passages()
    assert "default" in names
    assert len(names) >= 3
    for name in names:
        text = load_passage(name)
        assert 300 <= len(text) <= 800
        cells = text_to_cells(text)
        kinds = {c.kind for c in cells}
        assert {"letter", "digit", "punctuation", "space", "capital_sign", "number_sign"} <= kinds
        assert any(c.line_end for c in cells)


def test_passages_cover_required_punctuation():
    used = set("".join(load_passage(n) for n in list_passages()))
    assert set(",;:.!?'-()\"") <= used


def test_unknown_passage_lists_names():
    with pytest.raises(ValueError, match=r"unknown passage 'nope'.*default"):
        load_passage("nope")
