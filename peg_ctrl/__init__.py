"""peg_ctrl: a physics-faithful peg-in-hole simulator in MuJoCo and a controller research framework.

Importing the package registers the Gymnasium environment ``peg_ctrl/PegInsertion-v0``
(:mod:`peg_ctrl.gym.env`, imported only when the environment is made), with Gymnasium's
``TimeLimit`` of 1000 control periods.
"""

import os as _os

# One BLAS thread unless the user says otherwise: the controllers solve small problems every
# millisecond, where a threaded BLAS only spins. CasADi's qpOASES loads its own OpenBLAS, whose
# idle threads busy-wait: measured on 2 cores, 44 s of system time in 4 mpc episodes against
# 1 s with one thread (docs/controllers.md). Read when each BLAS library loads, so set before
# numpy (and CasADi's plugin) are imported.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    _os.environ.setdefault(_var, "1")


def _pin_blas_kernels() -> None:
    """The committed studies' BLAS kernels on every CPU that can run them: numpy's OpenBLAS picks
    its kernels by the CPU (or by ``OPENBLAS_CORETYPE``), and its Haswell kernels sum in another
    order than its SkylakeX (AVX-512) ones, which moves 7 of contact_hard's 10 arms
    (docs/reproducibility.md). On an x86-64 CPU with AVX-512 (F, CD, BW, DQ, VL), ``SkylakeX``,
    the kernels the studies were made with, overriding an inherited ``OPENBLAS_CORETYPE`` (recorded
    in every run's environment); ``PEG_CTRL_BLAS=keep`` keeps yours. Read when OpenBLAS loads:
    import peg_ctrl before numpy."""
    if _os.environ.get("PEG_CTRL_BLAS", "").lower() == "keep":
        _os.environ.pop("PEG_CTRL_BLAS_OVERRODE", None)
        return
    try:
        with open("/proc/cpuinfo") as f:
            flags = next((line.split(":", 1)[1].split() for line in f if line.startswith("flags")), [])
    except OSError:
        return
    if {"avx512f", "avx512cd", "avx512bw", "avx512dq", "avx512vl"} <= set(flags):
        before = _os.environ.get("OPENBLAS_CORETYPE")
        if before is not None and before != "SkylakeX":
            _os.environ["PEG_CTRL_BLAS_OVERRODE"] = before
        _os.environ["OPENBLAS_CORETYPE"] = "SkylakeX"


_pin_blas_kernels()


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

import importlib as _importlib  # noqa: E402
import importlib.abc as _importlib_abc  # noqa: E402
import importlib.util as _importlib_util  # noqa: E402
import sys as _sys  # noqa: E402
import warnings as _warnings  # noqa: E402
from importlib.machinery import ModuleSpec as _ModuleSpec  # noqa: E402
from types import ModuleType as _ModuleType  # noqa: E402

from gymnasium.envs.registration import register as _register  # noqa: E402
from gymnasium.envs.registration import registry as _registry  # noqa: E402

__version__ = "0.1.0"

# Modules that moved into the layered subpackages (docs/architecture.md) in 0.2. The old names
# still import, as the same module object, with a DeprecationWarning naming the new one.
_MOVED = {
    **{m: f"sim.{m}" for m in ("assets", "belief", "grasp_start", "jaw", "menagerie", "physics")},
    **{m: f"sim.{m}" for m in ("rotations", "scene", "sensing", "state", "validity")},
    **{m: f"run.{m}" for m in ("batch", "episode", "episode_log", "loop", "plots", "recorders")},
    **{m: f"run.{m}" for m in ("tracker", "workers")},
    **{m: f"tools.{m}" for m in ("bench", "profile_check", "replay", "validity_report")},
    "monitors": "tasks.monitors",
    "tasks.hop_search": "tasks.strategies.hop_search",
    "gym_env": "gym.env",
    "teleop_window": "cli.teleop_window",
}


class _MovedModules(_importlib_abc.MetaPathFinder, _importlib_abc.Loader):
    """``import peg_ctrl.episode`` gives :mod:`peg_ctrl.run.episode` itself (not a copy: one
    set of classes and globals), and warns where the import was written."""

    def __init__(self) -> None:
        self._own_specs: dict[str, _ModuleSpec | None] = {}

    def find_spec(self, fullname: str, path: object = None, target: object = None) -> _ModuleSpec | None:
        old = fullname.removeprefix(f"{__name__}.")
        if old == fullname or old not in _MOVED:
            return None
        return _importlib_util.spec_from_loader(fullname, self)

    def create_module(self, spec: _ModuleSpec) -> _ModuleType:
        new = f"{__name__}.{_MOVED[spec.name.removeprefix(__name__ + '.')]}"
        # stacklevel 2: the import statement (warnings skips the import system's own frames)
        _warnings.warn(
            f"{spec.name} moved to {new}; import it from there (the old name goes in 0.3)",
            DeprecationWarning,
            stacklevel=2,
        )
        module = _importlib.import_module(new)
        self._own_specs[new] = module.__spec__
        return module

    def exec_module(self, module: _ModuleType) -> None:
        # the import system stamped the alias's spec on the module: give it back its own
        module.__spec__ = self._own_specs.pop(module.__name__)


if not any(isinstance(finder, _MovedModules) for finder in _sys.meta_path):
    _sys.meta_path.insert(0, _MovedModules())  # first: before any finder that sees stale files

if "peg_ctrl/PegInsertion-v0" not in _registry:
    # The time limit is Gymnasium's TimeLimit: 1000 control periods (peg_ctrl.gym.env.MAX_EPISODE_STEPS).
    _register(id="peg_ctrl/PegInsertion-v0", entry_point="peg_ctrl.gym.make:make_env", max_episode_steps=1000)
