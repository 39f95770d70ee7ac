"""Tests for ebraille_sim.scenarios.braille (English Grade 1 / EBAE transcription)."""

import numpy as np
import pytest

from ebraille_sim.scenarios.braille import (
    Cell,
    cells_to_unicode,
    dots_grid,
    dots_to_mask,
    text_to_cells,
)


def dots_of(text, **kwargs):
    return [c.dots for c in text_to_cells(text, **kwargs)]


def kinds_of(text, **kwargs):
    return [c.kind for c in text_to_cells(text, **kwargs)]


@pytest.mark.parametrize(
    "letter, dots",
    [
        ("a", (1,)),
        ("b", (1, 2)),
        ("c", (1, 4)),
        ("j", (2, 4, 5)),
        ("k", (1, 3)),
        ("q", (1, 2, 3, 4, 5)),
        ("t", (2, 3, 4, 5)),
        ("u", (1, 3, 6)),
        ("w", (2, 4, 5, 6)),
        ("x", (1, 3, 4, 6)),
        ("y", (1, 3, 4, 5, 6)),
        ("z", (1, 3, 5, 6)),
    ],
)
def test_letter_patterns(letter, dots):
    (cell,) = text_to_cells(letter)
    assert cell.dots == dots
    assert cell.kind == "letter"
    assert cell.char == letter


def test_full_alphabet_unicode():
    expected = "⠁⠃⠉⠙⠑⠋⠛⠓⠊⠚⠅⠇⠍⠝⠕⠏⠟⠗⠎⠞⠥⠧⠺⠭⠽⠵"
    assert cells_to_unicode(text_to_cells("abcdefghijklmnopqrstuvwxyz")) == expected


def test_hello_unicode():
    assert cells_to_unicode(text_to_cells("hello")) == "⠓⠑⠇⠇⠕"


def test_mask_and_unicode_follow_unicode_convention():
    (z,) = text_to_cells("z")
    assert z.mask == 0b110101 == 53
    assert z.unicode == "\u2835"
    assert dots_to_mask((1, 2, 3, 4, 5, 6)) == 63
    assert dots_to_mask(()) == 0


def test_cells_are_frozen_and_validated():
    (a,) = text_to_cells("a")
    with pytest.raises(AttributeError):
        a.dots = (2,)
    with pytest.raises(ValueError):
        Cell(char="a", dots=(1,), mask=2, kind="letter")
    with pytest.raises(ValueError):
        Cell(char="a", dots=(2, 1), mask=3, kind="letter")
    with pytest.raises(ValueError):
        Cell(char="a", dots=(1,), mask=1, kind="vowel")


def test_capital_sign_before_uppercase_letter():
    cells = text_to_cells("Hi")
    assert [c.dots for c in cells] == [(6,), (1, 2, 5), (2, 4)]
    assert [c.kind for c in cells] == ["capital_sign", "letter", "letter"]
    assert cells[0].char == "capital_sign"
    assert cells[1].char == "H"


def test_single_capital_letter_word():
    assert dots_of("I am") == [(6,), (2, 4), (), (1,), (1, 3, 4)]


def test_double_capital_for_all_caps_word():
    assert dots_of("USA") == [(6,), (6,), (1, 3, 6), (2, 3, 4), (1,)]
    assert dots_of("USA", double_capital=False) == [
        (6,), (1, 3, 6), (6,), (2, 3, 4), (6,), (1,)
    ]


def test_mixed_case_word_marks_each_capital():
    assert kinds_of("McD") == ["capital_sign", "letter", "letter", "capital_sign", "letter"]


def test_number_sign_and_digits():
    cells = text_to_cells("1")
    assert [c.dots for c in cells] == [(3, 4, 5, 6), (1,)]
    assert [c.kind for c in cells] == ["number_sign", "digit"]
    assert cells[0].char == "number_sign"
    assert cells_to_unicode(text_to_cells("1234567890")) == "⠼⠁⠃⠉⠙⠑⠋⠛⠓⠊⠚"


def test_number_sign_once_per_run_of_digits():
    assert kinds_of("42 7") == ["number_sign", "digit", "digit", "space", "number_sign", "digit"]


def test_number_sign_not_repeated_after_colon_or_hyphen_between_digits():
    # EBAE / liblouis en-us-g1 "midnum : 25" and "midnum - 36"
    assert cells_to_unicode(text_to_cells("7:15")) == "⠼⠛⠒⠁⠑"
    assert cells_to_unicode(text_to_cells("555-1212")) == "⠼⠑⠑⠑⠤⠁⠃⠁⠃"
    assert kinds_of("7:15") == ["number_sign", "digit", "punctuation", "digit", "digit"]


