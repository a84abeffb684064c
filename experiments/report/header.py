"""The report's header: what was run, what the arms sensed, the environment that ran it and,
for a comparison, how each study arm's rerun sample was classed (docs/reproducibility.md)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from peg_ctrl.environment import ENVIRONMENT_FILE, describe
from peg_ctrl.experiments.report.axes import arm_of
from peg_ctrl.sim.ft_model import FT_DOMAIN_FIELDS

__all__ = ["header_section", "sensing_line", "environment_lines", "verification_lines"]


def header_section(
    exp: dict[str, Any],
    default_name: str,
    rows: list[dict[str, Any]],
    run_time: tuple[float, int] | None,
) -> list[str]:
    """The title and one line of what was run; ``run_time``: the sweep's run time [s] and the
    number of invocations it is summed over (None: not known)."""
    clearances = ", ".join(f"{c * 1e3:g} mm" for c in exp.get("clearances", []))
    took = ""
    if run_time is not None:
        seconds, invocations = run_time
        took = f" Run time {seconds:.0f} s" + (
            f" over {invocations} invocations." if invocations > 1 else "."
        )
    physics = exp.get("physics", {})
    friction = physics.get("friction_time")
    profile = f"`{physics.get('profile', 'seed')}`" + (
        f" with the peg's friction time constant {friction * 1e3:g} ms (`physics.friction_time`)"
        if friction is not None
        else ""
    )
    return [
        f"# Experiment report: {exp.get('name', default_name)}",
        "",
        f"{len(rows)} episodes: arms {', '.join(dict.fromkeys(arm_of(r) for r in rows))}; "
        f"planners {', '.join(exp.get('planners', []))}; clearances "
        f"{clearances}; {_count(exp.get('seeds', []))} seeds; physics profile {profile}." + took,
        "",
        sensing_line(exp),
        "",
    ]


def _count(seeds: int | list[int]) -> int:
    """How many seeds: an experiment gives a count (``seeds: 5``, ``--set seeds=1``) or a list."""
    return seeds if isinstance(seeds, int) else len(seeds)


def _gridded(grid: dict[str, Any]) -> set[str]:
    """The config keys a grid sweeps, its linked groups' included."""
    keys: set[str] = set()
    for key, values in grid.items():
        keys |= set(values) if isinstance(values, dict) else {key}
    return keys


def sensing_line(exp: dict[str, Any]) -> str:
    """What the arms sensed, from the experiment's ``domain`` and ``task`` (docs/sensing.md): the
    F/T sensor, the hand's position, velocity and orientation, the camera's noise on the hole and
    the drawing's tolerance; a key the grid sweeps is said to vary per cell. An experiment that
    does not record its ``domain`` says so."""
    if "domain" not in exp:
        return "Sensed (docs/sensing.md): not recorded with these results."
    d, task, grid = exp["domain"], exp.get("task", {}), _gridded(exp.get("grid", {}))

    def sigma(key: str, value: float, scale: float, unit: str, none: str = "exact") -> str:
        if key in grid:
            return "per cell"
        return f"σ {value * scale:g} {unit}" if value else none

    if "domain.ft_sensor" in grid or any(f"domain.{k}" in grid for k in FT_DOMAIN_FIELDS):
        ft = "per cell (the grid sweeps it)"
    elif d.get("ft_sensor"):
        ft = f"`{d['ft_sensor']}` (a preset)"
    elif any(d.get(k, 0.0) for k in FT_DOMAIN_FIELDS):
        ft = (
            f"σ {d.get('force_noise', 0.0):g} N and {d.get('torque_noise', 0.0):g} N m, "
            f"{d.get('ft_latency', 0.0) * 1e3:g} ms late, bias drift {d.get('ft_bias_drift', 0.0):g} N/√s, "
            + (f"{d['ft_rate']:g} Hz" if d.get("ft_rate") else "read every control period")
        )
    else:
        ft = "ideal"
    v = d.get("velocity_noise", 0.0)
    velocity = sigma("domain.velocity_noise", v, 1e3, f"mm/s ({v * 1e3:g} mrad/s)")
    hand = (
        f"position {sigma('domain.position_noise', d.get('position_noise', 0.0), 1e3, 'mm')}, "
        f"velocity {velocity}, "
        f"orientation {sigma('domain.orientation_noise', d.get('orientation_noise', 0.0), 1e3, 'mrad')}"
    )
    hole = sigma("task.position_noise", task.get("position_noise", 0.0), 1e3, "mm per axis", "none")
    tolerance = task.get("drawing_tolerance", 0.0)
    drawing = (
        "per cell"
        if "task.drawing_tolerance" in grid
        else f"±{tolerance * 1e3:g} mm"
        if tolerance
        else "exact"
    )
    return (
        f"Sensed (docs/sensing.md): the wrist F/T sensor {ft}; the hand's {hand}; the camera's "
        f"noise on the hole's position {hole}; the drawing {drawing}."
    )


def environment_lines(out_dir: Path, rows: list[dict[str, Any]]) -> list[str]:
    """One line per environment that ran the episodes (``environment.json``, by the id each
    episode records), with how many it ran; a run that records none says so."""
    path = Path(out_dir) / ENVIRONMENT_FILE
    known = json.loads(path.read_text()) if path.is_file() else {}
    counts: dict[str, int] = {}
    for row in rows:
        env = row.get("environment") or ""
        counts[env] = counts.get(env, 0) + 1
    lines = []
    for env, n in counts.items():
        if env and env in known:
            lines.append(f"Environment `{env}` ({n} episodes): {describe(known[env])}.")
        else:
            lines.append(f"Environment: {n} episodes record none (made before environments were recorded).")
    return [*lines, ""] if lines else []


def verification_lines(record: dict[str, Any] | None) -> list[str]:
    """A comparison's verification: each study arm's class (reproduced, agrees, differs) and
    what differs between the study's environment and this one."""
    if not record or not record.get("verified"):
        return []
    classes = "; ".join(f"{arm} {v.get('class', 'reproduced')}" for arm, v in record["verified"].items())
    lines = [f"Verification of {record['study']}'s arms (a rerun sample each): {classes}."]
    env = record.get("environment") or {}
    if env.get("differences"):
        lines.append(f"Environment here against the study's: {'; '.join(env['differences'])}.")
    elif env:
        lines.append("Environment here: the study's in everything recorded.")
    return [*lines, ""]
