"""A study's committed run as a baseline: where it is, which of its episodes a rerun checks, and
whether a rerun on this machine still says the same (docs/reproducibility.md).

A rerun of a committed episode is classed

- **reproduced**: every compared column the same, bit for bit (as its CSV text);
- **agrees**: the approach the same to the last bit (:data:`APPROACH`: the first contact at the
  same instant, the same physics), and then, for an episode that touched the block, anything:
  contact is chaotic, a last-bit nudge of the start (or another CPU's last bit) moved every
  post-contact column and outcome of some arm's rerun beyond what any calibration predicted
  (docs/reproducibility.md, "The rule"). An episode that never touched the block must stay within
  :data:`FACTOR` times the largest drift any calibrated arm showed (:class:`Tolerance`, measured
  by ``python -m peg_ctrl.experiments.reproduction calibrate`` into
  ``peg_ctrl/data/reproduction.json``), its outcome unchanged unless the perturbations changed it
  for that arm;
- **differs**: anything else. Only this stops ``peg-sim compare``.

An arm's class is its sample's worst episode's.
"""

from __future__ import annotations

import dataclasses
import json
import math
from importlib import resources
from pathlib import Path
from typing import Any

import peg_ctrl
from peg_ctrl.errors import ConfigError
from peg_ctrl.experiments.config import ExperimentConfig, Job, expand, experiment_from_mapping
from peg_ctrl.experiments.report import read_rows
from peg_ctrl.run.result import WALL_CLOCK_FIELDS

__all__ = [
    "CLASSES",
    "FACTOR",
    "STUDY_FILES",
    "NOT_COMPARED",
    "APPROACH",
    "Tolerance",
    "Verdict",
    "committed_studies",
    "find_study",
    "jobs_by_arm",
    "match_committed",
    "sample_jobs",
    "differences",
    "classify",
    "classify_arm",
    "tolerance",
    "load_calibration",
    "calibration_path",
    "CALIBRATION",
]

#: The classes of a rerun, from best to worst.
CLASSES = ("reproduced", "agrees", "differs")
#: A number may move by this many times the drift a last-bit perturbation produces.
FACTOR = 2.0
#: The drift a number may show: this quantile, over every calibrated arm, of the arms' largest
#: drift in the column, times :data:`FACTOR`. The largest: chaos is heavy-tailed, and an arm's
#: own few perturbed reruns (or the 90th percentile of all arms') underestimated what a rerun of
#: another episode did (docs/reproducibility.md, "The rule").
POOLED_QUANTILE = 1.0
#: What a committed run holds.
STUDY_FILES = ("experiment.json", "episodes.csv")
#: Columns a rerun is not compared in: measured in wall time, naming the episode (its key, its
#: log) or the machine (its environment) rather than saying what happened in it.
NOT_COMPARED = frozenset({*WALL_CLOCK_FIELDS, "key", "log_path", "environment"})
#: Columns the approach determines, before the first contact: a last-bit difference stays a
#: last bit there (never moved in any perturbed or emulated-machine rerun), so they must match.
#: With them the episode's inputs that a study records (its physics).
APPROACH = frozenset({"first_contact_s", "physics", "friction_time_s"})
#: The measured drift of every committed study arm (``reproduction calibrate``).
CALIBRATION = "reproduction.json"


def committed_studies() -> dict[str, Path]:
    """The committed runs by name: the ``docs/<study>/`` directories holding
    :data:`STUDY_FILES`, in the project beside the package and in the working directory."""
    roots = [Path(str(resources.files("peg_ctrl.experiments"))).parent / "docs", Path.cwd() / "docs"]
    found: dict[str, Path] = {}
    for root in roots:
        if root.is_dir():
            for entry in sorted(root.iterdir()):
                if all((entry / f).is_file() for f in STUDY_FILES):
                    found.setdefault(entry.name, entry)
    return found


def find_study(study: str) -> Path:
    """A committed run's directory: ``study`` as a path, or the name of one of
    :func:`committed_studies`.

    Raises:
        ConfigError: neither; the message lists the committed studies.
    """
    path = Path(study)
    if path.is_dir():
        missing = [f for f in STUDY_FILES if not (path / f).is_file()]
        if missing:
            raise ConfigError(
                f"study {study!r}: {path} holds no committed run (no {', '.join(missing)}); a study is a "
                "sweep's output directory or one of the committed studies"
            )
        return path
    known = committed_studies()
    if study in known:
        return known[study]
    raise ConfigError(
        f"study {study!r}: no such directory or committed study; committed: {', '.join(known) or '(none)'} "
        "(the committed studies are docs/<study>/ in the repository: run from its root, or give the path)"
    )


