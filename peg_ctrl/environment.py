"""What made a number: the environment a run records (``environment.json``, the report's header,
``peg-sim compare``), and the start perturbation that measures how far a last-bit difference
carries (docs/reproducibility.md).

A study's episode is deterministic on one machine, but two x86-64 machines can answer one
floating-point operation with different last bits: numpy's BLAS picks its kernels by the CPU
(OpenBLAS's runtime dispatch, or ``OPENBLAS_CORETYPE``), the C library picks its ``sin`` and
``exp`` by the CPU's FMA and AVX2, and another version of any numerical package can change any
result. Contact amplifies such a difference into another trajectory. :func:`environment` records
everything of that kind this process can read; :func:`differences` names what differs between
two records.

This module reads the environment and imports nothing of the package but ``errors`` (a
foundation layer, docs/architecture.md); numpy is looked up only once imported.
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import importlib
import json
import os
import platform
import sys
from importlib import metadata
from pathlib import Path
from typing import Any

from peg_ctrl.errors import ConfigError

__all__ = [
    "PACKAGES",
    "VARIABLES",
    "LOCK_FILE",
    "ENVIRONMENT_FILE",
    "PERTURBATION_VARIABLE",
    "environment",
    "environment_id",
    "describe",
    "differences",
    "lock_file",
    "start_perturbation",
]

#: The packages whose version can move a number of an episode (the physics, the maths, the
#: solvers the controllers call, the trajectories), in the order the report names them.
PACKAGES = (
    "mujoco",
    "numpy",
    "scipy",
    "casadi",
    "osqp",
    "daqp",
    "qpsolvers",
    "pin",
    "mink",
    "ruckig",
    "drake",
)
#: The environment variables that choose kernels, threads or the start (recorded when set).
VARIABLES = (
    "OPENBLAS_CORETYPE",
    "OPENBLAS_NUM_THREADS",
    "OMP_NUM_THREADS",
    "MKL_NUM_THREADS",
    "NPY_DISABLE_CPU_FEATURES",
    "NPY_ENABLE_CPU_FEATURES",
    "GLIBC_TUNABLES",
    "PEG_CTRL_START_PERTURBATION",
    "PEG_CTRL_BLAS",
    "PEG_CTRL_BLAS_OVERRODE",
)
#: The CPU features that choose a numerical path (the C library's maths, BLAS, numpy, MuJoCo).
_CPU_FLAGS = ("sse4_2", "avx", "avx2", "fma", "avx512f", "avx512dq", "avx512bw", "avx512vl", "avx512_fp16")
#: The lock of exact versions ``make install`` and CI install with, in a checkout.
LOCK_FILE = Path("requirements") / "lock.txt"
#: What a sweep writes into its directory: the record of each environment that ran its episodes.
ENVIRONMENT_FILE = "environment.json"
#: Moves the gripper's start along x by this many metres (a float): how far a last-bit difference
#: of the start carries (peg_ctrl.experiments.reproduction).
PERTURBATION_VARIABLE = "PEG_CTRL_START_PERTURBATION"


def start_perturbation() -> float:
    """The start perturbation [m] of ``PEG_CTRL_START_PERTURBATION`` (0 when unset).

    Raises:
        ConfigError: the variable is set to something that is not a finite number below 1 mm.
    """
    text = os.environ.get(PERTURBATION_VARIABLE, "").strip()
    if not text:
        return 0.0
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not abs(value) < 1e-3:
        raise ConfigError(f"{PERTURBATION_VARIABLE}={text!r}: a start perturbation in metres, |x| < 1e-3")
    return value


def lock_file() -> Path | None:
    """The lock beside the package in a checkout (None in an installed wheel)."""
    path = Path(__file__).resolve().parent.parent / LOCK_FILE
    return path if path.is_file() else None


def _lock(installed: dict[str, str | None]) -> dict[str, Any] | None:
    path = lock_file()
    if path is None:
        return None
    text = path.read_text()
    pinned = {}
    for line in text.splitlines():
        name, sep, version = line.partition("==")
        if sep and not line.lstrip().startswith("#"):
            pinned[_canonical(name)] = version.split(";")[0].strip()
    off = sorted(
        f"{name} {version} (lock {pinned[name]})"
        for name, version in installed.items()
        if name in pinned and version is not None and _release(version) != pinned[name]
    )
    return {"file": str(LOCK_FILE), "sha256": hashlib.sha256(text.encode()).hexdigest()[:16], "off_lock": off}


def _canonical(name: str) -> str:
    return name.strip().lower().replace("_", "-")


def _release(version: str) -> str:
    return version.split("+")[0]  # torch 2.13.0+cpu is the lock's 2.13.0


def _cpu() -> tuple[str, list[str]]:
    model, flags = platform.processor() or platform.machine(), set()
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                key, _, value = line.partition(":")
                if key.strip() == "model name" and model in ("", platform.machine(), platform.processor()):
                    model = value.strip()
                elif key.strip() == "flags":
                    flags = set(value.split())
                    break
    except OSError:
        pass
    return model, [f for f in _CPU_FLAGS if f in flags]


def _numpy_simd() -> list[str] | None:
    """The SIMD targets numpy dispatches to here (its baseline and the enabled dispatch targets)."""
    if "numpy" not in sys.modules:
        return None
    try:
        umath = importlib.import_module("numpy._core._multiarray_umath")
    except ImportError:  # numpy < 2
        return None
    features = umath.__cpu_features__
    return [*umath.__cpu_baseline__, *(t for t in umath.__cpu_dispatch__ if features.get(t))]


def _blas() -> dict[str, Any] | None:
    """numpy's OpenBLAS as this process runs it: its version, the kernels it chose, its threads."""
    if "numpy" not in sys.modules:
        return None
    try:
        with open("/proc/self/maps") as f:
            paths = sorted({line.split()[-1] for line in f if "openblas" in line.lower() and ".so" in line})
    except OSError:
        return None
    for path in paths:
        lib = ctypes.CDLL(path)
        for prefix, suffix in (("scipy_", "64_"), ("", "64_"), ("", "")):
            name = getattr(lib, f"{prefix}openblas_get_corename{suffix}", None)
            if name is None:
                continue
            config = getattr(lib, f"{prefix}openblas_get_config{suffix}")
            name.restype = config.restype = ctypes.c_char_p
            threads = getattr(lib, f"{prefix}openblas_get_num_threads{suffix}")
            return {
                "library": "OpenBLAS",
                "version": config().decode().split()[1],
                "kernels": name().decode(),
                "threads": int(threads()),
            }
    return None


