"""One reader for every input file (regular files only, a size bound, a nesting bound) and
one writer of single output files (an exclusive temporary file renamed over a regular file).

Every file the simulator reads on a user's behalf (a scenario, a reading text, a gains
file, an estimator model, a baseline, a results file, a bench CSV) goes through
:func:`read_bytes`: it opens the file without blocking (a FIFO cannot hang the command),
refuses what is not a regular file (a folder, a FIFO, a device such as ``/dev/zero``) and a
file larger than its bound, and reports each problem as one ``ValueError`` line (a missing
file as ``FileNotFoundError``).  :func:`read_json` and :func:`read_toml` parse the bytes and
refuse documents nested deeper than :data:`MAX_DEPTH` (the parsers' own recursion never
escapes as ``RecursionError``).

:func:`write_file` and :func:`staged_file` replace one output file: the data go into a
temporary file of a unique name created exclusively beside the target and are renamed over
it; the target must be absent or a regular file (never a link, FIFO, device or folder),
checked before and again just before the rename, with SIGINT and SIGTERM held back.  Output
folders are claimed, staged and locked by :mod:`ebraille_sim.tools.outputs`, which uses these.

Examples
--------
>>> import os, tempfile
>>> d = tempfile.mkdtemp()
>>> p = os.path.join(d, "g.json")
>>> _ = open(p, "w").write('{"kp": 1.5}')
>>> read_json(p, "gains file")
{'kp': 1.5}
>>> os.mkfifo(os.path.join(d, "f.json"))
>>> read_json(os.path.join(d, "f.json"), "gains file")
Traceback (most recent call last):
...
ValueError: gains file '.../f.json' is a FIFO, not a regular file
"""
from __future__ import annotations

import contextlib
import errno
import json
import os
import pathlib
import signal
import stat
import tempfile

__all__ = ["MAX_INPUT_BYTES", "MAX_DEPTH", "short", "file_kind", "check_regular", "read_bytes", "read_text", "read_json",
           "read_toml", "check_depth", "signals_held", "lstat_or_none", "check_existing", "writable_ancestor", "check_file",
           "staged_file", "write_file"]

MAX_INPUT_BYTES = 64 * 2 ** 20
"""Largest input file read (64 MiB) unless a reader states its own bound."""

MAX_DEPTH = 64
"""Deepest nesting of tables/arrays (objects/lists) accepted in an input document."""

MAX_SHOWN = 120
"""Longest path or name quoted whole in a message; longer ones are shortened in the middle."""


def short(text, limit: int = MAX_SHOWN) -> str:
    """``repr`` of ``text``, shortened in the middle to about ``limit`` characters.

    >>> short("a" * 10)
    "'aaaaaaaaaa'"
    >>> len(short("x" * 5000)) <= 130
    True
    """
    text = str(text)
    if len(text) > limit:
        keep = (limit - 3) // 2
        text = f"{text[:keep]}...{text[-keep:]}"
    return repr(text)


def _size(n: int) -> str:
    for unit, div in (("GiB", 2 ** 30), ("MiB", 2 ** 20), ("KiB", 2 ** 10)):
        if n >= div:
            return f"{n / div:.3g} {unit}"
    return f"{n} bytes"


def file_kind(mode: int) -> str:
    """Words for a file type that is not a regular file (``"a folder"``, ``"a FIFO"``, ...)."""
    if stat.S_ISDIR(mode):
        return "a folder"
    if stat.S_ISFIFO(mode):
        return "a FIFO"
    if stat.S_ISCHR(mode):
        return "a character device"
    if stat.S_ISBLK(mode):
        return "a block device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    if stat.S_ISLNK(mode):
        return "a symbolic link"
    return "a regular file" if stat.S_ISREG(mode) else "not a regular file"


