"""Output helpers: check an output location before any work starts, and write files atomically.

Every problem with an output location raises :class:`~peg_ctrl.errors.OutputError` with a
one-line message naming the path and the operating system's reason, so the command line can
report it without a traceback.
"""

from __future__ import annotations

import contextlib
import os
import secrets
import tempfile
from pathlib import Path

from peg_ctrl.errors import OutputError

__all__ = ["prepare_output_dir", "prepare_output_file", "atomic_write_text", "atomic_write_bytes"]


def _reason(exc: OSError) -> str:
    return exc.strerror or str(exc)


def _first_non_directory(path: Path) -> Path | None:
    """The nearest existing one of ``path`` and its ancestors, if it is not a directory."""
    for candidate in (path, *path.parents):
        if candidate.exists():
            return None if candidate.is_dir() else candidate
    return None


def prepare_output_dir(path: str | os.PathLike[str]) -> Path:
    """Create directory ``path`` (with its parents) and check that files can be written in it.

    Writability is checked by creating and removing a probe file, which also catches read-only
    mounts and permission rules that ``os.access`` does not see.

    Returns:
        The directory as a :class:`~pathlib.Path`.

    Raises:
        OutputError: ``path`` exists and is not a directory, cannot be created, or is not writable.
    """
    directory = Path(path)
    blocker = _first_non_directory(directory)
    if blocker is not None:
        where = "" if blocker == directory else f" (its parent {str(blocker)!r} is a file)"
        raise OutputError(f"output directory {str(directory)!r} is not a directory{where}")
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
    :func:`os.replace`.

    Raises:
        OutputError: naming the file and the reason (no space, read-only, ...); no temporary
            file is left behind.
    """
    target = Path(path)
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
        raise OutputError(f"cannot write {str(target)!r}: {_reason(exc)}") from None
    finally:
        if tmp is not None:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
    return target


def atomic_write_text(path: str | os.PathLike[str], text: str, *, encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path`` atomically (see :func:`atomic_write_bytes`).

    Raises:
        OutputError: naming the file and the reason; no temporary file is left behind.
    """
    return atomic_write_bytes(path, text.encode(encoding))
