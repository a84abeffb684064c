"""What a report is drawn against: the arms, their colours, the conditions a sweep varies, and
the names of its tasks (read from the data)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from peg_ctrl.experiments.stats import inserts_from_contact, numbers

__all__ = [
    "CONDITION_LABELS",
    "arm_of",
    "split_arm",
    "controller_colours",
    "swept_conditions",
    "contact_tasks",
    "episode_dir",
]

# Swept episode fields with a readable axis: column -> (label, factor from the column's unit).
CONDITION_LABELS = {
    "clearance_m": ("radial hole clearance [mm]", 1e3),
    "task.lateral_error": ("lateral error at first contact [mm]", 1e3),
    "task.tilt_error": ("peg tilt in the grasp [deg]", 180.0 / math.pi),
    "task.position_noise": ("noise on the observed hole position [mm]", 1e3),
    "scene.friction": ("friction coefficient", 1.0),
    "domain.ft_sensor": ("force/torque sensor model", 1.0),
    "peg_mass_scale": ("peg mass scale (drawn per seed)", 1.0),
    "friction_scale": ("friction scale (drawn per seed)", 1.0),
    "gain_scale": ("controller gain scale (drawn per seed)", 1.0),
}
_DOMAIN_COLUMNS = ("peg_mass_scale", "friction_scale", "gain_scale")


def arm_of(row: dict[str, Any]) -> str:
    """The row's arm: controller, and strategy when the sweep has them."""
    return str(row.get("arm") or row["controller"])


def split_arm(arm: str) -> tuple[str, str]:
    """(controller, strategy) of an arm (``mpc/align``); the strategy "" for an arm without one."""
    controller, _, strategy = arm.partition("/")
    return controller, strategy


def controller_colours(arms: list[str]) -> dict[str, Any]:
    """One colour per controller (strategies of one controller share it), from tab10/tab20."""
    import matplotlib

    controllers = list(dict.fromkeys(split_arm(a)[0] for a in arms))
    cmap = matplotlib.colormaps["tab10" if len(controllers) <= 10 else "tab20"]
    return {c: cmap(i % cmap.N) for i, c in enumerate(controllers)}


def swept_conditions(df: Any) -> list[str]:
    """The columns of an :func:`~peg_ctrl.experiments.stats.episodes_frame` that the experiment
    varies and that success can be plotted against: the clearance, every grid key (dotted
    column) and the per-seed domain draws, each when it takes more than one value."""
    candidates = ["clearance_m", *[c for c in df.columns if "." in c], *_DOMAIN_COLUMNS]
    found: list[str] = []
    for column in candidates:
        if column not in df or df[column].astype(str).nunique() < 2:
            continue
        numeric = numbers(df[column]).notna().all()
        if not numeric and "." not in column:
            continue  # a named grid value (a sensor preset) is a condition; other text is not
        if any(_same_levels(df, column, seen) for seen in found):
            continue  # moves with an earlier condition (a linked grid axis): one plot says it
        found.append(column)
    return found


def _same_levels(df: Any, a: str, b: str) -> bool:
    """Whether each value of column ``a`` goes with one value of ``b`` and back."""
    pairs = df[[a, b]].astype(str).drop_duplicates()
    return bool(pairs[a].is_unique and pairs[b].is_unique)


def contact_tasks(df: Any) -> str:
    """The names of the sweep's tasks that insert from the first contact
    (:func:`~peg_ctrl.experiments.stats.inserts_from_contact`), as its ``task`` column writes
    them, in words (``held_insertion``: "held insertion"); "" when it has none."""
    rows = df[inserts_from_contact(df)]
    if rows.empty:
        return ""
    if "task" not in rows:
        return "a task with an insertion strategy"
    names = dict.fromkeys(str(t).replace("_", " ") for t in rows["task"])
    return ", ".join(names)


def episode_dir(out_dir: Path, log_path: Any) -> Path:
    """The directory of the episode whose log is ``log_path`` (relative to the sweep's)."""
    return out_dir / Path(str(log_path)).parent
