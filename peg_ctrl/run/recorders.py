"""Recorders: what the loop hands every control step to logs, traces, video and viewers."""

from __future__ import annotations

import contextlib
import errno
import math
import os
import struct
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import mujoco
import numpy as np
from numpy.typing import NDArray

from peg_ctrl.commands import quat_to_euler
from peg_ctrl.errors import ConfigError, OutputError
from peg_ctrl.io import atomic_write_bytes, commit_temp, temp_path, write_error
from peg_ctrl.run.episode_log import TRACE_COLUMNS, EpisodeLogger
from peg_ctrl.sim.gl import before_gl_context
from peg_ctrl.sim.scene import PINCH_SITE
from peg_ctrl.sim.state import PAIRS

if TYPE_CHECKING:
    from peg_ctrl.run.loop import Loop, StepInfo

__all__ = [
    "TraceRecorder",
    "StepLogRecorder",
    "StateRecorder",
    "read_states",
    "VideoRecorder",
    "FollowCamera",
    "FOLLOW",
    "offscreen_renderer",
    "CallbackRecorder",
    "step_record",
]


def _round(values: Any, digits: int = 6) -> list[float]:
    return [round(v, digits) for v in np.asarray(values, dtype=float).tolist()]


class TraceRecorder:
    """The full-rate force trace (:data:`~peg_ctrl.run.episode_log.TRACE_COLUMNS`): time, phase
    index, every pair's force, the peg's deepest penetration and its depth below the hole mouth,
    at every physics step. Each control step costs two array copies; the rows are built and
    handed to the logger ``chunk`` physics steps at a time (and at :meth:`flush`)."""

    def __init__(self, logger: EpisodeLogger, phases: tuple[str, ...], *, chunk: int = 500) -> None:
        self.logger = logger
        self._index = {p: float(i) for i, p in enumerate(phases)}
        self._chunk = chunk
        self._top: float | None = None
        self._n = 0  # rows held
        self._raw = np.zeros((0, 0))  # sensordata of each physics step
        self._peg = np.zeros((0, 7))
        self._t_end: list[float] = []  # per control step: its time and phase
        self._phase: list[float] = []

    def record(self, loop: Loop, info: StepInfo) -> None:
        k = loop.decimation
        if self._top is None:
            self._top = float(loop.scene.assets.block_size[2])
            rows = self._chunk + k
            self._raw = np.zeros((rows, loop.model.nsensordata))
            self._sensors = info.sensors
            self._peg = np.zeros((rows, 7))
            self._dt = float(loop.model.opt.timestep)
            self._half = 0.5 * float(loop.scene.assets.peg_length)
            self._k = k
        n = self._n
        self._raw[n : n + k] = info.sensors.raw
        self._peg[n : n + k] = info.peg_qpos
        self._t_end.append(info.t)
        self._phase.append(self._index.get(info.phase, -1.0))
        self._n = n + k
        if self._n >= self._chunk:
            self.flush()

    def flush(self) -> None:
        """Hand the rows held to the logger."""
        n = self._n
        if not n:
            return
        assert self._top is not None
        k = self._k
        rows = np.empty((n, len(TRACE_COLUMNS)))
        back = np.arange(k - 1, -1, -1, dtype=float) * self._dt  # row i of a step: t - (k-1-i) dt
        rows[:, 0] = (np.asarray(self._t_end)[:, None] - back[None, :]).ravel()
        rows[:, 1] = np.repeat(self._phase, k)
        rows[:, 2 : 2 + len(PAIRS)] = self._sensors.forces(self._raw[:n])
        rows[:, 2 + len(PAIRS)] = self._sensors.penetrations(self._raw[:n])
        q = self._peg[:n]  # the lower end: centre - half length * |axis z| (axis z = 1 - 2(x^2+y^2))
        axis_z = np.abs(1.0 - 2.0 * (q[:, 4] ** 2 + q[:, 5] ** 2))
        rows[:, 3 + len(PAIRS)] = self._top - (q[:, 2] - self._half * axis_z)
        rows[:, 4 + len(PAIRS)] = self._sensors.grip(self._raw[:n])
        self.logger.trace(rows)
        self._n = 0
        self._t_end, self._phase = [], []


