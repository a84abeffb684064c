"""The teleoperation window: GLFW + MuJoCo's renderer, real-time paced, with an overlay.

See :mod:`peg_ctrl.teleop` for the keymap and why this is an own window rather than MuJoCo's
stock viewer (key releases, no colliding shortcuts).
"""

from __future__ import annotations

import time
from pathlib import Path

import mujoco
import numpy as np

from peg_ctrl.errors import PegCtrlError
from peg_ctrl.teleop import HELP_TITLES, HELP_VALUES, TeleopSession

__all__ = ["run_window", "WindowUnavailable"]


class WindowUnavailable(PegCtrlError, RuntimeError):
    """No window system (no DISPLAY, or GLFW failed to initialise): the user's environment, not a
    bug, so the command line reports it in one line with exit code 2."""


def _key_names() -> dict[int, str]:
    import glfw

    names = {getattr(glfw, f"KEY_{d}"): str(d) for d in range(10)}
    names.update({getattr(glfw, f"KEY_{c}"): c for c in "ABCDEFGHIJKLMNOPQRSTUVWXYZ"})
    names.update(
        {
            glfw.KEY_LEFT_BRACKET: "[",
            glfw.KEY_RIGHT_BRACKET: "]",
            glfw.KEY_MINUS: "-",
            glfw.KEY_EQUAL: "=",
            glfw.KEY_UP: "UP",
            glfw.KEY_DOWN: "DOWN",
            glfw.KEY_LEFT: "LEFT",
            glfw.KEY_RIGHT: "RIGHT",
            glfw.KEY_ESCAPE: "ESCAPE",
        }
    )
    return names


def run_window(
    session: TeleopSession,
    *,
    width: int = 1100,
    height: int = 720,
    screenshot: Path | None = None,
    max_frame_sim_s: float = 0.05,
) -> dict:
    """Open the window and run ``session`` until Esc, the window closes, or the session ends."""
    import glfw

    window = _Window(session, width, height)
    last = time.perf_counter()
    frame = None
    try:
        while not session.finished:
            if glfw.window_should_close(window.handle):
                session.finish("quit")
                break
            now = time.perf_counter()
            # Real-time pacing at the chosen multiplier; a slow frame is not caught up in one go.
            session.advance(min((now - last) * session.mapper.speed, max_frame_sim_s))
            last = now
            frame = window.draw(read_pixels=screenshot is not None)
            glfw.swap_buffers(window.handle)
            glfw.poll_events()
        if screenshot is not None and frame is not None:
            _save_png(screenshot, frame)
    finally:
        summary = session.finish(session.end_reason or "quit")
        window.close()
    return summary


