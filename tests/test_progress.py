"""Progress bars: shown on a terminal only, switched by PEG_SIM_PROGRESS, never in the way."""

from __future__ import annotations

import io
import sys

import pytest

from peg_ctrl.progress import ENV_VAR, progress, progress_bar, show_progress


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


@pytest.mark.parametrize(
    "setting, tty, requested, shown",
    [
        (None, True, True, True),
        (None, False, True, False),  # a pipe, a log file, pytest's capture
        (None, True, False, False),  # the caller said no (progress=False)
        ("0", True, True, False),
        ("off", True, True, False),
        ("1", False, True, True),
        ("1", True, False, False),  # the environment never overrides the caller's no
    ],
)
def test_bars_show_on_a_terminal_unless_switched_off(
    setting: str | None, tty: bool, requested: bool, shown: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    if setting is None:
        monkeypatch.delenv(ENV_VAR, raising=False)
    else:
        monkeypatch.setenv(ENV_VAR, setting)
    monkeypatch.setattr(sys, "stderr", _Terminal() if tty else io.StringIO())
    assert show_progress(requested) is shown


def test_progress_yields_every_item_and_writes_nothing_when_hidden(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.delenv(ENV_VAR, raising=False)
    assert list(progress(range(5), desc="x")) == [0, 1, 2, 3, 4]
    assert capsys.readouterr() == ("", "")


def test_a_shown_bar_goes_to_stderr(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setenv(ENV_VAR, "1")
    assert list(progress([1, 2, 3], desc="pushes", unit="push")) == [1, 2, 3]
    with progress_bar(total=2, desc="episodes", unit="ep") as bar:
        bar.update(2)
    out, err = capsys.readouterr()
    assert out == ""
    assert "pushes: 100%" in err and "3/3" in err and "2/2" in err
