"""One picture of an episode: a frame of the insertion beside its contact-force profile.

``peg-sim replay RUN_DIR --figure OUT.png [--at T]`` renders the recorded state at ``T`` (the
follow camera and the fixed camera on the hole, as the episode video shows them) beside the
peg-block force and the peg's depth against time, ``T`` marked. Without ``--at``, ``T`` is the
moment the peg is halfway to its deepest after its first touch of the block (the insertion under
way); for a peg that never went :data:`MIN_DEPTH_M` in, the peak peg-block force, or the
episode's end when it never touched the block. The README's picture is made this way (``make readme-figure``).
"""

from __future__ import annotations

import os
import zipfile
from pathlib import Path

import mujoco
import numpy as np

from peg_ctrl.errors import ConfigError

__all__ = ["insertion_figure", "figure_time"]

_FORCE, _DEPTH = "block-peg", "peg_depth_m"  # columns of the force trace (TRACE_COLUMNS)
#: A peg that went less deep than this [m] is shown at its peak force instead of halfway in.
MIN_DEPTH_M = 0.002


def figure_time(t: np.ndarray, force: np.ndarray, depth: np.ndarray) -> float:
    """The default moment of the figure [s]: after the first peg-block contact, the peg halfway
    to its deepest below the hole's mouth, else the peak peg-block force; the last sample when
    the peg never touched the block (its depth is then the table's, not the hole's)."""
    touched = np.flatnonzero(force > 0.0)
    if not touched.size:
        return float(t[-1])
    after = slice(int(touched[0]), None)
    deepest = float(np.nanmax(depth[after], initial=0.0))
    if deepest >= MIN_DEPTH_M:
        return float(t[after][int(np.argmax(depth[after] >= 0.5 * deepest))])
    return float(t[int(np.nanargmax(force))])


def insertion_figure(
    run_dir: str | os.PathLike[str], out: str | os.PathLike[str], *, at: float | None = None
) -> tuple[Path, float]:
    """Write the figure of the episode in ``run_dir`` to ``out`` (PNG); returns its path and the
    time shown [s].

    Raises:
        ConfigError: ``run_dir`` is not a recorded episode (:func:`~peg_ctrl.tools.replay.load_run`),
            has no force trace, or ``at`` is outside the episode.
    """
    from peg_ctrl.run.episode_log import TRACE_COLUMNS, read_trace
    from peg_ctrl.run.recorders import FollowCamera, offscreen_renderer
    from peg_ctrl.tools.replay import load_run

    model, t_states, qpos = load_run(run_dir)
    if not any((Path(run_dir) / name).is_file() for name in ("forces.npz", "forces.partial")):
        raise ConfigError(f"run directory {str(run_dir)!r} has no forces.npz (its force trace)")
    try:
        trace = read_trace(Path(run_dir))
    except (ValueError, KeyError, OSError, zipfile.BadZipFile) as exc:
        raise ConfigError(f"the force trace of {str(run_dir)!r} cannot be read: {exc}") from None
    if trace.ndim != 2 or len(trace) == 0:
        raise ConfigError(f"the force trace of {str(run_dir)!r} holds no sample")
    t, force = trace[:, 0], trace[:, TRACE_COLUMNS.index(_FORCE)]
    depth = trace[:, TRACE_COLUMNS.index(_DEPTH)]
    when = figure_time(t, force, depth) if at is None else float(at)
    if not t_states[0] <= when <= t_states[-1]:
        raise ConfigError(
            f"--at {when:g} s is outside the episode ({t_states[0]:.2f} to {t_states[-1]:.2f} s)"
        )
    data = mujoco.MjData(model)
    data.qpos[:] = qpos[int(np.argmin(np.abs(t_states - when)))]
    mujoco.mj_forward(model, data)
    renderer = offscreen_renderer(model, 480, 480)
    try:
        views = []
        for camera in (FollowCamera(model).update(data), "insertion"):  # as the episode video
            renderer.update_scene(data, camera=camera)
            views.append(renderer.render())
    finally:
        renderer.close()
    image = np.concatenate(views, axis=1)
    return _draw(image, t, force, depth, when, Path(out)), when


def _draw(
    image: np.ndarray, t: np.ndarray, force: np.ndarray, depth: np.ndarray, when: float, out: Path
) -> Path:
    from peg_ctrl.run.plots import pyplot, save_figure

    plt = pyplot()
    fig, (ax_img, ax) = plt.subplots(
        1, 2, figsize=(12.0, 3.6), dpi=110, width_ratios=[2.0, 1.25], layout="constrained"
    )
    ax_img.imshow(image)
    ax_img.set_axis_off()
    ax_img.set_title("follow camera  |  camera on the hole", fontsize=9)
    touched = np.flatnonzero(force > 0.0)
    start = max(float(t[touched[0]]) - 0.5, float(t[0])) if touched.size else float(t[0])
    shown = t >= start
    ax.plot(t[shown], force[shown], color="C0", lw=1.0, label="peg-block force")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("peg-block contact force [N]", color="C0")
    ax.axvline(when, color="0.3", lw=0.9, ls="--")
    ax.grid(alpha=0.3)
    twin = ax.twinx()
    twin.plot(t[shown], 1e3 * depth[shown], color="C2", lw=1.0)
    twin.set_ylabel("peg depth in the hole [mm]", color="C2")
    ax.set_title(f"frame at {when:.2f} s (dashed)", fontsize=9)
    out.parent.mkdir(parents=True, exist_ok=True)
    return save_figure(fig, out)
