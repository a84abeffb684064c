"""What a planning strategy chose (``plan``): per arm and grid cell, the skills its episodes
played, how many, their share of the time, and the planner's own compute per decision; and the
figure of one episode's belief, touch by touch.

    python -m peg_ctrl.experiments.belief_figure runs/contact_real_plan/episodes/KEY --out belief.png
"""

from __future__ import annotations

import argparse
import collections
import json
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

from peg_ctrl.experiments.report.axes import arm_of, episode_dir

__all__ = ["belief_figure", "skill_section", "touch_count"]

TOUCH_GAP = 0.05  # [s] a touch begins after the peg has been this long clear of the block

_SPREADS = (
    ("relative_mm", "where the end must go [mm]"),
    ("end_mm", "the end in the hand [mm]"),
    ("tilt_mrad", "the tilt in the hand [mrad]"),
    ("face_um", "the face's height [µm]"),
)


def touch_count(trace: Path, gap: float = TOUCH_GAP) -> int:
    """The peg's touches of the block in an episode's force trace (``forces.npz``): contacts
    (any peg-block force) each begun after at least ``gap`` [s] clear of the block."""
    with np.load(trace) as data:
        columns = [str(c) for c in data["columns"]]
        rows = data["data"]
    t, force = rows[:, columns.index("t")], rows[:, columns.index("block-peg")]
    count, clear_since, touching = 0, -math.inf, False
    for ti, fi in zip(t.tolist(), force.tolist(), strict=True):
        if touching and fi <= 0.0:
            touching, clear_since = False, ti
        elif not touching and fi > 0.0:
            count += ti - clear_since >= gap
            touching = True
    return count


def _cell(row: dict[str, Any], keys: list[str]) -> str:
    return ", ".join(f"{k.split('.')[-1]} {row[k]}" for k in keys)


class _Choices:
    """What the section reads from a run's episodes, per arm (and per cell for the choices)."""

    def __init__(self) -> None:
        self.table: dict[tuple[str, str], dict[str, Any]] = {}
        self.decisions: dict[str, list[float]] = collections.defaultdict(list)
        self.share: dict[str, list[float]] = collections.defaultdict(list)  # the planner's compute / wall
        self.touches: dict[str, list[int]] = collections.defaultdict(list)

    def add(self, out_dir: Path, row: dict[str, Any], grid_keys: list[str]) -> None:
        folder = episode_dir(out_dir, row["log_path"])
        arm = arm_of(row)
        if (folder / "forces.npz").is_file():
            self.touches[arm].append(touch_count(folder / "forces.npz"))
        path = folder / "summary.json"
        skills = (json.loads(path.read_text()).get("skills") or []) if path.is_file() else []
        if not skills:
            return
        wall = float(row.get("wall_time_s") or 0.0)
        if wall > 0:
            self.share[arm].append(sum(float(s.get("decision_s", 0.0)) for s in skills) / wall)
        entry = self.table.setdefault(
            (arm, _cell(row, grid_keys)),
            {"n": 0, "ok": 0, "orders": collections.Counter(), "count": [], "time": collections.Counter()},
        )
        entry["n"] += 1
        entry["ok"] += row.get("status") == "success"
        entry["orders"][">".join(s["skill"] for s in skills)] += 1
        entry["count"].append(len(skills))
        end = float(row.get("sim_time_s") or 0.0)
        for s in skills:
            entry["time"][s["skill"]] += float(s.get("t_end", end)) - float(s["t_start"])
            self.decisions[arm].append(float(s.get("decision_s", 0.0)))

    def choice_lines(self) -> list[str]:
        lines = [
            "## The skills the planner chose",
            "",
            "Per arm and cell: the orders of skills its episodes played (how many episodes each), the "
            "median number of skills, and each skill's share of the time the skills took.",
            "",
            "| arm | cell | episodes (seated) | orders | skills (median) | share of the time |",
            "|---|---|---|---|---|---|",
        ]
        for (arm, cell), e in sorted(self.table.items()):
            total = sum(e["time"].values()) or 1.0
            orders = "; ".join(f"{o} ({k})" for o, k in e["orders"].most_common())
            shares = ", ".join(f"{s} {100.0 * v / total:.0f} %" for s, v in e["time"].most_common())
            lines.append(
                f"| {arm} | {cell} | {e['n']} ({e['ok']}) | {orders} | {np.median(e['count']):g} | {shares} |"
            )
        return lines

    def compute_lines(self) -> list[str]:
        lines = [
            "",
            "The planner's own compute per decision (wall clock, this machine), and its share of each "
            "episode's wall time:",
            "",
            "| arm | decisions | median [ms] | p99 [ms] | largest [ms] | of wall time (median, largest) |",
            "|---|---|---|---|---|---|",
        ]
        for arm, times in sorted(self.decisions.items()):
            ms = 1e3 * np.asarray(times)
            part = 100.0 * np.asarray(self.share[arm] or [0.0])
            lines.append(
                f"| {arm} | {len(ms)} | {np.median(ms):.2f} | {np.percentile(ms, 99):.2f} | {ms.max():.2f} "
                f"| {np.median(part):.3f} %, {part.max():.3f} % |"
            )
        return lines

    def touch_lines(self) -> list[str]:
        lines = [
            "",
            f"Touches per episode, every arm: the peg's contacts with the block, each begun after at "
            f"least {1e3 * TOUCH_GAP:.0f} ms clear of it (from the force traces).",
            "",
            "| arm | episodes | touches: median | 5th-95th percentile |",
            "|---|---|---|---|",
        ]
        for arm, counts in sorted(self.touches.items()):
            lo, hi = np.percentile(counts, [5, 95])
            lines.append(f"| {arm} | {len(counts)} | {np.median(counts):g} | {lo:g}-{hi:g} |")
        return lines


