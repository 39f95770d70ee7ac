"""Transcription of plain text into six-dot Braille cells (English Grade 1).

The rules follow English Braille American Edition (EBAE), uncontracted
(Grade 1). Every displayed cell is one :class:`Cell`; composition signs
(capital, number and letter signs) are cells of their own because the
electrotactile display shows them for a dwell time like any other cell.

Rules implemented
-----------------
The cell patterns below are those of EBAE (Braille Authority of North
America, *English Braille, American Edition*, 1994 revision) as encoded in
the liblouis table ``en-us-g1.ctb`` (with ``en-chardefs.cti``, which it
includes); the liblouis rule behind each pattern is named in brackets.
``tests/test_braille_liblouis.py`` compares the transcription with liblouis
cell by cell when liblouis is installed.

Letters
    ``a``-``z`` use the standard EBAE letter patterns.
Capitals
    The capital sign (dot 6) precedes an uppercase letter. A run of two or
    more consecutive ASCII letters that are all uppercase (for example
    ``"USA"``) is preceded by the double capital sign (two dot-6 cells) and
    its letters are written without further capital signs
    [``capsletter 6``, ``begcapsword 6-6``]. Pass ``double_capital=False`` to
    :func:`text_to_cells` to mark every capital letter individually instead.
Numbers
    The number sign (dots 3-4-5-6) precedes a run of digits; the digits
    ``1``-``9`` and ``0`` use the patterns of ``a``-``j`` [``numsign 3456``].
    Between two digits these signs keep the number going, so the number sign
    is not repeated after them [``midnum``, ``decpoint``]: comma 2, decimal
    point 4-6, colon 2-5 (``7:15``), hyphen 3-6 (``555-1212``) and the
    fraction line 3-4 (``3/4``). A hyphen directly after a digit and before a
    letter also keeps the number going, so a following ``a``-``j`` gets the
    letter sign (``1-a``). Any other character, the dash included, ends the
    number.
Letter sign
    A lowercase letter ``a``-``j`` written directly after a number would
    read as a digit, so the letter sign (dots 5-6) is inserted before it
    [``letsign 56``]. An uppercase letter needs none because its capital
    sign already ends the number.
Punctuation (single-cell forms)
    ``,`` 2; ``;`` 2-3; ``:`` 2-5; ``.`` 2-5-6; ``!`` 2-3-5; ``?`` 2-3-6;
    ``-`` (hyphen) 3-6; ``(`` and ``)`` 2-3-5-6; opening double quote 2-3-6;
    closing double quote 3-5-6; apostrophe 3 [``postpunc``, ``prepunc``,
    ``hyphen``, ``punctuation`` rules]. A plain ``"`` alternates between
    opening and closing, starting with opening; ``“`` and ``”`` set the form
    explicitly. In EBAE the opening double quote and the question mark share
    the pattern 2-3-6.
Single quotes and apostrophe
    Opening single quote 6, 2-3-6 (two cells); closing single quote 3-5-6, 3
    (two cells); apostrophe 3 [``prepunc ' 6-236``, ``postpunc ' 356-3``,
    ``punctuation ' 3``]. A plain ``'`` opens a quotation when it begins a
    word (at the start of the text or after white space or an opening
    bracket or quote) and is followed by a non-space character, except in
    ``'em``, ``'tis`` and ``'twas`` [``word 'em``, ``word 'tis``,
    ``word 'twas``]; it closes an open quotation when it ends a word (the
    next character is not a letter or digit); otherwise it is an apostrophe
    (``it's``, ``o'clock``, ``dogs'`` outside a quotation). ``‘`` always
    opens; ``’`` closes an open quotation at the end of a word and is an
    apostrophe otherwise.
Dash
    A dash is two unspaced hyphen cells, 3-6, 3-6 [``always \\s-\\s 36-36``,
    ``always \\s--\\s 36-36``, ``punctuation \\x2014 36-36``]. It is written
    for ``--``, for an em dash ``—`` or en dash ``–``, and for a single
    hyphen with one space on each side (``word - word``). When the print
    dash has exactly one space on each side, both spaces are dropped
    (``word - word`` and ``word -- word`` give ``word``, dash, ``word``). A
    run of three hyphens is a dash followed by a hyphen.
Ellipsis
    Three periods ``...``, or ``. . .`` with single spaces, give three dot-3
    cells, 3-3-3 [``always ... 3-3-3``, ``always .\\s.\\s. 3-3-3``]; the
    spaces inside ``. . .`` are dropped, spaces around the ellipsis are kept.
Percent and slash
    ``%`` is the three cells 4, 2-5, 1-2-3-4 [``always % 4-25-1234``] and
    ends a number (a number after it takes a new number sign). ``/`` is the
    oblique stroke 4-5-6, 3-4 (two cells) [``always / 456-34``] except
    between two digits, where it is the fraction line 3-4 (see Numbers).
Symbols
    ``$`` is 4, 2-5-6 [``always $ 4-256``], and 2-5-6 right before a digit,
    whose number sign follows [``begnum $ 256``]: ``$5`` is 2-5-6, 3-4-5-6,
    1-5.  ``&`` is 4, 1-2-3-4-6 [``always & 4-12346``]; ``@`` is 4, 1
    [``always @ 4-1``]; ``*`` is 3-5, 3-5 [``always * 35-35``] and 4, 1-6
    between two digits, the number going on [``midnum * 4-16``]; ``#`` is
    4-5-6, 1-4-5-6 right before a digit [``begnum # 456-1456``] and the single
    cell 3-4-5-6 elsewhere [``sign # 3456`` of chardefs.cti].
White space
    A space gives an empty cell. A newline (``\\n``, ``\\r\\n`` or ``\\r``)
    gives an empty cell with ``line_end=True`` so that a reading schedule
    can add a line pause.
Rejected characters
    Every other character (tabs, ``@``, ``&``, ``€``, ``…`` and so on) raises
    a ``ValueError`` naming the character, its position and the accepted
    set (:data:`ACCEPTED_CHARACTERS`).

Differences from liblouis ``en-us-g1.ctb``
    liblouis writes the letter sign before every single letter standing
    alone (``a``, ``I``); this transcription does not. liblouis keeps the
    spaces around a spaced em or en dash (`` — ``), writes ``’`` always as an
    apostrophe, turns a word-final ``s'`` into an apostrophe even inside a
    single-quoted passage, and maps ``…`` to one dot-3 cell; here the dash
    is unspaced, ``’`` and ``s'`` close an open quotation, and ``…`` is
    rejected.

Dot numbering and bit masks follow the Unicode Braille Patterns block:
dots 1-2-3 run down the left column, dots 4-5-6 down the right column, and
dot *k* sets bit *k*-1 of the mask, so a cell's character is
``chr(0x2800 + mask)``.

Examples
--------
>>> from ebraille_sim.scenarios.braille import text_to_cells, cells_to_unicode
>>> cells_to_unicode(text_to_cells("hello"))
'⠓⠑⠇⠇⠕'
>>> [c.kind for c in text_to_cells("A1")]
['capital_sign', 'letter', 'number_sign', 'digit']
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Iterable, Sequence

import numpy as np

__all__ = [
    "ACCEPTED_CHARACTERS",
    "CELL_KINDS",
    "Cell",
    "cells_to_unicode",
    "dots_grid",
    "dots_to_mask",
    "text_to_cells",
]

CELL_KINDS: frozenset[str] = frozenset(
    {
        "letter",
        "digit",
        "punctuation",
        "space",
        "capital_sign",
        "number_sign",
        "letter_sign",
    }
)

_LETTER_DOTS: dict[str, tuple[int, ...]] = {
    "a": (1,),
    "b": (1, 2),
    "c": (1, 4),
    "d": (1, 4, 5),
    "e": (1, 5),
    "f": (1, 2, 4),
    "g": (1, 2, 4, 5),
    "h": (1, 2, 5),
    "i": (2, 4),
    "j": (2, 4, 5),
    "k": (1, 3),
    "l": (1, 2, 3),
    "m": (1, 3, 4),
    "n": (1, 3, 4, 5),
    "o": (1, 3, 5),
    "p": (1, 2, 3, 4),
    "q": (1, 2, 3, 4, 5),
    "r": (1, 2, 3, 5),
    "s": (2, 3, 4),
    "t": (2, 3, 4, 5),
    "u": (1, 3, 6),
    "v": (1, 2, 3, 6),
    "w": (2, 4, 5, 6),
    "x": (1, 3, 4, 6),
    "y": (1, 3, 4, 5, 6),
    "z": (1, 3, 5, 6),
}

_DIGIT_LETTER: dict[str, str] = {
    "1": "a",
    "2": "b",
    "3": "c",
    "4": "d",
    "5": "e",
    "6": "f",
    "7": "g",
    "8": "h",
    "9": "i",
    "0": "j",
}

_PUNCTUATION_DOTS: dict[str, tuple[int, ...]] = {
    ",": (2,),
    ";": (2, 3),
    ":": (2, 5),
    ".": (2, 5, 6),
    "!": (2, 3, 5),
    "?": (2, 3, 6),
    "-": (3, 6),
    "(": (2, 3, 5, 6),
    ")": (2, 3, 5, 6),
}

_APOSTROPHE_DOTS: tuple[int, ...] = (3,)
_OPEN_QUOTE_DOTS: tuple[int, ...] = (2, 3, 6)
_CLOSE_QUOTE_DOTS: tuple[int, ...] = (3, 5, 6)
_OPEN_SINGLE_QUOTE_DOTS: tuple[tuple[int, ...], ...] = ((6,), (2, 3, 6))
_CLOSE_SINGLE_QUOTE_DOTS: tuple[tuple[int, ...], ...] = ((3, 5, 6), (3,))
_DASH_DOTS: tuple[tuple[int, ...], ...] = ((3, 6), (3, 6))
_ELLIPSIS_DOTS: tuple[tuple[int, ...], ...] = ((3,), (3,), (3,))
_PERCENT_DOTS: tuple[tuple[int, ...], ...] = ((4,), (2, 5), (1, 2, 3, 4))
# print symbols [``always`` rules of en-us-g1.ctb], and their forms right before a digit
# [``begnum``] or between two digits [``midnum``]
_SYMBOL_DOTS: dict[str, tuple[tuple[int, ...], ...]] = {
    "$": ((4,), (2, 5, 6)),
    "&": ((4,), (1, 2, 3, 4, 6)),
    "*": ((3, 5), (3, 5)),
    "@": ((4,), (1,)),
    "#": ((3, 4, 5, 6),),
}
_SYMBOL_BEFORE_NUMBER_DOTS: dict[str, tuple[tuple[int, ...], ...]] = {
    "$": ((2, 5, 6),),
    "#": ((4, 5, 6), (1, 4, 5, 6)),
}
_SYMBOL_IN_NUMBER_DOTS: dict[str, tuple[tuple[int, ...], ...]] = {
    "*": ((4,), (1, 6)),
}
_SLASH_DOTS: tuple[tuple[int, ...], ...] = ((4, 5, 6), (3, 4))
_DECIMAL_POINT_DOTS: tuple[int, ...] = (4, 6)
_FRACTION_LINE_DOTS: tuple[int, ...] = (3, 4)
_CAPITAL_SIGN_DOTS: tuple[int, ...] = (6,)
_NUMBER_SIGN_DOTS: tuple[int, ...] = (3, 4, 5, 6)
_LETTER_SIGN_DOTS: tuple[int, ...] = (5, 6)

_LETTER_SIGN_TRIGGERS: frozenset[str] = frozenset("abcdefghij")
# signs between two digits that keep the number going (no new number sign)
_MIDNUM_DOTS: dict[str, tuple[int, ...]] = {
    ",": (2,),
    ".": _DECIMAL_POINT_DOTS,
    ":": (2, 5),
    "-": (3, 6),
    "/": _FRACTION_LINE_DOTS,
}
_TYPOGRAPHIC_DASHES: frozenset[str] = frozenset("\u2013\u2014")
# characters after which a plain ' begins a quotation
_QUOTE_OPENERS: frozenset[str] = frozenset('("\u201c\u2018')
# words whose leading ' is an apostrophe, not an opening quote
_APOSTROPHE_WORDS: tuple[str, ...] = ("twas", "tis", "em")

ACCEPTED_CHARACTERS: str = (
    "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789"
    " \n\r" + "".join(sorted(set(_PUNCTUATION_DOTS) | set("\"'%/") | set(_SYMBOL_DOTS)))
    + "\u201c\u201d\u2018\u2019\u2013\u2014"
)
"""Every character :func:`text_to_cells` accepts: ASCII letters and digits,
space, newline (``\\n``, ``\\r``), ``! " % ' ( ) , - . / : ; ?``, the
symbols ``$ & * @ #`` and the typographic quotes and dashes ``“ ” ‘ ’ – —``."""

