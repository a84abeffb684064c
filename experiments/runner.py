"""Run an experiment: every episode in parallel, resumable, then tables, plots and a report.

Layout of ``out_dir``::

    experiment.json         the resolved experiment (every default filled in)
    episodes/<key>/         one episode: summary.json, config.json, log.jsonl, forces.npz
    episodes.csv/.parquet   one row per episode: the arm (controller/strategy), the varied values
                            (clearance, seed, grid cells) and every column of summary.json that
                            the episode record declares (peg_ctrl.run.result)
    summary.csv             per arm x planner x clearance: success rate with a 95 % Wilson
                            interval, the metrics the record declares a summary for (peak force
                            median / p95, time to insert, ...), failure reasons
    run_time.json           the sweep's run time, summed over the invocations that ran episodes
    report.md, *.png        the tables and plots

An episode whose ``summary.json`` exists (and was not interrupted) is done: rerunning the same
command skips it, so an interrupted sweep resumes where it stopped. Results are assembled from
those files in the experiment's fixed job order, so the number of workers does not change them.
"""

from __future__ import annotations

import concurrent.futures as futures
import contextlib
import dataclasses
import json
import time
from collections.abc import Callable, Generator
from pathlib import Path
from typing import Any

from peg_ctrl.config import to_dict
from peg_ctrl.environment import ENVIRONMENT_FILE, environment
from peg_ctrl.errors import ConfigError, UnknownComponent
from peg_ctrl.experiments.config import ExperimentConfig, Job, expand, job_config, job_config_mapping
from peg_ctrl.io import atomic_path, atomic_write_text, lock_output_dir, remove_stale_temps, to_json
from peg_ctrl.run.result import result_columns
from peg_ctrl.run.workers import worker_pool

__all__ = [
    "run_sweep",
    "run_jobs",
    "record_environments",
    "unfinished",
    "collect_rows",
    "refresh_tables",
    "bench_sweep",
    "finished_summaries",
    "check_same_experiment",
    "experiment_text",
    "EPISODE_COLUMNS",
    "episode_columns",
    "BACKENDS",
]

# episodes.csv's columns of the experiment's job, before and after the episode record's own.
_JOB_COLUMNS = (
    "key",
    "arm",
    "controller",
    "controller_name",
    "task",
    "strategy",
    "planner",
    "clearance_m",
    "seed",
    "peg_mass_scale",
    "friction_scale",
    "gain_scale",
)
_LAST_COLUMNS = ("log_path",)


def episode_columns() -> tuple[str, ...]:
    """The columns of ``episodes.csv`` (before the experiment's grid keys): the job's, then
    every column the episode record declares (:func:`~peg_ctrl.run.result.result_columns`, in
    its field order), then the episode's log."""
    return (*_JOB_COLUMNS, *result_columns(), *_LAST_COLUMNS)


EPISODE_COLUMNS = episode_columns()


# One episode for a worker: its key, its config as plain data, its directory, and the user's
# files (PATH.py:ClassName) that register the controllers and strategies it names.
_Task = tuple[str, dict[str, Any], str, tuple[str, ...]]


def _run_one(args: _Task) -> dict[str, Any]:
    """Worker: one episode (the compiled model is cached per worker and scene)."""
    from peg_ctrl.run.episode import run_episode
    from peg_ctrl.run.plugins import load_plugins

    key, data, out, plugins = args
    load_plugins(plugins)  # once per worker and file: a spawned worker has only the package's
    result = run_episode(job_config(data), Path(out), plot=False).to_dict()
    result["key"] = key
    result["environment_record"] = environment()  # the worker's: it ran the episode
    return result


def _warm_up(scene_data: dict[str, Any]) -> float:
    """Worker: import everything and compile the scene once; returns the time it took [s]."""
    t0 = time.perf_counter()
    from peg_ctrl.run.episode import compiled_model, episode_config_from_mapping

    cfg = episode_config_from_mapping(scene_data)
    compiled_model(cfg.scene, cfg.physics.resolved())
    return time.perf_counter() - t0


