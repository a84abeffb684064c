"""The episode record's metadata: the columns, numbers and summaries derived from its fields."""

from __future__ import annotations

import csv
import dataclasses
from dataclasses import field
from pathlib import Path

import pytest

from peg_ctrl.run.result import (
    WALL_CLOCK_FIELDS,
    EpisodeResult,
    Summary,
    metric,
    metric_fields,
    numeric_columns,
    result_columns,
    summarised,
)

DOCS = Path(__file__).resolve().parents[2] / "docs"

# The episode record's columns of episodes.csv as the committed sweeps wrote them (docs/*/).
COMMITTED_COLUMNS = (
    "status",
    "reason",
    "phase",
    "peak_contact_force_n",
    "peak_any_contact_force_n",
    "time_to_insert_s",
    "first_contact_s",
    "contact_to_seat_s",
    "contact_impulse_ns",
    "max_tilt_rad",
    "search_distance_m",
    "end_state",
    "insertion_depth_m",
    "lateral_error_m",
    "tilt_rad",
    "max_penetration_m",
    "resting_penetration_m",
    "grip_penetration_m",
    "peg_slip_m",
    "physics",
    "total_timesteps",
    "sim_time_s",
    "wall_time_s",
    "control_time_p50_s",
    "control_time_p99_s",
    "solve_time_p50_s",
    "solve_time_p99_s",
    "solve_period_s",
    "solve_real_time_factor",
    "phantom_contacts",
    "friction_time_s",
    "peak_force_10ms_n",
    "environment",
)


def test_the_columns_are_the_scalar_fields_in_the_committed_order() -> None:
    assert result_columns() == COMMITTED_COLUMNS
    for sweep in ("contact", "contact_hard", "contact_real", "contact_real_offgrid"):
        with open(DOCS / sweep / "episodes.csv", newline="") as fh:
            header = next(csv.reader(fh))
        mine = [c for c in header if c in COMMITTED_COLUMNS]
        assert mine == list(COMMITTED_COLUMNS[: len(mine)]), sweep  # older sweeps: a prefix
    assert "detail" not in result_columns() and "phases" not in result_columns()  # declared / a list
    assert numeric_columns()[:2] == ("peak_contact_force_n", "peak_any_contact_force_n")
    assert "end_state" not in numeric_columns() and "status" not in numeric_columns()


def test_the_metadata_gives_units_kinds_and_summaries() -> None:
    fields = {f.name: f for f in metric_fields()}
    assert (
        fields["contact_impulse_ns"].metric.unit == "N s" and fields["contact_impulse_ns"].stem == "impulse"
    )
    assert fields["contact_to_seat_s"].stem == "contact_to_seat" and fields["contact_to_seat_s"].suffix == "s"
    assert (fields["time_to_insert_s"].kind, fields["phases"].kind, fields["status"].kind) == (
        "number",
        "other",
        "text",
    )
    assert fields["controller"].metric.job and fields["controller"].column
    assert [f.name for f in summarised()] == [  # the headline first, then in field order
        "peak_force_10ms_n",
        "peak_contact_force_n",
        "time_to_insert_s",
        "contact_to_seat_s",
        "contact_impulse_ns",
    ]
    assert WALL_CLOCK_FIELDS == (
        "wall_time_s",
        "skills",  # the planner's decisions carry its compute time
        "control_time_p50_s",
        "control_time_p99_s",
        "solve_time_p50_s",
        "solve_time_p99_s",
        "solve_real_time_factor",
        "solver_timing",
    )


def test_a_field_added_to_the_result_is_a_column_by_its_kind() -> None:
    extended = dataclasses.make_dataclass(
        "Extended",
        [
            ("wobble_m", float | None, dataclasses.field(default=None)),  # no metadata: a column
            ("jammed", bool, field(default=False, metadata=metric(summary=Summary("jammed", ("rate",))))),
            ("private_note", str, field(default="", metadata=metric(column=False))),
            ("samples", list, dataclasses.field(default_factory=list)),  # not a scalar
        ],
        bases=(EpisodeResult,),
    )
    columns = result_columns(extended)
    assert columns == (*COMMITTED_COLUMNS, "wobble_m", "jammed")
    assert numeric_columns(extended)[-1] == "wobble_m"
    assert [f.name for f in summarised(extended)][-1] == "jammed"


@pytest.mark.parametrize(
    ("stats", "message"),
    [(("median", "mean"), "['mean']; known: median, ci, p95, rate"), (("rate", "median"), "goes alone")],
)
def test_a_summary_names_known_statistics(stats: tuple[str, ...], message: str) -> None:
    with pytest.raises(ValueError, match=message.replace("[", r"\[").replace("]", r"\]")):
        Summary("x", stats=stats)
