"""Replay a logged episode: its recorded states shown again, in MuJoCo's viewer or as a video.

An episode directory written by :func:`~peg_ctrl.run.episode.run_episode` holds ``config.json`` (the
resolved configuration) and ``states.npz`` (time and ``qpos`` at every control step, see
:class:`~peg_ctrl.run.recorders.StateRecorder`). The replay rebuilds the episode's model from the
configuration (with the same per-seed domain draw), and for every frame sets the recorded
``qpos`` and calls ``mj_forward``: a kinematic replay, nothing is simulated again.

    peg-sim replay runs/episode                   # headless: runs/episode/replay.mp4
    peg-sim replay runs/episode --viewer --speed 0.5
"""

from __future__ import annotations

import json
import math
import os
import time
import zipfile
from collections.abc import Sequence
from pathlib import Path

import mujoco
import numpy as np
from numpy.typing import NDArray

from peg_ctrl.errors import ConfigError
from peg_ctrl.io import atomic_path, prepare_output_dir, prepare_output_file, write_error

__all__ = ["replay", "frame_times", "load_run", "extract_frames", "REPLAY_FPS"]

REPLAY_FPS = 30  # frames per second of a replay video (the episode video's rate)


def load_run(
    run_dir: str | os.PathLike[str],
) -> tuple[mujoco.MjModel, NDArray[np.float64], NDArray[np.float64]]:
    """The episode's model and its recorded states: (model, time (n,) [s], qpos (n, nq)).

    Raises:
        ConfigError: ``run_dir`` is not a directory, lacks ``config.json`` or ``states.npz``, or
            its states do not fit the model built from its configuration.
    """
    from peg_ctrl.run.episode import domain_draw, episode_config_from_mapping, prepare_model
    from peg_ctrl.run.recorders import read_states

    directory = Path(run_dir)
    expected = "an episode directory written by peg-sim run, with config.json and states.npz"
    if not directory.is_dir():
        raise ConfigError(
            f"run directory {str(directory)!r} does not exist or is not a directory; expected {expected}"
        )
    for name in ("config.json", "states.npz"):
        if not (directory / name).is_file():
            raise ConfigError(f"run directory {str(directory)!r} has no {name}; expected {expected}")
    try:
        mapping = json.loads((directory / "config.json").read_text(encoding="utf-8"))
    except ValueError as exc:
        raise ConfigError(f"{str(directory / 'config.json')!r} is not valid JSON: {exc}") from None
    cfg = episode_config_from_mapping(mapping)
    model = prepare_model(cfg, domain_draw(cfg.seed, cfg.domain))
    try:
        t, qpos = read_states(directory / "states.npz")
    except (ValueError, KeyError, zipfile.BadZipFile) as exc:
        raise ConfigError(
            f"{str(directory / 'states.npz')!r} is not a states file (arrays time and qpos): {exc}"
        ) from None
    if qpos.ndim != 2 or qpos.shape[1] != model.nq or len(t) != len(qpos) or len(t) == 0:
        raise ConfigError(
            f"{str(directory / 'states.npz')!r} holds qpos of shape {qpos.shape} for {len(t)} times; "
            f"expected (n >= 1, {model.nq}) for the model of its config.json"
        )
    return model, t, qpos


def frame_times(t: NDArray[np.float64], *, fps: float, speed: float = 1.0) -> NDArray[np.float64]:
    """Simulated times [s] of the frames of a replay of states at times ``t`` [s], played at
    ``fps`` [frames/s] and ``speed`` (simulated seconds per second of video): every
    ``speed / fps`` s from ``t[0]`` to ``t[-1]``."""
    step = speed / fps
    count = int(math.floor((t[-1] - t[0]) / step + 1e-9)) + 1
    return t[0] + step * np.arange(count)


def _state_index(t: NDArray[np.float64], when: NDArray[np.float64]) -> NDArray[np.intp]:
    """For each time in ``when``, the first recorded state at or after it (the loop records a
    video frame at the first control step at or after the frame's time)."""
    return np.minimum(np.searchsorted(t, when - 1e-9, side="left"), len(t) - 1)


def replay(
    run_dir: str | os.PathLike[str],
    *,
    video: str | os.PathLike[str] | None = None,
    viewer: bool = False,
    speed: float = 1.0,
    progress: bool = True,
) -> Path | None:
    """Replay the episode in ``run_dir``.

    Args:
        run_dir: an episode's output directory (``config.json`` and ``states.npz``).
        video: the MP4 to write (default ``run_dir/replay.mp4``); frames as in the episode
            video (:class:`~peg_ctrl.run.recorders.VideoRecorder`'s default views) at
            :data:`REPLAY_FPS`.
        viewer: show the replay in MuJoCo's passive viewer instead (needs a display), paced
            at ``speed`` times real time.
        speed: simulated seconds per second of replay, > 0 (0.5: half speed).
        progress: show a bar counting the video's frames on stderr (see
            :mod:`peg_ctrl.progress`: only on a terminal, or with ``PEG_SIM_PROGRESS=1``).

    Returns:
        The video's path, or None for a viewer replay.

    Raises:
        ConfigError: a bad ``run_dir`` (see :func:`load_run`), ``speed`` not a positive finite
            number, ``viewer`` with ``video``, or ``viewer`` without a display.
        OutputError: the video cannot be written.
    """
    _check(speed=speed, viewer=viewer, video=video)
    model, t, qpos = load_run(run_dir)
    if viewer:
        _replay_in_viewer(model, t, qpos, speed)
        return None
    out = prepare_output_file(video if video is not None else Path(run_dir) / "replay.mp4")
    _render_video(model, t, qpos, out, speed=speed, progress=progress)
    return out


