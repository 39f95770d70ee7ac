"""Output folders written all at once: a staging folder beside the target, moved into place at the end.

A command writes its files into :func:`staged` 's staging folder, ``NAME.incomplete-XXXXXXXX``
beside the output folder ``NAME``, which holds an ``INCOMPLETE`` marker file from the
start.  When the command's block ends normally the files move into place:

* the output folder does not exist yet: the staging folder is renamed to it (one atomic
  step);
* it exists: an ``INCOMPLETE`` marker is written into it, the outputs the command owns
  but did not write this time (an old force.png after ``run --no-plot``, old figures
  after ``sweep --no-figures``) are removed, the new ones are moved in, and the marker is
  removed.  Files the command does not own (your own notes) are kept.

While the files move, SIGINT and SIGTERM are held back (delivered right after), so an
interrupt cannot cut the move short.  When the block raises (an error, Ctrl-C, SIGTERM
turned into an exception by the CLI) the staging folder is removed and the output folder
is left as it was.  Only a process killed outright (SIGKILL, power loss) can leave a
staging folder or an output folder behind with an ``INCOMPLETE`` marker, never files
that look complete.
"""
from __future__ import annotations

import contextlib
import os
import pathlib
import secrets
import shutil
import signal

__all__ = ["INCOMPLETE", "staged", "signals_held", "remove_owned"]

INCOMPLETE = "INCOMPLETE"
"""Name of the marker file of a folder whose outputs are not all in place."""

_MARKER_TEXT = ("This folder is incomplete: ebraille-sim was stopped while writing it. "
                "Its files do not form a complete result; run the command again.\n")


@contextlib.contextmanager
def signals_held():
    """Hold SIGINT and SIGTERM back for the block; they are delivered when it ends."""
    sigs = {signal.SIGINT, signal.SIGTERM}
    if not hasattr(signal, "pthread_sigmask"):
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, sigs)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def remove_owned(path, owned: dict) -> None:
    """Remove one output the command owns: a file, or the owned files of a folder.

    Parameters
    ----------
    path : path
        The output (a name of ``owned`` inside an output folder).
    owned : dict
        Output name -> glob pattern of the files a command writes into a folder of that
        name (``None`` for a file).  A folder loses only its matching files, and is removed
        once empty.
    """
    p = pathlib.Path(path)
    pattern = owned.get(p.name)
    if p.is_dir() and not p.is_symlink():
        for f in p.glob(pattern or "*"):
            if f.is_file() or f.is_symlink():
                f.unlink()
        with contextlib.suppress(OSError):
            p.rmdir()
    elif p.exists() or p.is_symlink():
        p.unlink()


def _stage_folder(out: pathlib.Path) -> pathlib.Path:
    out.parent.mkdir(parents=True, exist_ok=True)
    while True:
        stage = out.parent / f"{out.name}.incomplete-{secrets.token_hex(4)}"
        try:
            stage.mkdir()
        except FileExistsError:
            continue
        (stage / INCOMPLETE).write_text(_MARKER_TEXT, encoding="utf-8")
        return stage


def _move_in(stage: pathlib.Path, out: pathlib.Path, owned: dict) -> None:
    (stage / INCOMPLETE).unlink()
    if not out.exists():
        os.rename(stage, out)
        return
    marker = out / INCOMPLETE
    marker.write_text(_MARKER_TEXT, encoding="utf-8")
    new = {p.name for p in stage.iterdir()}
    for name in owned:
        if name not in new and (out / name).exists():
            remove_owned(out / name, owned)
    for src in sorted(stage.iterdir()):
        dest = out / src.name
        if src.is_dir() and not src.is_symlink():
            if dest.exists() or dest.is_symlink():
                remove_owned(dest, owned)
            if dest.is_dir():               # a folder with files of your own: merge into it
                for f in sorted(src.rglob("*")):
                    target = dest / f.relative_to(src)
                    if f.is_dir():
                        target.mkdir(exist_ok=True)
                    else:
                        os.replace(f, target)
            else:
                os.replace(src, dest)
        else:
            if dest.is_dir() and not dest.is_symlink():
                remove_owned(dest, {dest.name: "*"})
            os.replace(src, dest)
    marker.unlink()
    shutil.rmtree(stage, ignore_errors=True)


@contextlib.contextmanager
def staged(out_dir, owned=()):
    """Write a command's outputs into a staging folder; move them into ``out_dir`` at the end.

    Parameters
    ----------
    out_dir : path
        The output folder (created with its parents when needed).
    owned : iterable of str or dict
        The names the command writes into ``out_dir``; those it does not write this time
        are removed from ``out_dir``.  A dict maps a folder's name to the glob pattern of
        the files the command writes into it (a name mapped to ``None`` is a file).

    Yields
    ------
    pathlib.Path
        The staging folder to write into.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> out = pathlib.Path(tempfile.mkdtemp()) / "run"
    >>> with staged(out, ["metrics.json"]) as folder:
    ...     _ = (folder / "metrics.json").write_text("{}")
    >>> sorted(p.name for p in out.iterdir())
    ['metrics.json']
    """
    out = pathlib.Path(out_dir)
    owned = dict(owned) if isinstance(owned, dict) else {name: None for name in owned}
    with signals_held():
        stage = _stage_folder(out)
    try:
        yield stage
    except BaseException:
        with signals_held():
            shutil.rmtree(stage, ignore_errors=True)
        raise
    with signals_held():
        try:
            _move_in(stage, out, owned)
        finally:
            shutil.rmtree(stage, ignore_errors=True)
