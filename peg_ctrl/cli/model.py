"""``peg-sim model``: write the compiled scene (scene.xml and its meshes)."""

from __future__ import annotations

import argparse

from peg_ctrl.cli.common import add_config, add_out, add_set, episode_mapping
from peg_ctrl.io import prepare_output_dir


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add ``model`` to the ``peg-sim`` subcommands."""
    p = sub.add_parser(
        "model",
        help="write the compiled scene (scene.xml + meshes)",
        description="Write the compiled scene as DIR/scene.xml plus its meshes "
        "(open it with: python -m mujoco.viewer --mjcf=DIR/scene.xml).",
    )
    add_out(p, required=True)
    add_config(p, "episode config file (.yaml, .toml or .json) whose scene to write")
    add_set(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Export the scene of ``--config`` and ``--set`` into ``--out``."""
    from peg_ctrl.run.episode import episode_config_from_mapping
    from peg_ctrl.sim.scene import export_scene

    cfg = episode_config_from_mapping(episode_mapping(args))
    path = export_scene(prepare_output_dir(args.out), cfg.scene, cfg.physics.resolved())
    print(f"wrote {path} (open it with: python -m mujoco.viewer --mjcf={path})")
    return 0