def bench_sweep(n_episodes: int = 6, *, workers: tuple[int, ...] = (1, 2)) -> dict[str, Any]:
    """Wall time of the same ``n_episodes`` on warm pools of 1 and 2 workers, and the speedup.

    Pools are started and warmed up (imports, model compiled) before the clock starts, so the
    ratio measures how the episodes themselves scale.
    """
    import tempfile

    from peg_ctrl.experiments.config import experiment_from_mapping

    exp = experiment_from_mapping({"name": "bench", "controllers": ["pd"], "seeds": n_episodes})
    jobs = expand(exp)
    times: dict[int, float] = {}
    for n in workers:
        with tempfile.TemporaryDirectory() as tmp, worker_pool(n) as pool:
            list(pool.map(_warm_up, [job_config_mapping(jobs[0])] * n))
            tasks = [(j.key, job_config_mapping(j), str(Path(tmp) / j.key), ()) for j in jobs]
            t0 = time.perf_counter()
            results = list(pool.map(_run_one, tasks))
            times[n] = time.perf_counter() - t0
            if not all(r["status"] == "success" for r in results):
                raise RuntimeError("benchmark episodes failed; the timing is not representative")
    return {
        "what": "sweep",
        "episodes": n_episodes,
        "wall_s": {str(k): v for k, v in times.items()},
        "speedup_2_vs_1": times[1] / times[2] if 1 in times and 2 in times else None,
        "target": "speedup_2_vs_1 >= 1.9",
    }


def _finished(out: Path) -> dict[str, Any] | None:
    """The summary of the episode in ``out`` if it finished, else None. The first summary,
    written the moment the episode ends, still points at ``forces.partial``; the final one,
    written once the trace and states are packed, at ``forces.npz``. An episode killed in
    between runs again."""
    path = out / "summary.json"
    if not path.is_file():
        return None
    try:
        summary = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError):
        return None
    if not isinstance(summary, dict):
        return None
    finished = summary.get("status") in ("success", "failure") and not str(
        summary.get("trace_path", "")
    ).endswith(".partial")
    return summary if finished else None


def _done(out: Path) -> bool:
    """Whether the episode in ``out`` finished: its final summary is there (see :func:`_finished`)."""
    return _finished(out) is not None


def finished_summaries(out_dir: Path) -> dict[str, dict[str, Any]]:
    """The finished episodes in ``out_dir/episodes``: key -> ``summary.json``; empty when there
    are none (or no ``out_dir``). Nothing is written."""
    root = Path(out_dir) / "episodes"
    if not root.is_dir():
        return {}
    found = {}
    for path in sorted(root.iterdir()):
        summary = _finished(path) if path.is_dir() else None
        if summary is not None:
            found[path.name] = summary
    return found


def experiment_text(exp: ExperimentConfig) -> str:
    """The resolved experiment as the sweep saves it in ``experiment.json``."""
    return to_json(to_dict(exp), indent=2, sort_keys=True) + "\n"


def check_same_experiment(out_dir: Path, exp: ExperimentConfig) -> None:
    """Refuse an ``out_dir`` that holds the results of another experiment.

    Raises:
        ConfigError: ``out_dir/experiment.json`` exists and is not ``exp``'s.
    """
    saved = Path(out_dir) / "experiment.json"
    if saved.is_file() and saved.read_text() != experiment_text(exp):
        raise ConfigError(
            f"{out_dir} holds results of a different experiment; use another --out or delete it"
        )


# A backend's results as they finish; closed early, it stops its work.
_Stream = Generator[dict[str, Any], None, None]