def _text(value: Any) -> str:
    """A value as ``episodes.csv`` writes it."""
    return "" if value is None else str(value)


def _json(config: Any) -> str:
    from peg_ctrl.config import to_dict

    return json.dumps(to_dict(config), sort_keys=True)


def jobs_by_arm(exp: ExperimentConfig) -> dict[str, tuple[Job, ...]]:
    """The experiment's episodes by arm, in its job order."""
    found: dict[str, list[Job]] = {}
    for job in expand(exp):
        found.setdefault(job.arm, []).append(job)
    return {arm: tuple(jobs) for arm, jobs in found.items()}


def match_committed(study_dir: Path, study_jobs: dict[str, tuple[Job, ...]]) -> dict[str, dict[str, str]]:
    """Each study job's committed row, by the job's key: the row of the committed job with the
    same arm and the same config (a ``--set`` of the seeds or a grid key keeps it; one of the
    physics or a task field does not). Matched by what the episode is rather than by its key,
    since a key leaves out the fields at their defaults: a default changed since the study ran
    changes the key, not the episode (the committed ``experiment.json`` holds every field's
    value). A committed job finds its row by what ``episodes.csv`` wrote of it: arm, planner,
    clearance, seed and its grid values, as text."""
    committed = expand(experiment_from_mapping(json.loads((study_dir / "experiment.json").read_text())))
    rows = {}
    for row in read_rows(study_dir):
        cell = tuple((k, row.get(k, "")) for k in sorted(committed[0].cell)) if committed else ()
        rows[(row["arm"], row["planner"], row["clearance_m"], row["seed"], cell)] = row
    by_config = {}
    for job in committed:
        cell = tuple((k, _text(v)) for k, v in sorted(job.cell.items()))
        written = rows.get((job.arm, job.planner, _text(job.clearance), _text(job.seed), cell))
        if written is not None:
            by_config[(job.arm, _json(job.config))] = written
    found = {}
    for jobs in study_jobs.values():
        for job in jobs:
            match = by_config.get((job.arm, _json(job.config)))
            if match is not None:
                found[job.key] = match
    return found


def sample_jobs(
    study_jobs: dict[str, tuple[Job, ...]], committed: dict[str, dict[str, str]], per_arm: int
) -> dict[str, tuple[Job, ...]]:
    """Each study arm's first ``per_arm`` committed episodes in key order (keys are hashes: a
    sample spread over the cells): the episodes ``compare`` reruns and the calibration measures."""
    return {
        a: tuple(sorted((j for j in jobs if j.key in committed), key=lambda j: j.key)[:per_arm])
        for a, jobs in study_jobs.items()
    }


def differences(committed: dict[str, str], fresh: dict[str, Any]) -> list[tuple[str, str, str]]:
    """The columns (recorded in both, :data:`NOT_COMPARED` left out) in which a rerun's text
    differs from its committed row: (column, committed, now)."""
    found = []
    for column, was in committed.items():
        if column in NOT_COMPARED or column not in fresh:
            continue
        now = _text(fresh[column])
        if now != was and not (_number(was) is not None and _number(was) == _number(now)):
            found.append((column, was, now))
    return found


def _number(text: str) -> float | None:
    try:
        value = float(text)
    except ValueError:
        return None
    return value if math.isfinite(value) else None


@dataclasses.dataclass(frozen=True)
class Tolerance:
    """How far a study arm's rerun may move and still agree: per numeric column, the largest
    absolute change; the text columns (and a number's appearing or vanishing: a time to insert
    of an episode that no longer inserts) that may change at all."""

    numbers: dict[str, float]
    may_change: frozenset[str] = frozenset()
    source: str = ""  # where it came from: "calibrated", "uncalibrated: ..."

    def allows(self, column: str, was: str, now: str) -> bool:
        a, b = _number(was), _number(now)
        if a is not None and b is not None:
            return abs(a - b) <= self.numbers.get(column, 0.0)
        return column in self.may_change


