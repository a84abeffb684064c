"""What this process must do before it makes its first OpenGL context.

Triton, which the CUDA build of PyTorch brings (``pip install 'peg-ctrl[rl]'`` without the CPU
build), crashes the process (exit 139, a segmentation fault inside ``libtriton``'s import) when
it is first imported after an OpenGL context exists: a ``mujoco.Renderer`` (EGL or OSMesa), the
passive viewer or the teleoperation window (GLFW). PyTorch imports it late, when it builds a
model (Stable-Baselines3's policy), or an ``rgb_array`` renderer opened after a ``human`` viewer
(Gymnasium's ``check_env``) would. Imported before the first context it is safe, whatever opens
afterwards: every place in the package that makes a context calls :func:`before_gl_context` first.

MuJoCo's passive viewer draws in a daemon thread, and its handle's ``close()`` only asks that
thread to end. A process that exits right after (a script that closes its environment and ends)
may cut the thread off inside the GL driver's teardown: a segmentation fault at exit, one run
in four under a virtual display beside an offscreen renderer. :class:`PassiveViewer` waits for
the thread in ``close()``.
"""

from __future__ import annotations

import importlib
import importlib.util
import threading
from typing import Any

__all__ = ["before_gl_context", "EARLY_IMPORTS", "PassiveViewer"]

#: How long ``PassiveViewer.close`` waits for the viewer's thread [s].
VIEWER_CLOSE_TIMEOUT_S = 5.0

#: Modules imported (when installed) before the first OpenGL context.
EARLY_IMPORTS = ("triton",)


def before_gl_context() -> list[str]:
    """Import :data:`EARLY_IMPORTS` that are installed and not imported yet; returns their names.

    Cheap after the first call (the modules are in ``sys.modules``); a no-op without them.
    """
    imported = []
    for name in EARLY_IMPORTS:
        if importlib.util.find_spec(name) is not None:
            importlib.import_module(name)
            imported.append(name)
    return imported


class PassiveViewer:
    """``mujoco.viewer.launch_passive(model, data)`` after :func:`before_gl_context`, whose
    :meth:`close` returns once the viewer's thread has ended."""

    def __init__(self, model: Any, data: Any) -> None:
        import mujoco.viewer

        before_gl_context()
        others = set(threading.enumerate())
        self.handle = mujoco.viewer.launch_passive(model, data)
        # The window's thread: launch_passive starts it and does not keep it.
        self._threads = [t for t in threading.enumerate() if t not in others]

    def is_running(self) -> bool:
        """Whether the window is still open."""
        return bool(self.handle.is_running())

    def sync(self) -> None:
        """Show the current state of the simulation's data."""
        self.handle.sync()

    def close(self) -> None:
        """Close the window and wait (at most :data:`VIEWER_CLOSE_TIMEOUT_S`) for its thread."""
        self.handle.close()
        for thread in self._threads:
            thread.join(VIEWER_CLOSE_TIMEOUT_S)
