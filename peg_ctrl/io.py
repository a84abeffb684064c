"""Output helpers: check an output location before any work starts, and write files atomically.

Every problem with an output location raises :class:`~peg_ctrl.errors.OutputError` with a
one-line message naming the path and the operating system's reason, so the command line can
report it without a traceback.

Every file the project writes is complete or absent: it is written to a temporary file in the
same directory (``.<name>.<random>.tmp...``) and renamed over its target
(:func:`atomic_write_bytes`, :func:`atomic_write_text`, and :func:`atomic_path` for libraries
that write to a path themselves), or, for a stream, appended in whole records
(:class:`~peg_ctrl.run.episode_log.EpisodeLogger`). Every JSON document or record is strict
(RFC 8259) JSON, made by :func:`to_json`: no ``NaN`` or ``Infinity``.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import re
import secrets
import stat
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from peg_ctrl.errors import OutputError, OutputInUse

__all__ = [
    "remove_stale_temps",
    "check_output_dir",
    "prepare_output_dir",
    "prepare_output_file",
    "atomic_write_text",
    "atomic_write_bytes",
    "atomic_path",
    "temp_path",
    "commit_temp",
    "write_error",
    "to_json",
    "lock_output_dir",
]


def _reason(exc: OSError) -> str:
    # The system's text for the errno: libraries (pyarrow) put their own long text in strerror.
    if exc.errno:
        return os.strerror(exc.errno)
    return exc.strerror or str(exc)


def _destination(path: str | os.PathLike[str]) -> tuple[Path, bool]:
    """Where a write of ``path`` lands, and whether it is a special file (a device such as
    ``/dev/stdout``, a FIFO) that must be written in place: a rename over it would put a
    regular file in the device's place. A symbolic link to a regular file (or to nothing yet)
    resolves to that file, so that the link is kept."""
    target = Path(path)
    try:
        mode: int | None = os.stat(target).st_mode  # follows symbolic links
    except OSError:
        mode = None  # not there (yet)
    if mode is not None and not (stat.S_ISREG(mode) or stat.S_ISDIR(mode)):
        return target, True
    if target.is_symlink():
        return Path(os.path.realpath(target)), False
    return target, False


def write_error(path: str | os.PathLike[str], exc: OSError) -> OutputError:
    """The one-line :class:`~peg_ctrl.errors.OutputError` for a failed write of ``path``."""
    return OutputError(f"cannot write {str(path)!r}: {_reason(exc)}")


def _first_non_directory(path: Path) -> Path | None:
    """The nearest existing one of ``path`` and its ancestors, if it is not a directory."""
    for candidate in (path, *path.parents):
        if candidate.exists():
            return None if candidate.is_dir() else candidate
    return None


def check_output_dir(path: str | os.PathLike[str]) -> Path:
    """Check, creating nothing, that no file stands where directory ``path`` (or one of its
    parents) would be.

    Raises:
        OutputError: as :func:`prepare_output_dir` does for such a file.
    """
    directory = Path(path)
    blocker = _first_non_directory(directory)
    if blocker is not None:
        where = "" if blocker == directory else f" (its parent {str(blocker)!r} is a file)"
        raise OutputError(f"output directory {str(directory)!r} is not a directory{where}")
    return directory


def prepare_output_dir(path: str | os.PathLike[str]) -> Path:
    """Create directory ``path`` (with its parents) and check that files can be written in it.

    Writability is checked by creating and removing a probe file, which also catches read-only
    mounts and permission rules that ``os.access`` does not see.

    Returns:
        The directory as a :class:`~pathlib.Path`.

    Raises:
        OutputError: ``path`` exists and is not a directory, cannot be created, or is not writable.
    """
    directory = check_output_dir(path)
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"cannot create output directory {str(directory)!r}: {_reason(exc)}") from None
    try:
        fd, probe = tempfile.mkstemp(prefix=".peg_ctrl-probe-", dir=directory)
    except OSError as exc:
        raise OutputError(f"output directory {str(directory)!r} is not writable: {_reason(exc)}") from None
    os.close(fd)
    with contextlib.suppress(OSError):
        os.unlink(probe)
    return directory


def prepare_output_file(path: str | os.PathLike[str]) -> Path:
    """Check that file ``path`` can be written: its directory is prepared, and it is not a directory.

    Raises:
        OutputError: as :func:`prepare_output_dir` for the parent, or ``path`` is a directory.
    """
    file = Path(path)
    if file.is_dir():
        raise OutputError(f"output file {str(file)!r} is a directory")
    blocker = _first_non_directory(file.parent)
    if blocker is not None:
        raise OutputError(f"cannot write output file {str(file)!r}: its parent {str(blocker)!r} is a file")
    prepare_output_dir(file.parent)
    return file


def atomic_write_bytes(path: str | os.PathLike[str], data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically: readers see the old file or the new one, never a part.

    The bytes go to a temporary file in the same directory (created with the usual permissions,
    i.e. ``0o666`` minus the umask), which is flushed, fsynced and renamed over ``path`` with
    :func:`os.replace`. A symbolic link is followed (the file it points to is replaced, not the
    link); a special file (``/dev/stdout``, a FIFO) is written in place, never replaced.

    Raises:
        OutputError: naming the file and the reason (no space, read-only, ...); no temporary
            file is left behind.
    """
    target, special = _destination(path)
    if special:
        try:
            with open(target, "wb") as fh:
                fh.write(data)
        except OSError as exc:
            raise write_error(path, exc) from None
        return Path(path)
    tmp: str | None = None
    try:
        name = str(target.parent / f".{target.name}.{secrets.token_hex(6)}.tmp")
        fd = os.open(name, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
        tmp = name
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, target)
        tmp = None
    except OSError as exc:
        raise write_error(path, exc) from None
    finally:
        if tmp is not None:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
    return Path(path)


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """A temporary path beside ``path`` for a library that writes to a path itself (matplotlib's
    ``savefig``, pyarrow, imageio, ``np.savez``); when the block ends normally the file is
    fsynced and renamed over ``path``, otherwise removed.

    The temporary name keeps ``path``'s suffix, from which such libraries pick the format:
    ``dir/.force_profile.<random>.tmp.png`` for ``dir/force_profile.png``.

    Raises:
        OutputError: an :class:`OSError` in the block or in the rename (no space, read-only,
            ...), naming ``path`` and the reason; nothing is left behind.
    """
    target, special = _destination(path)
    if special:  # a device or a FIFO: the library writes to it directly
        try:
            yield target
        except OSError as exc:
            if isinstance(exc, OutputError):
                raise
            raise write_error(target, exc) from None
        return
    tmp = temp_path(target)
    try:
        yield tmp
    except BaseException as exc:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if isinstance(exc, OSError) and not isinstance(exc, OutputError):
            raise write_error(target, exc) from None
        raise
    commit_temp(tmp, target)


