"""peg_ctrl: a physics-faithful peg-in-hole simulator in MuJoCo and a controller research framework.

Importing the package registers the Gymnasium environment ``peg_ctrl/PegInsertion-v0``
(:mod:`peg_ctrl.gym_env`, imported only when the environment is made).
"""

import os as _os

# One BLAS thread unless the user says otherwise: the controllers solve small problems every
# millisecond, where a threaded BLAS only spins. CasADi's qpOASES loads its own OpenBLAS, whose
# idle threads busy-wait: measured on 2 cores, 44 s of system time in 4 mpc episodes against
# 1 s with one thread (docs/controllers.md). Read when each BLAS library loads, so set before
# numpy (and CasADi's plugin) are imported.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    _os.environ.setdefault(_var, "1")


def _choose_gl_backend() -> None:
    """Headless by default: on Linux without a display, and with ``MUJOCO_GL`` unset, offscreen
    rendering (``render_mode="rgb_array"``, ``run --video``) uses EGL, else OSMesa, whichever
    library is installed. mujoco reads ``MUJOCO_GL`` once, when it is first imported: set it
    before (``import peg_ctrl`` first, or set ``MUJOCO_GL`` yourself)."""
    import sys
    from ctypes.util import find_library

    if _os.environ.get("MUJOCO_GL") or not sys.platform.startswith("linux"):
        return
    if _os.environ.get("DISPLAY") or _os.environ.get("WAYLAND_DISPLAY"):
        return
    for backend, library in (("egl", "EGL"), ("osmesa", "OSMesa")):
        if find_library(library):
            _os.environ["MUJOCO_GL"] = backend
            return


_choose_gl_backend()

from gymnasium.envs.registration import register as _register  # noqa: E402
from gymnasium.envs.registration import registry as _registry  # noqa: E402

__version__ = "0.1.0"

if "peg_ctrl/PegInsertion-v0" not in _registry:
    _register(id="peg_ctrl/PegInsertion-v0", entry_point="peg_ctrl.gym_env:PegInsertionEnv")
