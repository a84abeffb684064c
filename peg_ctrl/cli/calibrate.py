"""``peg-sim calibrate``: measure the jaw's byte <-> pad separation table."""

from __future__ import annotations

import argparse
from pathlib import Path

from peg_ctrl.errors import ConfigError
from peg_ctrl.io import atomic_write_text, prepare_output_file


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add ``calibrate`` to the ``peg-sim`` subcommands."""
    p = sub.add_parser(
        "calibrate",
        help="measure the jaw byte <-> pad separation table",
        description="Sweep the jaw actuator's byte over 0..255 on the model, fit the piecewise-linear "
        "byte <-> pad separation map and write it as JSON to --out FILE. --replace-packaged instead "
        "rewrites the table the package ships (peg_ctrl/data/jaw_calibration.json; source checkouts "
        "only).",
    )
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument("--out", metavar="FILE", help="output JSON file")
    where.add_argument(
        "--replace-packaged",
        action="store_true",
        help="rewrite the packaged calibration in this source checkout (refused in an installed copy)",
    )
    p.add_argument("--samples", type=int, default=103, help="bytes swept over 0..255 (default 103)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Calibrate on the default model and write the table."""
    from peg_ctrl.sim import jaw
    from peg_ctrl.sim.scene import build_model

    if args.samples < 4:
        raise ConfigError(f"--samples must be >= 4, got {args.samples}")
    if args.replace_packaged:
        target = jaw.source_tree_path()
        if target is None:
            raise ConfigError(
                "--replace-packaged works only in a source checkout: this installed copy's packaged "
                "calibration is read-only; use --out FILE"
            )
    else:
        target = Path(args.out)
    out = prepare_output_file(target)
    cal = jaw.calibrate(
        build_model(), n_samples=args.samples, n_knots=max(2, args.samples // 2 + 1), progress=True
    )
    atomic_write_text(out, cal.to_json() + "\n")
    print(
        f"jaw calibration: {len(cal.bytes_)} knots, open {cal.sep_open_m * 1e3:.2f} mm, "
        f"closed {cal.sep_closed_m * 1e3:.2f} mm, max fit error {cal.fit_max_error_m * 1e3:.3f} mm "
        f"-> {out}"
    )
    return 0
