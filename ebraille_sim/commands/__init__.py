"""Sub-commands of the ``ebraille-sim`` command line.

Each module in this package defines ``NAME`` (the sub-command), ``HELP`` (one line),
``add_arguments(parser)`` and ``main(args) -> int``; :mod:`ebraille_sim.cli` finds them
with :mod:`pkgutil`, so a new sub-command is a new module here.  Errors meant for the
user are raised as :class:`UserError` (or ``ValueError``/``FileNotFoundError``) and
printed as one ``error: ...`` line with exit status 2.

Numeric options are parsed by :func:`whole` and :func:`number`, which refuse a value out
of range (and NaN, infinities, fractions for whole numbers) while the command line is
read: ``error: argument --seed: ...``, exit status 2, before any work.  A command checks
what depends on its inputs (a duration against the memory of the run, the scenarios, the
controllers, the output folder) at the top of its ``main``, still before any simulation.

:mod:`ebraille_sim.cli` gives every sub-command ``--json`` and ``-q/--quiet`` and passes
a :class:`Console` as ``args.console``: a command prints its human-readable lines with
:meth:`Console.say`, hands its result to :meth:`Console.result` (printed as the one JSON
document under ``--json``) and shows progress only when :attr:`Console.progress` is true.
"""
from __future__ import annotations

import argparse
import builtins
import json
import math
import pathlib
import sys

SEED_LIMIT = 2 ** 63
"""Seeds are whole numbers in ``[0, SEED_LIMIT)``."""

MAX_JOBS = 256
"""Most local worker processes a command starts (``-j``)."""


class UserError(Exception):
    """An input problem to report as one line (exit status 2)."""


def plain(value):
    """``value`` with numpy scalars/arrays as Python numbers/lists and NaN/inf as None (strict JSON)."""
    if isinstance(value, dict):
        return {str(k): plain(v) for k, v in value.items()}
    # the sub-module ``list`` shadows the builtin in this package's namespace
    if isinstance(value, (builtins.list, tuple)):
        return [plain(v) for v in value]
    if isinstance(value, pathlib.PurePath):
        return str(value)
    if hasattr(value, "tolist") and not isinstance(value, (str, bytes)):
        return plain(value.tolist())
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


class Console:
    """Where a command's output goes.

    Parameters
    ----------
    json : bool
        Print only the command's result, as one JSON document, on stdout.
    quiet : bool
        Print nothing but errors and warnings (stderr); no progress.  With ``json`` the
        document is still printed.
    """

    def __init__(self, json: bool = False, quiet: bool = False):
        self.json, self.quiet = bool(json), bool(quiet)
        self.document = None

    @property
    def progress(self) -> bool:
        """Whether progress may be shown (on stderr)."""
        return not self.quiet

    def say(self, text: str = "") -> None:
        """A human-readable line on stdout (dropped under ``--json`` and ``--quiet``)."""
        if not (self.json or self.quiet):
            print(text)

    def result(self, doc: dict) -> None:
        """The command's result: the document ``--json`` prints."""
        self.document = doc

    def json_text(self) -> str:
        """The result as strict JSON (NaN and infinities as null)."""
        return json.dumps(plain(self.document), indent=2, allow_nan=False, default=str)


def _shown(text) -> str:
    text = str(text)
    return repr(text if len(text) <= 40 else text[:37] + "...")


def whole(lo: int, hi: int | None = None):
    """An argparse ``type``: a whole number in ``[lo, hi]`` (``hi`` None: no upper bound).

    >>> whole(1, 8)("3")
    3
    """
    def parse(text):
        try:
            value = int(str(text).strip())
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a whole number, got {_shown(text)}") from None
        if value < lo or (hi is not None and value > hi):
            span = f"in [{lo}, {hi}]" if hi is not None else f">= {lo}"
            raise argparse.ArgumentTypeError(f"must be a whole number {span}, got {_shown(text)}")
        return value
    parse.__name__ = "whole number"
    return parse