def skill_section(out_dir: Path, rows: list[dict[str, Any]], grid_keys: list[str]) -> list[str]:
    """The planner's choices (from the episodes' summary.json ``skills``), its compute, and every
    arm's touches; [] when no episode has skills."""
    choices = _Choices()
    for row in rows:
        if row.get("log_path"):
            choices.add(out_dir, row, grid_keys)
    if not choices.table:
        return []
    return [*choices.choice_lines(), *choices.compute_lines(), *choices.touch_lines(), ""]


def belief_figure(summary: dict[str, Any], out: Path) -> Path:
    """One episode's belief, reading by reading: each spread against time, each reading named."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    history = summary.get("belief") or []
    if not history:
        raise ValueError("the episode's summary has no belief readings (a strategy that plays no skill)")
    fig, axes = plt.subplots(len(_SPREADS), 1, sharex=True, figsize=(7.5, 7.0))
    t = [float(h["t"]) for h in history]
    for ax, (key, label) in zip(axes, _SPREADS, strict=True):
        ax.step(t, [h[key] for h in history], where="post", marker="o")
        ax.set_yscale("log")
        ax.set_ylabel(label, fontsize=8)
        for h in history:
            ax.annotate(
                h["skill"], (float(h["t"]), h[key]), fontsize=7, xytext=(3, 3), textcoords="offset points"
            )
    skills = summary.get("skills") or []
    for s in skills:
        for ax in axes:
            ax.axvline(float(s["t_start"]), color="0.8", lw=0.8, zorder=0)
    order = " > ".join(s["skill"] for s in skills)
    axes[0].set_title(f"{summary.get('strategy', '')}: {order} ({summary.get('status', '')})", fontsize=9)
    axes[-1].set_xlabel("time [s]")
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="One episode's belief, touch by touch (a figure).")
    parser.add_argument("episode", type=Path, help="an episode's directory (with summary.json)")
    parser.add_argument("--out", type=Path, required=True, help="the figure's file (.png)")
    args = parser.parse_args(argv)
    path = args.episode / "summary.json"
    if not path.is_file():
        print(f"error: {path} not found: give an episode's directory", file=sys.stderr)
        return 2
    try:
        belief_figure(json.loads(path.read_text()), args.out)
    except (ValueError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(args.out)
    return 0
