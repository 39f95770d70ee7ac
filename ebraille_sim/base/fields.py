"""Dataclass fields that carry a unit, a source tag, a description and their admissible range.

Every parameter of the simulator, physical or not, is declared with :func:`sourced`, so
that reports, docs and validation read the same metadata: ``unit``, ``source`` (``[R]``
read, ``[D]`` derived, ``[E]`` estimate, see docs/model.md), ``doc`` (one line saying what
the value is) and optional bounds ``positive``, ``nonneg``, ``lo``, ``hi`` and a ``kind``.
The scenario reference (:mod:`ebraille_sim.tools.schema`) is generated from this metadata
and refuses a field without ``unit`` or ``doc``.

Examples
--------
>>> from dataclasses import dataclass, fields
>>> @dataclass(frozen=True)
... class Spring:
...     k_n_per_m: float = sourced(3e4, "N/m", "[E] plastic mesh contact", positive=True,
...                                doc="Stiffness of the gear mesh.")
>>> m = fields(Spring)[0].metadata
>>> m["unit"], m["doc"]
('N/m', 'Stiffness of the gear mesh.')
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
        Further metadata: ``doc=`` (the one-line description the scenario reference shows),
        ``positive=True``, ``nonneg=True``, ``lo=``, ``hi=``, ``kind=``,
        ``experimental=True`` (a study knob: no stability promise).  ``default`` may be
        :data:`dataclasses.MISSING` for a required field.
    """
    return field(default=default, metadata={"unit": unit, "source": source, **flags})
