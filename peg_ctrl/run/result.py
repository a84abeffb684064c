"""The episode record, :class:`EpisodeResult`, and the metadata each of its fields carries.

A metric is declared once, as a field of :class:`EpisodeResult` with its :class:`Metric`
(``field(metadata=metric(...))``): its unit, whether it is a column of a sweep's
``episodes.csv``, and how a sweep summarises it (:class:`Summary`). Everything else derives
from the fields: the columns of ``episodes.csv`` (:func:`result_columns`, in field order), the
columns read as numbers (:func:`numeric_columns`), the statistics of ``summary.csv`` and the
report's summary table (:func:`summarised`). Every scalar field (a string, number or flag, or
None) is a column unless its metadata says otherwise; a field without metadata is a column with
no unit, not summarised.

This module imports nothing of the package, so that the statistics and the report
(``peg_ctrl.experiments``) read the declarations without the simulator.
"""

from __future__ import annotations

import dataclasses
import types
import typing
from dataclasses import field
from typing import Any

__all__ = [
    "COST_FIELDS",
    "WALL_CLOCK_FIELDS",
    "STATS",
    "Summary",
    "Metric",
    "metric",
    "MetricField",
    "metric_fields",
    "result_columns",
    "numeric_columns",
    "flag_columns",
    "summarised",
    "EpisodeResult",
]

#: The statistics a :class:`Summary` may ask for: the median, the 95 % bootstrap interval of the
#: median, the 95th percentile, and (of a flag) the share of episodes where it is set with its
#: 95 % Wilson interval.
STATS = ("median", "ci", "p95", "rate")


@dataclasses.dataclass(frozen=True)
class Summary:
    """How a sweep summarises a metric per arm, planner and clearance (``summary.csv`` and the
    report's summary table).

    The columns of ``summary.csv`` are named ``<name>_median_<unit>``,
    ``<name>_median_ci95_low_<unit>``/``..._high_<unit>``, ``<name>_p95_<unit>``,
    ``<name>_within_<within><unit>`` and ``<name>_rate`` (with ``_ci95_low``/``_high``), where
    ``<unit>`` is the metric's unit in lower case without spaces (``N s``: ``ns``).
    """

    label: str  # the report's name of the metric: "peak force"
    stats: tuple[str, ...] = ("median", "ci")  # of STATS, in this order in the tables
    within: float | None = None  # also the share of episodes at or below this [the metric's unit]
    successes: bool = False  # over the successful episodes only (a time to insert)
    name: str = ""  # stem of the summary's columns; "": the field's name without its unit
    decimals: int = 2  # of the interval's bounds in the report
    lead: bool = False  # first in the report's summary (the headline metric), whatever its column

    def __post_init__(self) -> None:
        unknown = [s for s in self.stats if s not in STATS]
        if unknown or not self.stats:
            raise ValueError(f"Summary.stats: {unknown or 'none'}; known: {', '.join(STATS)}")
        if "rate" in self.stats and len(self.stats) > 1:
            raise ValueError("Summary.stats: 'rate' (of a flag) goes alone")


@dataclasses.dataclass(frozen=True)
class Metric:
    """What a field of the episode record is, for the tables of a sweep."""

    unit: str = ""  # "N", "s", "m", "rad", "N s"; "" for a count, a flag or a text
    column: bool = True  # a column of episodes.csv (a scalar field only)
    job: bool = False  # a column the sweep writes from the experiment's job (the arm's label, ...)
    wall_clock: bool = False  # measured in wall time: it differs between two runs of one episode
    cost: bool = False  # what the control costs (the report's control-cost section)
    summary: Summary | None = None  # how a sweep summarises it; None: it does not


def metric(
    *,
    unit: str = "",
    column: bool = True,
    job: bool = False,
    wall_clock: bool = False,
    cost: bool = False,
    summary: Summary | None = None,
) -> dict[str, Metric]:
    """The metadata of a dataclass field that declares a :class:`Metric`:
    ``field(metadata=metric(unit="N", summary=Summary(...)))``."""
    return {
        "metric": Metric(unit=unit, column=column, job=job, wall_clock=wall_clock, cost=cost, summary=summary)
    }


@dataclasses.dataclass(frozen=True)
class MetricField:
    """One field of the episode record with its metadata and its kind of value."""

    name: str
    metric: Metric
    kind: str  # "number", "flag", "text" (scalars) or "other" (a list, a dict)

    @property
    def column(self) -> bool:
        """Whether it is a column of ``episodes.csv``."""
        return self.kind != "other" and self.metric.column

    @property
    def suffix(self) -> str:
        """The unit as the summary's column names write it: ``N s`` -> ``ns``."""
        return self.metric.unit.lower().replace(" ", "")

    @property
    def stem(self) -> str:
        """The stem of the summary's columns: the summary's ``name``, else the field's name
        without its unit (``contact_to_seat_s``: ``contact_to_seat``)."""
        summary = self.metric.summary
        if summary is not None and summary.name:
            return summary.name
        tail = f"_{self.suffix}"
        return self.name[: -len(tail)] if self.suffix and self.name.endswith(tail) else self.name


