"""The ``ebraille-sim`` command line (also ``python -m ebraille_sim``).

Sub-commands live in :mod:`ebraille_sim.commands`.  Every input problem (missing file,
malformed TOML, unknown key, bad number) ends with one ``error: ...`` line on stderr and
exit status 2, never a traceback; nothing is written half-way.  Exit status 1 means the
command ran but its checks failed: ``run`` when a scenario ``[criteria]`` limit fails,
``regress`` when a scenario moved from its baseline.  A warning (e.g. a setpoint below the
tactile range) is one ``warning: ...`` line on stderr.

Ctrl-C ends a command with ``error: interrupted`` and exit status 130, SIGTERM with
``error: terminated (SIGTERM)`` and exit status 143; either way the command's output
folder is left as it was (outputs are written into a staging folder and moved into
place at the end, :mod:`ebraille_sim.tools.outputs`).  A failure of the file system
while writing (disk full, permission denied) is one ``error: ...`` line, exit status 2.

Every sub-command takes ``--json`` (print only the command's result as one JSON document
on stdout; ``regress --json FILE`` writes it to FILE instead) and ``-q/--quiet`` (print
nothing but errors and warnings, no progress); the exit status does not change.  Under
``--json`` an input error prints no document, only its ``error:`` line.
"""
from __future__ import annotations

import argparse
import contextlib
import importlib
import io
import os
import pkgutil
import signal
import sys
import threading
import warnings

from ebraille_sim import __version__


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised in the main thread so that cleanup code runs as for Ctrl-C."""


def _on_sigterm(signum, frame):
    raise Terminated()


@contextlib.contextmanager
def _sigterm_as_exception():
    """Turn SIGTERM into :class:`Terminated` for the block (main thread only)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGTERM, _on_sigterm)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


MAX_ERROR_LINE = 300
"""Longest ``error: ...`` line printed; a longer message is shortened in the middle."""


def error_line(message: str) -> str:
    """``error: MESSAGE`` on one line of at most :data:`MAX_ERROR_LINE` characters."""
    text = " ".join(str(message).split())
    line = f"error: {text}"
    if len(line) > MAX_ERROR_LINE:
        keep = (MAX_ERROR_LINE - 5) // 2
        line = f"{line[:keep]} ... {line[-keep:]}"
    return line


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        self.exit(2, error_line(message) + "\n")


def _commands(only: str | None = None):
    """The sub-command modules, in the order of the help (``only``: just the module of that
    name, when there is one; the others are not imported)."""
    from ebraille_sim import commands
    mods = []
    names = sorted(info.name for info in pkgutil.iter_modules(commands.__path__))
    if only in names:
        names = [only]
    for name in names:
        mod = importlib.import_module(f"{commands.__name__}.{name}")
        if hasattr(mod, "NAME") and hasattr(mod, "main"):
            mods.append(mod)
    order = {"run": 0, "list": 1}
    return sorted(mods, key=lambda m: (order.get(m.NAME, 9), m.NAME))


def add_output_options(p, json_file: bool = False) -> None:
    """``--json`` and ``-q/--quiet``, the same on every sub-command.

    With ``json_file`` ``--json`` also takes an optional FILE to write the document to.
    """
    if json_file:
        p.add_argument("--json", nargs="?", const=True, default=False, metavar="FILE",
                       help="print the result as one JSON document on stdout and nothing else; "
                            "with FILE write it there and print the usual report")
    else:
        p.add_argument("--json", action="store_true",
                       help="print the result as one JSON document on stdout and nothing else")
    p.add_argument("-q", "--quiet", action="store_true",
                   help="print nothing but errors and warnings (no progress; --json still prints its document)")


def build_parser(command: str | None = None):
    """The parser of the command line and ``{name: module}`` of its sub-commands.

    With ``command`` (the first argument, when it names a sub-command) only that
    sub-command's parser is built: it parses its arguments, and reports errors and help, as
    the full parser does, without importing the other sub-commands."""
    parser = _Parser(prog="ebraille-sim",
                     description="Closed-loop contact-force simulator for a finger-wearable E-Braille reader.")
    parser.add_argument("--version", action="version", version=f"ebraille-sim {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    table = {}
    for mod in _commands(command):
        p = sub.add_parser(mod.NAME, help=mod.HELP, description=mod.HELP, epilog=getattr(mod, "EPILOG", None))
        mod.add_arguments(p)
        add_output_options(p, json_file=getattr(mod, "JSON_FILE", False))
        table[mod.NAME] = mod
    return parser, table


def _tolerant_streams() -> None:
    """Print what the terminal's encoding cannot show as escapes (a non-ASCII path under
    ``PYTHONIOENCODING=ascii``) instead of failing after the work is done."""
    for stream in (sys.stdout, sys.stderr):
        reconfigure = getattr(stream, "reconfigure", None)
        if reconfigure is not None and stream.errors == "strict":
            with contextlib.suppress(ValueError, OSError):
                reconfigure(errors="backslashreplace")


def main(argv=None) -> int:
    from ebraille_sim.commands import Console, UserError
    _tolerant_streams()
    argv = sys.argv[1:] if argv is None else list(argv)
    parser, table = build_parser(argv[0] if argv and not argv[0].startswith("-") else None)
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:
        return int(exc.code or 0)
    if os.environ.get("NUMBA_DISABLE_JIT", "0").strip() not in ("", "0"):
        print(error_line("NUMBA_DISABLE_JIT is set: the simulator runs only as compiled code (run as plain "
                         "Python its integer noise overflows and the run is wrong); unset it"), file=sys.stderr)
        return 2
    if not args.command:
        names = ", ".join(mod.NAME for mod in _commands())
        print(error_line(f"give a command: {names} (ebraille-sim --help describes them)"), file=sys.stderr)
        return 2
    def one_line(message, category, filename, lineno, file=None, line=None):
        text = str(message).strip().splitlines()
        print(f"warning: {text[0] if text else category.__name__}", file=sys.stderr)

    con = args.console = Console(json=args.json is True, quiet=args.quiet)
    stdout = sys.stdout
    # under --json stray prints of library code go to stderr, under --quiet nowhere
    divert = (contextlib.redirect_stdout(sys.stderr) if con.json else
              contextlib.redirect_stdout(io.StringIO()) if con.quiet else contextlib.nullcontext())
    try:
        with _sigterm_as_exception(), warnings.catch_warnings(), divert:
            warnings.showwarning = one_line
            code = int(table[args.command].main(args) or 0)
        if con.json and con.document is not None:
            print(con.json_text(), file=stdout)
        return code
    except (UserError, ValueError, FileNotFoundError, KeyError, FloatingPointError) as exc:
        msg = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        if isinstance(exc, KeyError):
            msg = msg.strip("'\"")
        print(error_line(msg), file=sys.stderr)
        return 2
    except RecursionError:
        print(error_line("input nested too deeply to read"), file=sys.stderr)
        return 2
    except MemoryError:
        print(error_line("out of memory: the inputs ask for more than this machine holds"), file=sys.stderr)
        return 2
    except Terminated:
        print("error: terminated (SIGTERM)", file=sys.stderr)
        return 143
    except KeyboardInterrupt:
        print("error: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        return _closed_stdout()
    except OSError as exc:
        where = f": {exc.filename}" if exc.filename else ""
        print(error_line(f"{exc.strerror or type(exc).__name__}{where}"), file=sys.stderr)
        return 2


def _closed_stdout() -> int:
    """The reader of stdout went away (e.g. ``| head``): stop quietly, as Unix tools do."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):
        pass
    return 0


if __name__ == "__main__":
    sys.exit(main())