def step_record(loop: Loop, info: StepInfo) -> dict[str, Any]:
    """The SPEC §7 per-step record."""
    target, s, peg, d = info.target, info.gripper, info.peg, info.output.diagnostics
    return {
        "event": "step",
        "step": info.step,
        "t": round(info.t, 6),
        "phase": info.phase,
        "command": {
            "position": _round(target.p_world),
            "quat": _round(target.quat_world),
            "omega_body": _round(target.omega_body),
            "jaw_sep_m": round(float(target.jaw_sep_m), 6),
        },
        "gripper": {
            "position": _round(s.p_world),
            "euler": _round(quat_to_euler(s.quat_world)),
            "quat": _round(s.quat_world),
            "jaw_sep_m": round(float(s.jaw_sep_m), 6),
        },
        "peg": {"position": _round(peg.p_world), "quat": _round(peg.quat_world)},
        "contacts": [c.to_dict() for c in loop.reader.contacts(loop.data)],
        "controller": {"solve_time_s": d.solve_time_s, "status": d.status, "iterations": d.iterations},
    }


class StepLogRecorder:
    """``log.jsonl``: a step record every ``interval`` physics steps, and a phase record whenever
    a phase of the task ends."""

    def __init__(self, logger: EpisodeLogger, interval: int) -> None:
        self.logger = logger
        self.interval = interval
        self._next = interval
        self._phases_logged = 0

    def record(self, loop: Loop, info: StepInfo) -> None:
        self.log_closed_phases(loop)
        if info.step >= self._next:
            self._next += self.interval
            self.logger.record(step_record(loop, info))

    def flush(self, loop: Loop) -> None:
        """At the end: log every phase record not yet logged, closed or not."""
        self.log_closed_phases(loop)
        for rec in loop.task.records[self._phases_logged :]:
            self.logger.record({"event": "phase", **rec.to_dict()})
        self._phases_logged = len(loop.task.records)

    def log_closed_phases(self, loop: Loop) -> None:
        records = loop.task.records
        while self._phases_logged < len(records) and records[self._phases_logged].t_end is not None:
            self.logger.record({"event": "phase", **records[self._phases_logged].to_dict()})
            self._phases_logged += 1


class StateRecorder:
    """The simulation state at every control step, for replays: time [s] and the full ``qpos``
    (``nq``,) after the step, plus the state at :meth:`start`. One array copy per control step
    into a buffer that doubles when full; :meth:`close` writes ``states.npz`` (arrays ``time``
    (n,), ``qpos`` (n, nq), and ``nq``) atomically, so a reader never sees a torn file."""

    def __init__(self, path: Path, nq: int, *, capacity: int = 4096) -> None:
        self.path = Path(path)
        self.nq = nq
        self.n = 0  # states held
        self._time = np.empty(capacity)
        self._qpos = np.empty((capacity, nq))

    def start(self, data: mujoco.MjData) -> None:
        """Keep the state before the first step (after the loop's reset)."""
        self._append(float(data.time), data.qpos)

    def record(self, loop: Loop, info: StepInfo) -> None:
        self._append(info.t, loop.data.qpos)

    def _append(self, t: float, qpos: NDArray[np.float64]) -> None:
        if self.n == len(self._time):
            self._time = np.resize(self._time, 2 * self.n)
            self._qpos = np.resize(self._qpos, (2 * self.n, self.nq))
        self._time[self.n] = t
        self._qpos[self.n] = qpos
        self.n += 1

    def close(self) -> Path:
        """Write ``states.npz`` atomically; returns its path."""
        import io

        buffer = io.BytesIO()
        np.savez_compressed(buffer, time=self._time[: self.n], qpos=self._qpos[: self.n], nq=self.nq)
        return atomic_write_bytes(self.path, buffer.getvalue())