_SCALARS = {bool: "flag", int: "number", float: "number", str: "text"}


def _kind(hint: Any) -> str:
    """ "number", "flag" or "text" for a scalar type hint (or one that may be None), else "other"."""
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        kinds = {_kind(a) for a in typing.get_args(hint) if a is not type(None)}
        return kinds.pop() if len(kinds) == 1 else "other"
    return _SCALARS.get(hint, "other")


def metric_fields(result: type | None = None) -> list[MetricField]:
    """The fields of ``result`` (a dataclass; default :class:`EpisodeResult`), in order."""
    cls = EpisodeResult if result is None else result
    hints = typing.get_type_hints(cls)
    return [
        MetricField(f.name, f.metadata.get("metric", Metric()), _kind(hints[f.name]))
        for f in dataclasses.fields(cls)
    ]


def result_columns(result: type | None = None) -> tuple[str, ...]:
    """The columns of ``episodes.csv`` copied from each episode's record, in field order (the
    job's columns, which the sweep writes itself, left out)."""
    return tuple(f.name for f in metric_fields(result) if f.column and not f.metric.job)


def numeric_columns(result: type | None = None) -> tuple[str, ...]:
    """The columns of :func:`result_columns` that hold numbers."""
    return tuple(
        f.name for f in metric_fields(result) if f.column and not f.metric.job and f.kind == "number"
    )


def flag_columns(result: type | None = None) -> tuple[str, ...]:
    """The columns of :func:`result_columns` that hold flags (true or false)."""
    return tuple(f.name for f in metric_fields(result) if f.column and not f.metric.job and f.kind == "flag")


def summarised(result: type | None = None) -> list[MetricField]:
    """The columns of :func:`result_columns` that a sweep summarises: those that lead, then the
    others, each in field order."""
    fields = [
        f for f in metric_fields(result) if f.column and not f.metric.job and f.metric.summary is not None
    ]
    return sorted(fields, key=lambda f: not (f.metric.summary and f.metric.summary.lead))


# The metadata of the fields that repeat in the record.
_JOB = metric(job=True)  # a column the sweep writes from the experiment's job
_NO_COLUMN = metric(column=False)
_COST_S = metric(unit="s", wall_clock=True, cost=True)