_ACCEPTED_DESCRIPTION: str = (
    "letters A-Z a-z, digits 0-9, space, newline and "
    + " ".join(sorted(set(_PUNCTUATION_DOTS) | set("\"'%/") | set(_SYMBOL_DOTS)))
    + " \u201c \u201d \u2018 \u2019 \u2013 \u2014"
)


def dots_to_mask(dots: Iterable[int]) -> int:
    """Convert raised dot numbers to a Unicode-convention bit mask.

    Parameters
    ----------
    dots : iterable of int
        Raised dot numbers, each in 1..6.

    Returns
    -------
    int
        Mask in 0..63 with bit ``k - 1`` set for every raised dot ``k``.

    Raises
    ------
    ValueError
        If a dot number lies outside 1..6.

    Examples
    --------
    >>> dots_to_mask((1, 3, 5, 6))
    53
    """
    mask = 0
    for dot in dots:
        if not isinstance(dot, (int, np.integer)) or not 1 <= dot <= 6:
            raise ValueError(f"dot numbers must be integers in 1..6, got {dot!r}")
        mask |= 1 << (int(dot) - 1)
    return mask


@dataclass(frozen=True)
class Cell:
    """One six-dot Braille cell as shown on the 3x2 display.

    Parameters
    ----------
    char : str
        Source character (``"H"``, ``"7"``, ``"?"``, ``" "``, ``"\\n"``) or,
        for composition signs, the sign name (``"capital_sign"``,
        ``"number_sign"``, ``"letter_sign"``).
    dots : tuple of int
        Raised dot numbers in 1..6, sorted ascending and without repeats.
        Empty for a space.
    mask : int
        Bit mask with bit ``k - 1`` set for raised dot ``k``; must agree
        with `dots`.
    kind : str
        One of ``"letter"``, ``"digit"``, ``"punctuation"``, ``"space"``,
        ``"capital_sign"``, ``"number_sign"``, ``"letter_sign"``.
    line_end : bool, optional
        True only for the space cell produced by a newline.

    Examples
    --------
    >>> Cell(char="z", dots=(1, 3, 5, 6), mask=53, kind="letter").unicode
    '⠵'
    """

    char: str
    dots: tuple[int, ...]
    mask: int
    kind: str
    line_end: bool = False

    def __post_init__(self) -> None:
        if not isinstance(self.dots, tuple):
            raise ValueError(f"Cell.dots must be a tuple, got {type(self.dots).__name__}")
        if list(self.dots) != sorted(set(self.dots)):
            raise ValueError(f"Cell.dots must be sorted without repeats, got {self.dots}")
        expected = dots_to_mask(self.dots)
        if self.mask != expected:
            raise ValueError(
                f"Cell.mask {self.mask} does not match dots {self.dots} (expected {expected})"
            )
        if self.kind not in CELL_KINDS:
            raise ValueError(f"Cell.kind must be one of {sorted(CELL_KINDS)}, got {self.kind!r}")
        if self.line_end and self.kind != "space":
            raise ValueError("only a space cell can carry line_end=True")

    @property
    def unicode(self) -> str:
        """Unicode Braille Patterns character for this cell (U+2800 + mask)."""
        return chr(0x2800 + self.mask)


