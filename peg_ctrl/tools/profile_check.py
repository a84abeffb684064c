"""Validate a physics profile against a reference: ``peg-sim validate-profile fast``.

The same seeds of two tasks run in both profiles, each task and profile as its own sweep on the
same workers (so its wall time is a whole-sweep measurement, process start-up and file writing
included):

- ``default``: the default task (pick and place, 1 mm clearance) with the quick sweep's
  randomization (start pose, peg mass and friction, controller gains), the ``pd`` controller;
- ``contact``: the held insertion of the featured comparison's hardest cell: 0.1 mm clearance,
  1 mm chamfer, 1.5 mm lateral error and 1.5 degrees of tilt, sliding friction 0.3, the
  ``impedance`` controller with its remote centre of compliance and the spiral search.

Per task the report gives success with Wilson 95 % intervals (the candidate passes if its rate
lies in the reference's interval), the peak peg-block force (medians with bootstrap intervals
and a two-sample Kolmogorov-Smirnov test: it passes at p >= 0.05), grasp slip (the same test,
reported) and the speed: episodes per hour of each sweep and their ratio.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path
from typing import Any

from peg_ctrl.run.episode import EpisodeConfig, episode_config_from_mapping

__all__ = ["TASKS", "task_config", "validate_profile", "format_report"]

ALPHA = 0.05  # significance level of the distribution tests

TASKS: dict[str, dict[str, Any]] = {
    "default": {
        "controller": {"name": "pd"},
        "randomization": {"enabled": True, "peg_xy": 0.015, "peg_yaw": 0.2},
        "domain": {"peg_mass_scale": [0.8, 1.25], "friction_scale": [0.8, 1.2], "gain_scale": [0.9, 1.1]},
    },
    "contact": {
        "controller": {
            "name": "impedance",
            "compliance_center": [0.0, -0.07, -0.01],
            "k_pos": [1000.0, 1000.0, 1500.0],
            "k_rot": [2.0, 2.0, 2.0],
            "damping_compensation": 0.9,
        },
        "task": {
            "name": "held_insertion",
            "strategy": "spiral",
            "lateral_error": 0.0015,
            "tilt_error": 0.02618,
            "position_noise": 0.0,
        },
        "scene": {
            "assets": {"clearance": 0.0001, "chamfer": 0.001},
            "peg_friction": [0.3, 0.1, 0.0001],
            "block_friction": [0.3, 0.1, 0.0001],
        },
    },
}


def task_config(task: str, profile: str, seed: int) -> EpisodeConfig:
    """The episode of ``task`` (a key of :data:`TASKS`) in ``profile`` for ``seed``."""
    data = json.loads(json.dumps(TASKS[task]))  # a deep copy
    data.update(seed=seed, physics={"profile": profile}, log={"trace": False, "interval": 10**9})
    return episode_config_from_mapping(data)


def _ks(a: list[float], b: list[float]) -> float | None:
    from scipy.stats import ks_2samp

    if not a or not b:
        return None
    if max(a + b) == min(a + b):
        return 1.0  # identical constants: nothing differs
    return float(ks_2samp(a, b).pvalue)


def _side(rows: list[dict[str, Any]], wall: float, workers: int) -> dict[str, Any]:
    from peg_ctrl.experiments.report import wilson_interval
    from peg_ctrl.experiments.stats import median_ci

    n = len(rows)
    wins = sum(r["status"] == "success" for r in rows)
    lo, hi = wilson_interval(wins, n)
    peaks = [float(r["peak_contact_force_n"]) for r in rows]
    slips = [float(r["peg_slip_m"]) for r in rows]
    med, med_lo, med_hi = median_ci(peaks)
    reasons: dict[str, int] = {}
    for r in rows:
        if r["status"] != "success":
            reasons[r["reason"]] = reasons.get(r["reason"], 0) + 1
    return {
        "episodes": n,
        "successes": wins,
        "success_ci95": [lo, hi],
        "failure_reasons": reasons,
        "peak_force_n": {"median": med, "median_ci95": [med_lo, med_hi], "max": max(peaks)},
        "slip_m": {"median": sorted(slips)[n // 2], "max": max(slips)},
        "sweep_wall_s": wall,
        "workers": workers,
        "episodes_per_hour": 3600.0 * n / wall,
        "loop_wall_s_mean": sum(float(r["wall_time_s"]) for r in rows) / n,
        "_peaks": peaks,
        "_slips": slips,
    }


def validate_profile(
    candidate: str, out: Path, *, reference: str = "seed", seeds: int = 100, workers: int = 2
) -> dict[str, Any]:
    """Run both tasks in both profiles; write ``validation.json`` and ``validation.md`` to ``out``."""
    from peg_ctrl.io import atomic_write_text, to_json
    from peg_ctrl.run.batch import run_batch

    result: dict[str, Any] = {
        "candidate": candidate,
        "reference": reference,
        "seeds": seeds,
        "workers": workers,
        "alpha": ALPHA,
        "tasks": {},
    }
    for task in TASKS:
        sides = {}
        for profile in (reference, candidate):
            jobs = [
                (task_config(task, profile, s), out / "episodes" / task / profile / f"seed{s:04d}")
                for s in range(seeds)
            ]
            t0 = time.perf_counter()
            rows = run_batch(jobs, workers=workers, desc=f"{task} / {profile}")
            sides[profile] = _side(rows, time.perf_counter() - t0, workers)
        ref, cand = sides[reference], sides[candidate]
        rate = cand["successes"] / cand["episodes"]
        p_force = _ks(ref.pop("_peaks"), cand.pop("_peaks"))
        p_slip = _ks(ref.pop("_slips"), cand.pop("_slips"))
        checks = {
            "success_in_reference_ci": ref["success_ci95"][0] <= rate <= ref["success_ci95"][1],
            "peak_force_same_distribution": p_force is not None and p_force >= ALPHA,
            "speedup_at_least_5x": cand["episodes_per_hour"] >= 5.0 * ref["episodes_per_hour"],
        }
        result["tasks"][task] = {
            "config": TASKS[task],
            reference: ref,
            candidate: cand,
            "peak_force_ks_p": p_force,
            "slip_ks_p": p_slip,
            "speedup": cand["episodes_per_hour"] / ref["episodes_per_hour"],
            "checks": checks,
        }
    result["passed"] = all(all(t["checks"].values()) for t in result["tasks"].values())
    atomic_write_text(out / "validation.json", to_json(result, indent=2) + "\n")
    atomic_write_text(out / "validation.md", format_report(result))
    return result


def _pct(lo: float, hi: float) -> str:
    return f"[{100 * lo:.0f}, {100 * hi:.0f}] %"


def _p(value: float | None) -> str:
    return "n/a" if value is None or not math.isfinite(value) else f"{value:.3f}"


def format_report(result: dict[str, Any]) -> str:
    """A Markdown summary of :func:`validate_profile`'s result."""
    cand, ref = result["candidate"], result["reference"]
    lines = [
        f"# Physics profile `{cand}` against `{ref}`",
        "",
        f"{result['seeds']} seeds per task and profile, {result['workers']} workers; "
        f"tests at the {100 * result['alpha']:.0f} % level. Verdict: "
        f"**{'passed' if result['passed'] else 'not passed'}**.",
        "",
        "| task | profile | success (95 % CI) | failures | peak force median (95 % CI), max | "
        "slip median / max | episodes/hour |",
        "|---|---|---|---|---|---|---|",
    ]
    for task, t in result["tasks"].items():
        for name in (ref, cand):
            s = t[name]
            pf = s["peak_force_n"]
            ci = pf["median_ci95"]
            ci_text = f"({ci[0]:.1f}-{ci[1]:.1f})" if ci[0] is not None else ""
            reasons = ", ".join(f"{k} {v}" for k, v in sorted(s["failure_reasons"].items())) or "-"
            lines.append(
                f"| {task} | {name} | {s['successes']}/{s['episodes']} {_pct(*s['success_ci95'])} | "
                f"{reasons} | {pf['median']:.2f} N {ci_text}, {pf['max']:.1f} N | "
                f"{1e6 * s['slip_m']['median']:.0f} / {1e6 * s['slip_m']['max']:.0f} um | "
                f"{s['episodes_per_hour']:.0f} |"
            )
    lines += ["", "| task | speed-up | peak force KS p | slip KS p | checks |", "|---|---|---|---|---|"]
    for task, t in result["tasks"].items():
        checks = ", ".join(f"{k}: {'yes' if v else 'NO'}" for k, v in t["checks"].items())
        lines.append(
            f"| {task} | {t['speedup']:.1f}x | {_p(t['peak_force_ks_p'])} | {_p(t['slip_ks_p'])} | {checks} |"
        )
    return "\n".join(lines) + "\n"