def test_comma_and_decimal_point_inside_number():
    assert dots_of("1,000") == [(3, 4, 5, 6), (1,), (2,), (2, 4, 5), (2, 4, 5), (2, 4, 5)]
    assert dots_of("2.5") == [(3, 4, 5, 6), (1, 2), (4, 6), (1, 5)]
    assert dots_of("2.") == [(3, 4, 5, 6), (1, 2), (2, 5, 6)]


def test_letter_sign_after_digits_for_a_to_j():
    cells = text_to_cells("10a")
    assert [c.dots for c in cells] == [(3, 4, 5, 6), (1,), (2, 4, 5), (5, 6), (1,)]
    assert cells[3].kind == "letter_sign"
    assert cells[3].char == "letter_sign"
    assert kinds_of("3j") == ["number_sign", "digit", "letter_sign", "letter"]


def test_no_letter_sign_when_not_needed():
    assert kinds_of("2nd") == ["number_sign", "digit", "letter", "letter"]
    assert kinds_of("3 a") == ["number_sign", "digit", "space", "letter"]
    assert kinds_of("3-x") == ["number_sign", "digit", "punctuation", "letter"]
    assert kinds_of("3-D") == ["number_sign", "digit", "punctuation", "capital_sign", "letter"]


def test_letter_sign_after_number_and_hyphen():
    # liblouis en-us-g1: "1-a" -> number sign, 1, hyphen, letter sign, a
    assert kinds_of("3-a") == ["number_sign", "digit", "punctuation", "letter_sign", "letter"]
    assert kinds_of("3D") == ["number_sign", "digit", "capital_sign", "letter"]


@pytest.mark.parametrize(
    "char, dots",
    [
        (",", (2,)),
        (";", (2, 3)),
        (":", (2, 5)),
        (".", (2, 5, 6)),
        ("!", (2, 3, 5)),
        ("?", (2, 3, 6)),
        ("'", (3,)),
        ("-", (3, 6)),
        ("(", (2, 3, 5, 6)),
        (")", (2, 3, 5, 6)),
    ],
)
def test_punctuation_patterns(char, dots):
    (cell,) = text_to_cells(char)
    assert cell.dots == dots
    assert cell.kind == "punctuation"


def test_double_quotes_alternate_open_close():
    cells = text_to_cells('"a" "b"')
    quotes = [c.dots for c in cells if c.char == '"']
    assert quotes == [(2, 3, 6), (3, 5, 6), (2, 3, 6), (3, 5, 6)]


def test_typographic_quotes_and_apostrophe():
    assert dots_of("\u201ca\u201d") == [(2, 3, 6), (1,), (3, 5, 6)]
    assert dots_of("it\u2019s")[2] == (3,)


def test_space_and_newline_cells():
    cells = text_to_cells("a b\nc")
    assert [c.kind for c in cells] == ["letter", "space", "letter", "space", "letter"]
    assert cells[1].dots == () and cells[1].mask == 0 and not cells[1].line_end
    assert cells[3].dots == () and cells[3].line_end
    assert cells[1].unicode == "\u2800"


def test_crlf_is_a_single_line_end():
    cells = text_to_cells("a\r\nb")
    assert [c.line_end for c in cells] == [False, True, False]


def test_sentence_unicode():
    assert cells_to_unicode(text_to_cells("Yes, 3 cats!")) == "⠠⠽⠑⠎⠂⠀⠼⠉⠀⠉⠁⠞⠎⠖"


def test_error_names_character_and_position():
    with pytest.raises(ValueError, match=r"cannot transcribe '€' at position 12 to Grade 1 Braille"):
        text_to_cells("It costs 10 €.")
    with pytest.raises(ValueError, match=r"'~' at position 1"):
        text_to_cells("a~b")
    with pytest.raises(ValueError, match=r"'\\t' at position 0"):
        text_to_cells("\tx")


def test_error_lists_the_accepted_characters():
    with pytest.raises(ValueError) as info:
        text_to_cells("wait\u2026")
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith("cannot transcribe '\u2026' at position 4 to Grade 1 Braille; accepted: ")
    for shown in ("A-Z a-z", "0-9", "%", "/", "\u2014", "\u2018"):
        assert shown in message
    for bad in "~^_\t\u20ac[":
        with pytest.raises(ValueError, match="accepted: letters"):
            text_to_cells(f"ok {bad}")


