"""The one writer of every output: folders written all at once, report files replaced whole.

**Output folders.**  A command claims its output folder with :class:`OutputFolder` before
any simulation: the folder is created when needed (with its parents), locked (a second run
into the same folder is refused in one line while the first holds it), and a hidden staging
folder ``.ebraille-sim-staging-XXXXXXXX`` is created inside it, holding an ``INCOMPLETE``
marker.  Writing that marker answers every writability question (permissions, a read-only
or full file system) before the work starts, and keeps the staging folder on the file
system of the output folder itself, so a folder on its own mount (a container volume)
works as any other.  Staging folders left by a run that was killed outright (SIGKILL,
power loss) are found when the next run claims the same folder: they are removed and
reported in one ``warning:`` line.

The command writes its files into the staging folder (:meth:`OutputFolder.staged`).  When
the block ends normally the files move into place: an ``INCOMPLETE`` marker is written
into the output folder, the outputs the command owns but did not write this time (an old
force.png after ``run --no-plot``, old figures after ``sweep --no-figures``) are removed,
the new ones are renamed in, and the marker is removed.  Files the command does not own
(your own notes) are kept.  While the files move, SIGINT and SIGTERM are held back
(delivered right after).  When the block raises (an error, Ctrl-C, SIGTERM turned into an
exception by the CLI) the staging folder is removed, and a folder the claim created is
removed again: the output folder is left as it was.

**Report files.**  :func:`~ebraille_sim.base.files.write_file` writes one file
(``regress --junit FILE``, a baseline, a policy's metadata) into a temporary file of a unique
name created exclusively beside it, then renames it over the target (it lives in the base
layer, so that every layer writes its files the same way).

**What is never touched.**  Nothing is written through a symbolic link: a symbolic link,
a FIFO, a device node, a socket or a folder where an output file goes (or a link or file
where an output folder goes) is refused in one line (:func:`check_file`,
:meth:`OutputFolder.check`) before the work, and again before anything is replaced.
"""
from __future__ import annotations

import contextlib
import errno
import glob
import os
import pathlib
import secrets
import shutil
import signal
import stat
import sys
import tempfile

from ebraille_sim.base.files import (check_existing, lstat_or_none, writable_ancestor, check_file, file_kind, short,
                                     signals_held, staged_file, write_file)

__all__ = ["INCOMPLETE", "STAGING_PREFIX", "OutputFolder", "staged", "signals_held", "remove_owned",
           "check_file", "staged_file", "write_file"]

INCOMPLETE = "INCOMPLETE"
"""Name of the marker file of a folder whose outputs are not all in place."""

STAGING_PREFIX = ".ebraille-sim-staging-"
"""Name prefix of the hidden staging folder inside an output folder."""

_MARKER_TEXT = ("This folder is incomplete: ebraille-sim was stopped while writing it. "
                "Its files do not form a complete result; run the command again.\n")


def remove_owned(path, owned: dict) -> None:
    """Remove one output the command owns: a file, or the owned files of a folder.

    Parameters
    ----------
    path : path
        The output (a name of ``owned`` inside an output folder).
    owned : dict
        Output name -> glob pattern of the files a command writes into a folder of that
        name (``None`` for a file).  A folder loses only its matching files, and is removed
        once empty.  A symbolic link is removed itself, never followed.
    """
    p = pathlib.Path(path)
    pattern = owned.get(p.name)
    if p.is_dir() and not p.is_symlink():
        for f in p.glob(pattern or "*"):
            if f.is_file() or f.is_symlink():
                f.unlink()
        with contextlib.suppress(OSError):
            p.rmdir()
    elif lstat_or_none(p) is not None:
        p.unlink()


def _write_marker(folder: pathlib.Path) -> None:
    path = folder / INCOMPLETE
    check_existing(path, "marker")
    flags = os.O_WRONLY | os.O_CREAT | os.O_TRUNC | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
    fd = os.open(path, flags, 0o666)
    with os.fdopen(fd, "w", encoding="utf-8") as fh:
        fh.write(_MARKER_TEXT)


_LOCK_FDS: set = set()
"""The folder descriptors this process holds locks through."""


