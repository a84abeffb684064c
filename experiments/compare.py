"""Bring a controller to a committed study: its arm's episodes run, the study's arms come from
the committed run (``peg-sim compare``).

A study's committed run is a directory holding the resolved experiment (``experiment.json``)
and one row per episode (``episodes.csv``): ``docs/<study>/`` in the project, or any sweep's
output directory. :func:`plan_comparison` builds the new arm on the study's grid and seeds
(after ``--set``), finds each of the study's episodes that the comparison needs in the
committed table by its key (the hash of its config), and picks a verification sample: the first
``verify`` episodes of each study arm in key order (keys are hashes: a sample spread over the
cells). :func:`run_comparison` reruns the sample and compares every recorded column but the
wall-clock ones (:data:`~peg_ctrl.run.result.WALL_CLOCK_FIELDS`); a committed episode that no
longer reproduces stops the comparison (:class:`BaselineMismatch`, one line naming the arm and
the column) unless ``rerun_baselines``, which reruns that arm's episodes instead, as it does an
arm whose episodes the committed run lacks (a ``--set`` that changes what the study ran). Then
it runs the new arm and writes the study's tables and report with the new arm in them, led by
its comparison against each study arm (:func:`~peg_ctrl.experiments.report.sections.against_section`).

Layout of ``out_dir``: a sweep's (:mod:`peg_ctrl.experiments.runner`), the committed rows in
its tables, and ``compare.json``: what was compared, the verification sample's outcome and the
arms rerun.
"""

from __future__ import annotations

import dataclasses
import json
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from peg_ctrl.config import apply_overrides, to_dict
from peg_ctrl.environment import ENVIRONMENT_FILE, differences, environment, environment_id
from peg_ctrl.errors import ConfigError
from peg_ctrl.experiments.baseline import (
    Verdict,
    classify,
    classify_arm,
    committed_studies,
    find_study,
    jobs_by_arm,
    match_committed,
    sample_jobs,
    tolerance,
)
from peg_ctrl.experiments.config import (
    ExperimentConfig,
    Job,
    apply_experiment_overrides,
    expand,
    experiment_from_mapping,
)
from peg_ctrl.experiments.report.run_time import add_run_time
from peg_ctrl.experiments.runner import collect_rows, episode_columns, run_jobs, unfinished, write_tables
from peg_ctrl.io import atomic_write_text, lock_output_dir, remove_stale_temps, to_json
from peg_ctrl.run.plugins import is_plugin, load_plugin

__all__ = [
    "BaselineMismatch",
    "Comparison",
    "committed_studies",
    "find_study",
    "plan_comparison",
    "run_comparison",
    "NEW_ARM_MARK",
]

#: Appended to the new controller's label when a study's controller has its name.
NEW_ARM_MARK = "*"


class BaselineMismatch(ConfigError):
    """A study arm's committed episode does not reproduce on this code (exit 2: rerun it with
    ``--rerun-baselines``, or recommit the study)."""


@dataclasses.dataclass(frozen=True)
class Comparison:
    """A new arm against a committed study: what will run and what is taken from the study."""

    study: str  # the study's name
    study_dir: Path
    arm: str  # the new arm's label (controller/strategy)
    controller: dict[str, Any]  # the new controller's config as plain data
    strategy: dict[str, Any] | None  # the new strategy's (None: the task has no strategies)
    plugins: tuple[str, ...]  # the user's files (PATH.py:ClassName) that register them
    assignments: tuple[str, ...]  # --set
    experiment: dict[str, Any]  # the study's experiment after --set
    new_jobs: tuple[Job, ...]
    study_jobs: dict[str, tuple[Job, ...]]  # study arm -> its episodes the comparison needs
    committed: dict[str, dict[str, str]]  # a study job's key -> its committed row (values as text)
    sample: dict[str, tuple[Job, ...]]  # study arm -> the episodes rerun to verify it

    @property
    def missing(self) -> dict[str, int]:
        """Study arm -> how many of its needed episodes the committed run lacks."""
        found = {arm: sum(j.key not in self.committed for j in jobs) for arm, jobs in self.study_jobs.items()}
        return {arm: n for arm, n in found.items() if n}

    def sample_jobs(self, rerun: set[str]) -> list[Job]:
        """The verification sample of the study arms not in ``rerun``."""
        return [j for a, jobs in self.sample.items() if a not in rerun for j in jobs]

    def rerun_jobs(self, rerun: set[str]) -> list[Job]:
        """Every episode of the study arms in ``rerun``, in the study's order."""
        return [j for a, jobs in self.study_jobs.items() if a in rerun for j in jobs]

    def record(self) -> dict[str, Any]:
        """What ``compare.json`` says was compared (a resumed comparison must match it)."""
        return {
            "study": self.study,
            "study_dir": _shown(self.study_dir),
            "arm": self.arm,
            "controller": self.controller,
            "strategy": self.strategy,
            "plugins": list(self.plugins),
            "set": list(self.assignments),
        }