def _local_backend(tasks: list[_Task], workers: int) -> _Stream:
    # Closing this generator early (Ctrl-C, an error) ends the workers and starts no queued
    # episode; they also die with this process (peg_ctrl.run.workers).
    if not tasks:
        return
    with worker_pool(min(workers, len(tasks))) as pool:
        pending = [pool.submit(_run_one, t) for t in tasks]
        for fut in futures.as_completed(pending):
            yield fut.result()


def _ray_backend(tasks: list[_Task], workers: int, address: str | None) -> _Stream:
    try:
        import ray
    except ImportError:
        raise RuntimeError(
            "the ray backend needs Ray: pip install 'peg-ctrl[ray]' (or pip install ray)"
        ) from None
    if not ray.is_initialized():
        ray.init(address=address, num_cpus=None if address else workers, log_to_driver=False)
    remote = ray.remote(num_cpus=1)(_run_one)
    refs = [remote.remote(t) for t in tasks]
    while refs:
        ready, refs = ray.wait(refs, num_returns=1)
        yield ray.get(ready[0])


BACKENDS: dict[str, Callable[..., _Stream]] = {
    "local": _local_backend,
    "ray": _ray_backend,
}


def run_sweep(
    exp: ExperimentConfig,
    out_dir: Path,
    *,
    workers: int = 1,
    backend: str = "local",
    address: str | None = None,
    progress: bool = True,
    report: bool = True,
    plugins: tuple[str, ...] = (),
) -> list[dict[str, Any]]:
    """Run (or resume) ``exp`` into ``out_dir``; returns one row per episode, in job order.

    ``out_dir`` is locked while the sweep runs (:func:`~peg_ctrl.io.lock_output_dir`). Ctrl-C
    (or any exception) cancels the episodes not started and ends the running ones, which run
    again on resume; the finished episodes' tables are written either way. ``plugins``: the
    user's files (``PATH.py:ClassName``, :mod:`peg_ctrl.run.plugins`) that register controllers
    or strategies the experiment names; every worker loads them.

    Raises:
        OutputInUse: another process is running a sweep (or a run) in ``out_dir``.
        ConfigError: ``out_dir`` holds another experiment, or an argument is invalid.
    """
    _check_backend(backend, workers)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    jobs = expand(exp)  # before anything is written: a bad experiment leaves nothing behind
    with lock_output_dir(out_dir):
        remove_stale_temps(out_dir)  # left by a sweep killed while writing its tables or plots
        check_same_experiment(out_dir, exp)
        atomic_write_text(out_dir / "experiment.json", experiment_text(exp))
        try:
            run_jobs(
                jobs,
                out_dir,
                workers=workers,
                backend=backend,
                address=address,
                plugins=plugins,
                desc=f"sweep {exp.name}",
                progress=progress,
            )
        finally:
            # Whatever stopped the sweep (Ctrl-C, a crashed worker), the finished episodes'
            # tables are written; the report only for a complete sweep.
            rows = collect_rows(jobs, out_dir)
            write_tables(rows, out_dir)
        if report:
            from peg_ctrl.experiments.report import write_report

            write_report(out_dir)
        return rows


def _check_backend(backend: str, workers: int) -> None:
    if backend not in BACKENDS:
        raise UnknownComponent("backend", backend, BACKENDS)
    if workers < 1:
        raise ConfigError(f"workers must be >= 1, got {workers}")


def unfinished(jobs: list[Job], out_dir: Path) -> list[Job]:
    """The ``jobs`` whose episode in ``out_dir/episodes/<key>`` has not finished."""
    return [job for job in jobs if _finished(out_dir / "episodes" / job.key) is None]


