"""Replays of logged episodes: frames at the video rate that match the run's, and one-line errors."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from peg_ctrl.cli import main
from peg_ctrl.config import ConfigError
from peg_ctrl.progress import ENV_VAR
from peg_ctrl.run.episode import EpisodeConfig, run_episode
from peg_ctrl.tools.figure import figure_time, insertion_figure
from peg_ctrl.tools.replay import REPLAY_FPS, extract_frames, frame_times, replay

# The recorded run renders every frame (as the replays do): kept short.
DURATION = 0.2  # of the recorded run [s]: 200 physics steps of 1 ms


def _frames(path: Path) -> list[np.ndarray]:
    import imageio.v2 as imageio

    reader = imageio.get_reader(str(path))
    try:
        return [frame for frame in reader]
    finally:
        reader.close()


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The first DURATION seconds of an episode, with its video."""
    out = tmp_path_factory.mktemp("run")
    run_episode(EpisodeConfig(max_steps=round(DURATION * 1000)), out, video=True, plot=False)
    return out


def test_replay_renders_the_run_at_the_video_rate(run: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "replay.mp4"
    assert main(["replay", str(run), "--video", str(out)]) == 0
    assert capsys.readouterr().out.strip() == f"wrote {out}"
    replayed, recorded = _frames(out), _frames(run / "episode.mp4")
    assert abs(len(replayed) - round(DURATION * REPLAY_FPS + 1)) <= 1  # 0 .. DURATION, both ends
    assert len(replayed) == len(recorded)
    assert replayed[0].shape == recorded[0].shape == (480, 1280, 3)
    # The same state at the same time: the frames agree up to video compression (the run renders
    # the body poses of one physics step, 1 ms, earlier).
    k = len(replayed) // 2
    difference = np.abs(replayed[k].astype(float) - recorded[k].astype(float))
    assert difference.mean() < 2.0, difference.mean()
    assert replayed[k].std() > 10  # a rendered scene, not a blank frame


def test_replay_writes_beside_the_run_by_default(run: Path, tmp_path: Path) -> None:
    copy = tmp_path / "run"
    shutil.copytree(run, copy)
    assert replay(copy, speed=3.0) == copy / "replay.mp4"
    assert len(_frames(copy / "replay.mp4")) == len(
        frame_times(np.array([0.0, DURATION]), fps=REPLAY_FPS, speed=3.0)
    )


def test_replay_shows_a_bar_over_the_frames_only_when_asked(
    run: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    frames = len(frame_times(np.array([0.0, DURATION]), fps=REPLAY_FPS, speed=3.0))
    argv = ["replay", str(run), "--speed", "3", "--video"]
    monkeypatch.setenv(ENV_VAR, "1")
    assert main([*argv, str(tmp_path / "shown.mp4")]) == 0
    out, err = capsys.readouterr()
    assert out.strip() == f"wrote {tmp_path / 'shown.mp4'}"
    assert "replay: 100%" in err and f"{frames}/{frames}" in err, err
    monkeypatch.delenv(ENV_VAR)
    assert main([*argv, str(tmp_path / "hidden.mp4")]) == 0
    assert capsys.readouterr().err == ""  # stderr is not a terminal here: no bar
    assert len(_frames(tmp_path / "shown.mp4")) == len(_frames(tmp_path / "hidden.mp4")) == frames


def test_frame_times_follow_the_speed() -> None:
    t = np.array([0.0, 0.3, 0.6])
    np.testing.assert_allclose(frame_times(t, fps=30, speed=1.0), np.arange(19) / 30)
    np.testing.assert_allclose(frame_times(t, fps=30, speed=2.0), np.arange(10) / 15)
    np.testing.assert_allclose(frame_times(t, fps=30, speed=0.5), np.arange(37) / 60)


def test_extract_frames_scales_them(run: Path, tmp_path: Path) -> None:
    paths = extract_frames(run / "episode.mp4", [0.0, 0.15], tmp_path, width=320)
    assert [p.name for p in paths] == ["frame_00.00s.png", "frame_00.15s.png"]
    from PIL import Image

    assert Image.open(paths[1]).size == (320, 120)
    with pytest.raises(ConfigError, match=r"time 5\.0 s is outside the video"):
        extract_frames(run / "episode.mp4", [5.0], tmp_path)


def test_bad_run_directories_exit_2_in_one_line(run: Path, tmp_path: Path, capsys) -> None:
    missing = tmp_path / "missing"
    empty = tmp_path / "empty"
    empty.mkdir()
    no_states = tmp_path / "no_states"
    no_states.mkdir()
    shutil.copy(run / "config.json", no_states)
    wrong = tmp_path / "wrong"
    wrong.mkdir()
    shutil.copy(run / "config.json", wrong)
    np.savez(wrong / "states.npz", time=np.zeros(3), qpos=np.zeros((3, 4)), nq=4)
    torn = tmp_path / "torn"
    torn.mkdir()
    shutil.copy(run / "config.json", torn)
    (torn / "states.npz").write_bytes((run / "states.npz").read_bytes()[:100])
    cases = [
        (["replay", str(missing)], f"run directory '{missing}' does not exist or is not a directory"),
        (["replay", str(empty)], f"run directory '{empty}' has no config.json"),
        (["replay", str(no_states)], f"run directory '{no_states}' has no states.npz"),
        (["replay", str(wrong)], "holds qpos of shape (3, 4) for 3 times; expected (n >= 1, "),
        (["replay", str(torn)], f"'{torn / 'states.npz'}' is not a states file (arrays time and qpos)"),
        (["replay", str(run), "--speed", "0"], "speed must be a finite number > 0, got 0.0"),
        (["replay", str(run), "--viewer", "--video", "x.mp4"], "give a video file or the viewer, not both"),
    ]
    for argv, message in cases:
        assert main(argv) == 2, argv
        lines = capsys.readouterr().err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("peg-sim: error: ") and message in lines[0], lines


def test_the_viewer_needs_a_display(run: Path, monkeypatch: pytest.MonkeyPatch, capsys) -> None:
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert main(["replay", str(run), "--viewer"]) == 2
    assert "the replay viewer needs a display (DISPLAY is not set)" in capsys.readouterr().err


def test_figure_time_is_halfway_in_else_the_peak_force_else_the_end() -> None:
    t = np.linspace(0.0, 1.0, 11)
    force = np.array([0, 0, 1, 5, 2, 1, 1, 1, 1, 1, 1], dtype=float)
    depth = np.array([20, 0, 0, 0, 1, 2, 4, 6, 8, 10, 10], dtype=float) * 1e-3  # on the table first
    assert figure_time(t, force, depth) == pytest.approx(0.7)  # first at >= 5 mm after the touch
    assert figure_time(t, force, depth * 0.1) == pytest.approx(0.3)  # 1 mm deep: the peak force
    assert figure_time(t, np.zeros(11), depth) == pytest.approx(1.0)  # never touched: the end


def test_the_figure_shows_the_frame_beside_the_force_profile(run: Path, tmp_path: Path, capsys) -> None:
    from PIL import Image

    out = tmp_path / "figure.png"
    assert main(["replay", str(run), "--figure", str(out), "--at", "0.1"]) == 0
    assert capsys.readouterr().out.strip() == f"wrote {out} (the frame at 0.10 s)"
    image = np.asarray(Image.open(out).convert("RGB"))
    assert image.shape == (396, 1320, 3)  # 12 x 3.6 in at 110 dpi
    assert image[:, : image.shape[1] // 2].std() > 20.0  # a rendered scene on the left
    path, when = insertion_figure(run, tmp_path / "default.png")
    assert when == pytest.approx(DURATION, abs=0.002)  # no contact: the last recorded state
    bad = {
        ("--at", "0.1"): "--at is the moment of --figure",
        ("--figure", str(out), "--at", "5"): "--at 5 s is outside the episode",
        ("--figure", str(out), "--video", str(tmp_path / "v.mp4")): "not with --video or --viewer",
    }
    for argv, message in bad.items():
        assert main(["replay", str(run), *argv]) == 2
        assert message in capsys.readouterr().err