def read_states(path: Path) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(time (n,) [s], qpos (n, nq)) of a ``states.npz`` written by :class:`StateRecorder`."""
    with np.load(path) as npz:
        return np.asarray(npz["time"], dtype=float), np.asarray(npz["qpos"], dtype=float)


class FollowCamera:
    """A free camera that keeps the peg and the gripper's pinch point in frame: it looks at
    their midpoint from a fixed direction (``azimuth`` and ``elevation`` [deg], MuJoCo's
    convention: azimuth 90 looks along +Y) and backs off as they move apart, never closer than
    ``min_distance`` [m], with ``margin`` [m] kept free around them.

    The default looks across the table from its +Y side, a little towards -X (the peg's start):
    there, the body of the gripper, once turned, stays behind the peg rather than in front of it.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        *,
        azimuth: float = -60.0,
        elevation: float = -22.0,
        min_distance: float = 0.32,
        margin: float = 0.07,
    ) -> None:
        self._peg = model.body("peg").id
        self._pinch = model.site(PINCH_SITE).id
        self._margin = margin  # [m] kept free around the two points
        self._min_distance = min_distance
        self._tan = math.tan(math.radians(0.5 * float(model.vis.global_.fovy)))
        self.camera = mujoco.MjvCamera()
        self.camera.type = mujoco.mjtCamera.mjCAMERA_FREE
        self.camera.azimuth = azimuth
        self.camera.elevation = elevation

    def update(self, data: mujoco.MjData) -> mujoco.MjvCamera:
        """Aim the camera at the state in ``data`` (after ``mj_forward``/``mj_step``); returns it."""
        peg, pinch = data.xpos[self._peg], data.site_xpos[self._pinch]
        half = 0.5 * float(np.linalg.norm(peg - pinch))
        self.camera.lookat[:] = 0.5 * (peg + pinch)
        # Both points within 80 % of the half field of view.
        self.camera.distance = max(self._min_distance, (half + self._margin) / (0.8 * self._tan))
        return self.camera


#: The views a video can show side by side: ``"follow"`` (a :class:`FollowCamera`) or the name
#: of one of the model's cameras (``"insertion"``: fixed on the hole; ``"overview"``).
FOLLOW = "follow"


def offscreen_renderer(model: mujoco.MjModel, height: int, width: int) -> mujoco.Renderer:
    """A ``mujoco.Renderer`` of ``height`` x ``width`` [px], made after
    :func:`~peg_ctrl.sim.gl.before_gl_context` (Triton, if installed, imported first: it crashes
    the process when first imported after a GL context exists)."""
    before_gl_context()
    return mujoco.Renderer(model, height, width)


