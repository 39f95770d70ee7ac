"""Dataclass fields that carry a unit, a source tag and their admissible range.

Every parameter of the simulator, physical or not, is declared with :func:`sourced`, so
that reports, docs and validation read the same metadata: ``unit``, ``source`` (``[R]``
read, ``[D]`` derived, ``[E]`` estimate, see docs/model.md) and optional bounds
``positive``, ``nonneg``, ``lo``, ``hi`` and a ``kind``.

Examples
--------
>>> from dataclasses import dataclass, fields
>>> @dataclass(frozen=True)
... class Spring:
...     k_n_per_m: float = sourced(3e4, "N/m", "[E] plastic mesh contact", positive=True)
>>> fields(Spring)[0].metadata["unit"]
'N/m'
"""
from __future__ import annotations

from dataclasses import field
from typing import Any

__all__ = ["sourced"]


def sourced(default: Any, unit: str, source: str, **flags) -> Any:
    """A dataclass field with ``unit`` and ``source`` metadata and any extra ``flags``.

    Parameters
    ----------
    default : object
        The field's default value.
    unit : str
        SI unit (``"-"`` for a pure number).
    source : str
        Source tag and reference, e.g. ``"[R] FSR 402 datasheet"``.
    **flags
        Further metadata: ``positive=True``, ``nonneg=True``, ``lo=``, ``hi=``, ``kind=``.
    """
    return field(default=default, metadata={"unit": unit, "source": source, **flags})