class _Window:
    """A GLFW window with MuJoCo's renderer: a free camera the mouse moves, keys to the session's
    mapper, the session's overlay top left and the key help top right."""

    def __init__(self, session: TeleopSession, width: int, height: int) -> None:
        import glfw

        from peg_ctrl.sim.gl import before_gl_context

        before_gl_context()  # before GLFW's context (peg_ctrl.sim.gl)
        if not glfw.init():
            raise WindowUnavailable("GLFW could not initialise a window system (is DISPLAY set?)")
        self.handle = glfw.create_window(width, height, "peg_ctrl teleop", None, None)
        if not self.handle:
            glfw.terminate()
            raise WindowUnavailable("GLFW could not open a window")
        glfw.make_context_current(self.handle)
        glfw.swap_interval(0)
        self.session = session
        model = session.model
        self.context = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_100)
        self.scene = mujoco.MjvScene(model, maxgeom=3000)
        self.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = False  # software GL: keep frames cheap
        self.option = mujoco.MjvOption()
        self.camera = mujoco.MjvCamera()
        self.camera.type = mujoco.mjtCamera.mjCAMERA_FREE
        self.camera.lookat[:] = [0.0, 0.0, 0.06]
        self.camera.distance = 0.85
        self.camera.azimuth = 90.0
        self.camera.elevation = -25.0
        self.names = _key_names()
        self.mouse = {"left": False, "right": False, "x": 0.0, "y": 0.0}
        glfw.set_key_callback(self.handle, self._on_key)
        glfw.set_window_focus_callback(self.handle, self._on_focus)
        glfw.set_mouse_button_callback(self.handle, self._on_button)
        glfw.set_cursor_pos_callback(self.handle, self._on_move)
        glfw.set_scroll_callback(self.handle, self._on_scroll)

    def draw(self, *, read_pixels: bool) -> np.ndarray | None:
        """Render the scene and both overlays; with ``read_pixels``, return the frame (RGB)."""
        import glfw

        w, h = glfw.get_framebuffer_size(self.handle)
        viewport = mujoco.MjrRect(0, 0, w, h)
        model, data = self.session.model, self.session.data
        mujoco.mjv_updateScene(
            model, data, self.option, None, self.camera, mujoco.mjtCatBit.mjCAT_ALL, self.scene
        )
        mujoco.mjr_render(viewport, self.scene, self.context)
        titles, values = self.session.overlay_lines()
        font = mujoco.mjtFontScale.mjFONTSCALE_100
        mujoco.mjr_overlay(font, mujoco.mjtGridPos.mjGRID_TOPLEFT, viewport, titles, values, self.context)
        mujoco.mjr_overlay(
            font, mujoco.mjtGridPos.mjGRID_TOPRIGHT, viewport, HELP_TITLES, HELP_VALUES, self.context
        )
        if not read_pixels:
            return None
        rgb = np.zeros((h, w, 3), dtype=np.uint8)
        mujoco.mjr_readPixels(rgb, None, viewport, self.context)
        return np.flipud(rgb)

    def close(self) -> None:
        """Free the GL context and the window."""
        import glfw

        self.context.free()
        glfw.destroy_window(self.handle)
        glfw.terminate()

    def _on_key(self, win, key, scancode, action, mods) -> None:  # type: ignore[no-untyped-def]
        import glfw

        name = self.names.get(key)
        if name is None:
            return
        shift = bool(mods & glfw.MOD_SHIFT)
        if action == glfw.PRESS:
            self.session.mapper.press(name, shift=shift)
        elif action == glfw.RELEASE:
            self.session.mapper.release(name, shift=shift)

    def _on_focus(self, win, focused) -> None:  # type: ignore[no-untyped-def]
        if not focused:
            self.session.mapper.release_all()  # a release we never see must not leave a key stuck

    def _on_button(self, win, button, action, mods) -> None:  # type: ignore[no-untyped-def]
        import glfw

        self.mouse["left"] = glfw.get_mouse_button(win, glfw.MOUSE_BUTTON_LEFT) == glfw.PRESS
        self.mouse["right"] = glfw.get_mouse_button(win, glfw.MOUSE_BUTTON_RIGHT) == glfw.PRESS
        self.mouse["x"], self.mouse["y"] = glfw.get_cursor_pos(win)

    def _on_move(self, win, x, y) -> None:  # type: ignore[no-untyped-def]
        import glfw

        mouse = self.mouse
        dx, dy = x - mouse["x"], y - mouse["y"]
        mouse["x"], mouse["y"] = x, y
        if not (mouse["left"] or mouse["right"]):
            return
        _, h = glfw.get_window_size(win)
        action = mujoco.mjtMouse.mjMOUSE_ROTATE_V if mouse["left"] else mujoco.mjtMouse.mjMOUSE_MOVE_V
        mujoco.mjv_moveCamera(self.session.model, action, dx / h, dy / h, self.scene, self.camera)

    def _on_scroll(self, win, dx, dy) -> None:  # type: ignore[no-untyped-def]
        zoom = mujoco.mjtMouse.mjMOUSE_ZOOM
        mujoco.mjv_moveCamera(self.session.model, zoom, 0.0, -0.05 * dy, self.scene, self.camera)


def _save_png(path: Path, frame: np.ndarray) -> None:
    import imageio.v2 as imageio

    from peg_ctrl.io import atomic_path

    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        imageio.imwrite(str(tmp), frame)
