"""Measure what moves a committed study's episodes, and calibrate the rule that tells a last-bit
difference from a changed baseline (docs/reproducibility.md).

``python -m peg_ctrl.experiments.reproduction``:

- ``calibrate STUDY...``: reruns each study arm's first :data:`PER_ARM` episodes (the ones
  ``compare`` samples) with the gripper's start moved by each of :data:`PERTURBATIONS` metres
  (``PEG_CTRL_START_PERTURBATION``), and records per arm and column how far the reruns drift
  from the committed episodes, and which outcomes changed, into ``peg_ctrl/data/reproduction.json``
  (merged: other studies' arms are kept). :mod:`~peg_ctrl.experiments.baseline` derives the
  tolerance from it.
- ``dispatch STUDY``: reruns the same sample under each of :data:`SETTINGS` (another CPU
  emulated on this one: the BLAS kernels, numpy's SIMD, the C library's maths, threads) and
  classes every arm against the committed run: which setting moves which arm, how far.
- ``power STUDY --arm ARM``: the sample rerun with the arm's controller gains scaled by each of
  :data:`POWER_FACTORS`, classed under the rule: the smallest change of a baseline it catches.
- ``heldout STUDY...``: the sample rerun with start perturbations the calibration did not use:
  the rule must class every one "reproduced" or "agrees".
- ``record STUDY...``: the sample rerun unperturbed; where every arm reproduces bit for bit,
  this environment is written into the study's ``environment.json`` as one that reproduces it.

Each writes into ``--scratch`` (episodes, resumable) and prints a markdown table.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import os
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from peg_ctrl.environment import ENVIRONMENT_FILE, PERTURBATION_VARIABLE, environment
from peg_ctrl.errors import ConfigError
from peg_ctrl.experiments.baseline import (
    FACTOR,
    Tolerance,
    calibration_path,
    classify,
    classify_arm,
    differences,
    find_study,
    jobs_by_arm,
    load_calibration,
    match_committed,
    sample_jobs,
    tolerance,
)
from peg_ctrl.experiments.config import Job, experiment_from_mapping
from peg_ctrl.experiments.runner import collect_rows, run_jobs
from peg_ctrl.io import atomic_write_text, to_json

__all__ = ["PER_ARM", "PERTURBATIONS", "SETTINGS", "POWER_FACTORS", "calibrate", "dispatch", "power", "main"]

#: Episodes per study arm the calibration reruns (the first by key: compare's sample among them).
PER_ARM = 2
#: The start perturbations of the calibration [m].
PERTURBATIONS = (1e-12, -1e-12, 1e-10)
#: Held out of the calibration, to check the rule on perturbations it was not derived from [m]
#: (on compare's sample and on an episode the calibration never ran). A first rule (the median
#: arm's drift as the floor) failed on 3e-12 and -1e-10 (docs/reproducibility.md); these came after.
HELD_OUT = {1: (5e-12, -3e-11), 2: (7e-12, -7e-11)}
#: Another CPU emulated on this one: the environment each setting runs under (None: unset).
_KEEP: dict[str, str | None] = {"PEG_CTRL_BLAS": "keep"}  # peg_ctrl does not pin the BLAS kernels
SETTINGS: dict[str, dict[str, str | None]] = {
    "as it is (peg_ctrl pins SkylakeX kernels on AVX-512)": {},
    "this machine's environment unpinned (PEG_CTRL_BLAS=keep)": _KEEP,
    "OpenBLAS picks by the CPU (no OPENBLAS_CORETYPE, no pin)": {**_KEEP, "OPENBLAS_CORETYPE": None},
    "OpenBLAS Haswell kernels (AVX2, FMA)": {**_KEEP, "OPENBLAS_CORETYPE": "Haswell"},
    "OpenBLAS Zen kernels": {**_KEEP, "OPENBLAS_CORETYPE": "Zen"},
    "OpenBLAS Sandybridge kernels (AVX, no FMA)": {**_KEEP, "OPENBLAS_CORETYPE": "Sandybridge"},
    "numpy without AVX-512": {"NPY_DISABLE_CPU_FEATURES": "X86_V4 AVX512_ICL AVX512_SPR"},
    "numpy without AVX2 and AVX-512": {"NPY_DISABLE_CPU_FEATURES": "X86_V3 X86_V4 AVX512_ICL AVX512_SPR"},
    "the C library's maths without AVX2 and FMA": {"GLIBC_TUNABLES": "glibc.cpu.hwcaps=-AVX2,-FMA"},
    "the C library without AVX-512": {"GLIBC_TUNABLES": "glibc.cpu.hwcaps=-AVX512F"},
    "2 BLAS threads": {"OPENBLAS_NUM_THREADS": "2"},
}
#: The controller gains scaled by these factors in ``power``.
POWER_FACTORS = (1.0001, 1.001, 1.01, 1.05, 1.2)
#: The columns the tables report the drift of.
DRIFT_COLUMNS = (
    "peak_force_10ms_n",
    "peak_contact_force_n",
    "contact_to_seat_s",
    "time_to_insert_s",
    "total_timesteps",
)


@dataclasses.dataclass(frozen=True)
class Study:
    """A committed study's arms, their sample and the committed rows."""

    name: str
    directory: Path
    sample: dict[str, tuple[Job, ...]]
    committed: dict[str, dict[str, str]]


