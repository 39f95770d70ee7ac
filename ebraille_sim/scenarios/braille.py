"""Transcription of plain text into six-dot Braille cells (English Grade 1).

The rules follow English Braille American Edition (EBAE), uncontracted
(Grade 1). Every displayed cell is one :class:`Cell`; composition signs
(capital, number and letter signs) are cells of their own because the
electrotactile display shows them for a dwell time like any other cell.

Rules implemented
-----------------
Letters
    ``a``-``z`` use the standard EBAE letter patterns.
Capitals
    The capital sign (dot 6) precedes an uppercase letter. A run of two or
    more consecutive ASCII letters that are all uppercase (for example
    ``"USA"``) is preceded by the double capital sign (two dot-6 cells) and
    its letters are written without further capital signs. Pass
    ``double_capital=False`` to :func:`text_to_cells` to mark every capital
    letter individually instead.
Numbers
    The number sign (dots 3-4-5-6) precedes a run of digits; the digits
    ``1``-``9`` and ``0`` use the patterns of ``a``-``j``. Inside a number
    (a digit on both sides) a comma keeps its comma form (dot 2) and a
    period is written as the EBAE decimal point (dots 4-6); neither repeats
    the number sign. Any other character ends the number.
Letter sign
    A lowercase letter ``a``-``j`` written directly after a digit would read
    as a digit, so the letter sign (dots 5-6) is inserted before it. An
    uppercase letter after a digit needs no letter sign because its capital
    sign already ends the number.
Punctuation (EBAE single-cell forms)
    ``,`` 2; ``;`` 2-3; ``:`` 2-5; ``.`` 2-5-6; ``!`` 2-3-5; ``?`` 2-3-6;
    ``'`` 3; ``-`` 3-6; ``(`` and ``)`` 2-3-5-6; opening double quote 2-3-6;
    closing double quote 3-5-6. A plain ``"`` alternates between opening and
    closing, starting with opening; typographic ``“`` and ``”`` set the form
    explicitly and ``’`` is read as an apostrophe. In EBAE the opening quote
    and the question mark share the pattern 2-3-6.
White space
    A space gives an empty cell. A newline (``\\n``, ``\\r\\n`` or ``\\r``)
    gives an empty cell with ``line_end=True`` so that a reading schedule
    can add a line pause. Other characters (tabs included) are rejected.

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
    "'": (3,),
    "\u2019": (3,),
    "-": (3, 6),
    "(": (2, 3, 5, 6),
    ")": (2, 3, 5, 6),
}

_OPEN_QUOTE_DOTS: tuple[int, ...] = (2, 3, 6)
_CLOSE_QUOTE_DOTS: tuple[int, ...] = (3, 5, 6)
_DECIMAL_POINT_DOTS: tuple[int, ...] = (4, 6)
_CAPITAL_SIGN_DOTS: tuple[int, ...] = (6,)
_NUMBER_SIGN_DOTS: tuple[int, ...] = (3, 4, 5, 6)
_LETTER_SIGN_DOTS: tuple[int, ...] = (5, 6)

_LETTER_SIGN_TRIGGERS: frozenset[str] = frozenset("abcdefghij")


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


def text_to_cells(text: str, *, double_capital: bool = True) -> list[Cell]:
    """Transcribe text into English Grade 1 (EBAE, uncontracted) Braille cells.

    Parameters
    ----------
    text : str
        Text made of ASCII letters, digits, spaces, newlines and the
        punctuation ``, ; : . ! ? ' - ( ) "`` (plus ``“ ” ’``).
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
        character and its 0-based position in `text`.

    Examples
    --------
    >>> [c.dots for c in text_to_cells("Hi")]
    [(6,), (1, 2, 5), (2, 4)]
    >>> cells_to_unicode(text_to_cells("10a"))
    '⠼⠁⠚⠰⠁'
    """
    if not isinstance(text, str):
        raise ValueError(f"text must be a str, got {type(text).__name__}")

    cells: list[Cell] = []
    in_number = False
    quote_open = False
    caps_run_end = -1
    n = len(text)
    i = 0
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
            and ch in ",."
            and i + 1 < n
            and text[i + 1].isascii()
            and text[i + 1].isdigit()
        ):
            dots = _PUNCTUATION_DOTS[","] if ch == "," else _DECIMAL_POINT_DOTS
            cells.append(_cell(ch, dots, "punctuation"))
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

        in_number = False

        if ch == " ":
            cells.append(_cell(" ", (), "space"))
            i += 1
            continue

        if ch in "\r\n":
            cells.append(_cell("\n", (), "space", line_end=True))
            i += 2 if text.startswith("\r\n", i) else 1
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

        if ch in _PUNCTUATION_DOTS:
            cells.append(_cell(ch, _PUNCTUATION_DOTS[ch], "punctuation"))
            i += 1
            continue

        raise ValueError(f"cannot transcribe {ch!r} at position {i} to Grade 1 Braille")

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