@functools.lru_cache(maxsize=1024)
def _cell(char: str, dots: tuple[int, ...], kind: str, line_end: bool = False) -> Cell:
    """The (immutable) cell of these fields, built and checked once."""
    return Cell(char=char, dots=dots, mask=dots_to_mask(dots), kind=kind, line_end=line_end)


def _letter_run_end(text: str, start: int) -> int:
    end = start
    while end < len(text) and text[end].isascii() and text[end].isalpha():
        end += 1
    return end


def _is_digit(text: str, i: int) -> bool:
    return 0 <= i < len(text) and text[i].isascii() and text[i].isdigit()


def _is_alnum(text: str, i: int) -> bool:
    return 0 <= i < len(text) and text[i].isascii() and text[i].isalnum()


def _dash_length(text: str, i: int) -> int:
    """Characters of the print dash starting at `i` (0 if none), spaces not counted."""
    if text[i] in _TYPOGRAPHIC_DASHES:
        return 1
    if text.startswith("--", i):
        return 2
    return 0


def _spaced_dash_length(text: str, i: int) -> int:
    """Length of a print dash after the space at `i` that has one space on each side.

    The dash is ``-``, ``--``, ``–`` or ``—``; 0 when there is none or the
    spacing differs (no space after it, or two spaces on a side).
    """
    start = i + 1
    if start >= len(text) or (i >= 1 and text[i - 1] == " "):
        return 0
    length = _dash_length(text, start) or (1 if text[start] == "-" else 0)
    end = start + length
    if length == 0 or end >= len(text) or text[end] != " ":
        return 0
    if end + 1 < len(text) and text[end + 1] == " ":
        return 0
    return length


