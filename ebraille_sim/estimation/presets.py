"""Named firmware presets: the estimator settings a board's firmware ships with.

A firmware preset is a named set of :class:`ebraille_sim.physics.params.EstimatorParams`
values (the ``[estimator]`` keys of a scenario file) with a description and the benchmark
score of the best shipped design that runs on it.  The presets ship as package data
(``ebraille_sim/data/firmware/*.toml``); a scenario names one with ``[estimator] firmware =
"NAME"`` and a design (:mod:`controllers.designs`) carries the name of the firmware it was
tuned for.

A preset file::

    name = "fast_1khz"
    description = "..."
    [estimator]
    model = "paper:wiener:5@1000"
    [benchmark]
    score = 88.0
    design = "dob_learn_1khz"
    command = "ebraille-sim benchmark dob_learn_1khz --no-bounds"

Examples
--------
>>> from ebraille_sim.estimation.presets import firmware_presets, get_firmware
>>> sorted(firmware_presets())
['fast_1khz', 'fast_1khz_centred', 'paper_100hz']
>>> get_firmware("fast_1khz").estimator["model"]
'paper:wiener:5@1000'
"""
from __future__ import annotations

import dataclasses
import functools
import importlib.resources
import math
import pathlib
from dataclasses import dataclass, field

from ebraille_sim.base.validation import check_keys, read_table, replace_checked
from ebraille_sim.physics.params import EstimatorParams

__all__ = ["Firmware", "firmware_presets", "get_firmware", "read_score", "check_name"]

_KEYS = ("name", "description", "estimator", "benchmark")
_SCORE_KEYS = ("score", "design", "suite", "readers", "command", "measured")
ESTIMATOR_KEYS = tuple(f.name for f in dataclasses.fields(EstimatorParams))
"""The settings a firmware preset may hold (the fields of ``EstimatorParams``)."""


@dataclass(frozen=True)
class Firmware:
    """A named firmware preset.

    Attributes
    ----------
    name : str
    description : str
    estimator : dict
        ``EstimatorParams`` fields and their values (checked).
    benchmark : dict
        ``score`` (the benchmark's overall score, points), ``design`` (the design that made it),
        ``suite``, ``readers``, ``command`` (the command that reproduces it), ``measured``.
    """
    name: str
    description: str
    estimator: dict = field(default_factory=dict)
    benchmark: dict = field(default_factory=dict)

    @property
    def score(self) -> float | None:
        """The benchmark score of the best design on this firmware, points (None: not measured)."""
        return self.benchmark.get("score")


def check_name(where: str, name) -> str:
    """A preset or design name: a non-empty identifier-like string (one-line ``ValueError``)."""
    if not isinstance(name, str) or not name or not all(c.isalnum() or c in "_-." for c in name):
        raise ValueError(f"{where}: 'name' must be letters, digits, '_', '-' or '.', got {name!r}")
    return name


def read_score(where: str, data) -> dict:
    """Check a ``[benchmark]`` table: its keys, and ``score`` a finite number (one-line ``ValueError``)."""
    if not isinstance(data, dict):
        raise ValueError(f"{where}: [benchmark] must be a table, got {type(data).__name__}")
    check_keys(f"{where} [benchmark]", data, _SCORE_KEYS)
    s = data.get("score")
    if s is not None and (isinstance(s, bool) or not isinstance(s, (int, float)) or not math.isfinite(s)):
        raise ValueError(f"{where}: [benchmark] score must be a finite number, got {s!r}")
    return dict(data)


def _from_table(where: str, data: dict) -> Firmware:
    check_keys(where, data, _KEYS)
    name = check_name(where, data.get("name"))
    desc = data.get("description", "")
    if not isinstance(desc, str):
        raise ValueError(f"{where}: 'description' must be text")
    est = data.get("estimator", {})
    if not isinstance(est, dict):
        raise ValueError(f"{where}: [estimator] must be a table, got {type(est).__name__}")
    check_keys(f"{where} [estimator]", est, ESTIMATOR_KEYS)
    replace_checked(EstimatorParams(), **est)
    return Firmware(name, desc, dict(est), read_score(where, data.get("benchmark", {})))


def _shipped_dir() -> pathlib.Path:
    return pathlib.Path(str(importlib.resources.files("ebraille_sim") / "data" / "firmware"))


@functools.lru_cache(maxsize=1)
def firmware_presets() -> dict[str, Firmware]:
    """The shipped firmware presets by name (read once per process)."""
    out = {}
    for p in sorted(_shipped_dir().glob("*.toml")):
        fw = _from_table(p.name, read_table(str(p), "firmware preset"))
        if fw.name != p.stem:
            raise ValueError(f"{p.name}: name {fw.name!r} differs from the file's")
        out[fw.name] = fw
    return out


def get_firmware(name: str) -> Firmware:
    """A shipped firmware preset by name, or a preset file (``.toml``/``.json``) by path.

    Raises a one-line ``ValueError`` naming the available presets for an unknown name.
    """
    presets = firmware_presets()
    if isinstance(name, str) and name in presets:
        return presets[name]
    if isinstance(name, str) and name.lower().endswith((".toml", ".json")):
        return _from_table(name, read_table(name, "firmware preset"))
    raise ValueError(f"unknown firmware {name!r}; available: {', '.join(presets)} (or a preset file .toml/.json)")