class VideoRecorder:
    """Offscreen video at ``fps`` [frames/s], written as MP4 (H.264) by :meth:`close`.

    Each frame shows ``views`` side by side, each ``size`` = (height, width) [px]: by default on
    the left a camera that follows the peg and the gripper (:class:`FollowCamera`), on the right
    the fixed close-up of the hole (the model's ``insertion`` camera). In the loop it records a
    frame every ``1/fps`` s of simulated time; :meth:`add_frame` adds one from any ``MjData``
    (e.g. a replay).

    The video is written to a temporary file beside ``path`` and renamed to ``path`` by
    :meth:`close`, so ``path`` is a whole video or absent. In the loop a failing frame (a full
    disk, the renderer) does not stop the episode: recording stops and :meth:`close` raises.

    Raises:
        ConfigError: a view that is neither ``"follow"`` nor one of the model's cameras (the
            message lists them), no views, or ``fps`` < 1.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        path: Path,
        *,
        views: Sequence[str] = (FOLLOW, "insertion"),
        fps: int = 30,
        size: tuple[int, int] = (480, 640),
    ) -> None:
        import imageio.v2 as imageio

        cameras = [model.camera(i).name for i in range(model.ncam)]
        if not views:
            raise ConfigError("video views must name at least one view")
        for view in views:
            if view != FOLLOW and view not in cameras:
                raise ConfigError(f"unknown video view {view!r}; known: {', '.join([FOLLOW, *cameras])}")
        if fps < 1:
            raise ConfigError(f"video fps must be >= 1, got {fps}")
        self.path = Path(path)
        self.views = tuple(views)
        self.fps = fps
        self.size = size
        self.frames = 0  # frames written
        self._period = 1.0 / fps
        self._next = 0.0
        self._follow = FollowCamera(model) if FOLLOW in self.views else None
        self._renderer = offscreen_renderer(model, *size)
        self._tmp = temp_path(self.path)
        self._error: Exception | None = None
        try:
            self._writer = imageio.get_writer(
                str(self._tmp),
                fps=fps,
                codec="libx264",
                quality=7,
                macro_block_size=8,
                ffmpeg_log_level="quiet",  # a failure is raised as an OutputError, in one line
            )
        except BaseException:
            self._renderer.close()
            raise
        self._closed = False

    def cameras(self, data: mujoco.MjData) -> list[mujoco.MjvCamera | str]:
        """The camera of each view, aimed at the state in ``data``."""
        out: list[mujoco.MjvCamera | str] = []
        for view in self.views:
            if view == FOLLOW:
                assert self._follow is not None
                out.append(self._follow.update(data))
            else:
                out.append(view)
        return out

    def render(self, data: mujoco.MjData) -> NDArray[np.uint8]:
        """The frame of the state in ``data``: (height, width x views, 3) RGB."""
        images = []
        for camera in self.cameras(data):
            self._renderer.update_scene(data, camera=camera)
            images.append(self._renderer.render())
        return np.concatenate(images, axis=1)

    def add_frame(self, data: mujoco.MjData) -> None:
        """Render the state in ``data`` and append it to the video."""
        self._writer.append_data(self.render(data))
        self.frames += 1

    def record(self, loop: Loop, info: StepInfo) -> None:
        if self._error is not None or info.t + 1e-9 < self._next:
            return
        self._next += self._period
        try:
            self.add_frame(loop.data)
        except Exception as exc:  # the episode goes on without its video; close() raises it
            self._error = exc

    def close(self) -> str:
        """Finish the MP4, free the renderer and put the video in place; returns its path.

        Raises:
            OutputError: the video could not be written (no space left, ...); nothing is left.
            Exception: whatever stopped the recording (e.g. the renderer).
        """
        if self._closed:
            return str(self.path)
        self._closed = True
        try:
            self._writer.close()
        except OSError as exc:
            self._error = self._error or exc
        finally:
            self._renderer.close()
        if self._error is not None:
            Path(self._tmp).unlink(missing_ok=True)
            if isinstance(self._error, OSError):
                raise write_error(self.path, self._error) from None
            raise self._error
        if self.frames or Path(self._tmp).exists():  # no frame, no file (imageio starts on the first)
            # imageio does not report an encoder that failed at the end (writing the index):
            # check the file's structure before it goes in place.
            if not _mp4_is_whole(self._tmp):
                Path(self._tmp).unlink(missing_ok=True)
                raise OutputError(f"cannot write {str(self.path)!r}: {_encoder_failure(self.path)}")
            commit_temp(self._tmp, self.path)
        return str(self.path)

    def discard(self) -> None:
        """Stop without a video: free the writer and the renderer, remove the partial file."""
        if self._closed:
            return
        self._closed = True
        try:
            with contextlib.suppress(Exception):  # the partial video is removed anyway
                self._writer.close()
        finally:
            self._renderer.close()
            Path(self._tmp).unlink(missing_ok=True)


def _mp4_is_whole(path: Path) -> bool:
    """Whether ``path`` is a structurally complete MP4: top-level boxes that fill the file
    exactly, among them the media data and the index (``moov``, which ffmpeg writes last)."""
    size = os.path.getsize(path)
    kinds = set()
    pos = 0
    with open(path, "rb") as fh:
        while pos < size:
            fh.seek(pos)
            head = fh.read(16)
            if len(head) < 8:
                return False
            length, kind = struct.unpack(">I4s", head[:8])
            if length == 1 and len(head) == 16:  # a 64-bit size follows
                length = struct.unpack(">Q", head[8:])[0]
            elif length == 0:  # to the end of the file
                length = size - pos
            if length < 8:
                return False
            kinds.add(kind)
            pos += length
    return pos == size and {b"ftyp", b"mdat", b"moov"} <= kinds


def _encoder_failure(path: Path) -> str:
    """Why the encoder left an incomplete video, as well as it can be told."""
    try:
        free = os.statvfs(Path(path).parent)
    except OSError:
        return "the video encoder (ffmpeg) failed"
    if free.f_bavail * free.f_frsize < 1 << 20:
        return os.strerror(errno.ENOSPC)
    return "the video encoder (ffmpeg) failed"


class CallbackRecorder:
    """Calls ``fn(model, data)`` after every control step (e.g. a viewer's sync)."""

    def __init__(self, fn: Callable[[mujoco.MjModel, mujoco.MjData], None]) -> None:
        self.fn = fn

    def record(self, loop: Loop, info: StepInfo) -> None:
        self.fn(loop.model, loop.data)
