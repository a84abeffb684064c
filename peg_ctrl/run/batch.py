"""Run many episodes in parallel worker processes and collect their summaries."""

from __future__ import annotations

import concurrent.futures as futures
import os
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from peg_ctrl.config import to_dict
from peg_ctrl.errors import ConfigError
from peg_ctrl.run.workers import worker_pool

__all__ = ["run_batch", "default_workers"]


def default_workers() -> int:
    return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1)


def _worker(args: tuple[dict[str, Any], str, bool]) -> dict[str, Any]:
    from peg_ctrl.run.episode import episode_config_from_mapping, run_episode

    cfg_data, out_dir, plot = args
    cfg = episode_config_from_mapping(cfg_data)
    return run_episode(cfg, Path(out_dir), plot=plot).to_dict()


def run_batch(
    jobs: Iterable[tuple[Any, Path]],
    *,
    workers: int | None = None,
    plot: bool = False,
    progress: bool = True,
    desc: str = "episodes",
) -> list[dict[str, Any]]:
    """Run ``(EpisodeConfig, out_dir)`` jobs on ``workers`` processes (default: one per core);
    summaries in job order. Workers die with this process, and a Ctrl-C ends them and starts no
    queued job (see :mod:`peg_ctrl.run.workers`).

    Raises:
        ConfigError: ``workers`` is below 1 (0 is refused, not taken as "the default").
    """
    from peg_ctrl.progress import progress_bar

    if workers is not None and workers < 1:
        raise ConfigError(f"workers must be >= 1, got {workers}")
    # Configs travel as plain data and are validated again in the worker.
    items = [(to_dict(cfg), str(out), plot) for cfg, out in jobs]
    if not items:
        return []
    results: list[dict[str, Any] | None] = [None] * len(items)
    with worker_pool(min(workers or default_workers(), len(items))) as pool:
        pending = {pool.submit(_worker, item): i for i, item in enumerate(items)}
        successes = 0
        with progress_bar(
            total=len(items), desc=desc, unit="ep", enabled=progress, lines="episodes", postfix="0 inserted"
        ) as bar:
            for fut in futures.as_completed(pending):
                i = pending[fut]
                results[i] = fut.result()
                successes += results[i]["status"] == "success"  # type: ignore[index]
                bar.set_postfix_str(f"{successes} inserted", refresh=False)
                bar.update(1)
    return [r for r in results if r is not None]