def test_ebae_symbols_and_their_number_forms():
    """``$ & * @ #`` as en-us-g1.ctb writes them: dollar 4, 2-5-6 (2-5-6 before a digit, the
    number sign after it), ampersand 4, 1-2-3-4-6, at 4, 1, asterisk 3-5, 3-5 (4, 1-6 between
    digits, one number), hash 3-4-5-6 (4-5-6, 1-4-5-6 before a digit)."""
    assert dots_of("$5") == [(2, 5, 6), (3, 4, 5, 6), (1, 5)]
    assert dots_of("$ 5")[:2] == [(4,), (2, 5, 6)]
    assert dots_of("&") == [(4,), (1, 2, 3, 4, 6)]
    assert dots_of("@") == [(4,), (1,)]
    assert dots_of("*") == [(3, 5), (3, 5)]
    assert dots_of("3*4") == [(3, 4, 5, 6), (1, 4), (4,), (1, 6), (1, 4, 5)]      # no second number sign
    assert dots_of("3 * 4")[3:5] == [(3, 5), (3, 5)]
    assert dots_of("#5") == [(4, 5, 6), (1, 4, 5, 6), (3, 4, 5, 6), (1, 5)]
    assert dots_of("#") == [(3, 4, 5, 6)]
    assert kinds_of("$5") == ["punctuation", "number_sign", "digit"]


def test_accepted_characters_all_transcribe():
    from ebraille_sim.scenarios.braille import ACCEPTED_CHARACTERS

    for ch in ACCEPTED_CHARACTERS:
        assert text_to_cells(f"x{ch}y")
    assert "\t" not in ACCEPTED_CHARACTERS and "\u2026" not in ACCEPTED_CHARACTERS


def test_dash_cells_and_spacing():
    dash = [(3, 6), (3, 6)]
    assert dots_of("a--b")[1:3] == dash
    assert kinds_of("go - now") == ["letter"] * 2 + ["punctuation"] * 2 + ["letter"] * 3
    assert dots_of("go \u2014 now") == dots_of("go--now") == dots_of("go -- now")
    # spacing other than one space on each side is kept
    assert dots_of("go -now")[2:4] == [(), (3, 6)]
    assert dots_of("go  -  now")[2:7] == [(), (), (3, 6), (), ()]
    assert dots_of("go---now")[2:5] == [(3, 6)] * 3


def test_ellipsis_is_three_dot_3_cells():
    assert dots_of("so...")[2:] == [(3,), (3,), (3,)]
    assert dots_of("so . . . now") == dots_of("so ... now")
    assert [c.char for c in text_to_cells("...")] == ["."] * 3
    assert dots_of("2.5") == [(3, 4, 5, 6), (1, 2), (4, 6), (1, 5)]


def test_percent_and_slash():
    assert dots_of("5%") == [(3, 4, 5, 6), (1, 5), (4,), (2, 5), (1, 2, 3, 4)]
    assert kinds_of("5%6")[-2:] == ["number_sign", "digit"]      # % ends the number
    assert dots_of("3/4") == [(3, 4, 5, 6), (1, 4), (3, 4), (1, 4, 5)]
    assert dots_of("a/b") == [(1,), (4, 5, 6), (3, 4), (1, 2)]


def test_single_quotes_open_close_and_apostrophe():
    open_, close, apostrophe = [(6,), (2, 3, 6)], [(3, 5, 6), (3,)], [(3,)]
    assert dots_of("'no'") == open_ + [(1, 3, 4, 5), (1, 3, 5)] + close
    assert dots_of("it's")[2:3] == apostrophe
    assert dots_of("dogs' bones")[4:5] == apostrophe              # no quotation open
    assert dots_of("'em")[:1] == apostrophe and dots_of("'Twas")[:1] == apostrophe
    # a word-final s' or a typographic ’ closes an open quotation (liblouis writes an apostrophe)
    assert dots_of("'yes' no")[5:7] == close
    assert dots_of("\u2018hi\u2019")[-2:] == close
    assert dots_of("\u2018tom\u2019s")[5:6] == apostrophe
    assert dots_of("'") == apostrophe


def test_empty_text():
    assert text_to_cells("") == []
    assert cells_to_unicode([]) == ""


def test_dots_grid_layout():
    (d,) = text_to_cells("d")
    grid = dots_grid(d)
    assert grid.shape == (3, 2)
    assert grid.dtype == bool
    np.testing.assert_array_equal(grid, [[True, True], [False, True], [False, False]])
    (y,) = text_to_cells("y")
    np.testing.assert_array_equal(dots_grid(y), [[True, True], [False, True], [True, True]])
    np.testing.assert_array_equal(dots_grid(text_to_cells(" ")[0]), np.zeros((3, 2), bool))


def test_dots_grid_matches_mask_for_every_letter():
    for cell in text_to_cells("abcdefghijklmnopqrstuvwxyz"):
        grid = dots_grid(cell)
        mask = sum(1 << (r + 3 * c) for r in range(3) for c in range(2) if grid[r, c])
        assert mask == cell.mask
