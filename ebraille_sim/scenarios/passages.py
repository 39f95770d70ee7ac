"""Short built-in reading passages for simulation runs.

Passages are plain UTF-8 text files in ``ebraille_sim/data/passages/``
named ``<name>.txt``. Each is a few hundred characters of original prose
that uses capitals, digits and the punctuation supported by
:mod:`ebraille_sim.scenarios.braille`, so it can be transcribed to Grade 1 Braille
without errors. The passage named ``"default"`` is the one to use when no
other choice is made.

Examples
--------
>>> "default" in list_passages()
True
>>> load_passage("default")[:10]
'The kettle'
"""

from __future__ import annotations

import functools
from importlib import resources

__all__ = ["DEFAULT_PASSAGE", "list_passages", "load_passage"]

DEFAULT_PASSAGE: str = "default"

_SUFFIX = ".txt"


def _passage_dir():
    return resources.files("ebraille_sim") / "data" / "passages"


def list_passages() -> list[str]:
    """Names of the built-in passages.

    Returns
    -------
    list of str
        Passage names (file names without ``.txt``), sorted alphabetically.

    Examples
    --------
    >>> list_passages()
    ['default', 'garden', 'letter', 'market']
    """
    return list(_shipped_passages())


@functools.lru_cache(maxsize=1)
def _shipped_passages() -> tuple[str, ...]:
    """The passage names of the installed package (listed once per process)."""
    names = [
        entry.name[: -len(_SUFFIX)]
        for entry in _passage_dir().iterdir()
        if entry.name.endswith(_SUFFIX) and entry.is_file()
    ]
    return tuple(sorted(names))


def load_passage(name: str) -> str:
    """Text of a built-in passage.

    Parameters
    ----------
    name : str
        Passage name as returned by :func:`list_passages`.

    Returns
    -------
    str
        Passage text with trailing white space removed; line breaks inside
        the passage are kept (they become line-end cells when transcribed).

    Raises
    ------
    ValueError
        If `name` is not a built-in passage; the message lists the
        available names.

    Examples
    --------
    >>> load_passage("market").split()[0]
    'Every'
    """
    available = list_passages()
    if name not in available:
        raise ValueError(
            f"unknown passage {name!r}; available passages: {', '.join(available)}"
        )
    text = (_passage_dir() / f"{name}{_SUFFIX}").read_text(encoding="utf-8")
    return text.rstrip()