def _packages() -> dict[str, str | None]:
    found: dict[str, str | None] = {}
    for name in PACKAGES:
        try:
            found[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            found[name] = None
    return found


def environment() -> dict[str, Any]:
    """This process's environment, as a run records it (``environment.json``). What it reads
    does not change within a process once numpy is loaded (numpy's SIMD and BLAS are None
    before: they are read from the loaded libraries)."""
    if "numpy" in sys.modules:
        return _environment_cached()
    return _environment()


@functools.lru_cache(maxsize=1)
def _environment_cached() -> dict[str, Any]:
    return _environment()


def _environment() -> dict[str, Any]:
    model, flags = _cpu()
    packages = _packages()
    record = {
        "python": platform.python_version(),
        "platform": f"{platform.system()} {platform.machine()}",
        "libc": " ".join(platform.libc_ver()).strip() or None,
        "cpu": model,
        "cpu_flags": flags,
        "numpy_simd": _numpy_simd(),
        "blas": _blas(),
        "packages": packages,
        "variables": {v: os.environ[v] for v in VARIABLES if v in os.environ},
        "lock": _lock({_canonical(k): v for k, v in packages.items()}),
    }
    return record


def environment_id(record: dict[str, Any] | None = None) -> str:
    """A short hash of a record (this process's by default): two runs with one id had the same
    environment in everything :func:`environment` reads."""
    text = json.dumps(record if record is not None else environment(), sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:12]


def describe(record: dict[str, Any]) -> str:
    """One line for a report's header."""
    pkgs = record.get("packages") or {}
    named = ", ".join(
        f"{k} {v}" for k, v in pkgs.items() if v and k in ("mujoco", "numpy", "scipy", "casadi")
    )
    parts = [
        f"Python {record.get('python')}, {named}",
        f"{record.get('cpu')} ({'/'.join(record.get('cpu_flags') or [])})",
    ]
    if record.get("libc"):
        parts[-1] += f", {record['libc']}"
    blas = record.get("blas")
    if blas:
        parts.append(
            f"numpy's BLAS {blas['library']} {blas['version']}, {blas['kernels']} kernels, "
            f"{blas['threads']} thread{'s' if blas['threads'] != 1 else ''}"
        )
    lock = record.get("lock")
    if lock:
        parts.append(
            f"lock {lock['sha256']}" + (f" ({len(lock['off_lock'])} off it)" if lock["off_lock"] else "")
        )
    variables = record.get("variables") or {}
    shown = {k: v for k, v in variables.items() if not k.endswith("_NUM_THREADS")}
    if shown:
        parts.append(", ".join(f"{k}={v}" for k, v in shown.items()))
    return "; ".join(parts)


def differences(theirs: dict[str, Any], mine: dict[str, Any]) -> list[str]:
    """What differs between two records, one item each: ``"mujoco 3.3.0 here, 4.0.0 in the study"``."""
    found = []

    def differ(label: str, a: Any, b: Any) -> None:
        if a != b:
            found.append(f"{label}: {_shown(b)} here, {_shown(a)} in the study")

    for key in ("python", "platform", "libc", "cpu", "cpu_flags", "numpy_simd"):
        differ(key, theirs.get(key), mine.get(key))
    a_blas, b_blas = theirs.get("blas") or {}, mine.get("blas") or {}
    for key in sorted(set(a_blas) | set(b_blas)):
        differ(f"BLAS {key}", a_blas.get(key), b_blas.get(key))
    a_pkg, b_pkg = theirs.get("packages") or {}, mine.get("packages") or {}
    for name in sorted(set(a_pkg) | set(b_pkg)):
        differ(name, a_pkg.get(name), b_pkg.get(name))
    a_var, b_var = theirs.get("variables") or {}, mine.get("variables") or {}
    for name in sorted((set(a_var) | set(b_var)) - {"PEG_CTRL_BLAS_OVERRODE"}):  # the kernels say it
        differ(name, a_var.get(name), b_var.get(name))
    a_lock, b_lock = theirs.get("lock") or {}, mine.get("lock") or {}
    differ("lock", a_lock.get("sha256"), b_lock.get("sha256"))
    if b_lock.get("off_lock"):
        found.append(f"installed off the lock: {', '.join(b_lock['off_lock'])}")
    return found


def _shown(value: Any) -> str:
    if value is None:
        return "(none)"
    if isinstance(value, list):
        return "/".join(map(str, value)) or "(none)"
    return str(value)
