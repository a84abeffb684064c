"""Recorders: what the loop hands every control step to logs, traces, video and viewers."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import mujoco
import numpy as np

from peg_ctrl.commands import quat_to_euler
from peg_ctrl.episode_log import TRACE_COLUMNS, EpisodeLogger
from peg_ctrl.state import PAIRS

if TYPE_CHECKING:
    from peg_ctrl.loop import Loop, StepInfo

__all__ = ["TraceRecorder", "StepLogRecorder", "VideoRecorder", "CallbackRecorder", "step_record"]


def _round(values: Any, digits: int = 6) -> list[float]:
    return [round(float(v), digits) for v in values]


class TraceRecorder:
    """The full-rate force trace (:data:`~peg_ctrl.episode_log.TRACE_COLUMNS`): time, phase
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


class VideoRecorder:
    """Offscreen frames from ``camera`` at ``fps``, written as MP4 by :meth:`close`."""

    def __init__(
        self,
        model: mujoco.MjModel,
        path: Path,
        *,
        camera: str = "insertion",
        fps: int = 30,
        size: tuple[int, int] = (480, 640),
    ) -> None:
        import imageio.v2 as imageio

        self.path = path
        self.camera = camera
        self._period = 1.0 / fps
        self._next = 0.0
        self._renderer = mujoco.Renderer(model, *size)
        self._writer = imageio.get_writer(str(path), fps=fps, codec="libx264", quality=7, macro_block_size=8)

    def record(self, loop: Loop, info: StepInfo) -> None:
        if info.t + 1e-9 < self._next:
            return
        self._next += self._period
        self._renderer.update_scene(loop.data, camera=self.camera)
        self._writer.append_data(self._renderer.render())

    def close(self) -> str:
        self._writer.close()
        self._renderer.close()
        return str(self.path)


class CallbackRecorder:
    """Calls ``fn(model, data)`` after every control step (e.g. a viewer's sync)."""

    def __init__(self, fn: Callable[[mujoco.MjModel, mujoco.MjData], None]) -> None:
        self.fn = fn

    def record(self, loop: Loop, info: StepInfo) -> None:
        self.fn(loop.model, loop.data)