def _close_lock_fds_in_child() -> None:
    """A forked worker process (a sweep's, a benchmark's) closes its copies of the locked
    folders' descriptors, so that the lock ends with the command's own process: a command
    killed outright frees its folder even while its workers finish their last task."""
    for fd in list(_LOCK_FDS):
        with contextlib.suppress(OSError):
            os.close(fd)
    _LOCK_FDS.clear()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_close_lock_fds_in_child)


def _say_warning(text: str) -> None:
    print(f"warning: {text}", file=sys.stderr)


class OutputFolder:
    """An output folder claimed for one command: created, locked and staged before the work.

    Parameters
    ----------
    path : path
        The output folder (created with its parents when needed).
    owned : iterable of str or dict
        The names the command writes into it (a dict maps a folder's name to the glob
        pattern of the files written into it; a name mapped to ``None`` is a file).
    option : str
        The option that named the folder, for the messages (``--out``).

    Use it as a context manager: entering claims the folder (:meth:`claim`), leaving
    releases it (:meth:`release`); write with :meth:`staged`.
    """

    def __init__(self, path, owned=(), option: str = "--out"):
        self._given = os.fspath(path)
        self.path = pathlib.Path(path)
        self.owned = dict(owned) if isinstance(owned, dict) else {name: None for name in owned}
        self.option = option
        self.stage = None
        self._fd = None
        self._created: list[pathlib.Path] = []

    def check(self) -> pathlib.Path:
        """Refuse now (one ``ValueError`` line) a folder that cannot be written; nothing is created.

        The folder must be absent or a real folder (not a symbolic link or a file), its
        nearest existing folder writable, and each output name in it absent or of its kind
        (a regular file, or a real folder for a folder of files).
        """
        if not str(self._given).strip():
            raise ValueError(f"{self.option} is empty; give a folder")
        st = lstat_or_none(self.path)
        if st is not None and stat.S_ISLNK(st.st_mode):
            raise ValueError(f"{self.option} {short(self.path)} is a symbolic link; give the folder itself "
                             f"({short(os.path.realpath(self.path))})")
        if st is not None and not stat.S_ISDIR(st.st_mode):
            kind = "a file" if stat.S_ISREG(st.st_mode) else file_kind(st.st_mode)
            raise ValueError(f"{self.option} {short(self.path)} is {kind}, not a folder")
        writable_ancestor(self.path, self.option)
        if st is not None:
            for name, pattern in self.owned.items():
                check_existing(self.path / name, f"{self.option} entry", folder=pattern is not None)
            check_existing(self.path / INCOMPLETE, f"{self.option} entry")
        return self.path

    def claim(self) -> "OutputFolder":
        """Check, create and lock the folder and make its staging folder (the work may start).

        Raises
        ------
        ValueError
            The folder cannot be written (:meth:`check`, or the system's reason), or another
            run holds it.
        """
        self.check()
        try:
            self._make()
            fd = os.open(self.path, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0) | getattr(os, "O_NOFOLLOW", 0)
                         | getattr(os, "O_CLOEXEC", 0))
        except OSError as exc:
            self._undo_created()
            raise ValueError(f"{self.option} {short(self.path)}: cannot create the folder: "
                             f"{exc.strerror or type(exc).__name__}") from None
        self._fd = fd
        try:
            self._lock()
            self._clear_stale()
            self.check()
            with signals_held():
                self.stage = self._new_stage()
        except BaseException:
            self.release()
            raise
        return self

    def _make(self) -> None:
        missing = []
        p = self.path
        while lstat_or_none(p) is None and p != p.parent:
            missing.append(p)
            p = p.parent
        for d in reversed(missing):
            try:
                d.mkdir()
            except FileExistsError:
                continue
            self._created.append(d)

    def _lock(self) -> None:
        try:
            import fcntl
        except ModuleNotFoundError:          # no advisory locks here: runs are not excluded
            return
        try:
            fcntl.flock(self._fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            _LOCK_FDS.add(self._fd)
        except OSError as exc:
            if exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                raise ValueError(f"{self.option} {short(self.path)} is being written by another ebraille-sim "
                                 f"run; wait for it to end or choose another {self.option}") from None
            raise

    def _clear_stale(self) -> None:
        """Remove the staging folders of killed runs (this run holds the lock: no other is writing)."""
        stale = [p for p in self.path.iterdir() if p.name.startswith(STAGING_PREFIX)]
        legacy = self.path.parent / f"{self.path.name}.incomplete-"
        stale += [p for p in self.path.parent.glob(f"{glob.escape(legacy.name)}*")
                  if len(p.name) == len(legacy.name) + 8 and (p / INCOMPLETE).is_file()]
        removed = []
        for p in stale:
            st = lstat_or_none(p)
            if st is not None and stat.S_ISDIR(st.st_mode):
                with contextlib.suppress(OSError):
                    shutil.rmtree(p)
                    removed.append(p.name)
        if removed:
            _say_warning(f"removed {len(removed)} staging folder(s) left in {short(self.path)} by an earlier "
                         f"run that was killed before it finished")

    def _new_stage(self) -> pathlib.Path:
        while True:
            stage = self.path / f"{STAGING_PREFIX}{secrets.token_hex(4)}"
            try:
                stage.mkdir()
            except FileExistsError:
                continue
            try:
                _write_marker(stage)
            except OSError as exc:
                shutil.rmtree(stage, ignore_errors=True)
                raise ValueError(f"{self.option} {short(self.path)}: cannot write into the folder: "
                                 f"{exc.strerror or type(exc).__name__}") from None
            return stage

    @contextlib.contextmanager
    def staged(self):
        """Write into the staging folder; its files move into the output folder when the block ends."""
        if self._fd is None:
            raise RuntimeError("claim the output folder first")
        if self.stage is None:
            with signals_held():
                self.stage = self._new_stage()
        stage = self.stage
        try:
            yield stage
        except BaseException:
            with signals_held():
                shutil.rmtree(stage, ignore_errors=True)
                self.stage = None
            raise
        with signals_held():
            try:
                self._move_in(stage)
                self._created.clear()          # the folder holds a result now: keep it
            finally:
                shutil.rmtree(stage, ignore_errors=True)
                self.stage = None

    def _move_in(self, stage: pathlib.Path) -> None:
        out, owned = self.path, self.owned
        (stage / INCOMPLETE).unlink()
        new = sorted(stage.iterdir())
        for src in new:                               # refuse before anything is replaced
            check_existing(out / src.name, f"{self.option} entry",
                            folder=src.is_dir() and not src.is_symlink())
            if src.is_dir() and not src.is_symlink() and (out / src.name).is_dir():
                for f in src.rglob("*"):
                    if not f.is_dir():
                        check_existing(out / src.name / f.relative_to(src), f"{self.option} entry")
        _write_marker(out)
        names = {p.name for p in new}
        for name in owned:
            if name not in names and lstat_or_none(out / name) is not None:
                remove_owned(out / name, owned)
        for src in new:
            dest = out / src.name
            if src.is_dir() and not src.is_symlink():
                if dest.is_dir() and not dest.is_symlink():     # a folder with files of your own: merge
                    pattern = owned.get(src.name)
                    if pattern is not None:                      # owned files not written again go
                        written = {f.name for f in src.glob(pattern)}
                        for old in dest.glob(pattern):
                            if old.name not in written and (old.is_file() or old.is_symlink()):
                                old.unlink()
                    for f in sorted(src.rglob("*")):
                        target = dest / f.relative_to(src)
                        if f.is_dir():
                            target.mkdir(exist_ok=True)
                        else:
                            os.replace(f, target)
                else:
                    os.replace(src, dest)
            else:
                os.replace(src, dest)
        (out / INCOMPLETE).unlink()

    def release(self) -> None:
        """Unlock; remove the staging folder, and the folders the claim created if they are still empty."""
        with signals_held():
            if self.stage is not None:
                shutil.rmtree(self.stage, ignore_errors=True)
                self.stage = None
            self._undo_created()
            if self._fd is not None:
                _LOCK_FDS.discard(self._fd)
                os.close(self._fd)
                self._fd = None

    def _undo_created(self) -> None:
        for d in reversed(self._created):
            with contextlib.suppress(OSError):
                d.rmdir()
        self._created.clear()

    def __enter__(self) -> "OutputFolder":
        return self if self._fd is not None else self.claim()

    def __exit__(self, *exc) -> None:
        self.release()


@contextlib.contextmanager
def staged(out_dir, owned=(), option: str = "--out"):
    """Write a command's outputs into a staging folder; move them into ``out_dir`` at the end.

    The folder is claimed for the block (:class:`OutputFolder`): created when needed,
    locked, staged.

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
    with OutputFolder(out_dir, owned, option) as target, target.staged() as folder:
        yield folder