@dataclasses.dataclass
class EpisodeResult:
    """The episode record (also written as ``summary.json``).

    Its fields are in the order of the columns of a sweep's ``episodes.csv``; see the module's
    docstring for their metadata.
    """

    status: str  # "success" or "failure" ("interrupted" on Ctrl-C)
    reason: str  # "" on success, else one of FAILURE_REASONS
    phase: str  # phase when the episode ended
    controller: str = field(metadata=_JOB)
    planner: str = field(metadata=_JOB)
    task: str = field(metadata=_JOB)  # the task's name
    strategy: str = field(metadata=_JOB)  # the insertion strategy ("" for a task without one)
    seed: int = field(metadata=_JOB)
    # peg-block: the largest force of one physics step, as the solver returned it (a one-step
    # spike of the convex contact model counts in full: docs/physics.md, "Cross-check against Drake")
    peak_contact_force_n: float = field(
        metadata=metric(
            unit="N",
            summary=Summary(
                "solver peak (one step)", ("median", "p95"), within=10.0, name="peak_force", decimals=1
            ),
        )
    )
    peak_any_contact_force_n: float = field(metadata=metric(unit="N"))
    time_to_insert_s: float | None = field(
        metadata=metric(unit="s", summary=Summary("time to insert", successes=True))
    )
    first_contact_s: float | None = field(metadata=metric(unit="s"))  # first peg-block contact
    # From the first contact to the start of the seated hold.
    contact_to_seat_s: float | None = field(
        metadata=metric(unit="s", summary=Summary("contact to seated", ("median", "p95"), successes=True))
    )
    # Integral of the peg-block force from the first contact.
    contact_impulse_ns: float = field(
        metadata=metric(unit="N s", summary=Summary("impulse", ("median",), name="impulse"))
    )
    # Largest peg tilt from the first contact on (None: no contact).
    max_tilt_rad: float | None = field(metadata=metric(unit="rad"))
    # Lateral travel of the peg's lower end from the first contact on.
    search_distance_m: float = field(metadata=metric(unit="m"))
    end_state: str  # seated, missed, jammed, wedged or not_at_hole (monitors.episode_end_state)
    # The peg in the hole; None (null) when it is not at the hole (end_state "not_at_hole", see
    # peg_ctrl.tasks.monitors.InsertionMeasure.at_hole): a lying peg has no depth in the bore.
    insertion_depth_m: float | None = field(metadata=metric(unit="m"))
    lateral_error_m: float | None = field(metadata=metric(unit="m"))
    tilt_rad: float | None = field(metadata=metric(unit="rad"))
    max_penetration_m: float = field(metadata=metric(unit="m"))  # peg-block and peg-table, whole episode
    resting_penetration_m: float = field(metadata=metric(unit="m"))  # peg's contacts at the end
    grip_penetration_m: float = field(metadata=metric(unit="m"))  # pads into the peg, whole episode
    peg_slip_m: float = field(metadata=metric(unit="m"))  # peg motion relative to the pad while held
    physics: str  # the physics profile
    total_timesteps: int
    sim_time_s: float = field(metadata=metric(unit="s"))
    wall_time_s: float = field(metadata=metric(unit="s", wall_clock=True))
    detail: str = field(metadata=_NO_COLUMN)
    log_path: str = field(metadata=_JOB)  # in episodes.csv: relative to the sweep's directory
    trace_path: str = field(metadata=_NO_COLUMN)
    plot_path: str | None = field(default=None, metadata=_NO_COLUMN)
    video_path: str | None = field(default=None, metadata=_NO_COLUMN)
    phases: list[dict[str, Any]] = field(default_factory=list)
    # The task's belief, reading by reading (peg_ctrl.tasks.belief: time, skill, bits, spreads);
    # and the skills a planning strategy (plan) chose, with its decisions. The decisions carry
    # the planner's own compute time (wall clock): the field is not compared between runs.
    belief: list[dict[str, Any]] = field(default_factory=list)
    skills: list[dict[str, Any]] = field(default_factory=list, metadata=metric(wall_clock=True))
    # What the control costs, in wall time: per control step (the whole controller), and per
    # solve of each of its optimisers (controllers.base.SolveTiming), with its period and its
    # real-time factor (mean solve time over its period). The solve_time_* fields repeat the
    # first optimiser's (the MPC's effort QP, the sampling MPC's planner, the IK's QP); None
    # for a controller without one.
    control_time_p50_s: float | None = field(default=None, metadata=_COST_S)
    control_time_p99_s: float | None = field(default=None, metadata=_COST_S)
    solve_time_p50_s: float | None = field(default=None, metadata=_COST_S)
    solve_time_p99_s: float | None = field(default=None, metadata=_COST_S)
    solve_period_s: float | None = field(default=None, metadata=metric(unit="s", cost=True))
    solve_real_time_factor: float | None = field(default=None, metadata=metric(wall_clock=True, cost=True))
    solver_timing: dict[str, dict[str, float]] = field(default_factory=dict, metadata=metric(wall_clock=True))
    phantom_contacts: int = 0  # physics steps whose collider returned a phantom (loop.PhantomGuard)
    # The peg's friction time constant set on the profile (physics.friction_time) [s]; None: the profile's.
    friction_time_s: float | None = field(default=None, metadata=metric(unit="s"))
    # peg-block: the largest mean force over any 10 ms (peg_ctrl.sim.force_metric): the force
    # the studies report, which agrees with Drake's lagged contact; None in runs made before it
    peak_force_10ms_n: float | None = field(
        default=None,
        metadata=metric(
            unit="N",
            summary=Summary(
                "peak force (10 ms)",
                ("median", "ci", "p95"),
                within=10.0,
                name="force_10ms",
                decimals=1,
                lead=True,
            ),
        ),
    )
    # The environment that ran it (peg_ctrl.environment.environment_id: the record is in the
    # sweep's environment.json); None in runs made before it. Not compared between reruns.
    environment: str | None = None

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    def _force_text(self) -> str:
        solver = f"{self.peak_contact_force_n:.2f} N"
        if self.peak_force_10ms_n is None:
            return f"{solver} (one step)"
        return f"{self.peak_force_10ms_n:.2f} N over 10 ms (solver peak {solver})"

    def one_line(self) -> str:
        if self.status == "success":
            head = "SUCCESS"
        else:
            head = f"{self.status.upper()} ({self.reason} in {self.phase})"
        tti = f", inserted at {self.time_to_insert_s:.2f} s" if self.time_to_insert_s is not None else ""
        task = f"{self.task}/{self.strategy}" if self.strategy else self.task
        depth = (
            f"depth {self.insertion_depth_m * 1e3:.1f} mm"
            if self.insertion_depth_m is not None
            else "peg not at the hole"
        )
        physics = f"{self.physics} physics" + (
            f", the peg's friction time {self.friction_time_s * 1e3:g} ms"
            if self.friction_time_s is not None
            else ""
        )
        return (
            f"{head}: {self.controller}+{self.planner} seed {self.seed} ({task}, {physics}), "
            f"{self.total_timesteps} steps "
            f"({self.sim_time_s:.2f} s sim, {self.wall_time_s:.1f} s wall){tti}, "
            f"{depth}, peak peg-block force {self._force_text()}"
        )


#: The summary's fields of what the control costs (the report's control-cost section), in order.
COST_FIELDS = tuple(f.name for f in metric_fields(EpisodeResult) if f.metric.cost)
#: Summary fields measured in wall time: they differ between two runs of the same episode.
WALL_CLOCK_FIELDS = tuple(f.name for f in metric_fields(EpisodeResult) if f.metric.wall_clock)