@dataclasses.dataclass(frozen=True)
class Verdict:
    """A rerun's class, and the column that decided it (empty when reproduced)."""

    cls: str
    column: str = ""
    was: str = ""
    now: str = ""
    allowed: float | None = None  # the column's tolerance, for a number
    moved: int = 0  # columns that differ from the committed text

    def detail(self) -> str:
        if self.cls == "reproduced":
            return "bit for bit"
        if self.column in APPROACH:
            bound = " (the approach, before the first contact: it must reproduce)"
        else:
            bound = f" (allowed {self.allowed:.3g})" if self.allowed is not None else ""
        what = f"{self.column} was {self.was or '(blank)'}, is {self.now or '(blank)'}{bound}"
        more = f"; {self.moved} columns moved" if self.moved > 1 else ""
        return what + more


def classify(committed: dict[str, str], fresh: dict[str, Any], tol: Tolerance) -> Verdict:
    """One rerun against its committed row under ``tol`` (the module's rule)."""
    diffs = differences(committed, fresh)
    if not diffs:
        return Verdict("reproduced")

    def allowed(column: str) -> float | None:
        return tol.numbers.get(column, 0.0) if column not in tol.may_change or column in tol.numbers else None

    approach = [d for d in diffs if d[0] in APPROACH]
    if approach:  # the approach is not chaotic: it reproduces to the last bit or the baseline changed
        column, was, now = approach[0]
        return Verdict("differs", column, was, now, 0.0, len(diffs))
    touched = _number(committed.get("first_contact_s", "")) is not None
    outside = [] if touched else [d for d in diffs if not tol.allows(*d)]
    if outside:
        column, was, now = outside[0]
        return Verdict("differs", column, was, now, allowed(column), len(diffs))
    # the column that came closest to its bound (after a contact, the bound is the arm's chaos)
    column, was, now = max(diffs, key=lambda d: _share(tol, *d))
    return Verdict("agrees", column, was, now, None if touched else allowed(column), len(diffs))


def _share(tol: Tolerance, column: str, was: str, now: str) -> float:
    a, b = _number(was), _number(now)
    if a is None or b is None:
        return 1.0
    bound = tol.numbers.get(column, 0.0)
    return abs(a - b) / bound if bound > 0 else math.inf


def classify_arm(verdicts: list[Verdict]) -> Verdict:
    """An arm's class: its worst episode's verdict."""
    return max(verdicts, key=lambda v: CLASSES.index(v.cls))


def calibration_path() -> Path:
    """The packaged calibration, ``peg_ctrl/data/reproduction.json`` (read here, written by
    ``reproduction calibrate``)."""
    return Path(peg_ctrl.__file__).parent / "data" / CALIBRATION


def load_calibration(path: Path | None = None) -> dict[str, Any]:
    """The calibration at ``path`` (default: the packaged one), or ``{}`` when none."""
    path = path or calibration_path()
    return dict(json.loads(path.read_text())) if path.is_file() else {}


def tolerance(study: str, arm: str, calibration: dict[str, Any] | None = None) -> Tolerance:
    """The rule's tolerance for ``study``'s ``arm`` (module docstring)."""
    data = load_calibration() if calibration is None else calibration
    arms: dict[str, dict[str, Any]] = {
        f"{s}:{a}": entry for s, by_arm in data.get("studies", {}).items() for a, entry in by_arm.items()
    }
    factor = float(data.get("factor", FACTOR))
    if not arms:
        return Tolerance({}, frozenset(), "uncalibrated: no calibration, reruns must reproduce")
    columns = sorted({c for e in arms.values() for c in e["drift"]})
    drifts = {c: sorted(e["drift"].get(c, 0.0) for e in arms.values()) for c in columns}
    pooled = {c: d[round(POOLED_QUANTILE * (len(d) - 1))] for c, d in drifts.items()}
    entry = arms.get(f"{study}:{arm}")
    if entry is None:
        numbers = {c: factor * pooled[c] for c in columns}
        return Tolerance(numbers, frozenset(), f"uncalibrated: {study}:{arm} has no measured outcome changes")
    numbers = {c: factor * max(entry["drift"].get(c, 0.0), pooled[c]) for c in columns}
    return Tolerance(numbers, frozenset(entry.get("may_change", ())), "calibrated")
