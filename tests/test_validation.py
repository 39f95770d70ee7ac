"""The shared validation vocabulary: accepted values, normalisation and one-line messages."""
import math

import numpy as np
import pytest

from ebraille_sim.base.validation import (admissible, check_bool, check_choice, check_finite, check_keys,
                                          check_number, check_pair, check_positive, check_range)
from ebraille_sim.scenarios.spec import ScenarioError


@pytest.mark.parametrize("value, kwargs, expected", [
    (3, {}, 3.0),
    (np.float32(0.5), {"lo": 0, "hi": 1}, 0.5),
    (np.int64(7), {"lo": 1, "integer": True}, 7),
    (2.0, {"lo": 1, "hi": 10, "integer": True}, 2),
    (2**60 + 1, {"lo": 0, "integer": True}, 2**60 + 1),        # big ints are not rounded through float
    (math.inf, {"lo": 0, "finite": False}, math.inf),
    (0.0, {"lo": 0, "hi": 1}, 0.0),
    (1.0, {"lo": 0, "hi": 1}, 1.0),
])
def test_check_number_accepts_and_normalises(value, kwargs, expected):
    got = check_number("x", value, **kwargs)
    assert got == expected and type(got) is type(expected)


@pytest.mark.parametrize("value, kwargs, message", [
    (-3, {"lo": 0, "hi": 1000, "lo_open": True}, "wpm = -3 is out of range (0, 1000]"),
    (0, {"lo": 0, "hi": 1000, "lo_open": True}, "wpm = 0 is out of range (0, 1000]"),
    (1000, {"lo": 0, "hi": 1000, "hi_open": True}, "wpm = 1000 is out of range [0, 1000)"),
    (-1.0, {"lo": 0}, "wpm must be >= 0, got -1.0"),
    (0.0, {"lo": 0, "lo_open": True}, "wpm must be > 0, got 0.0"),
    (5.0, {"hi": 4}, "wpm must be <= 4, got 5.0"),
    (math.nan, {"lo": 0, "hi": 3}, "wpm must be finite, got nan; admissible: a finite number in [0, 3]"),
    (math.nan, {"lo": 0, "finite": False}, "wpm must be finite, got nan; admissible: a finite number >= 0"),
    (math.inf, {}, "wpm must be finite, got inf; admissible: a finite number"),
    (True, {"lo": 0}, "wpm must be a number >= 0, got True"),
    ("90", {}, "wpm must be a number, got '90'"),
    (None, {"lo": 0, "hi": 1}, "wpm must be a number in [0, 1], got None"),
    (1.5, {"lo": 1, "integer": True}, "wpm must be a whole number, got 1.5; admissible: an int >= 1"),
    (0, {"lo": 1, "hi": 10, "integer": True}, "wpm must be an int in [1, 10], got 0"),
    (10 ** 400, {"lo": 0, "hi": 1000}, f"wpm must be finite, got {10 ** 400}; admissible: a finite number in [0, 1000]"),
    (-10 ** 400, {}, f"wpm must be finite, got {-10 ** 400}; admissible: a finite number"),
    (10 ** 400, {"lo": 1, "hi": 24, "integer": True}, f"wpm must be an int in [1, 24], got {10 ** 400}"),
])
def test_check_number_messages(value, kwargs, message):
    with pytest.raises(ValueError) as info:
        check_number("wpm", value, **kwargs)
    assert str(info.value) == message


def test_admissible_words():
    assert admissible() == ""
    assert admissible(0) == ">= 0" and admissible(0, lo_open=True) == "> 0"
    assert admissible(hi=2, hi_open=True) == "< 2"
    assert admissible(-1, 1, lo_open=True) == "in (-1, 1]"


def test_shorthands():
    assert check_finite("f", 2) == 2.0
    assert check_positive("dt_s", 1e-3) == 1e-3
    with pytest.raises(ValueError, match=r"^dt_s must be > 0, got 0.0$"):
        check_positive("dt_s", 0.0)
    assert check_range("r", 0.5, 0, 1) == 0.5
    with pytest.raises(ValueError, match=r"^r = 2 is out of range \[0, 1\)$"):
        check_range("r", 2, 0, 1, hi_open=True)


def test_check_bool_and_choice():
    assert check_bool("enabled", False) is False
    for bad in (0, 1, "true", None):
        with pytest.raises(ValueError, match=r"^enabled must be true or false, got "):
            check_bool("enabled", bad)
    assert check_choice("mode", "refresh", ("continuous", "refresh")) == "refresh"
    with pytest.raises(ValueError, match=r"^mode = 'flip' is not one of: continuous, refresh$"):
        check_choice("mode", "flip", ("continuous", "refresh"))
    with pytest.raises(ValueError, match="is not one of"):
        check_choice("mode", ["unhashable"], {"a": 1})


def test_check_pair():
    assert check_pair("band_hz", (8, 12), 0, 100) == (8.0, 12.0)
    assert check_pair("band_hz", [3, 3], 0, 100) == (3.0, 3.0)
    with pytest.raises(ValueError, match=r"^band_hz must have low < high, got \[3, 3\]$"):
        check_pair("band_hz", [3, 3], 0, 100, strict=True)
    with pytest.raises(ValueError, match=r"^band_hz\[1\] = 200 is out of range \[0, 100\]$"):
        check_pair("band_hz", [3, 200], 0, 100)
    for bad in ("ab", [1], (1, 2, 3), 5.0):
        with pytest.raises(ValueError, match=r"^band_hz must be a pair \(low, high\), got "):
            check_pair("band_hz", bad)


def test_check_keys():
    check_keys("[reading]", {"wpm": 1}, ["passage", "wpm"])
    check_keys("[reading]", [], ["wpm"])
    with pytest.raises(ValueError) as info:
        check_keys("[reading]", {"wpm": 1, "wmp": 2}, ["passage", "wpm"])
    assert str(info.value) == "unknown key 'wmp' in [reading]; allowed: passage, wpm"


def test_scenario_error_is_a_value_error():
    assert issubclass(ScenarioError, ValueError)


def test_read_table_reads_toml_and_json_and_names_each_problem(tmp_path):
    from ebraille_sim.base.validation import read_table
    (tmp_path / "a.toml").write_text('controller = "pid"\n')
    (tmp_path / "a.json").write_text('{"controller": "pid"}')
    assert read_table(str(tmp_path / "a.toml"), "config") == read_table(str(tmp_path / "a.json"), "config")
    (tmp_path / "bad.json").write_text("[1, 2]")
    with pytest.raises(ValueError, match=r"config '.*bad.json' must hold a table/object, got list"):
        read_table(str(tmp_path / "bad.json"), "config")
    (tmp_path / "broken.toml").write_text("controller = ")
    with pytest.raises(ValueError, match="is not valid TOML"):
        read_table(str(tmp_path / "broken.toml"), "config")
    with pytest.raises(FileNotFoundError, match="config not found"):
        read_table(str(tmp_path / "missing.json"), "config")
