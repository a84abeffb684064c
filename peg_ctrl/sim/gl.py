"""What this process must do before it makes its first OpenGL context.

Triton, which the CUDA build of PyTorch brings (``pip install 'peg-ctrl[rl]'`` without the CPU
build), crashes the process (exit 139, a segmentation fault inside ``libtriton``'s import) when
it is first imported after an OpenGL context exists: a ``mujoco.Renderer`` (EGL or OSMesa), the
passive viewer or the teleoperation window (GLFW). PyTorch imports it late, when it builds a
model (Stable-Baselines3's policy), or an ``rgb_array`` renderer opened after a ``human`` viewer
(Gymnasium's ``check_env``) would. Imported before the first context it is safe, whatever opens
afterwards: every place in the package that makes a context calls :func:`before_gl_context` first.
"""

from __future__ import annotations

import importlib
import importlib.util

__all__ = ["before_gl_context", "EARLY_IMPORTS"]

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
