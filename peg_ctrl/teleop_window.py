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

    if not glfw.init():
        raise WindowUnavailable("GLFW could not initialise a window system (is DISPLAY set?)")
    window = glfw.create_window(width, height, "peg_ctrl teleop", None, None)
    if not window:
        glfw.terminate()
        raise WindowUnavailable("GLFW could not open a window")
    glfw.make_context_current(window)
    glfw.swap_interval(0)
    model, data = session.model, session.data
    context = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_100)
    scene = mujoco.MjvScene(model, maxgeom=3000)
    scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = False  # software GL: keep frames cheap
    option = mujoco.MjvOption()
    camera = mujoco.MjvCamera()
    camera.type = mujoco.mjtCamera.mjCAMERA_FREE
    camera.lookat[:] = [0.0, 0.0, 0.06]
    camera.distance = 0.85
    camera.azimuth = 90.0
    camera.elevation = -25.0
    names = _key_names()
    mapper = session.mapper
    mouse = {"left": False, "right": False, "x": 0.0, "y": 0.0}

    def on_key(win, key, scancode, action, mods) -> None:  # type: ignore[no-untyped-def]
        name = names.get(key)
        if name is None:
            return
        shift = bool(mods & glfw.MOD_SHIFT)
        if action == glfw.PRESS:
            mapper.press(name, shift=shift)
        elif action == glfw.RELEASE:
            mapper.release(name, shift=shift)

    def on_focus(win, focused) -> None:  # type: ignore[no-untyped-def]
        if not focused:
            mapper.release_all()  # a release we never see must not leave a key stuck

    def on_button(win, button, action, mods) -> None:  # type: ignore[no-untyped-def]
        mouse["left"] = glfw.get_mouse_button(win, glfw.MOUSE_BUTTON_LEFT) == glfw.PRESS
        mouse["right"] = glfw.get_mouse_button(win, glfw.MOUSE_BUTTON_RIGHT) == glfw.PRESS
        mouse["x"], mouse["y"] = glfw.get_cursor_pos(win)

    def on_move(win, x, y) -> None:  # type: ignore[no-untyped-def]
        dx, dy = x - mouse["x"], y - mouse["y"]
        mouse["x"], mouse["y"] = x, y
        if not (mouse["left"] or mouse["right"]):
            return
        _, h = glfw.get_window_size(win)
        action = mujoco.mjtMouse.mjMOUSE_ROTATE_V if mouse["left"] else mujoco.mjtMouse.mjMOUSE_MOVE_V
        mujoco.mjv_moveCamera(model, action, dx / h, dy / h, scene, camera)

    def on_scroll(win, dx, dy) -> None:  # type: ignore[no-untyped-def]
        mujoco.mjv_moveCamera(model, mujoco.mjtMouse.mjMOUSE_ZOOM, 0.0, -0.05 * dy, scene, camera)

    glfw.set_key_callback(window, on_key)
    glfw.set_window_focus_callback(window, on_focus)
    glfw.set_mouse_button_callback(window, on_button)
    glfw.set_cursor_pos_callback(window, on_move)
    glfw.set_scroll_callback(window, on_scroll)

    viewport = mujoco.MjrRect(0, 0, width, height)
    last = time.perf_counter()
    try:
        while not session.finished:
            if glfw.window_should_close(window):
                session.finish("quit")
                break
            now = time.perf_counter()
            # Real-time pacing at the chosen multiplier; a slow frame is not caught up in one go.
            session.advance(min((now - last) * mapper.speed, max_frame_sim_s))
            last = now
            w, h = glfw.get_framebuffer_size(window)
            viewport = mujoco.MjrRect(0, 0, w, h)
            mujoco.mjv_updateScene(model, data, option, None, camera, mujoco.mjtCatBit.mjCAT_ALL, scene)
            mujoco.mjr_render(viewport, scene, context)
            titles, values = session.overlay_lines()
            mujoco.mjr_overlay(
                mujoco.mjtFontScale.mjFONTSCALE_100,
                mujoco.mjtGridPos.mjGRID_TOPLEFT,
                viewport,
                titles,
                values,
                context,
            )
            mujoco.mjr_overlay(
                mujoco.mjtFontScale.mjFONTSCALE_100,
                mujoco.mjtGridPos.mjGRID_TOPRIGHT,
                viewport,
                HELP_TITLES,
                HELP_VALUES,
                context,
            )
            if screenshot is not None:
                rgb = np.zeros((h, w, 3), dtype=np.uint8)
                mujoco.mjr_readPixels(rgb, None, viewport, context)
                last_frame = np.flipud(rgb)
            glfw.swap_buffers(window)
            glfw.poll_events()
        if screenshot is not None:
            import imageio.v2 as imageio

            from peg_ctrl.io import atomic_path

            screenshot.parent.mkdir(parents=True, exist_ok=True)
            with atomic_path(screenshot) as tmp:
                imageio.imwrite(str(tmp), last_frame)
    finally:
        summary = session.finish(session.end_reason or "quit")
        context.free()
        glfw.destroy_window(window)
        glfw.terminate()
    return summary
