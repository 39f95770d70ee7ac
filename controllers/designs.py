"""Designs: a controller, its gains and the firmware they were tuned for, by name.

A design is what a user takes to a board: the controller family, its gains, the firmware
preset (:mod:`ebraille_sim.estimation.presets`) the gains were tuned on, a description, and
the benchmark score it made with the command that reproduced it.  The shipped designs are
package data (``ebraille_sim/data/designs/*.toml``); a user's own design file has the same
keys and works the same way wherever a design name is accepted (``run --controller``,
``benchmark``)::

    name = "my_design"                 # optional in a user file
    description = "..."                # optional
    controller = "pid_dob"             # a registered controller
    firmware = "fast_1khz"             # optional: the firmware preset the gains need
    [gains]
    kp_v_per_n = 2.9
    [benchmark]                        # optional: score, suite, readers, command, measured
    score = 88.0
    [check]                            # optional: a metric of a nominal run it reproduces
    scenario = "refresh_120wpm"
    char_in_band_fraction = 0.95

A plain gains file (``controller`` and ``gains`` only) is a design without a firmware: it
runs on the scenario's.

Examples
--------
>>> from controllers.designs import designs, get_design
>>> sorted(designs())
['dob_100hz', 'dob_hold_1khz', 'dob_learn_1khz', 'dob_wide_1khz']
>>> d = get_design("dob_learn_1khz")
>>> d.controller, d.firmware
('pid_dob', 'fast_1khz')
"""
from __future__ import annotations

import functools
import importlib.resources
import math
import os
import pathlib
from dataclasses import dataclass, field

from ebraille_sim.base.validation import check_keys, read_table
from ebraille_sim.estimation.presets import check_name, get_firmware, read_score

__all__ = ["Design", "designs", "get_design", "is_design_file", "design_files", "DESIGN_KEYS", "WORKING_FOLDER"]

DESIGN_KEYS = ("name", "description", "controller", "firmware", "gains", "benchmark", "check")
"""The keys of a design file (a gains file uses ``controller`` and ``gains``)."""

_SUFFIXES = (".toml", ".json")

WORKING_FOLDER = "designs"
"""Folder of the working directory whose design files ``ebraille-sim list`` shows with the
shipped ones (as ``./scenarios`` holds your own scenarios)."""


@dataclass(frozen=True)
class Design:
    """A controller with its gains and the firmware preset they were tuned for.

    Attributes
    ----------
    name : str
        The design's name (a file's stem when the file names none).
    description : str
    controller : str
        A registered controller family (:func:`controllers.available`; checked when the
        controller is made).
    gains : dict
        Keyword arguments of that family's factory.
    firmware : str or None
        The firmware preset the design runs on (None: the scenario's firmware).
    benchmark : dict
        ``score`` (points), ``suite``, ``readers``, ``command`` (reproduces the score), ``measured``.
    check : dict
        ``scenario`` and metric values that a nominal run of that scenario with this design gives.
    source : str
        The file it was read from.
    """
    name: str
    description: str
    controller: str
    gains: dict = field(default_factory=dict)
    firmware: str | None = None
    benchmark: dict = field(default_factory=dict)
    check: dict = field(default_factory=dict)
    source: str = ""

    @property
    def score(self) -> float | None:
        """The design's benchmark score, points (None: not measured)."""
        return self.benchmark.get("score")


def _from_table(where: str, data: dict, stem: str, source: str | None = None) -> Design:
    check_keys(where, data, DESIGN_KEYS)
    name = check_name(where, data.get("name", stem))
    ctrl = data.get("controller")
    if not isinstance(ctrl, str):
        raise ValueError(f"{where}: 'controller' must name a controller family, got {ctrl!r}")
    gains = data.get("gains", {})
    if not isinstance(gains, dict):
        raise ValueError(f"{where}: [gains] must be a table, got {type(gains).__name__}")
    fw = data.get("firmware")
    if fw is not None:
        try:
            get_firmware(fw)
        except (ValueError, FileNotFoundError) as exc:
            raise ValueError(f"{where}: firmware: {exc}") from None
    desc = data.get("description", "")
    if not isinstance(desc, str):
        raise ValueError(f"{where}: 'description' must be text")
    check = data.get("check", {})
    if not isinstance(check, dict) or (check and not isinstance(check.get("scenario"), str)):
        raise ValueError(f"{where}: [check] must be a table naming a 'scenario'")
    for k, v in check.items():
        if k != "scenario" and (isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v)):
            raise ValueError(f"{where}: [check] {k} must be a finite number, got {v!r}")
    return Design(name, desc, ctrl, dict(gains), fw, read_score(where, data.get("benchmark", {})), dict(check),
                  where if source is None else source)


def _shipped_dir() -> pathlib.Path:
    return pathlib.Path(str(importlib.resources.files("ebraille_sim") / "data" / "designs"))


@functools.lru_cache(maxsize=1)
def designs() -> dict[str, Design]:
    """The shipped designs by name (read once per process; :func:`controllers.make` builds one)."""
    out = {}
    for p in sorted(_shipped_dir().glob("*.toml")):
        d = _from_table(p.name, read_table(str(p), "design"), p.stem, str(p))
        if d.name != p.stem:
            raise ValueError(f"{p.name}: name {d.name!r} differs from the file's")
        out[d.name] = d
    return out


def is_design_file(name_or_path) -> bool:
    """Whether ``name_or_path`` names a ``.toml``/``.json`` file (a design or gains file)."""
    return isinstance(name_or_path, (str, os.PathLike)) and os.fspath(name_or_path).lower().endswith(_SUFFIXES)


def get_design(name_or_path) -> Design:
    """A shipped design by name, or a design/gains file by path (one-line ``ValueError``,
    ``FileNotFoundError`` for a missing file)."""
    shipped = designs()
    if isinstance(name_or_path, str) and name_or_path in shipped:
        return shipped[name_or_path]
    if is_design_file(name_or_path):
        p = os.fspath(name_or_path)
        return _from_table(p, read_table(p, "design file"), pathlib.Path(p).stem)
    raise ValueError(f"unknown design {name_or_path!r}; available: {', '.join(shipped)} (or a design file .toml/.json)")


def design_files(paths=(), working_folder: bool = True) -> list[Design]:
    """Your own design files: each ``.toml``/``.json`` of :data:`WORKING_FOLDER` (with
    ``working_folder``) and of ``paths`` (files, or folders whose design files are taken), in
    that order, sorted by file within a folder; a file given twice is read once.

    Each is read as :func:`get_design` reads it.  Raises one line naming the file and its
    problem: a ``FileNotFoundError`` for a path that does not exist, a ``ValueError``
    otherwise (a file that is no ``.toml``/``.json``, malformed, or not a design).
    """
    files: list[pathlib.Path] = []
    folder = pathlib.Path(WORKING_FOLDER)
    roots = ([folder] if working_folder and folder.is_dir() else []) + [pathlib.Path(os.fspath(p)) for p in paths]
    for root in roots:
        if root.is_dir():
            files += sorted(f for f in root.iterdir() if f.is_file() and is_design_file(f.name))
        elif not root.exists():
            raise FileNotFoundError(f"design file not found: {root}")
        elif not is_design_file(root.name):
            raise ValueError(f"{root}: a design file is .toml or .json")
        else:
            files.append(root)
    out, seen = [], set()
    for f in files:
        key = f.resolve()
        if key in seen:
            continue
        seen.add(key)
        out.append(get_design(str(f)))
    return out
