"""Run an experiment: every episode in parallel, resumable, then tables, plots and a report.

Layout of ``out_dir``::

    experiment.json         the resolved experiment (every default filled in)
    episodes/<key>/         one episode: summary.json, config.json, log.jsonl, forces.npz
    episodes.csv/.parquet   one row per episode: the arm (controller/strategy), the varied values
                            (clearance, seed, grid cells) and every metric of summary.json
    summary.csv             per arm x planner x clearance: success rate with a 95 % Wilson
                            interval, peak force median / p95, time to insert, failure reasons
    report.md, *.png        the tables and plots

An episode whose ``summary.json`` exists (and was not interrupted) is done: rerunning the same
command skips it, so an interrupted sweep resumes where it stopped. Results are assembled from
those files in the experiment's fixed job order, so the number of workers does not change them.
"""

from __future__ import annotations

import concurrent.futures as futures
import dataclasses
import json
import multiprocessing
import time
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from peg_ctrl.config import to_dict
from peg_ctrl.errors import ConfigError, UnknownComponent
from peg_ctrl.experiments.config import ExperimentConfig, Job, expand, job_config, job_config_mapping
from peg_ctrl.io import atomic_write_text

__all__ = ["run_sweep", "collect_rows", "bench_sweep", "EPISODE_COLUMNS", "BACKENDS"]

# episodes.csv columns copied from each episode's summary.json.
_SUMMARY_COLUMNS = (
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
)

EPISODE_COLUMNS = (
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
    *_SUMMARY_COLUMNS,
    "log_path",
)


def _run_one(args: tuple[str, dict[str, Any], str]) -> dict[str, Any]:
    """Worker: one episode (the compiled model is cached per worker and scene)."""
    from peg_ctrl.episode import run_episode

    key, data, out = args
    result = run_episode(job_config(data), Path(out), plot=False).to_dict()
    result["key"] = key
    return result


def _warm_up(scene_data: dict[str, Any]) -> float:
    """Worker: import everything and compile the scene once; returns the time it took [s]."""
    t0 = time.perf_counter()
    from peg_ctrl.episode import compiled_model, episode_config_from_mapping

    cfg = episode_config_from_mapping(scene_data)
    compiled_model(cfg.scene, cfg.physics.profile)
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
    ctx = multiprocessing.get_context("spawn")
    for n in workers:
        with tempfile.TemporaryDirectory() as tmp, futures.ProcessPoolExecutor(n, mp_context=ctx) as pool:
            list(pool.map(_warm_up, [job_config_mapping(jobs[0])] * n))
            tasks = [(j.key, job_config_mapping(j), str(Path(tmp) / j.key)) for j in jobs]
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


def _done(out: Path) -> bool:
    path = out / "summary.json"
    if not path.is_file():
        return False
    try:
        return json.loads(path.read_text()).get("status") in ("success", "failure")
    except json.JSONDecodeError:
        return False


def _local_backend(tasks: list[tuple[str, dict[str, Any], str]], workers: int) -> Iterable[dict[str, Any]]:
    ctx = multiprocessing.get_context("spawn")
    with futures.ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as pool:
        pending = [pool.submit(_run_one, t) for t in tasks]
        try:
            for fut in futures.as_completed(pending):
                yield fut.result()
        except BaseException:
            for fut in pending:
                fut.cancel()
            raise


def _ray_backend(
    tasks: list[tuple[str, dict[str, Any], str]], workers: int, address: str | None
) -> Iterable[dict[str, Any]]:
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


BACKENDS: dict[str, Callable[..., Iterable[dict[str, Any]]]] = {
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
) -> list[dict[str, Any]]:
    """Run (or resume) ``exp`` into ``out_dir``; returns one row per episode, in job order."""
    from peg_ctrl.progress import progress_bar

    if backend not in BACKENDS:
        raise UnknownComponent("backend", backend, BACKENDS)
    if workers < 1:
        raise ConfigError(f"workers must be >= 1, got {workers}")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    jobs = expand(exp)  # before anything is written: a bad experiment leaves nothing behind
    saved = out_dir / "experiment.json"
    resolved = json.dumps(to_dict(exp), indent=2, sort_keys=True) + "\n"
    if saved.is_file() and saved.read_text() != resolved:
        raise ConfigError(
            f"{out_dir} holds results of a different experiment; use another --out or delete it"
        )
    atomic_write_text(saved, resolved)
    tasks = [
        (job.key, job_config_mapping(job), str(out_dir / "episodes" / job.key))
        for job in jobs
        if not _done(out_dir / "episodes" / job.key)
    ]
    done_before = len(jobs) - len(tasks)
    started = time.perf_counter()
    try:
        with progress_bar(
            total=len(jobs), initial=done_before, desc=exp.name, unit="ep", enabled=progress
        ) as bar:
            successes = 0
            runner = BACKENDS[backend]
            stream = runner(tasks, workers, address) if backend == "ray" else runner(tasks, workers)
            for result in stream:
                successes += result["status"] == "success"
                bar.set_postfix(success=f"{successes}/{bar.n + 1 - done_before}", refresh=False)
                bar.update(1)
    finally:
        # Whatever stopped the sweep (Ctrl-C, a crashed worker), the finished episodes' tables
        # are written; the report only for a complete sweep.
        rows = collect_rows(jobs, out_dir)
        write_tables(rows, out_dir)
    if report:
        from peg_ctrl.experiments.report import write_report

        write_report(out_dir, elapsed_s=time.perf_counter() - started)
    return rows


def collect_rows(jobs: list[Job], out_dir: Path) -> list[dict[str, Any]]:
    """One row per finished episode, in job order, from the episodes' ``summary.json``."""
    from peg_ctrl.episode import domain_draw

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
                **{name: s[name] for name in _SUMMARY_COLUMNS},
                "log_path": str(Path("episodes") / job.key / "log.jsonl"),
                **job.cell,
            }
        )
    return rows


def columns(rows: list[dict[str, Any]]) -> list[str]:
    """:data:`EPISODE_COLUMNS` and the experiment's grid keys (``task.lateral_error``, ...)."""
    extra = [k for k in (rows[0] if rows else {}) if k not in EPISODE_COLUMNS]
    return [*EPISODE_COLUMNS, *extra]


def write_tables(rows: list[dict[str, Any]], out_dir: Path) -> None:
    """``episodes.csv``, ``episodes.parquet`` and ``summary.csv``."""
    import csv

    from peg_ctrl.experiments.report import summarise

    names = columns(rows)
    with open(out_dir / "episodes.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=names)
        writer.writeheader()
        # wall time varies run to run; everything else is deterministic
        for row in rows:
            writer.writerow({k: ("" if row[k] is None else row[k]) for k in names})
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq

        table = pa.Table.from_pylist([{k: row[k] for k in names} for row in rows])
        pq.write_table(table, out_dir / "episodes.parquet")
    except ImportError:  # pragma: no cover - pyarrow is a dependency
        pass
    summary = summarise(rows)
    with open(out_dir / "summary.csv", "w", newline="") as fh:
        if summary:
            writer = csv.DictWriter(fh, fieldnames=list(summary[0]))
            writer.writeheader()
            writer.writerows(summary)