def run_jobs(
    jobs: list[Job],
    out_dir: Path,
    *,
    workers: int = 1,
    backend: str = "local",
    address: str | None = None,
    plugins: tuple[str, ...] = (),
    desc: str = "episodes",
    progress: bool = True,
    record_time: bool = True,
) -> int:
    """Run the ``jobs`` not finished in ``out_dir/episodes/<key>``, with a progress bar; the
    time spent is added to ``out_dir``'s run time as an invocation (unless not ``record_time``:
    the caller adds it). The caller holds ``out_dir``'s lock. Returns how many episodes ran."""
    from peg_ctrl.progress import progress_bar

    _check_backend(backend, workers)
    tasks: list[_Task] = []
    wins = 0  # of the episodes done, before and now
    for job in jobs:
        summary = _finished(out_dir / "episodes" / job.key)
        if summary is None:
            tasks.append((job.key, job_config_mapping(job), str(out_dir / "episodes" / job.key), plugins))
        else:
            wins += summary["status"] == "success"
    started = time.perf_counter()
    seen: dict[str, dict[str, Any]] = {}  # the environments that ran episodes now, by id
    try:
        with progress_bar(
            total=len(jobs),
            initial=len(jobs) - len(tasks),
            desc=desc,
            unit="ep",
            enabled=progress,
            lines="episodes",
            postfix=f"{wins} inserted",
        ) as bar:
            runner = BACKENDS[backend]
            stream = runner(tasks, workers, address) if backend == "ray" else runner(tasks, workers)
            # closing(): an exception here reaches the backend now (it ends its workers), not
            # whenever the suspended generator is collected.
            with contextlib.closing(stream):
                for result in stream:
                    seen.setdefault(result["environment"], result.pop("environment_record"))
                    wins += result["status"] == "success"
                    bar.set_postfix_str(f"{wins} inserted", refresh=False)
                    bar.update(1)
    finally:
        record_environments(out_dir, seen)
        if tasks and record_time:  # a resumed sweep's run time is the sum over its invocations
            from peg_ctrl.experiments.report.run_time import add_run_time

            add_run_time(out_dir, time.perf_counter() - started)
    return len(tasks)


def record_environments(out_dir: Path, seen: dict[str, dict[str, Any]]) -> None:
    """Add the environments in ``seen`` (id -> record, :mod:`peg_ctrl.environment`) to
    ``out_dir/environment.json``, which keeps every environment that ran one of its episodes
    (each episode's summary names its own by id)."""
    path = out_dir / ENVIRONMENT_FILE
    known = json.loads(path.read_text()) if path.is_file() else {}
    if set(seen) <= set(known):
        return
    atomic_write_text(path, to_json({**known, **seen}, indent=2) + "\n")


def collect_rows(jobs: list[Job], out_dir: Path) -> list[dict[str, Any]]:
    """One row per finished episode, in job order, from the episodes' ``summary.json``."""
    from peg_ctrl.run.episode import domain_draw

    record = result_columns()
    rows = []
    for job in jobs:
        path = out_dir / "episodes" / job.key / "summary.json"
        if not _done(path.parent):
            continue
        s = json.loads(path.read_text())
        draw = dataclasses.asdict(domain_draw(job.config.seed, job.config.domain))
        rows.append(
            {
                "key": job.key,
                "arm": job.arm,
                "controller": job.controller_label,
                "controller_name": job.controller,
                "task": job.config.task.name,
                "strategy": job.strategy,
                "planner": job.planner,
                "clearance_m": job.clearance,
                "seed": job.seed,
                **draw,
                **{name: s.get(name) for name in record},
                # The job knows it whether or not the summary (an older run's) records it.
                "friction_time_s": job.config.physics.friction_time,
                "log_path": str(Path("episodes") / job.key / "log.jsonl"),
                **job.cell,
            }
        )
    return rows


