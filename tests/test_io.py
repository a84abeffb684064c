"""Output helpers: output locations are checked up front; files are replaced atomically."""

from __future__ import annotations

import errno
import os
import stat
from pathlib import Path

import pytest

from peg_ctrl import io
from peg_ctrl.errors import OutputError

needs_non_root = pytest.mark.skipif(
    hasattr(os, "geteuid") and os.geteuid() == 0, reason="root can write to read-only directories"
)


def test_prepare_output_dir_creates_parents(tmp_path: Path) -> None:
    out = io.prepare_output_dir(tmp_path / "a" / "b")
    assert out == tmp_path / "a" / "b" and out.is_dir()
    assert list(out.iterdir()) == []  # the probe file is gone
    assert io.prepare_output_dir(out) == out  # an existing directory is fine


def test_prepare_output_dir_rejects_a_regular_file(tmp_path: Path) -> None:
    (tmp_path / "f").write_text("keep me")
    with pytest.raises(OutputError, match="is not a directory") as exc:
        io.prepare_output_dir(tmp_path / "f")
    assert "\n" not in str(exc.value)
    assert (tmp_path / "f").read_text() == "keep me"


def test_prepare_output_dir_under_a_file_names_the_file(tmp_path: Path) -> None:
    (tmp_path / "f").write_text("")
    with pytest.raises(OutputError, match=r"its parent '.*f' is a file"):
        io.prepare_output_dir(tmp_path / "f" / "sub" / "dir")


@needs_non_root
def test_prepare_output_dir_rejects_a_read_only_directory(tmp_path: Path) -> None:
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(stat.S_IRUSR | stat.S_IXUSR)
    try:
        with pytest.raises(OutputError, match="not writable"):
            io.prepare_output_dir(ro)
        with pytest.raises(OutputError, match="cannot create"):
            io.prepare_output_dir(ro / "sub")
    finally:
        ro.chmod(stat.S_IRWXU)


def test_prepare_output_file(tmp_path: Path) -> None:
    assert io.prepare_output_file(tmp_path / "x" / "bench.json") == tmp_path / "x" / "bench.json"
    assert (tmp_path / "x").is_dir() and not (tmp_path / "x" / "bench.json").exists()
    with pytest.raises(OutputError, match="is a directory"):
        io.prepare_output_file(tmp_path / "x")


def test_atomic_write_text_replaces_the_file(tmp_path: Path) -> None:
    path = tmp_path / "out.json"
    path.write_text("old")
    assert io.atomic_write_text(path, "new\n") == path
    assert path.read_text() == "new\n"
    assert os.listdir(tmp_path) == ["out.json"]
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(path.stat().st_mode) == 0o666 & ~umask  # not mkstemp's 0600


def test_atomic_write_failure_names_the_file_and_leaves_no_temp(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "out.json"
    path.write_text("old")

    def full_disk(src: str, dst: str) -> None:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(io.os, "replace", full_disk)
    with pytest.raises(OutputError) as exc:
        io.atomic_write_text(path, "new")
    assert str(exc.value) == f"cannot write {str(path)!r}: No space left on device"
    assert os.listdir(tmp_path) == ["out.json"]
    assert path.read_text() == "old"


def test_atomic_write_into_a_missing_directory(tmp_path: Path) -> None:
    with pytest.raises(OutputError, match="No such file or directory"):
        io.atomic_write_text(tmp_path / "missing" / "out.json", "x")
    assert os.listdir(tmp_path) == []
