"""The Markdown report and plots of a sweep (also ``peg-sim plot DIR``).

Every table and plot is drawn from ``episodes.csv`` alone, except the two that need the
episodes' force traces (``episodes/<key>/forces.npz``): the aligned force profiles and force
against depth, which are left out (and the report says so) when the traces are not there.

Modules: :mod:`~peg_ctrl.experiments.report.episodes_csv` (reading and checking
``episodes.csv``), :mod:`~peg_ctrl.experiments.report.header` (what ran, sensed, on which environment),
:mod:`~peg_ctrl.experiments.report.sections` (the report's other sections),
:mod:`~peg_ctrl.experiments.report.plots` and :mod:`~peg_ctrl.experiments.report.traces` (the
plots), :mod:`~peg_ctrl.experiments.report.axes` (arms, swept conditions, task names),
:mod:`~peg_ctrl.experiments.report.run_time` (the sweep's run time over its invocations). The
statistics are :mod:`peg_ctrl.experiments.stats`'.
"""

from __future__ import annotations

import json
from pathlib import Path

from peg_ctrl.experiments.report.axes import arm_of, swept_conditions
from peg_ctrl.experiments.report.episodes_csv import episodes_csv_problem, read_rows
from peg_ctrl.experiments.report.header import environment_lines, header_section, verification_lines
from peg_ctrl.experiments.report.plots import draw_plots
from peg_ctrl.experiments.report.run_time import run_time
from peg_ctrl.experiments.report.sections import (
    against_section,
    cell_section,
    comparison_section,
    cost_section,
    phase_section,
    plots_section,
    summary_section,
)
from peg_ctrl.experiments.report.skills import skill_section
from peg_ctrl.experiments.stats import summarise, wilson_interval
from peg_ctrl.io import atomic_write_text

__all__ = [
    "wilson_interval",
    "summarise",
    "write_report",
    "read_rows",
    "episodes_csv_problem",
    "arm_of",
    "swept_conditions",
]


def write_report(out_dir: Path, *, elapsed_s: float | None = None) -> Path:
    """Draw the plots and write ``report.md`` from the saved ``episodes.csv``; returns its path.

    The run time in the header is ``elapsed_s`` [s] when given, else the sweep's recorded run
    time (:func:`~peg_ctrl.experiments.report.run_time.run_time`, summed over its invocations),
    else none.
    """
    out_dir = Path(out_dir)
    rows = read_rows(out_dir)
    summary = summarise(rows)
    # A comparison of a new arm with a committed study (peg-sim compare) leads with that arm,
    # and only its episodes' force traces are drawn (of the study's arms, a sample ran here).
    compared = out_dir / "compare.json"
    brought = json.loads(compared.read_text()) if compared.is_file() else None
    traced = [brought["arm"]] if brought else None
    plots = draw_plots(out_dir, rows, traced_arms=traced) if rows else []
    exp = (
        json.loads((out_dir / "experiment.json").read_text())
        if (out_dir / "experiment.json").is_file()
        else {}
    )
    took = (elapsed_s, 1) if elapsed_s is not None else run_time(out_dir)
    against = against_section(rows, brought["arm"], brought["study"], brought.get("rerun")) if brought else []
    parts = [
        *header_section(exp, out_dir.name, rows, took),
        *environment_lines(out_dir, rows),
        *verification_lines(brought),
        *against,
        *summary_section(summary),
        *cell_section(rows),
        *comparison_section(rows),
        # the phases are read from the episodes' logs: of a comparison's study arms only a sample ran here
        *phase_section(out_dir, rows if traced is None else [r for r in rows if arm_of(r) in traced]),
        *skill_section(out_dir, rows, [k for k in rows[0] if "." in k] if rows else []),
        *cost_section(rows),
        *plots_section(rows, plots),
    ]
    path = out_dir / "report.md"
    atomic_write_text(path, "\n".join(parts))
    return path
