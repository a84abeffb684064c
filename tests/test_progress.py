"""Progress: bars on a terminal, plain lines in a log, switched by PEG_SIM_PROGRESS, never in the way."""

from __future__ import annotations

import io
import sys

import pytest

from peg_ctrl.progress import (
    ENV_VAR,
    ProgressLines,
    format_duration,
    progress,
    progress_bar,
    progress_mode,
    show_progress,
)


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def _environment(monkeypatch: pytest.MonkeyPatch, setting: str | None, tty: bool) -> None:
    """The progress variable (ENV_VAR) set to ``setting`` (None: unset); stderr a terminal or not."""
    if setting is None:
        monkeypatch.delenv(ENV_VAR, raising=False)
    else:
        monkeypatch.setenv(ENV_VAR, setting)
    monkeypatch.setattr(sys, "stderr", _Terminal() if tty else io.StringIO())


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
    _environment(monkeypatch, setting, tty)
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


# -- plain progress lines (stderr not a terminal) ---------------------------------------------


class _Clock:
    """A clock the test moves by hand."""

    def __init__(self, t: float = 1000.0) -> None:
        self.t = t

    def __call__(self) -> float:
        return self.t


def _lines(stream: io.StringIO) -> list[str]:
    return stream.getvalue().splitlines()


def test_lines_are_throttled_and_say_count_successes_elapsed_and_eta() -> None:
    clock, out = _Clock(), io.StringIO()
    reporter = ProgressLines(
        total=400, desc="sweep contact_hard", noun="episodes", stream=out, clock=clock, background=False
    )
    with reporter as lines:
        assert _lines(out) == ["sweep contact_hard: 0/400 episodes (0%), elapsed 0s"]  # at once
        for _ in range(119):
            clock.t += 5.0
            lines.set_postfix_str("117 inserted")
            lines.update(1)
        clock.t += 10.0
        lines.update(1)  # 120 done in 605 s: 280 left at 120 per 605 s
        assert not lines.tick()  # just printed
        clock.t += 9.9
        assert not lines.tick()
        clock.t += 0.1
        assert lines.tick()  # 10 s after the last line, even without progress
    printed = _lines(out)
    # The first line, one about every 10 s (5 s per item: every other update), and the last.
    assert len(printed) == 1 + 119 // 2 + 1 + 1 + 1
    assert (
        printed[-3] == "sweep contact_hard: 120/400 episodes (30%), 117 inserted, elapsed 10m05s, ETA 23m32s"
    )
    assert printed[-2].endswith("elapsed 10m15s, ETA 23m55s")
    assert printed[-1] == "sweep contact_hard: 120/400 episodes (30%), 117 inserted, elapsed 10m15s, stopped"


def test_a_resumed_job_counts_what_was_done_and_its_eta_uses_only_this_run() -> None:
    clock, out = _Clock(), io.StringIO()
    with ProgressLines(
        total=10,
        desc="sweep x",
        noun="episodes",
        initial=6,
        postfix="5 inserted",
        stream=out,
        clock=clock,
        background=False,
    ) as lines:
        clock.t += 20.0
        lines.set_postfix_str("6 inserted")
        lines.update(1)  # 1 episode in 20 s: the 3 left take 60 s
        clock.t += 40.0
        lines.update(3)
    assert _lines(out) == [
        "sweep x: 6/10 episodes (60%), 5 inserted, elapsed 0s",
        "sweep x: 7/10 episodes (70%), 6 inserted, elapsed 20s, ETA 1m00s",
        "sweep x: 10/10 episodes (100%), 6 inserted, elapsed 1m00s, ETA 0s",
        "sweep x: 10/10 episodes (100%), 6 inserted, elapsed 1m00s, done",
    ]


def test_lines_without_a_total_and_with_tqdm_style_postfix() -> None:
    clock, out = _Clock(), io.StringIO()
    with ProgressLines(
        total=None, desc="PPO", noun="steps", stream=out, clock=clock, background=False
    ) as lines:
        lines.set_postfix(success="40%")
        clock.t += 3725.0
        lines.update(512)
    assert _lines(out) == [
        "PPO: 0 steps, elapsed 0s",
        "PPO: 512 steps, success=40%, elapsed 1h02m",
        "PPO: 512 steps, success=40%, elapsed 1h02m, done",
    ]


def test_lines_come_while_nothing_finishes() -> None:
    """The background thread prints the due lines: a job of long items shows it is alive."""
    import time

    out = io.StringIO()
    with ProgressLines(total=3, desc="slow", noun="items", stream=out, period_s=0.05):
        time.sleep(0.5)
    printed = _lines(out)
    assert len(printed) >= 4, printed  # the first, at least two while waiting, the last
    assert all(line.startswith("slow: 0/3 items (0%), elapsed ") for line in printed)
    assert printed[-1].endswith(", stopped")


@pytest.mark.parametrize(
    "seconds, text",
    [
        (0, "0s"),
        (59.4, "59s"),
        (60, "1m00s"),
        (605, "10m05s"),
        (3599.4, "59m59s"),
        (3600, "1h00m"),
        (7380, "2h03m"),
        (86399, "1d00h"),
        (3 * 86400 + 4 * 3600, "3d04h"),
    ],
)
def test_durations(seconds: float, text: str) -> None:
    assert format_duration(seconds) == text


@pytest.mark.parametrize(
    "setting, tty, lines, mode",
    [
        (None, True, True, "bar"),
        (None, False, True, "lines"),  # nohup, CI, a log file
        (None, False, False, "off"),  # a command that offers no lines
        ("0", False, True, "off"),
        ("0", True, True, "off"),
        ("1", False, True, "bar"),
    ],
)
def test_lines_replace_the_bar_when_stderr_is_not_a_terminal(
    setting: str | None, tty: bool, lines: bool, mode: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    _environment(monkeypatch, setting, tty)
    assert progress_mode(lines=lines) == mode
    assert progress_mode(False, lines=lines) == "off"


def test_a_bar_offering_lines_prints_them_into_a_log(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.delenv(ENV_VAR, raising=False)
    assert list(progress(range(3), desc="pushes", unit="push", lines="pushes")) == [0, 1, 2]
    out, err = capsys.readouterr()
    assert out == ""
    first, *_, last = err.splitlines()
    assert first == "pushes: 0/3 pushes (0%), elapsed 0s"
    assert last.startswith("pushes: 3/3 pushes (100%), elapsed ") and last.endswith(", done")
    assert "\r" not in err