def load_study(study: str, per_arm: int) -> Study:
    directory = find_study(study)
    data = json.loads((directory / "experiment.json").read_text())
    jobs = jobs_by_arm(experiment_from_mapping(data))
    committed = match_committed(directory, jobs)
    name = str(data.get("name") or directory.name)
    return Study(name, directory, sample_jobs(jobs, committed, per_arm), committed)


@contextlib.contextmanager
def _environ(changes: dict[str, str | None]) -> Iterator[None]:
    """``os.environ`` changed for the workers spawned inside (each starts a new interpreter)."""

    def apply(values: dict[str, str | None]) -> None:
        for k, v in values.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v

    before = {k: os.environ.get(k) for k in changes}
    try:
        apply(changes)
        yield
    finally:
        apply(before)


def rerun(jobs: list[Job], out: Path, changes: dict[str, str | None], workers: int, desc: str) -> None:
    """The ``jobs`` run into ``out`` under the environment ``changes`` (finished ones skipped)."""
    out.mkdir(parents=True, exist_ok=True)
    setting = out / "setting.json"
    if setting.is_file() and json.loads(setting.read_text()) != json.loads(to_json(changes)):
        raise ConfigError(
            f"{out} holds episodes run under {setting.read_text().strip()}; choose another --scratch"
        )
    setting.write_text(to_json(changes) + "\n")
    inherited = os.environ.get("PEG_CTRL_BLAS_OVERRODE")  # this process's own pin replaced it
    if changes.get("PEG_CTRL_BLAS") == "keep" and "OPENBLAS_CORETYPE" not in changes and inherited:
        changes = {**changes, "OPENBLAS_CORETYPE": inherited}
    with _environ(changes):
        run_jobs(jobs, out, workers=workers, desc=desc, progress=sys.stderr.isatty(), record_time=False)


def _drift(committed: dict[str, str], fresh: dict[str, Any]) -> tuple[dict[str, float], set[str]]:
    """Per numeric column the absolute change; the columns whose text or presence changed."""
    numbers: dict[str, float] = {}
    changed: set[str] = set()
    for column, was, now in differences(committed, fresh):
        try:
            numbers[column] = abs(float(now) - float(was))
        except ValueError:
            changed.add(column)
    return numbers, changed


def calibrate(studies: list[str], scratch: Path, workers: int, path: Path | None = None) -> dict[str, Any]:
    """Measure each study arm's drift under :data:`PERTURBATIONS` and merge it into the
    calibration at ``path`` (default: the packaged ``reproduction.json``)."""
    path = path or calibration_path()
    data = load_calibration(path) or {"factor": FACTOR, "studies": {}}
    data.update(
        {
            "factor": FACTOR,
            "per_arm": PER_ARM,
            "perturbations_m": list(PERTURBATIONS),
            "environment": environment(),
        }
    )
    for name in studies:
        study = load_study(name, PER_ARM)
        jobs = [j for js in study.sample.values() for j in js]
        arms: dict[str, dict[str, Any]] = {}
        for delta in PERTURBATIONS:
            out = scratch / study.name / f"start{delta:+.0e}"
            rerun(jobs, out, {PERTURBATION_VARIABLE: repr(delta)}, workers, f"{study.name} {delta:+.0e} m")
            for arm, arm_jobs in study.sample.items():
                entry = arms.setdefault(arm, {"drift": {}, "may_change": set(), "episodes": 0, "moved": 0})
                for job in arm_jobs:
                    numbers, changed = _drift(study.committed[job.key], collect_rows([job], out)[0])
                    for column, d in numbers.items():
                        entry["drift"][column] = max(entry["drift"].get(column, 0.0), d)
                    entry["may_change"] |= changed
                    entry["episodes"] += 1
                    entry["moved"] += bool(numbers or changed)
        data["studies"][study.name] = {
            arm: {**e, "may_change": sorted(e["may_change"]), "drift": dict(sorted(e["drift"].items()))}
            for arm, e in arms.items()
        }
        atomic_write_text(path, to_json(data, indent=2) + "\n")  # each study as it is measured
    return data