def _ellipsis_length(text: str, i: int) -> int:
    """Characters of the ellipsis ``...`` or ``. . .`` starting at `i` (0 if none)."""
    if text.startswith("...", i):
        return 3
    if text.startswith(". . .", i):
        return 5
    return 0


def _opens_single_quote(text: str, i: int) -> bool:
    """Whether the plain ``'`` at `i` begins a quotation (see the module rules)."""
    if i + 1 >= len(text) or text[i + 1].isspace():
        return False
    if i > 0 and not (text[i - 1].isspace() or text[i - 1] in _QUOTE_OPENERS):
        return False
    for word in _APOSTROPHE_WORDS:
        end = i + 1 + len(word)
        if text[i + 1:end].lower() == word and not _is_alnum(text, end):
            return False
    return True


def text_to_cells(
    text: str, *, double_capital: bool = True
) -> list[Cell]:
    """Transcribe text into English Grade 1 (EBAE, uncontracted) Braille cells.

    Parameters
    ----------
    text : str
        Text made of the characters in :data:`ACCEPTED_CHARACTERS`: ASCII
        letters, digits, spaces, newlines, the punctuation
        ``! " % ' ( ) , - . / : ; ?``, the symbols ``$ & * @ #`` and
        ``“ ” ‘ ’ – —``.
    double_capital : bool, optional
        If True (default), a run of two or more consecutive uppercase ASCII
        letters gets the double capital sign (two dot-6 cells) instead of a
        capital sign before each letter.
    Returns
    -------
    list of Cell
        One entry per displayed cell, composition signs included.

    Raises
    ------
    ValueError
        If a character cannot be transcribed; the message names the
        character, its 0-based position in `text` and the accepted set.

    Examples
    --------
    >>> [c.dots for c in text_to_cells("Hi")]
    [(6,), (1, 2, 5), (2, 4)]
    >>> cells_to_unicode(text_to_cells("10a"))
    '⠼⠁⠚⠰⠁'
    >>> cells_to_unicode(text_to_cells("at 7:15 - wait..."))
    '⠁⠞⠀⠼⠛⠒⠁⠑⠤⠤⠺⠁⠊⠞⠄⠄⠄'
    """
    if not isinstance(text, str):
        raise ValueError(f"text must be a str, got {type(text).__name__}")

    cells: list[Cell] = []
    in_number = False
    quote_open = False
    single_quote_open = False
    caps_run_end = -1
    n = len(text)
    i = 0

    def signs(char: str, patterns: tuple[tuple[int, ...], ...]) -> None:
        for dots in patterns:
            cells.append(_cell(char, dots, "punctuation"))

    while i < n:
        ch = text[i]
        lower = ch.lower()

        if ch.isascii() and ch.isdigit():
            if not in_number:
                cells.append(_cell("number_sign", _NUMBER_SIGN_DOTS, "number_sign"))
                in_number = True
            cells.append(_cell(ch, _LETTER_DOTS[_DIGIT_LETTER[ch]], "digit"))
            i += 1
            continue

        if (
            in_number
            and ch in _MIDNUM_DOTS
            and _is_digit(text, i + 1)
        ):
            cells.append(_cell(ch, _MIDNUM_DOTS[ch], "punctuation"))
            i += 1
            continue

        if in_number and ch in _SYMBOL_IN_NUMBER_DOTS and _is_digit(text, i + 1):
            signs(ch, _SYMBOL_IN_NUMBER_DOTS[ch])
            i += 1
            continue

        if ch.isascii() and ch.isalpha():
            if ch.isupper():
                if i >= caps_run_end:
                    run_end = _letter_run_end(text, i)
                    run = text[i:run_end]
                    if double_capital and len(run) >= 2 and run.isupper():
                        cells.append(_cell("capital_sign", _CAPITAL_SIGN_DOTS, "capital_sign"))
                        cells.append(_cell("capital_sign", _CAPITAL_SIGN_DOTS, "capital_sign"))
                        caps_run_end = run_end
                    else:
                        cells.append(_cell("capital_sign", _CAPITAL_SIGN_DOTS, "capital_sign"))
            elif in_number and ch in _LETTER_SIGN_TRIGGERS:
                cells.append(_cell("letter_sign", _LETTER_SIGN_DOTS, "letter_sign"))
            in_number = False
            cells.append(_cell(ch, _LETTER_DOTS[lower], "letter"))
            i += 1
            continue

        if (
            in_number
            and ch == "-"
            and i + 1 < n
            and text[i + 1].isascii()
            and text[i + 1].isalpha()
        ):
            # "1-a": the number goes on through the hyphen (letter sign before a-j)
            cells.append(_cell(ch, _PUNCTUATION_DOTS["-"], "punctuation"))
            i += 1
            continue

        in_number = False

        if ch == " ":
            dash = _spaced_dash_length(text, i)
            if dash:
                # EBAE writes the dash unspaced: both print spaces are dropped
                signs(text[i + 1], _DASH_DOTS)
                i += dash + 2
                continue
            cells.append(_cell(" ", (), "space"))
            i += 1
            continue

        if ch in "\r\n":
            cells.append(_cell("\n", (), "space", line_end=True))
            i += 2 if text.startswith("\r\n", i) else 1
            continue

        dash = _dash_length(text, i)
        if dash:
            signs(ch, _DASH_DOTS)
            i += dash
            continue

        ellipsis = _ellipsis_length(text, i)
        if ellipsis:
            signs(".", _ELLIPSIS_DOTS)
            i += ellipsis
            continue

        if ch == '"':
            dots = _CLOSE_QUOTE_DOTS if quote_open else _OPEN_QUOTE_DOTS
            quote_open = not quote_open
            cells.append(_cell(ch, dots, "punctuation"))
            i += 1
            continue

        if ch == "\u201c":
            quote_open = True
            cells.append(_cell(ch, _OPEN_QUOTE_DOTS, "punctuation"))
            i += 1
            continue

        if ch == "\u201d":
            quote_open = False
            cells.append(_cell(ch, _CLOSE_QUOTE_DOTS, "punctuation"))
            i += 1
            continue

        if ch == "\u2018" or (ch == "'" and _opens_single_quote(text, i)):
            single_quote_open = True
            signs(ch, _OPEN_SINGLE_QUOTE_DOTS)
            i += 1
            continue

        if ch in "'\u2019":
            if single_quote_open and i > 0 and not text[i - 1].isspace() and not _is_alnum(text, i + 1):
                single_quote_open = False
                signs(ch, _CLOSE_SINGLE_QUOTE_DOTS)
            else:
                cells.append(_cell(ch, _APOSTROPHE_DOTS, "punctuation"))
            i += 1
            continue

        if ch == "%":
            signs(ch, _PERCENT_DOTS)
            i += 1
            continue

        if ch == "/":
            signs(ch, _SLASH_DOTS)
            i += 1
            continue

        if ch in _SYMBOL_DOTS:
            before_number = _SYMBOL_BEFORE_NUMBER_DOTS.get(ch)
            signs(ch, before_number if before_number is not None and _is_digit(text, i + 1) else _SYMBOL_DOTS[ch])
            i += 1
            continue

        if ch in _PUNCTUATION_DOTS:
            cells.append(_cell(ch, _PUNCTUATION_DOTS[ch], "punctuation"))
            i += 1
            continue

        raise ValueError(
            f"cannot transcribe {ch!r} at position {i} to Grade 1 Braille; "
            f"accepted: {_ACCEPTED_DESCRIPTION}"
        )

    return cells