def _shown(path: Path) -> str:
    """``path`` relative to the working directory when it is under it (a record to commit names
    no machine's folders), else as it is."""
    try:
        return str(path.resolve().relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(path)


def _split_assignments(assignments: list[str]) -> tuple[list[str], list[str], list[str]]:
    """``--set``s on the new controller (``controller.*``), its strategy (``strategy.*``) and the
    study's experiment (everything else)."""
    ctrl: list[str] = []
    strat: list[str] = []
    rest: list[str] = []
    for item in assignments:
        key = item.partition("=")[0].strip()
        (ctrl if key.startswith("controller.") else strat if key.startswith("strategy.") else rest).append(
            item
        )
    return ctrl, strat, rest


def _component(value: str, kind: str, plugins: list[str]) -> str:
    """The registered name of ``value``: a name, or ``PATH.py:ClassName`` loaded and registered."""
    if is_plugin(value):
        plugin = load_plugin(value, kind)
        plugins.append(plugin.spec)
        return plugin.name
    return value


def plan_comparison(
    study: str,
    controller: str,
    strategy: str | None = None,
    assignments: list[str] | None = None,
    *,
    verify: int = 1,
) -> Comparison:
    """The comparison of ``controller`` (with ``strategy``) against ``study``'s committed arms.

    Args:
        study: a committed study's name or a run's directory (:func:`find_study`).
        controller: a registered controller name (the study's controller of that name brings its
            fields) or ``PATH.py:ClassName`` (a config in a file).
        strategy: the same for the strategy; needed when the study crosses strategies. A study
            strategy of that name brings its fields.
        assignments: ``--set KEY=VALUE``: ``controller.<field>`` and ``strategy.<field>`` set the
            new arm's fields, any other key the study's experiment (``seeds=2``, a grid key).
        verify: study episodes rerun per arm to check that the committed ones reproduce.

    Raises:
        ConfigError: an unknown study, component or field; a study arm's twin; ``verify`` < 1.
    """
    if verify < 1:
        raise ConfigError(f"--verify must be >= 1, got {verify}")
    study_dir = find_study(study)
    ctrl_sets, strat_sets, exp_sets = _split_assignments(list(assignments or []))
    name, data, study_exp = _study_experiment(study_dir, exp_sets)
    plugins: list[str] = []
    ctrl_spec = _controller_spec(study_exp, controller, ctrl_sets, plugins)
    strategy_spec = _strategy_spec(study_exp, strategy, strat_sets, plugins)
    new_data = {**data, "controllers": [ctrl_spec], "arms": {}}
    new_data["strategies"] = [strategy_spec] if strategy_spec is not None else []
    try:
        new_exp = experiment_from_mapping(new_data)
    except ConfigError as exc:
        raise ConfigError(f"the new arm: {exc}") from None

    study_jobs, new_jobs = _jobs(name, study_exp, new_exp)
    arm = new_jobs[0].arm
    committed = match_committed(study_dir, study_jobs)
    sample = sample_jobs(study_jobs, committed, verify)
    return Comparison(
        study=name,
        study_dir=study_dir,
        arm=arm,
        controller=to_dict(new_exp.controllers[0]),
        strategy=to_dict(new_exp.strategies[0]) if new_exp.strategies else None,
        plugins=tuple(plugins),
        assignments=tuple(assignments or ()),
        experiment=data,
        new_jobs=new_jobs,
        study_jobs=study_jobs,
        committed=committed,
        sample=sample,
    )


def _jobs(
    name: str, study_exp: ExperimentConfig, new_exp: ExperimentConfig
) -> tuple[dict[str, tuple[Job, ...]], tuple[Job, ...]]:
    """The study's episodes by arm, and the new arm's (its controller marked when a study
    controller has its name).

    Raises:
        ConfigError: the new arm's episodes are one of the study arms'.
    """
    study_jobs = jobs_by_arm(study_exp)
    new_ctrl = new_exp.controllers[0]
    mark = NEW_ARM_MARK if any(c.name == new_ctrl.name for c in study_exp.controllers) else ""
    new_jobs = tuple(dataclasses.replace(j, controller_label=new_ctrl.name + mark) for j in expand(new_exp))
    study_keys = {j.key: a for a, jobs in study_jobs.items() for j in jobs}
    same = next((study_keys[j.key] for j in new_jobs if j.key in study_keys), None)
    if same is not None:
        raise ConfigError(
            f"the new arm {new_jobs[0].arm} runs the same episodes as {name}'s arm {same}: nothing to compare"
        )
    return study_jobs, new_jobs


def _study_experiment(study_dir: Path, sets: list[str]) -> tuple[str, dict[str, Any], ExperimentConfig]:
    """The committed study's name, its experiment's plain data after ``sets`` and the experiment."""
    data = json.loads((study_dir / "experiment.json").read_text())
    name = str(data.get("name") or study_dir.name)
    data = apply_experiment_overrides(data, sets)
    try:
        return name, data, experiment_from_mapping(data)
    except ConfigError as exc:
        if sets:
            raise ConfigError(f"study {name} (after --set): {exc}") from None
        raise ConfigError(
            f"study {name}: its committed experiment.json does not load on this code ({exc}): the run "
            f"predates a change of the configs; rerun it (peg-sim sweep {name}) to compare with it"
        ) from None


def _controller_spec(
    exp: ExperimentConfig, controller: str, sets: list[str], plugins: list[str]
) -> dict[str, Any]:
    """The new arm's controller as plain data: the study's controller of that name when it has
    exactly one (its fields), else the registered one's defaults, then ``controller.*`` ``--set``s."""
    name = _component(controller, "controller", plugins)
    theirs = [to_dict(c) for c in exp.controllers if c.name == name]
    return dict(
        apply_overrides({"controller": theirs[0] if len(theirs) == 1 else {"name": name}}, sets)["controller"]
    )


def _strategy_spec(
    exp: ExperimentConfig, strategy: str | None, sets: list[str], plugins: list[str]
) -> dict[str, Any] | None:
    """The new arm's strategy as plain data: the study's strategy of that name (its fields) or
    the registered one's defaults, then ``strategy.*`` ``--set``s."""
    if not exp.strategies:
        if strategy is not None or sets:
            raise ConfigError(f"--strategy: study {exp.name}'s task has no strategies to choose among")
        return None
    if strategy is None:
        raise ConfigError(
            f"--strategy is needed: study {exp.name} crosses strategies ({', '.join(exp.strategy_names)}); "
            "give one of them, another registered one or PATH.py:ClassName"
        )
    name = _component(strategy, "strategy", plugins)
    theirs = next((to_dict(s) for s in exp.strategies if s.name == name), {"name": name})
    return apply_overrides({"strategy": theirs}, sets)["strategy"]


def jobs_to_run(comp: Comparison, rerun: set[str]) -> list[Job]:
    """The verification sample, the study arms in ``rerun`` and the new arm, in that order."""
    return [*comp.sample_jobs(rerun), *comp.rerun_jobs(rerun), *comp.new_jobs]


def run_comparison(
    comp: Comparison,
    out_dir: Path,
    *,
    workers: int = 1,
    rerun_baselines: bool = False,
    progress: bool = True,
    report: bool = True,
) -> list[dict[str, Any]]:
    """Verify the study's committed episodes, run the new arm and write the tables and report
    into ``out_dir`` (resumable like a sweep); returns one row per episode, study arms first.

    Raises:
        BaselineMismatch: a sampled committed episode does not reproduce (and not
            ``rerun_baselines``); the message names the arm, the episode and the column.
        ConfigError: the committed run lacks episodes the comparison needs (and not
            ``rerun_baselines``), or ``out_dir`` holds something else.
        OutputInUse: another process works in ``out_dir``.
    """
    out_dir = Path(out_dir)
    if comp.missing and not rerun_baselines:
        arm, n = next(iter(comp.missing.items()))
        raise ConfigError(
            f"{comp.study}'s committed run lacks {n} of {arm}'s episodes this comparison needs (--set "
            "changed what the study ran?); pass --rerun-baselines to run them"
        )
    out_dir.mkdir(parents=True, exist_ok=True)
    with lock_output_dir(out_dir):
        remove_stale_temps(out_dir)
        _check_same_comparison(out_dir, comp)
        _write_record(out_dir, comp, {}, set())  # first: a stopped comparison resumes as one
        experiment = {**comp.experiment, "name": f"{comp.study}+{comp.arm.split('/')[0]}"}
        atomic_write_text(out_dir / "experiment.json", to_json(experiment, indent=2) + "\n")
        rows = _run_locked(comp, out_dir, workers, rerun_baselines, progress)
        if report:
            from peg_ctrl.experiments.report import write_report

            write_report(out_dir)
        return rows


def _run_locked(
    comp: Comparison, out_dir: Path, workers: int, rerun_baselines: bool, progress: bool
) -> list[dict[str, Any]]:
    """:func:`run_comparison`'s episodes and tables, in the locked ``out_dir``: the
    verification sample, then (once it passes) the arms to rerun and the new arm."""
    rerun = set(comp.missing)
    started, ran = time.perf_counter(), [0]

    def run(jobs: list[Job], desc: str) -> None:
        ran[0] += len(unfinished(jobs, out_dir))  # a resumed comparison with nothing left adds no time
        run_jobs(
            jobs,
            out_dir,
            workers=workers,
            plugins=comp.plugins,
            desc=desc,
            progress=progress,
            record_time=False,  # one invocation: the verification and the new arm together
        )

    try:
        run(comp.sample_jobs(rerun), f"verify {comp.study}")
        verified = _verify(comp, out_dir, rerun, rerun_baselines)  # no tables unless it passes
        _write_record(out_dir, comp, verified, rerun)
        try:
            run([*comp.rerun_jobs(rerun), *comp.new_jobs], f"compare {comp.arm}")
        finally:
            rows = _rows(comp, out_dir, rerun)
            write_tables(rows, out_dir)
    finally:
        if ran[0]:
            add_run_time(out_dir, time.perf_counter() - started)
    return rows


def _verify(comp: Comparison, out_dir: Path, rerun: set[str], rerun_baselines: bool) -> dict[str, Any]:
    """Class each study arm's rerun sample against its committed rows
    (:mod:`~peg_ctrl.experiments.baseline`); an arm that differs is added to ``rerun``
    (``rerun_baselines``) or stops the comparison. Returns, per arm checked, its sample's keys,
    its class and what decided it."""
    verified = {}
    for arm, jobs in comp.sample.items():
        if arm in rerun:
            continue
        tol = tolerance(comp.study, arm)
        verdicts = [classify(comp.committed[j.key], collect_rows([j], out_dir)[0], tol) for j in jobs]
        worst = classify_arm(verdicts)
        verified[arm] = {
            "episodes": [j.key for j in jobs],
            "class": worst.cls,
            "detail": worst.detail(),
            "tolerance": tol.source,
            "reproduced": worst.cls == "reproduced",
        }
        if worst.cls == "differs" and not rerun_baselines:
            job = jobs[verdicts.index(worst)]
            raise BaselineMismatch(_mismatch_line(comp, arm, job, worst))
        if worst.cls == "differs":
            rerun.add(arm)
    return verified


def _mismatch_line(comp: Comparison, arm: str, job: Job, verdict: Verdict) -> str:
    where = ", ".join(f"{k}={v}" for k, v in job.cell.items())
    return (
        f"{comp.study}'s committed {arm} differs: episode {job.key} (seed {job.seed}"
        f"{', ' + where if where else ''}) {verdict.detail()}; pass --rerun-baselines to rerun that arm, "
        "or recommit the study"
    )


def study_environment_differences(study_dir: Path) -> list[str]:
    """What differs between the environment that made the study (its ``environment.json``) and
    this one; ``["unknown: ..."]`` when the study does not record it."""
    path = study_dir / ENVIRONMENT_FILE
    if not path.is_file():
        return [f"unknown: {study_dir.name} records no environment (no {ENVIRONMENT_FILE})"]
    recorded = json.loads(path.read_text())
    mine = environment()
    found = [differences(record, mine) for record in recorded.values()]
    return min(found, key=len) if found else []


def _write_record(out_dir: Path, comp: Comparison, verified: dict[str, Any], rerun: set[str]) -> None:
    record = {
        **comp.record(),
        "environment": {
            "here": environment_id(),
            "differences": study_environment_differences(comp.study_dir),
        },
        "verified": verified,
        "rerun": sorted(rerun),
    }
    atomic_write_text(out_dir / "compare.json", to_json(record, indent=2) + "\n")


def _check_same_comparison(out_dir: Path, comp: Comparison) -> None:
    path = out_dir / "compare.json"
    if path.is_file():
        mine = {k: v for k, v in json.loads(to_json(comp.record())).items() if k != "study_dir"}
        before = {k: v for k, v in json.loads(path.read_text()).items() if k in mine}
        if before != mine:
            raise ConfigError(
                f"{out_dir} holds another comparison ({before.get('arm')} against {before.get('study')}); "
                "choose another --out"
            )
    elif (out_dir / "experiment.json").is_file():
        raise ConfigError(f"{out_dir} holds a sweep, not a comparison; choose another --out")


def _rows(comp: Comparison, out_dir: Path, rerun: set[str]) -> list[dict[str, Any]]:
    """The tables' rows: each study arm's (committed, or rerun here) in the study's job order,
    then the new arm's finished episodes."""
    ran = collect_rows([*comp.rerun_jobs(rerun), *comp.new_jobs], out_dir)
    templates = [*ran, *collect_rows(comp.sample_jobs(set()), out_dir)]
    parse = _parsers(templates)
    by_key = {row["key"]: row for row in ran}
    # Every row with the columns of this code and this grid: a committed row may lack a column
    # added since, or keep one removed since, or that of an axis a --set fixed.
    names = [*episode_columns(), *comp.new_jobs[0].cell]
    rows = []
    for a, jobs in comp.study_jobs.items():
        for job in jobs:
            if a in rerun:
                if job.key in by_key:
                    rows.append(by_key[job.key])
            else:
                row = comp.committed[job.key]
                rows.append({k: parse.get(k, _guess)(row.get(k, "")) for k in names})
    return rows + [by_key[j.key] for j in comp.new_jobs if j.key in by_key]


def _parsers(rows: list[dict[str, Any]]) -> dict[str, Callable[[str], Any]]:
    """Per column, how to read its CSV text back into the type the fresh rows have."""
    kinds: dict[str, type] = {}
    for row in rows:
        for k, v in row.items():
            if v is not None:
                kinds.setdefault(k, type(v))

    def reader(kind: type) -> Callable[[str], Any]:
        def read(text: str) -> Any:
            if text == "":
                return None
            if kind is bool:
                return text == "True"
            if kind is int and text.lstrip("-").isdigit():
                return int(text)
            return float(text) if kind in (int, float) else text

        return read

    return {k: reader(kind) for k, kind in kinds.items()}


def _guess(text: str) -> Any:
    if text == "":
        return None
    try:
        return float(text)
    except ValueError:
        return text
