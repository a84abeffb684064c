"""Recorders: the state record for replays, and a video whose follow view keeps the peg in frame."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest

from peg_ctrl.config import ConfigError
from peg_ctrl.run.episode import EpisodeConfig, RandomizationConfig, run_episode
from peg_ctrl.run.recorders import FOLLOW, StateRecorder, VideoRecorder, read_states
from peg_ctrl.tools.replay import load_run


def test_state_recorder_grows_its_buffer_and_writes_atomically(tmp_path: Path) -> None:
    model = mujoco.MjModel.from_xml_string(
        "<mujoco><worldbody><body><freejoint/><geom size='0.1'/></body></worldbody></mujoco>"
    )
    data = mujoco.MjData(model)
    recorder = StateRecorder(tmp_path / "states.npz", model.nq, capacity=2)
    recorder.start(data)
    for k in range(1, 6):  # grows 2 -> 4 -> 8
        data.time = 0.01 * k
        data.qpos[0] = k
        recorder._append(float(data.time), data.qpos)
    path = recorder.close()
    t, qpos = read_states(path)
    np.testing.assert_allclose(t, 0.01 * np.arange(6))
    assert qpos.shape == (6, 7)
    np.testing.assert_array_equal(qpos[:, 0], np.arange(6))
    np.testing.assert_array_equal(qpos[:, 3], np.ones(6))  # the free joint's quaternion w, kept
    assert sorted(p.name for p in tmp_path.iterdir()) == ["states.npz"]  # no temporary left


@pytest.fixture(scope="module")
def episodes(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    """Two whole randomized pick-and-place episodes (no video: 1.5 s each)."""
    dirs = []
    for seed in (0, 1):
        out = tmp_path_factory.mktemp(f"seed{seed}")
        result = run_episode(
            EpisodeConfig(seed=seed, randomization=RandomizationConfig(enabled=True)), out, plot=False
        )
        assert result.status == "success"
        dirs.append(out)
    return dirs


def test_an_episode_records_its_state_at_every_control_step(episodes: list[Path]) -> None:
    import json

    model, t, qpos = load_run(episodes[0])
    summary = json.loads((episodes[0] / "summary.json").read_text())
    control_dt = 0.005  # pd at 200 Hz
    assert len(t) == summary["total_timesteps"] // 5 + 1  # every control step, and the start
    assert t[0] == 0.0 and t[-1] == pytest.approx(summary["sim_time_s"])
    np.testing.assert_allclose(np.diff(t), control_dt, atol=1e-9)
    assert qpos.shape == (len(t), model.nq)


def _peg_in_view(model: mujoco.MjModel, segmentation: np.ndarray) -> tuple[int, float, float]:
    """(pixels, x, y) of the peg's geoms in a segmentation image (h, w, 2): how many pixels show
    the peg, and their centroid as fractions of the width and height (nan if none)."""
    peg = model.body("peg").id
    geoms = [g for g in range(model.ngeom) if model.geom_bodyid[g] == peg]
    mask = (segmentation[..., 1] == mujoco.mjtObj.mjOBJ_GEOM) & np.isin(segmentation[..., 0], geoms)
    ys, xs = np.nonzero(mask)
    if len(xs) == 0:
        return 0, float("nan"), float("nan")
    return len(xs), xs.mean() / mask.shape[1], ys.mean() / mask.shape[0]


def test_the_follow_view_keeps_the_peg_in_frame_all_episode(episodes: list[Path], tmp_path: Path) -> None:
    """Sampled every 0.6 s over two whole episodes (grasp, lift, turn, align, drop, seated), the
    video's left view shows the peg near its centre (the fixed hole close-up has it at its right
    edge until the transport); the close-up shows the peg once it is seated."""
    for run in episodes:
        model, t, qpos = load_run(run)
        data = mujoco.MjData(model)
        video = VideoRecorder(model, tmp_path / "unused.mp4", size=(120, 160))
        seg = mujoco.Renderer(model, 120, 160)
        seg.enable_segmentation_rendering()
        try:
            for i in np.searchsorted(t, np.arange(0.0, t[-1], 0.6)):
                data.qpos[:] = qpos[i]
                mujoco.mj_forward(model, data)
                follow, fixed = video.cameras(data)
                seg.update_scene(data, camera=follow)
                pixels, x, y = _peg_in_view(model, seg.render())
                where = f"{run.name} at {t[i]:.1f} s: {pixels} px at ({x:.2f}, {y:.2f})"
                assert pixels > 50 and 0.2 < x < 0.8 and 0.2 < y < 0.8, where
            seg.update_scene(data, camera=fixed)
            pixels, x, y = _peg_in_view(model, seg.render())
            assert pixels > 50 and 0.2 < x < 0.8, f"the hole close-up: {pixels} px at ({x:.2f}, {y:.2f})"
        finally:
            seg.close()
            video.close()


def test_video_frames_put_the_views_side_by_side(tmp_path: Path) -> None:
    import imageio.v2 as imageio

    from peg_ctrl.run.episode import compiled_model

    model = compiled_model(EpisodeConfig().scene)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    video = VideoRecorder(model, tmp_path / "v.mp4", size=(96, 128))
    assert video.views == (FOLLOW, "insertion")
    frame = video.render(data)
    assert frame.shape == (96, 256, 3) and frame.dtype == np.uint8
    video.add_frame(data)
    video.add_frame(data)
    assert video.close() == str(tmp_path / "v.mp4") and video.frames == 2
    assert len([f for f in imageio.get_reader(str(tmp_path / "v.mp4"))]) == 2


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"views": ("top",)}, "unknown video view 'top'; known: follow, insertion, overview"),
        ({"views": ()}, "video views must name at least one view"),
        ({"fps": 0}, "video fps must be >= 1, got 0"),
    ],
)
def test_bad_video_settings_are_refused(tmp_path: Path, kwargs: dict, message: str) -> None:
    from peg_ctrl.run.episode import compiled_model

    with pytest.raises(ConfigError, match=message):
        VideoRecorder(compiled_model(EpisodeConfig().scene), tmp_path / "v.mp4", **kwargs)


@pytest.fixture
def render_log(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """The order in which ``mujoco.Renderer`` (a stand-in: no GL context) is created and, logged
    by :func:`_logging_triton`, ``triton`` imported."""
    import sys
    import types

    log: list[str] = []
    logger = types.ModuleType("peg_ctrl_test_log")
    logger.append = log.append  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "peg_ctrl_test_log", logger)

    class Renderer:
        def __init__(self, model: mujoco.MjModel, height: int, width: int) -> None:
            log.append("renderer")
            self.size = (height, width)

    monkeypatch.setattr(mujoco, "Renderer", Renderer)
    return log


def test_offscreen_renderer_imports_triton_before_the_context(
    render_log: list[str], fake_triton: Path
) -> None:
    from peg_ctrl.run.recorders import offscreen_renderer

    fake_triton.write_text("import sys\nsys.modules['peg_ctrl_test_log'].append('triton')\n")
    model = mujoco.MjModel.from_xml_string("<mujoco/>")
    renderer = offscreen_renderer(model, 48, 64)
    assert render_log == ["triton", "renderer"]
    assert renderer.size == (48, 64)
    offscreen_renderer(model, 48, 64)  # imported once
    assert render_log == ["triton", "renderer", "renderer"]


def test_offscreen_renderer_without_triton_only_creates_the_renderer(
    render_log: list[str], fake_triton: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``find_spec`` finds no Triton (the stand-in is hidden from it): nothing is imported."""
    import importlib.util
    import sys

    from peg_ctrl.run.recorders import offscreen_renderer

    real_find_spec = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util, "find_spec", lambda name, *a: None if name == "triton" else real_find_spec(name, *a)
    )
    offscreen_renderer(mujoco.MjModel.from_xml_string("<mujoco/>"), 48, 64)
    assert render_log == ["renderer"]
    assert "triton" not in sys.modules
