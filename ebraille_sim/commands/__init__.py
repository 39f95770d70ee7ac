"""Sub-commands of the ``ebraille-sim`` command line.

Each module in this package defines ``NAME`` (the sub-command), ``HELP`` (one line),
``add_arguments(parser)`` and ``main(args) -> int``; :mod:`ebraille_sim.cli` finds them
with :mod:`pkgutil`, so a new sub-command is a new module here.  Errors meant for the
user are raised as :class:`UserError` (or ``ValueError``/``FileNotFoundError``) and
printed as one ``error: ...`` line with exit status 2.

:mod:`ebraille_sim.cli` gives every sub-command ``--json`` and ``-q/--quiet`` and passes
a :class:`Console` as ``args.console``: a command prints its human-readable lines with
:meth:`Console.say`, hands its result to :meth:`Console.result` (printed as the one JSON
document under ``--json``) and shows progress only when :attr:`Console.progress` is true.
"""
from __future__ import annotations

import builtins
import json
import math
import os
import pathlib
import sys


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


def console(args) -> Console:
    """The :class:`Console` of parsed ``args`` (a plain one when called without the CLI)."""
    con = getattr(args, "console", None)
    if con is None:
        con = Console(json=getattr(args, "json", False) is True, quiet=getattr(args, "quiet", False))
        args.console = con
    return con


def check_out_dir(path, option: str = "--out") -> pathlib.Path:
    """``path`` as an output folder, refused now (one line) if it cannot be one.

    Nothing is created: the folder itself, or else its nearest existing parent, must be a
    folder this process may write into.
    """
    p = pathlib.Path(path)
    if p.exists() and not p.is_dir():
        raise UserError(f"{option} {str(p)!r} is a file, not a folder")
    probe = p
    while not probe.exists() and probe != probe.parent:
        probe = probe.parent
    if not probe.is_dir():
        raise UserError(f"{option} {str(p)!r}: {str(probe)!r} is a file, not a folder")
    if not os.access(probe, os.W_OK | os.X_OK):
        raise UserError(f"{option} {str(p)!r}: folder {str(probe)!r} is not writable")
    return p


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