def cells_to_unicode(cells: Sequence[Cell]) -> str:
    """Render cells as a string of Unicode Braille Patterns characters.

    Parameters
    ----------
    cells : sequence of Cell
        Cells to render, in reading order.

    Returns
    -------
    str
        One character per cell; a space cell renders as U+2800 (blank
        pattern) and newline information is not kept.

    Examples
    --------
    >>> cells_to_unicode(text_to_cells("w"))
    '⠺'
    """
    return "".join(cell.unicode for cell in cells)


def dots_grid(cell: Cell) -> np.ndarray:
    """Raised-dot layout of a cell on the 3x2 display.

    Parameters
    ----------
    cell : Cell
        Cell to lay out.

    Returns
    -------
    numpy.ndarray
        Boolean array of shape (3, 2); element ``[r, c]`` is True when the
        dot in row ``r`` (0 = top) and column ``c`` (0 = left) is raised.
        Dots 1, 2, 3 occupy column 0 rows 0..2; dots 4, 5, 6 occupy column 1
        rows 0..2.

    Examples
    --------
    >>> dots_grid(text_to_cells("d")[0]).astype(int).tolist()
    [[1, 1], [0, 1], [0, 0]]
    """
    grid = np.zeros((3, 2), dtype=bool)
    for dot in cell.dots:
        grid[(dot - 1) % 3, (dot - 1) // 3] = True
    return grid