def classed(study: Study, out: Path, tol_of: Any = None) -> dict[str, dict[str, Any]]:
    """Each arm's class of its sample rerun into ``out``, with its drift in :data:`DRIFT_COLUMNS`."""
    found = {}
    for arm, jobs in study.sample.items():
        tol: Tolerance = tol_of(arm) if tol_of else tolerance(study.name, arm)
        fresh = collect_rows(list(jobs), out)
        verdicts = [classify(study.committed[j.key], f, tol) for j, f in zip(jobs, fresh, strict=True)]
        drift: dict[str, float] = {}
        for job, f in zip(jobs, fresh, strict=True):
            for column, d in _drift(study.committed[job.key], f)[0].items():
                drift[column] = max(drift.get(column, 0.0), d)
        worst = classify_arm(verdicts)
        found[arm] = {"class": worst.cls, "detail": worst.detail(), "drift": drift}
    return found


def dispatch(study_name: str, scratch: Path, workers: int, settings: list[str] | None = None) -> list[str]:
    """Rerun ``study_name``'s first episode of each arm under each setting; a markdown table."""
    study = load_study(study_name, 1)
    jobs = [j for js in study.sample.values() for j in js]
    lines = [
        f"| setting ({study.name}, first episode of each arm) | moved | reproduced | agrees | differs "
        "| largest move: force 10 ms [N], contact to seated [s] |",
        "|---|---|---|---|---|---|",
    ]
    for name in settings or list(SETTINGS):
        out = scratch / study.name / f"setting{list(SETTINGS).index(name):02d}"
        rerun(jobs, out, SETTINGS[name], workers, name)
        result = classed(study, out)
        moved = [a for a, r in result.items() if r["class"] != "reproduced"]
        by = {c: sum(r["class"] == c for r in result.values()) for c in ("reproduced", "agrees", "differs")}
        force = max((r["drift"].get("peak_force_10ms_n", 0.0) for r in result.values()), default=0.0)
        seat = max((r["drift"].get("contact_to_seat_s", 0.0) for r in result.values()), default=0.0)
        counts = f"{by['reproduced']} | {by['agrees']} | {by['differs']}"
        lines.append(f"| {name} | {', '.join(moved) or 'none'} | {counts} | {force:.3g}, {seat:.3g} |")
        print(lines[-1], flush=True)
        (scratch / study.name / f"setting{list(SETTINGS).index(name):02d}.json").write_text(
            to_json({"setting": name, "changes": SETTINGS[name], "arms": result}, indent=2) + "\n"
        )
    return lines


def _scaled(job: Job, factor: float) -> Job:
    """``job`` with its controller's gains (its ``GAINS`` fields, nested configs' included) scaled."""
    ctrl = job.config.controller
    if not ctrl.GAINS and ctrl.scaled(2.0) == ctrl:
        raise ConfigError(f"controller {ctrl.name} declares no gains (GAINS) to scale")
    config = dataclasses.replace(job.config, controller=ctrl.scaled(factor))
    return dataclasses.replace(job, config=config, key=f"{job.key}-x{factor:g}")


def power(study_name: str, arm: str, scratch: Path, workers: int, per_arm: int = 1) -> list[str]:
    """Rerun ``arm``'s compare sample with its controller's gains scaled; a markdown table of the
    classes the rule gives (the committed rows stand for the baseline the user compares with)."""
    study = load_study(study_name, per_arm)
    if arm not in study.sample:
        raise ConfigError(f"arm {arm!r}: {study.name} has {', '.join(study.sample)}")
    lines = [
        f"| {study.name} {arm}: gains x | class | what decided it |",
        "|---|---|---|",
    ]
    tol = tolerance(study.name, arm)
    for factor in POWER_FACTORS:
        jobs = [_scaled(j, factor) for j in study.sample[arm]]
        out = scratch / study.name / arm.replace("/", "_") / f"x{factor:g}"
        rerun(jobs, out, {}, workers, f"{arm} x{factor:g}")
        verdicts = [
            classify(study.committed[orig.key], collect_rows([j], out)[0], tol)
            for orig, j in zip(study.sample[arm], jobs, strict=True)
        ]
        worst = classify_arm(verdicts)
        lines.append(f"| {factor:g} | {worst.cls} | {worst.detail()} |")
        print(lines[-1], flush=True)
    return lines