def _rows_from_summaries(out_dir: Path) -> tuple[list[dict[str, Any]], int] | str:
    """The rows :func:`collect_rows` makes from ``out_dir``'s saved experiment and episode
    summaries, and the number of jobs; or why they cannot be made."""
    from peg_ctrl.experiments.config import experiment_from_mapping

    saved = out_dir / "experiment.json"
    if not saved.is_file():
        return f"there is no {saved}"
    try:
        jobs = expand(experiment_from_mapping(json.loads(saved.read_text())))
        rows = collect_rows(jobs, out_dir)
    except (OSError, ValueError) as exc:  # ConfigError, JSONDecodeError, UnicodeDecodeError
        return f"{saved} cannot be used: {' '.join(str(exc).split())}"
    except KeyError as exc:
        return f"an episode summary in {out_dir / 'episodes'} has no field {exc}"
    if not rows:
        return f"no episode in {out_dir / 'episodes'} has finished"
    return rows, len(jobs)


def refresh_tables(out_dir: Path) -> list[str]:
    """Make ``out_dir``'s tables fit to draw a report from (``peg-sim plot``): when
    ``episodes.csv`` is missing, cut off, damaged or behind the episodes' ``summary.json`` files
    (a sweep killed before it wrote its tables), rebuild the tables from those summaries.

    Returns:
        Notes for the user: what was rebuilt and why, and how many of the experiment's episodes
        the report covers when the sweep is not finished. Empty when there is nothing to say.

    Raises:
        ConfigError: ``episodes.csv`` is unusable and there are no summaries to rebuild it from;
            the message names the file and both problems.
    """
    from peg_ctrl.experiments.report import episodes_csv_problem, read_rows

    out_dir = Path(out_dir)
    table = out_dir / "episodes.csv"
    problem = episodes_csv_problem(table)
    found = _rows_from_summaries(out_dir)
    if isinstance(found, str):
        if problem is None:
            return []  # the table alone (its episodes' directories may have been pruned)
        raise ConfigError(f"{table} {problem}, and it cannot be rebuilt: {found}")
    rows, n_jobs = found
    notes = []
    if problem is None:
        have = {row["key"] for row in read_rows(out_dir)}
        behind = sum(row["key"] not in have for row in rows)
        if behind:
            problem = f"is behind the episode summaries ({behind} finished episodes are not in it)"
    if problem is not None:
        write_tables(rows, out_dir)
        notes.append(f"{table} {problem}: rebuilt the tables from {len(rows)} episode summaries")
        have = {row["key"] for row in rows}
    if len(have) < n_jobs:
        notes.append(f"{len(have)} of {n_jobs} episodes have finished: the report covers those")
    return notes


def columns(rows: list[dict[str, Any]]) -> list[str]:
    """:func:`episode_columns` and the experiment's grid keys (``task.lateral_error``, ...)."""
    known = episode_columns()
    extra = [k for k in (rows[0] if rows else {}) if k not in known]
    return [*known, *extra]


def write_tables(rows: list[dict[str, Any]], out_dir: Path) -> None:
    """``episodes.csv``, ``episodes.parquet`` and ``summary.csv``, each written atomically. An
    undefined value (None: a metric of a peg that never got to the hole) is an empty cell in the
    CSV files and a null in the parquet file."""
    import csv
    import io

    from peg_ctrl.experiments.stats import summarise

    names = columns(rows)
    text = io.StringIO(newline="")
    writer = csv.DictWriter(text, fieldnames=names)
    writer.writeheader()
    # wall time varies run to run; everything else is deterministic
    for row in rows:
        writer.writerow({k: ("" if row[k] is None else row[k]) for k in names})
    atomic_write_text(out_dir / "episodes.csv", text.getvalue())
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq

        table = pa.Table.from_pylist([{k: row[k] for k in names} for row in rows])
        with atomic_path(out_dir / "episodes.parquet") as tmp:
            pq.write_table(table, tmp)
    except ImportError:  # pragma: no cover - pyarrow is a dependency
        pass
    summary = summarise(rows)
    text = io.StringIO(newline="")
    if summary:
        writer = csv.DictWriter(text, fieldnames=list(summary[0]))
        writer.writeheader()
        writer.writerows(summary)
    atomic_write_text(out_dir / "summary.csv", text.getvalue())