def remove_stale_temps(directory: str | os.PathLike[str]) -> list[Path]:
    """Delete the temporary files (``.<name>.<random>.tmp...``) that a process killed while
    writing left in ``directory`` (not in its subdirectories); returns them. Call it only while
    holding the directory (:func:`lock_output_dir`), so no live writer's file is taken."""
    removed = []
    for entry in Path(directory).glob(".*.tmp*"):
        if _TEMP_NAME.fullmatch(entry.name) and entry.is_file():
            with contextlib.suppress(OSError):
                entry.unlink()
                removed.append(entry)
    return removed


_TEMP_NAME = re.compile(r"\.[^/]+\.[0-9a-f]{12}\.tmp(\.[^./]+)?")


def temp_path(path: str | os.PathLike[str]) -> Path:
    """A fresh temporary name beside ``path`` that keeps its suffix (see :func:`atomic_path`)."""
    target = Path(path)
    return target.parent / f".{target.stem}.{secrets.token_hex(6)}.tmp{target.suffix}"


def commit_temp(tmp: str | os.PathLike[str], path: str | os.PathLike[str]) -> Path:
    """Fsync the finished temporary file ``tmp`` and rename it over ``path``.

    Raises:
        OutputError: naming ``path`` and the reason; ``tmp`` is removed.
    """
    try:
        with open(tmp, "rb") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except OSError as exc:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise write_error(path, exc) from None
    return Path(path)