def heldout(studies: list[str], scratch: Path, workers: int, round_: int = 2) -> list[str]:
    """compare's sample and an episode the calibration never ran (the ``PER_ARM + round_``-th by
    key), rerun with :data:`HELD_OUT`'s perturbations of that round, classed."""
    lines = [
        "| study (arms x 2 episodes) | start moved by [m] | reproduced | agrees | differs | differing arms |",
        "|---|---|---|---|---|---|",
    ]
    for name in studies:
        every = load_study(name, PER_ARM + round_)
        # compare's sample (the first by key) and one the calibration did not run
        picked = {a: (js[0], *js[PER_ARM + round_ - 1 :]) for a, js in every.sample.items()}
        study = dataclasses.replace(every, sample=picked)
        jobs = [j for js in study.sample.values() for j in js]
        for delta in HELD_OUT[round_]:
            out = scratch / study.name / f"heldout{delta:+.0e}"
            rerun(jobs, out, {PERTURBATION_VARIABLE: repr(delta)}, workers, f"{study.name} {delta:+.0e} m")
            result = classed(study, out)
            by = {
                c: [a for a, r in result.items() if r["class"] == c]
                for c in ("reproduced", "agrees", "differs")
            }
            differing = "; ".join(a + ": " + result[a]["detail"] for a in by["differs"]) or "-"
            lines.append(
                f"| {study.name} | {delta:+.0e} | {len(by['reproduced'])} | {len(by['agrees'])} | "
                f"{len(by['differs'])} | {differing} |"
            )
            print(lines[-1], flush=True)
    return lines


def record(studies: list[str], scratch: Path, workers: int) -> list[str]:
    """Rerun each study's compare sample here; where every arm reproduces bit for bit, write this
    environment into the study's ``environment.json`` as one that reproduces it (for studies whose
    episodes were made before runs recorded their environment). Returns a line per study.

    Raises:
        ConfigError: an arm does not reproduce: this environment cannot stand for the study's.
    """
    lines = []
    for name in studies:
        study = load_study(name, 1)
        out = scratch / study.name / "record"
        rerun([j for js in study.sample.values() for j in js], out, {}, workers, f"{study.name} here")
        result = classed(study, out, lambda arm: Tolerance({}, frozenset(), "bit for bit"))
        moved = [f"{a} ({r['detail']})" for a, r in result.items() if r["class"] != "reproduced"]
        if moved:
            raise ConfigError(f"{study.name}: not reproduced here: {'; '.join(moved)}")
        env = json.loads((out / ENVIRONMENT_FILE).read_text())
        for entry in env.values():
            entry["reproduced"] = (
                f"{len(result)} episodes, one per arm, reproduced bit for bit in this environment "
                f"({time.strftime('%Y-%m-%d')}); the study's episodes predate recorded environments"
            )
        atomic_write_text(study.directory / ENVIRONMENT_FILE, to_json(env, indent=2) + "\n")
        lines.append(
            f"{study.name}: {len(result)} arms reproduced; wrote {study.directory / ENVIRONMENT_FILE}"
        )
        print(lines[-1], flush=True)
    return lines


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m peg_ctrl.experiments.reproduction", description=__doc__)
    parser.add_argument("what", choices=("calibrate", "dispatch", "power", "heldout", "record"))
    parser.add_argument("studies", nargs="+", help="committed studies' names or directories")
    parser.add_argument("--scratch", type=Path, default=Path("runs/reproduction"), help="where episodes run")
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--arm", help="power: the study arm whose gains are scaled")
    parser.add_argument("--round", type=int, default=2, choices=sorted(HELD_OUT), help="heldout: which")
    parser.add_argument("--setting", action="append", choices=list(SETTINGS), help="dispatch: only these")
    args = parser.parse_args(argv)
    started = time.perf_counter()
    try:
        if args.what == "calibrate":
            calibrate(args.studies, args.scratch, args.workers)
        elif args.what == "dispatch":
            for study in args.studies:
                print("\n".join(dispatch(study, args.scratch, args.workers, args.setting)))
        elif args.what == "power":
            if not args.arm:
                raise ConfigError("power needs --arm ARM")
            print("\n".join(power(args.studies[0], args.arm, args.scratch, args.workers)))
        elif args.what == "record":
            record(args.studies, args.scratch, args.workers)
        else:
            print("\n".join(heldout(args.studies, args.scratch, args.workers, args.round)))
    except ConfigError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"{time.perf_counter() - started:.0f} s", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