def check_regular(path, what: str, limit: int = MAX_INPUT_BYTES) -> None:
    """Refuse now what :func:`read_bytes` would refuse later (missing, not a regular file, too
    large), without opening the file: for inputs read after other work has begun."""
    shown = short(os.fspath(path))
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise FileNotFoundError(f"{what} {shown} not found") from None
    except OSError as exc:
        raise ValueError(f"cannot read {what} {shown}: {exc.strerror or type(exc).__name__}") from None
    if not stat.S_ISREG(st.st_mode):
        raise ValueError(f"{what} {shown} is {file_kind(st.st_mode)}, not a regular file")
    if st.st_size > limit:
        raise ValueError(f"{what} {shown} holds {_size(st.st_size)}, more than the {_size(limit)} "
                         f"an input file may hold")


def read_bytes(path, what: str, limit: int = MAX_INPUT_BYTES) -> bytes:
    """The bytes of the regular file ``path``, at most ``limit`` of them.

    Raises
    ------
    FileNotFoundError
        ``"WHAT 'PATH' not found"``.
    ValueError
        One line: not a regular file (folder, FIFO, device, socket), larger than ``limit``
        (both sizes stated), or unreadable (the system's reason).
    """
    shown = short(os.fspath(path))
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0)
    try:
        fd = os.open(path, flags)
    except FileNotFoundError:
        raise FileNotFoundError(f"{what} {shown} not found") from None
    except OSError as exc:
        raise ValueError(f"cannot read {what} {shown}: {exc.strerror or type(exc).__name__}") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise ValueError(f"{what} {shown} is {file_kind(st.st_mode)}, not a regular file")
        if st.st_size > limit:
            raise ValueError(f"{what} {shown} holds {_size(st.st_size)}, more than the {_size(limit)} "
                             f"an input file may hold")
        chunks, total = [], 0
        while True:
            chunk = os.read(fd, min(1 << 20, limit + 1 - total))
            if not chunk:
                break
            chunks.append(chunk)
            total += len(chunk)
            if total > limit:
                raise ValueError(f"{what} {shown} holds more than the {_size(limit)} an input file may hold")
        return b"".join(chunks)
    except OSError as exc:
        raise ValueError(f"cannot read {what} {shown}: {exc.strerror or type(exc).__name__}") from None
    finally:
        os.close(fd)


def read_text(path, what: str, limit: int = MAX_INPUT_BYTES, encoding: str = "utf-8") -> str:
    """The text of ``path`` (:func:`read_bytes`), decoded; one ``ValueError`` line if it is not ``encoding``."""
    raw = read_bytes(path, what, limit)
    try:
        return raw.decode(encoding)
    except UnicodeDecodeError as exc:
        raise ValueError(f"{what} {short(os.fspath(path))} is not valid {encoding.upper()} "
                         f"(byte 0x{raw[exc.start]:02x} at offset {exc.start})") from None


def check_depth(data, what: str, limit: int = MAX_DEPTH):
    """``data`` itself if its dicts and lists nest at most ``limit`` deep (checked without recursion).

    >>> check_depth({"a": [[1]]}, "doc", 3)
    {'a': [[1]]}
    >>> check_depth({"a": [[1]]}, "doc", 2)
    Traceback (most recent call last):
    ...
    ValueError: doc nests tables or arrays more than 2 deep
    """
    stack = [(data, 1)]
    while stack:
        item, depth = stack.pop()
        if isinstance(item, dict):
            children = item.values()
        elif isinstance(item, (list, tuple)):
            children = item
        else:
            continue
        if depth > limit:
            raise ValueError(f"{what} nests tables or arrays more than {limit} deep")
        stack.extend((c, depth + 1) for c in children)
    return data


def _parsed(parse, text: str, path, what: str, kind: str, errors: tuple):
    shown = short(os.fspath(path))
    try:
        data = parse(text)
    except RecursionError:
        raise ValueError(f"{what} {shown} nests tables or arrays more than {MAX_DEPTH} deep") from None
    except errors as exc:
        first = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        raise ValueError(f"{what} {shown} is not valid {kind}: {first[:160]}") from None
    return check_depth(data, f"{what} {shown}")


def read_json(path, what: str, limit: int = MAX_INPUT_BYTES):
    """The JSON document of ``path`` (:func:`read_text`), nesting at most :data:`MAX_DEPTH` deep."""
    return _parsed(json.loads, read_text(path, what, limit), path, what, "JSON", (ValueError,))