def seed(text) -> int:
    """An argparse ``type``: a seed, a whole number in ``[0, 2**63)``."""
    try:
        value = int(str(text).strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {_shown(text)}") from None
    if not 0 <= value < SEED_LIMIT:
        raise argparse.ArgumentTypeError(f"a seed must lie in [0, 2**63), got {_shown(text)}")
    return value


def number(lo: float | None = None, hi: float | None = None, lo_open: bool = False, hi_open: bool = False,
           allow_inf: bool = False):
    """An argparse ``type``: a finite number in the interval ``lo..hi`` (open ends as flagged).

    With ``allow_inf`` ``+inf`` is accepted too (meaning "no bound").

    >>> number(0, None, lo_open=True)("2.5")
    2.5
    """
    def parse(text):
        try:
            value = float(str(text).strip())
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number, got {_shown(text)}") from None
        if math.isnan(value) or (math.isinf(value) and not (allow_inf and value > 0)):
            raise argparse.ArgumentTypeError(f"must be a finite number, got {_shown(text)}")
        below = lo is not None and (value <= lo if lo_open else value < lo)
        above = hi is not None and (value >= hi if hi_open else value > hi)
        if below or above:
            left = "-inf" if lo is None else f"{lo:g}"
            right = ("inf" if hi is None else f"{hi:g}")
            span = f"{'(' if lo_open or lo is None else '['}{left}, {right}{')' if hi_open or hi is None else ']'}"
            raise argparse.ArgumentTypeError(f"must lie in {span}, got {_shown(text)}")
        return value
    parse.__name__ = "number"
    return parse


def check_duration(spec, duration_s, option: str = "--duration") -> None:
    """Refuse a duration shorter than one control period or whose arrays exceed the memory bound.

    The bound is :data:`ebraille_sim.scenarios.inputs.MAX_RUN_BYTES` over
    :data:`~ebraille_sim.scenarios.inputs.BYTES_PER_CONTROL_SAMPLE` bytes per control
    period of the scenario's control rate (the message gives the numbers).
    """
    from ebraille_sim.scenarios.inputs import check_run_size
    if duration_s is None:
        return
    hz = spec.device.rates.control_rate_hz
    if round(duration_s * hz) < 1:
        raise UserError(f"{option} {duration_s:g} s is shorter than one control period "
                        f"({1.0 / hz:g} s at control_hz = {hz:g})")
    try:
        check_run_size(spec, duration_s, f"{option} {duration_s:g} s")
    except ValueError as exc:
        raise UserError(str(exc)) from None


def console(args) -> Console:
    """The :class:`Console` of parsed ``args`` (a plain one when called without the CLI)."""
    con = getattr(args, "console", None)
    if con is None:
        con = Console(json=getattr(args, "json", False) is True, quiet=getattr(args, "quiet", False))
        args.console = con
    return con


def check_out_dir(path, option: str = "--out", owned=()) -> pathlib.Path:
    """``path`` as an output folder, refused now (one line) if it cannot be one.

    Nothing is created: the folder must be absent or a real folder (not a symbolic link),
    its nearest existing folder writable, and each of the ``owned`` output names in it
    absent or a regular file (:meth:`ebraille_sim.tools.outputs.OutputFolder.check`).
    """
    from ebraille_sim.tools.outputs import OutputFolder
    try:
        return OutputFolder(path, owned, option).check()
    except ValueError as exc:
        raise UserError(str(exc)) from None


def claim_out_dir(path, owned=(), option: str = "--out"):
    """The :class:`~ebraille_sim.tools.outputs.OutputFolder` of ``path``, claimed now (created,
    locked, staged) so that every writability question is answered before the work; a
    refusal is a :class:`UserError`.  Use it as a context manager around the work."""
    from ebraille_sim.tools.outputs import OutputFolder
    folder = OutputFolder(path, owned, option)
    try:
        return folder.claim()
    except ValueError as exc:
        raise UserError(str(exc)) from None


class FrameProgress:
    """Progress of a long loop on stderr: a carriage-return counter on a terminal, else a
    line every ``every`` items (and one at the end).

    Call it as ``progress(done, total)``; :meth:`close` ends the counter's line.
    """

    def __init__(self, label: str, enabled: bool = True, every: int | None = None, stream=None):
        self.label, self.enabled, self.every = label, enabled, every
        self.stream = sys.stderr if stream is None else stream
        self._tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self._open = False

    def __call__(self, done: int, total: int) -> None:
        if not self.enabled:
            return
        if self._tty:
            self.stream.write(f"\r{self.label} {done}/{total}")
            self._open = True
            if done >= total:
                self.close()
            self.stream.flush()
            return
        every = self.every or max(25, math.ceil(total / 10))
        if done % every == 0 or done >= total:
            self.stream.write(f"{self.label} {done}/{total}\n")
            self.stream.flush()

    def close(self) -> None:
        if self._open:
            self.stream.write("\n")
            self.stream.flush()
            self._open = False