def _check(*, speed: float, viewer: bool, video: str | os.PathLike[str] | None) -> None:
    if not (math.isfinite(speed) and speed > 0):
        raise ConfigError(f"speed must be a finite number > 0, got {speed}")
    if viewer and video is not None:
        raise ConfigError("give a video file or the viewer, not both")
    if viewer and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise ConfigError(
            "the replay viewer needs a display (DISPLAY is not set); leave it out to render a video"
        )


def _render_video(
    model: mujoco.MjModel,
    t: NDArray[np.float64],
    qpos: NDArray[np.float64],
    out: Path,
    *,
    speed: float,
    progress: bool,
) -> None:
    """Write the recorded states to ``out`` at :data:`REPLAY_FPS`, whole or not at all."""
    from peg_ctrl.progress import progress_bar
    from peg_ctrl.run.recorders import VideoRecorder

    data = mujoco.MjData(model)
    recorder = VideoRecorder(model, out, fps=REPLAY_FPS)
    states = _state_index(t, frame_times(t, fps=REPLAY_FPS, speed=speed))
    try:
        with progress_bar(total=len(states), desc="replay", unit="frame", enabled=progress) as bar:
            for i in states:
                data.qpos[:] = qpos[i]
                data.time = t[i]
                mujoco.mj_forward(model, data)
                recorder.add_frame(data)
                bar.update(1)
    except OSError as exc:
        recorder.discard()
        raise write_error(out, exc) from None
    except BaseException:
        recorder.discard()  # no partial video
        raise
    recorder.close()


def _replay_in_viewer(
    model: mujoco.MjModel, t: NDArray[np.float64], qpos: NDArray[np.float64], speed: float
) -> None:
    from peg_ctrl.sim.gl import PassiveViewer

    data = mujoco.MjData(model)
    # The viewer refreshes at about 60 Hz; a state per refresh is enough.
    times = frame_times(t, fps=60.0, speed=speed)
    handle = PassiveViewer(model, data)  # Triton first, a close that waits (peg_ctrl.sim.gl)
    try:
        wall0 = time.perf_counter()
        for k, i in enumerate(_state_index(t, times)):
            if not handle.is_running():
                return
            data.qpos[:] = qpos[i]
            data.time = t[i]
            mujoco.mj_forward(model, data)
            handle.sync()
            lag = (times[k] - times[0]) / speed - (time.perf_counter() - wall0)
            if lag > 0:
                time.sleep(lag)
    finally:
        handle.close()


def extract_frames(
    video: str | os.PathLike[str],
    times: Sequence[float],
    out_dir: str | os.PathLike[str],
    *,
    width: int | None = None,
    prefix: str = "frame",
) -> list[Path]:
    """Save the frames of ``video`` nearest to ``times`` [s of video] as PNGs in ``out_dir``
    (``<prefix>_<t>s.png``), scaled to ``width`` [px] if given; returns their paths.

    Raises:
        ConfigError: ``video`` does not exist, a time is outside the video, or ``width`` < 16.
    """
    import imageio.v2 as imageio
    from PIL import Image

    path = Path(video)
    if not path.is_file():
        raise ConfigError(f"video {str(path)!r} does not exist")
    if width is not None and width < 16:
        raise ConfigError(f"width must be >= 16 px, got {width}")
    directory = prepare_output_dir(out_dir)
    reader = imageio.get_reader(str(path))
    try:
        meta = reader.get_meta_data()
        fps = float(meta["fps"])
        written = []
        for when in times:
            index = round(when * fps)
            try:
                if index < 0:
                    raise IndexError(index)
                frame = reader.get_data(index)
            except IndexError:
                raise ConfigError(
                    f"time {when} s is outside the video ({float(meta['duration']):.2f} s at {fps:g} fps)"
                ) from None
            image = Image.fromarray(frame)
            if width is not None and image.width != width:
                size = (width, round(image.height * width / image.width))
                image = image.resize(size, Image.Resampling.LANCZOS)
            target = directory / f"{prefix}_{when:05.2f}s.png"
            with atomic_path(target) as tmp:
                image.save(tmp, optimize=True)
            written.append(target)
    finally:
        reader.close()
    return written