def read_toml(path, what: str, limit: int = MAX_INPUT_BYTES) -> dict:
    """The TOML document of ``path`` (:func:`read_text`), nesting at most :data:`MAX_DEPTH` deep."""
    try:
        import tomllib
    except ModuleNotFoundError:  # Python < 3.11
        import tomli as tomllib
    return _parsed(tomllib.loads, read_text(path, what, limit), path, what, "TOML", (tomllib.TOMLDecodeError,))


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


def lstat_or_none(path):
    try:
        return os.lstat(path)
    except (FileNotFoundError, NotADirectoryError):
        return None
    except OSError as exc:
        if exc.errno == errno.ENAMETOOLONG:       # cannot exist
            return None
        raise


def _refuse(option: str, path, kind: str, want: str):
    raise ValueError(f"{option} {short(os.fspath(path))} is {kind}; ebraille-sim replaces only {want}")


def check_existing(path, option: str, folder: bool = False) -> None:
    """Refuse ``path`` unless it is absent or a regular file (a real folder with ``folder``)."""
    st = lstat_or_none(path)
    if st is None:
        return
    if folder:
        if not stat.S_ISDIR(st.st_mode):
            raise ValueError(f"{option} {short(os.fspath(path))} is {file_kind(st.st_mode)}; ebraille-sim writes "
                             f"this output only into a real folder")
    elif not stat.S_ISREG(st.st_mode):
        _refuse(option, path, file_kind(st.st_mode), "regular files")


def writable_ancestor(path: pathlib.Path, option: str) -> pathlib.Path:
    """The nearest existing folder of ``path`` (itself included), refused unless writable."""
    probe = path
    while lstat_or_none(probe) is None and probe != probe.parent:
        probe = probe.parent
    if not probe.is_dir():
        raise ValueError(f"{option} {short(path)}: {short(probe)} is a file, not a folder")
    if not os.access(probe, os.W_OK | os.X_OK):
        raise ValueError(f"{option} {short(path)}: folder {short(probe)} is not writable")
    return probe


def check_file(path, option: str = "FILE") -> pathlib.Path:
    """``path`` as an output file, refused now (one ``ValueError`` line) if it cannot be one.

    It must be absent or a regular file (not a symbolic link, FIFO, device, socket or
    folder), and its nearest existing folder writable.  Nothing is created.
    """
    if not str(path).strip():
        raise ValueError(f"{option} is empty; give a file name")
    p = pathlib.Path(path)
    check_existing(p, option)
    writable_ancestor(p.parent, option)
    return p


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def _replacing(path, option: str):
    """``(descriptor, name)`` of a temporary file created exclusively beside ``path``, renamed
    over it when the block ends normally (the caller closes the descriptor)."""
    p = check_file(path, option)
    p.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{p.name[:80]}.", suffix=f".tmp{p.suffix[:16]}", dir=p.parent)
    try:
        os.fchmod(fd, 0o666 & ~_umask())
        yield fd, tmp
        with signals_held():
            check_existing(p, option)
            os.replace(tmp, p)
    finally:
        with signals_held(), contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)


@contextlib.contextmanager
def staged_file(path, option: str = "FILE"):
    """A temporary file to write, renamed over the file ``path`` when the block ends normally.

    The temporary file has a unique name, is created exclusively in the folder of ``path``
    (so the rename stays on one file system) and keeps the suffix of ``path``; ``path`` must
    be absent or a regular file (:func:`check_file`), checked again just before the rename
    (signals held back).  When the block raises, the temporary file is removed and ``path``
    is left as it was.
    """
    with _replacing(path, option) as (fd, tmp):
        os.close(fd)
        yield pathlib.Path(tmp)


def write_file(path, data, option: str = "FILE") -> pathlib.Path:
    """Replace the file ``path`` with ``data`` (str: UTF-8) in one rename, the data written
    through the descriptor of the temporary file created for them (:func:`staged_file`)."""
    if isinstance(data, str):
        data = data.encode("utf-8")
    with _replacing(path, option) as (fd, _), os.fdopen(fd, "wb") as fh:
        fh.write(data)
    return pathlib.Path(path)
