"""What the belief planner did in one episode, as a figure: the end's path over the hole, and the
belief's spread and the depth against time.

    python -m peg_ctrl.experiments.plan_figure runs/plan/episodes/KEY --out docs/plan/success.png

The episode is run again from its ``config.json`` (the same seed: the same episode, checked
against its ``summary.json``: the peak force and the outcome must agree, or it stops). At every
replan of the ``handover`` phase it records the peg's true lower end against the true hole, the
belief's mean (where the planner thinks the end is against the hole) and its spread, and writes
the figure and the numbers beside it (``.json``). The committed plan study's episodes name the
strategy ``plan``, which it was called when they ran (now the planner over skills): their
``config.json`` must name ``handover`` to be drawn again.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from peg_ctrl.errors import ConfigError
from peg_ctrl.io import atomic_write_text

__all__ = ["trace_episode", "draw", "main"]


def trace_episode(episode_dir: Path) -> dict[str, Any]:
    """Run the episode in ``episode_dir`` again, recording the planner's belief (see the module docstring)."""
    from peg_ctrl.controllers.sampling_mpc import SamplingMPCController
    from peg_ctrl.run.episode import build_loop, episode_config_from_mapping

    cfg = episode_config_from_mapping(json.loads((episode_dir / "config.json").read_text()))
    loop = build_loop(cfg)
    loop.reset(np.random.default_rng(cfg.seed))
    task, controller = loop.task, loop.controller
    rows: list[list[float]] = []
    seen = 0
    while True:
        ev = loop.step()
        planner = controller.planner if isinstance(controller, SamplingMPCController) else None
        if planner is not None and len(planner.history) > seen:
            seen = len(planner.history)
            rec = planner.history[-1]
            m = task.insertion  # type: ignore[attr-defined]
            end = loop.peg.bottom_world  # type: ignore[union-attr]
            rows.append(
                [
                    rec.t,
                    (end[0] - m.hole_x) * 1e3,
                    (end[1] - m.hole_y) * 1e3,
                    (end[2] - m.block_top) * 1e3,
                    rec.mean[0] * 1e3,
                    rec.mean[1] * 1e3,
                    rec.spread * 1e3,
                    rec.ess,
                ]
            )
        if ev.done:
            break
    summary = json.loads((episode_dir / "summary.json").read_text())
    peak = float(loop.contact.peak_block)
    recorded = summary["status"] == "success"
    if not np.isclose(peak, summary["peak_contact_force_n"], rtol=1e-9) or ev.success != recorded:
        raise ConfigError(
            f"{episode_dir}: the rerun differs from the recorded episode (peak {peak:.3f} N against "
            f"{summary['peak_contact_force_n']:.3f} N): not the code that ran it"
        )
    return {
        "episode": episode_dir.name,
        "success": bool(ev.success),
        "detail": ev.detail,
        "peak_force_n": peak,
        "columns": [
            "t_s",
            "end_x_mm",
            "end_y_mm",
            "end_z_mm",
            "belief_x_mm",
            "belief_y_mm",
            "spread_mm",
            "ess",
        ],
        "rows": rows,
        "capture_mm": (task.hole_radius - task.radius + task.chamfer) * 1e3,  # type: ignore[attr-defined]
    }


def draw(trace: dict[str, Any], out: Path, title: str) -> None:
    """The figure: the end's path over the hole (x, y, against the true hole, with the mouth and
    the chamfer's rim) and, against time, the depth and the belief's spread."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    a = np.asarray(trace["rows"], dtype=float)
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(10, 4.2), gridspec_kw={"width_ratios": [1, 1.3]})
    if len(a):
        above = a[:, 3] > -1.0
        ax.plot(a[:, 1], a[:, 2], color="0.6", lw=0.8, label="the end's path")
        ax.plot(a[above, 1], a[above, 2], ".", ms=2, color="C0", label="... on or above the face")
        ax.plot(a[0, 1], a[0, 2], "o", color="C2", label="hand-over")
        ax.plot(a[-1, 1], a[-1, 2], "s", color="C3", label="end")
    theta = np.linspace(0, 2 * np.pi, 200)
    r = trace["capture_mm"]
    ax.plot(
        r * np.cos(theta), r * np.sin(theta), "--", color="k", lw=0.8, label="capture (clearance + chamfer)"
    )
    ax.plot([0], [0], "+", color="k", ms=10, label="the hole's axis")
    ax.set_aspect("equal")
    ax.set_xlabel("x [mm] (from the hole's axis)")
    ax.set_ylabel("y [mm]")
    ax.set_title("the peg's lower end over the hole")
    ax.legend(fontsize=7, loc="best")
    if len(a):
        t = a[:, 0]
        bx.plot(t, a[:, 3], color="C0", label="the end's height above the face [mm]")
        bx.set_xlabel("time [s]")
        bx.set_ylabel("height [mm]", color="C0")
        cx = bx.twinx()
        cx.plot(t, a[:, 6], color="C1", label="belief spread [mm]")
        cx.set_ylabel("belief spread (x, y) [mm]", color="C1")
        bx.set_title("depth, and what the planner knows")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m peg_ctrl.experiments.plan_figure", description=__doc__.splitlines()[0]
    )
    parser.add_argument("episode", type=Path, help="an episode's directory (runs/<study>/episodes/<key>)")
    parser.add_argument(
        "--out", type=Path, required=True, help="the figure (PNG); its numbers go beside it (.json)"
    )
    parser.add_argument("--title", default="", help="the figure's title")
    args = parser.parse_args(argv)
    if not (args.episode / "config.json").is_file() or not (args.episode / "summary.json").is_file():
        print(
            f"plan_figure: error: {args.episode} holds no episode (config.json and summary.json)",
            file=sys.stderr,
        )
        return 2
    try:
        trace = trace_episode(args.episode)
    except ConfigError as exc:
        print(f"plan_figure: error: {exc}", file=sys.stderr)
        return 2
    title = args.title or f"{trace['episode']}: {'seated' if trace['success'] else trace['detail']}"
    draw(trace, args.out, title)
    atomic_write_text(args.out.with_suffix(".json"), json.dumps(trace, indent=1) + "\n")
    print(f"wrote {args.out} and {args.out.with_suffix('.json')}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