def atomic_write_text(path: str | os.PathLike[str], text: str, *, encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path`` atomically (see :func:`atomic_write_bytes`).

    Raises:
        OutputError: naming the file and the reason; no temporary file is left behind.
    """
    return atomic_write_bytes(path, text.encode(encoding))


def _plain(obj: Any) -> Any:
    """``obj`` with every non-finite float as None and numpy scalars and arrays as plain values."""
    if isinstance(obj, float):  # also numpy's float64
        return float(obj) if math.isfinite(obj) else None
    if obj is None or isinstance(obj, (str, int)):
        return obj
    if isinstance(obj, dict):
        return {k: _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    if hasattr(obj, "tolist"):  # numpy scalars and arrays (numpy is not imported here)
        return _plain(obj.tolist())
    return obj  # anything else: json.dumps raises TypeError, naming it


def to_json(obj: Any, **kwargs: Any) -> str:
    """``obj`` as strict JSON (RFC 8259): a non-finite float (an undefined metric) is ``null``;
    numpy scalars and arrays become numbers and lists. ``kwargs`` go to :func:`json.dumps`.

    Every JSON file and record the project writes goes through here, so any strict parser
    reads it.
    """
    return json.dumps(_plain(obj), allow_nan=False, **kwargs)


#: The lock file :func:`lock_output_dir` keeps in an output directory (it may stay: it is harmless).
LOCK_NAME = ".peg_ctrl.lock"


def _lock_owner(fd: int) -> int | None:
    """The pid written in a lock file held by another process (None if it has not written it)."""
    import time

    for _ in range(20):  # the owner writes its pid just after it takes the lock
        text = os.pread(fd, 32, 0).decode("ascii", "replace").strip()
        if text.isdigit():
            return int(text)
        time.sleep(0.025)
    return None


@contextlib.contextmanager
def lock_output_dir(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Hold directory ``path`` (which must exist) for this process while the block runs, so two
    runs or sweeps never write into the same directory at once.

    An exclusive advisory ``fcntl.flock`` on ``path/.peg_ctrl.lock``, which holds the owner's pid
    for the message. The kernel releases it when the process ends, however it ends: a sweep
    killed with ``SIGKILL`` can be resumed at once. It is not passed to worker processes; they
    end with their parent (:mod:`peg_ctrl.run.workers`). The file is left in place, as unlinking a
    lock file races with a process about to take it. Where there is no ``flock`` (Windows),
    nothing is locked.

    Raises:
        OutputInUse: another process holds the directory (also this process, through another
            call: the lock is not reentrant).
        OutputError: the lock file cannot be created.
    """
    directory = Path(path)
    try:
        import fcntl
    except ImportError:  # pragma: no cover - Windows
        yield directory
        return
    lock = directory / LOCK_NAME
    try:
        fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o666)
    except OSError as exc:
        raise OutputError(f"cannot lock output directory {str(directory)!r}: {_reason(exc)}") from None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            pid = _lock_owner(fd)
            who = "this process" if pid == os.getpid() else "another peg-sim process"
            raise OutputInUse(
                f"output directory {str(directory)!r} is in use by {who} "
                f"(pid {pid if pid is not None else 'unknown'})",
                pid=pid,
            ) from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode("ascii"), 0)
        yield directory
    finally:
        os.close(fd)
