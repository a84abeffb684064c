"""Experiment files, sweeps (resume, worker-count invariance), statistics and reports."""

from __future__ import annotations

import csv
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from peg_ctrl.experiments.config import expand, experiment_from_mapping, load_experiment
from peg_ctrl.experiments.report import wilson_interval
from peg_ctrl.experiments.runner import _done, run_sweep
from peg_ctrl.run.episode import WALL_CLOCK_FIELDS
from peg_ctrl.tasks.monitors import END_STATES

from ..conftest import assert_one_line_error, peg_sim_here, sigint_default

CONFIGS = Path(__file__).resolve().parents[2] / "experiments" / "configs"
SMALL = """\
name: small
controllers: [{name: pd}, {name: impedance, k_pos: [1200.0, 1200.0, 1200.0]}]
clearances: [0.001]
seeds: [0, 1]
max_steps: 2000
"""


def _rows(path: Path) -> list[dict]:
    with open(path, newline="") as fh:
        return [{k: v for k, v in row.items() if k not in WALL_CLOCK_FIELDS} for row in csv.DictReader(fh)]


def test_an_episode_key_is_its_whole_config() -> None:
    """Any F/T sensor setting (the sensor model's fields, a preset) makes another episode."""
    import dataclasses

    from peg_ctrl.experiments.config import episode_key
    from peg_ctrl.run.episode import DomainConfig, EpisodeConfig

    plain = EpisodeConfig(seed=3, domain=DomainConfig(position_noise=1e-4))
    assert episode_key(plain) == episode_key(dataclasses.replace(plain)) and len(episode_key(plain)) == 16
    keys = {episode_key(plain)}
    for ft in ({"ft_sensor": "ideal"}, {"force_noise": 0.1}, {"torque_noise": 0.1}, {"ft_latency": 0.01}):
        keys.add(episode_key(dataclasses.replace(plain, domain=dataclasses.replace(plain.domain, **ft))))
    assert len(keys) == 5


def test_shipped_experiments_load() -> None:
    for path in sorted(CONFIGS.glob("*.yaml")):
        exp = load_experiment(path)
        assert len(expand(exp)) >= 20, path
    quick = load_experiment(CONFIGS / "quick.yaml")
    assert {c.name for c in quick.controllers} == {"pd", "impedance", "admittance", "diffik", "mpc"}
    clearance = load_experiment(CONFIGS / "clearance.yaml")
    assert min(clearance.clearances) == pytest.approx(5e-5) and max(clearance.clearances) >= 1e-3


@pytest.mark.parametrize(
    "text, message",
    [
        ("controllers: [{name: lqg}]", "controllers[0]: unknown controller 'lqg'; known: admittance, diffik"),
        ("controllers: [pd]\nclearances: [-0.002]", "clearances[0]: clearance must be > -0.001 m"),
        ("clearances: [0.001]", "controllers: missing field"),
        ("controllers: [pd]\nseeds: many", "seeds: expected a list"),
        ("controllers: [{name: pd, kp_pos: fast}]", "controllers[0].kp_pos: expected a number"),
        ("controllers: [pd]\nplanners: [rrt]", "planners[0]: unknown planner 'rrt'"),
        (
            "controllers: [pd]\ndomain: {friction_scale: [1.2, 0.8]}",
            "domain.friction_scale must be [low, high]",
        ),
        ("controllers: [pd]\nwarp: 9", "warp: unknown field"),
    ],
)
def test_bad_experiment_files_fail_in_one_line(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text(text + "\n")
    proc = peg_sim_here(["sweep", str(path), "--out", str(tmp_path / "out")], cwd=tmp_path)
    assert_one_line_error(proc, message)
    assert not (tmp_path / "out").exists()


def test_jobs_are_keyed_by_their_full_config() -> None:
    exp = experiment_from_mapping(
        {"controllers": ["pd", "impedance"], "seeds": 3, "clearances": [0.001, 0.0005]}
    )
    jobs = expand(exp)
    assert len(jobs) == 12 and len({j.key for j in jobs}) == 12
    assert [j.key for j in jobs] == [j.key for j in expand(exp)]


def test_report_handles_all_successes(tmp_path: Path) -> None:
    """A 100 % group has a Wilson upper bound a hair below 1: the plot must still draw."""
    from peg_ctrl.experiments.report.plots import draw_plots

    rows = [
        {
            "controller": "pd",
            "planner": "ruckig",
            "clearance_m": c,
            "status": "success",
            "reason": "",
            "phase": "",
            "peak_contact_force_n": 0.0,
            "time_to_insert_s": 9.0,
            "log_path": "episodes/x/log.jsonl",
        }
        for c in (0.001, 0.0001)
        for _ in range(10)
    ]
    names = [name for _, name in draw_plots(tmp_path, rows)]
    assert "success_vs_clearance.png" in names and (tmp_path / "success_vs_clearance.png").is_file()


@pytest.mark.parametrize("n", [5, 10, 20])
def test_success_vs_disturbance_handles_all_successes(tmp_path: Path, n: int) -> None:
    """5/5 has a Wilson upper bound a round-off below 1: the error bars must still draw."""
    from peg_ctrl.experiments.report.plots import draw_plots

    rows = [
        {
            "arm": "pd/spiral",
            "controller": "pd",
            "task": "pick_and_place",
            "planner": "ruckig",
            "clearance_m": 0.0001,
            "status": "success",
            "reason": "",
            "phase": "",
            "peak_contact_force_n": 5.0,
            "time_to_insert_s": 4.0,
            "log_path": "episodes/x/log.jsonl",
            "task.lateral_error": e,
        }
        for e in (0.0005, 0.003)
        for _ in range(n)
    ]
    names = [name for _, name in draw_plots(tmp_path, rows)]
    assert "success_vs_disturbance.png" in names and (tmp_path / "success_vs_disturbance.png").is_file()


def test_wilson_interval() -> None:
    lo, hi = wilson_interval(19, 20)
    assert lo == pytest.approx(0.7639, abs=1e-3) and hi == pytest.approx(0.9911, abs=1e-3)
    assert wilson_interval(0, 10)[0] == 0.0 and wilson_interval(10, 10)[1] == pytest.approx(1.0)


def test_interrupted_sweep_resumes_to_the_same_results(tmp_path: Path) -> None:
    config = tmp_path / "small.yaml"
    config.write_text(SMALL)
    # Uninterrupted, with two workers.
    run_sweep(load_experiment(config), tmp_path / "whole", workers=2, progress=False, report=False)
    # Interrupted with Ctrl-C after the first finished episode, then resumed with one worker.
    out = tmp_path / "resumed"
    proc = subprocess.Popen(
        [sys.executable, "-m", "peg_ctrl", "sweep", str(config), "--out", str(out), "--workers", "1"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
        preexec_fn=sigint_default,  # interrupted below
    )
    # Interrupt once an episode is done as the runner counts it (its final summary written: the
    # first summary, written the moment the episode ends, is not yet "done").
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not any(
        _done(p.parent) for p in out.glob("episodes/*/summary.json")
    ):
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGINT)
    proc.wait(timeout=60)
    finished = sum(_done(p.parent) for p in out.glob("episodes/*/summary.json"))
    assert 1 <= finished < 4, "the interruption came too late to test resuming"
    rows = run_sweep(load_experiment(config), out, workers=1, progress=False)
    assert len(rows) == 4
    assert _rows(out / "episodes.csv") == _rows(tmp_path / "whole" / "episodes.csv")
    summary = list(csv.DictReader(open(out / "summary.csv")))
    assert [s["controller"] for s in summary] == ["pd", "impedance"]
    report = (out / "report.md").read_text()
    assert "## Summary" in report and "peak_force.png" in report
    assert (out / "episodes.parquet").stat().st_size > 0


def test_a_different_experiment_in_the_same_directory_is_refused(tmp_path: Path) -> None:
    config = tmp_path / "small.yaml"
    config.write_text(SMALL.replace("max_steps: 2000", "max_steps: 100"))
    run_sweep(load_experiment(config), tmp_path / "out", workers=1, progress=False, report=False)
    config.write_text(SMALL.replace("max_steps: 2000", "max_steps: 101"))
    with pytest.raises(ValueError, match="different experiment"):
        run_sweep(load_experiment(config), tmp_path / "out", workers=1, progress=False)


def test_plot_redraws_the_report(tmp_path: Path) -> None:
    config = tmp_path / "small.yaml"
    config.write_text(SMALL.replace("max_steps: 2000", "max_steps: 100"))
    out = tmp_path / "out"
    run_sweep(load_experiment(config), out, workers=1, progress=False, report=False)
    assert not (out / "report.md").exists()
    proc = subprocess.run(
        [sys.executable, "-m", "peg_ctrl", "plot", str(out)], capture_output=True, text=True
    )
    assert proc.returncode == 0, proc.stderr
    for name in ("report.md", "force_profiles.png", "peak_force.png", "failures.png"):
        assert (out / name).stat().st_size > 0
    # One clearance: a success-vs-clearance plot would be one point per arm, so there is none.
    assert not (out / "success_vs_clearance.png").exists()


def test_ray_backend_gives_the_local_results(tmp_path: Path) -> None:
    pytest.importorskip("ray", reason="the ray extra is not installed (pip install 'peg-ctrl[ray]')")
    import ray

    config = tmp_path / "small.yaml"
    config.write_text(SMALL.replace("max_steps: 2000", "max_steps: 200"))
    exp = load_experiment(config)
    run_sweep(exp, tmp_path / "local", workers=2, progress=False, report=False)
    try:
        run_sweep(exp, tmp_path / "ray", workers=2, backend="ray", progress=False, report=False)
    finally:
        ray.shutdown()
    assert _rows(tmp_path / "ray" / "episodes.csv") == _rows(tmp_path / "local" / "episodes.csv")


def test_tuple_gains_with_gain_scale_run_to_a_report(tmp_path: Path) -> None:
    """Once a crash: list-valued gains perturbed by domain.gain_scale."""
    config = tmp_path / "crash.yaml"
    config.write_text(
        "controllers: [{name: impedance, k_pos: [1200, 1200, 1200]}]\n"
        "domain: {gain_scale: [0.9, 1.1]}\nseeds: 1\nmax_steps: 500\n"
    )
    out = tmp_path / "out"
    proc = peg_sim_here(["sweep", str(config), "--out", str(out), "--workers", "1"], cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    (row,) = _rows(out / "episodes.csv")
    assert row["controller"] == "impedance" and float(row["gain_scale"]) != 1.0
    assert 0.9 <= float(row["gain_scale"]) <= 1.1
    assert (out / "summary.csv").is_file() and "## Summary" in (out / "report.md").read_text()


# -- contact studies: strategies and grids -----------------------------------------------------
def test_contact_comparison_crosses_controllers_strategies_and_the_grid() -> None:
    exp = load_experiment(CONFIGS / "contact.yaml")
    jobs = expand(exp)
    arms = list(dict.fromkeys(j.arm for j in jobs))
    assert len(arms) == len(exp.controllers) * len(exp.strategies) >= 5
    assert "pd/straight" in arms and "impedance/spiral" in arms
    cells = list(dict.fromkeys(tuple(sorted(j.cell.items())) for j in jobs))
    assert len(cells) == 6
    assert len(jobs) == len(arms) * 6 * len(exp.seeds) and len({j.key for j in jobs}) == len(jobs)
    job = next(j for j in jobs if j.arm == "impedance/tilt" and j.cell["task.lateral_error"] == 0.003)
    cfg = job.config
    assert cfg.task.name == "held_insertion" and cfg.task.strategy.name == "tilt"  # type: ignore[attr-defined]
    assert cfg.task.lateral_error == 0.003  # type: ignore[attr-defined]
    assert cfg.scene.assets.clearance == 0.0001 and cfg.scene.assets.chamfer == 0.001
    assert cfg.physics.profile == "precision"


def test_set_fixes_a_swept_key_and_the_seed_count() -> None:
    from peg_ctrl.config import read_mapping
    from peg_ctrl.experiments.config import apply_experiment_overrides

    data = apply_experiment_overrides(
        read_mapping(CONFIGS / "contact.yaml"), ["task.lateral_error=0.002", "seeds=40"]
    )
    exp = experiment_from_mapping(data)
    jobs = expand(exp)
    assert {j.config.task.lateral_error for j in jobs} == {0.002}  # type: ignore[attr-defined]
    assert len(exp.seeds) == 40 and len(jobs) == len(exp.controllers) * len(exp.strategies) * 2 * 40


_LINKED = {
    "controllers": [{"name": "pd"}],
    "seeds": 1,
    "task": {"name": "held_insertion"},
    "grid": {
        "scene.friction": [0.3, 0.9],
        "sensor": {"domain.ft_sensor": ["ideal", "wrist", "forge"], "task.position_noise": [0.0, 5e-4, 5e-4]},
    },
}


def test_a_linked_axis_moves_its_keys_together() -> None:
    jobs = expand(experiment_from_mapping(_LINKED))
    assert len(jobs) == 2 * 3
    pairs = {(j.config.domain.ft_sensor, j.config.task.position_noise) for j in jobs}  # type: ignore[attr-defined]
    assert pairs == {("ideal", 0.0), ("wrist", 5e-4), ("forge", 5e-4)}
    assert set(jobs[0].cell) == {"scene.friction", "domain.ft_sensor", "task.position_noise"}


@pytest.mark.parametrize(
    "setting, pairs",
    [
        ("domain.ft_sensor=forge", {("forge", 5e-4)}),  # the level where the key has that value
        ("domain.ft_sensor=ideal", {("ideal", 0.0)}),
        ("task.position_noise=0.001", {("", 0.001)}),  # no such level: the axis goes (no preset)
    ],
)
def test_set_on_a_linked_key_keeps_its_level(setting: str, pairs: set[tuple[str, float]]) -> None:
    from peg_ctrl.experiments.config import apply_experiment_overrides

    jobs = expand(experiment_from_mapping(apply_experiment_overrides(_LINKED, [setting])))
    assert {(j.config.domain.ft_sensor, j.config.task.position_noise) for j in jobs} == pairs  # type: ignore[attr-defined]
    assert len(jobs) == 2


@pytest.mark.parametrize(
    "axis, message",
    [
        ({"domain.ft_sensor": ["ideal", "forge"], "task.position_noise": [0.0]}, "must have one length"),
        ({"domain.ft_sensor": ["ideal", "ideal"], "task.position_noise": [0.0, 0.0]}, "repeated levels"),
        ({"ft_sensor": ["ideal"]}, "keys of a linked axis must be dotted field names, got 'ft_sensor'"),
        ({"domain.ft_sensor": "forge"}, "grid.sensor.domain.ft_sensor: expected a non-empty list"),
        ({"domain.ft_sensor": ["ideal", "laser"]}, "ft_sensor"),
        ({}, "a linked axis needs at least one dotted key"),
    ],
)
def test_a_bad_linked_axis_is_named(axis: dict[str, object], message: str) -> None:
    from peg_ctrl.config import ConfigError

    data = {**_LINKED, "grid": {"sensor": axis}}
    with pytest.raises(ConfigError, match=message):
        experiment_from_mapping(data)


@pytest.mark.parametrize(
    "text, message",
    [
        ("controllers: [pd]\nstrategies: [spiral]", "strategies: task 'pick_and_place' has no strategy"),
        (
            "controllers: [pd]\ntask: {name: held_insertion}\nstrategies: [poke]",
            "strategies[0]: unknown strategy 'poke'; known: align, force, handover, locate, plan, probe, "
            "spiral, straight, tilt",
        ),
        (
            "controllers: [pd]\ntask: {name: held_insertion}\ngrid: {task.wobble: [1, 2]}",
            "grid.task.wobble: no such field in the episode config",
        ),
        (
            "controllers: [pd]\ntask: {name: held_insertion}\ngrid: {task.lateral_error: [-1]}",
            "task.lateral_error must be >= 0, got -1",
        ),
        ("controllers: [pd]\ngrid: {seed: [1, 2]}", "grid.seed: sweep this with controllers/strategies"),
        (
            "controllers: [pd]\ntask: {name: held_insertion}\ngrid: {task.tilt_error: [0.01, 0.01]}",
            "grid.task.tilt_error: repeated values [0.01, 0.01]",
        ),
        (
            "controllers: [pd]\ngrid: {scene.assets.clearance: [0.001]}",
            "grid.scene.assets.clearance: sweep this with controllers/strategies/planners/clearances",
        ),
        (
            "controllers: [pd]\nphysics: {profile: precision}\nscene: {assets: {n_parts: 12}}",
            "scene.assets.n_parts",
        ),
        (
            "controllers: [pd]\ntask: {name: held_insertion}\nstrategies: [spiral]\narms: {mpc: [spiral]}",
            "arms.mpc: no such controller; the controllers are pd",
        ),
        (
            "controllers: [pd]\ntask: {name: held_insertion}\nstrategies: [spiral]\narms: {pd: [tilt]}",
            "arms.pd: 'tilt' is not one of the experiment's strategies (spiral)",
        ),
        (
            "controllers: [pd]\ntask: {name: held_insertion}\nstrategies: [spiral]\narms: {pd: []}",
            "arms.pd: expected a non-empty list of strategies, got []",
        ),
        ("controllers: [pd]\nscene: {friction: -0.2}", "friction must be finite and > 0"),
    ],
)
def test_bad_contact_studies_fail_in_one_line(text: str, message: str) -> None:
    import yaml

    from peg_ctrl.config import ConfigError

    with pytest.raises(ConfigError) as err:
        experiment_from_mapping(yaml.safe_load(text))
    assert message in str(err.value)


def test_a_controller_named_twice_is_labelled_by_what_differs() -> None:
    """Two configs of one controller are two arms, each labelled by the fields in which they
    differ (not by every field off its defaults: the shared ones would repeat in both)."""
    from peg_ctrl.experiments.config import arms

    inner = {"k_pos": [3000.0] * 3, "k_rot": [2.0] * 3, "damping_compensation": 0.9}
    exp = experiment_from_mapping(
        {
            "name": "ablation",
            "controllers": [
                {"name": "sampling_mpc", "hypotheses": 4, "inner": inner},
                {"name": "sampling_mpc", "hypotheses": 1, "inner": inner},
                "pd",
            ],
            "task": {"name": "held_insertion"},
            "strategies": ["handover", "straight"],
            "arms": {
                "sampling_mpc(hypotheses=4)": ["handover"],
                "sampling_mpc(hypotheses=1)": ["handover"],
                "pd": ["straight"],
            },
        }
    )
    assert arms(exp) == [
        ("sampling_mpc(hypotheses=4)/handover", "sampling_mpc"),
        ("sampling_mpc(hypotheses=1)/handover", "sampling_mpc"),
        ("pd/straight", "pd"),
    ]


def test_a_small_contact_sweep_writes_its_metrics_statistics_and_plots(tmp_path: Path) -> None:
    exp = experiment_from_mapping(
        {
            "name": "tiny",
            "controllers": ["pd"],
            "strategies": ["straight", "spiral"],
            "clearances": [0.0001],
            "seeds": 1,
            "max_steps": 3000,  # 1.5 s: past the first contact
            "task": {"name": "held_insertion"},
            "scene": {"assets": {"chamfer": 0.001}},
            "physics": {"profile": "precision"},
            "grid": {"task.lateral_error": [0.0005, 0.002]},
        }
    )
    rows = run_sweep(exp, tmp_path, workers=2, progress=False)
    assert len(rows) == 4
    header = (tmp_path / "episodes.csv").read_text().splitlines()[0].split(",")
    for column in (
        "arm",
        "strategy",
        "task.lateral_error",
        "first_contact_s",
        "contact_to_seat_s",
        "contact_impulse_ns",
        "max_tilt_rad",
        "search_distance_m",
        "end_state",
        "lateral_error_m",
        "tilt_rad",
        "insertion_depth_m",
        "peak_any_contact_force_n",
        "max_penetration_m",
        "sim_time_s",
    ):
        assert column in header, column
    assert {r["arm"] for r in rows} == {"pd/straight", "pd/spiral"}
    assert all(r["end_state"] in END_STATES for r in rows)
    report = (tmp_path / "report.md").read_text()
    assert "## Success per grid cell" in report and "## Which arms differ" in report
    for name in ("success_vs_disturbance.png", "force_vs_depth.png", "peak_force.png"):
        assert (tmp_path / name).stat().st_size > 10_000, name


# -- the report from episodes.csv alone -----------------------------------------------------------
def _contact_rows() -> list[dict]:
    """Two arms x two lateral errors x 8 seeds; the friction drawn per seed; no traces."""
    rows = []
    for arm, wins_at in (("pd/spiral", {0.0005: 8, 0.003: 2}), ("impedance/spiral", {0.0005: 8, 0.003: 7})):
        for error, wins in wins_at.items():
            for seed in range(8):
                ok = seed < wins
                rows.append(
                    {
                        "key": f"{arm}-{error}-{seed}",
                        "arm": arm,
                        "controller": arm.split("/")[0],
                        "task": "held_insertion",
                        "strategy": "spiral",
                        "planner": "ruckig",
                        "clearance_m": "0.0001",
                        "seed": str(seed),
                        "friction_scale": str(0.8 + 0.05 * seed),
                        "gain_scale": "1.0",
                        "status": "success" if ok else "failure",
                        "reason": "" if ok else "wedged",
                        "phase": "push" if ok else "search",
                        "peak_contact_force_n": str(10.0 + seed + (20.0 if arm.startswith("pd") else 0.0)),
                        "time_to_insert_s": "4.0" if ok else "",
                        "contact_to_seat_s": "3.0" if ok else "",
                        "log_path": f"episodes/{arm}-{error}-{seed}/log.jsonl",
                        "task.lateral_error": str(error),
                        "task.tilt_error": "0.0",
                    }
                )
    return rows


def _write_csv(out: Path, rows: list[dict]) -> None:
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "episodes.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def test_swept_conditions_are_the_varied_columns() -> None:
    from peg_ctrl.experiments.report import swept_conditions
    from peg_ctrl.experiments.stats import episodes_frame

    # Constant: the clearance, the tilt, the gain scale; varied: the lateral error, the friction.
    assert swept_conditions(episodes_frame(_contact_rows())) == ["task.lateral_error", "friction_scale"]


def test_success_table_counts_per_arm_and_level_with_wilson_intervals() -> None:
    from peg_ctrl.experiments.stats import episodes_frame, success_by_level

    df = episodes_frame(_contact_rows())
    df["won"] = df["status"] == "success"
    table = success_by_level(df, "task.lateral_error")
    row = table[(table["arm"] == "pd/spiral") & (table["x"] == 0.003)].iloc[0]
    assert (row["k"], row["n"], row["rate"]) == (2, 8, 0.25)
    assert (row["low"], row["high"]) == wilson_interval(2, 8)
    assert len(table) == 4 and not table.attrs["binned"]
    # Eight friction values (one per seed): four quartile bins per arm, at the bins' medians.
    friction = success_by_level(df, "friction_scale")
    assert friction.attrs["binned"] and len(friction) == 8
    assert friction.groupby("arm")["n"].sum().tolist() == [16, 16]
    assert friction["x"].iloc[0] == pytest.approx(0.825)  # the median of 0.80 and 0.85


def test_a_report_from_episodes_csv_alone_leaves_out_the_trace_plots(tmp_path: Path) -> None:
    """Without the episodes' traces, no blank per-arm panels: the trace plots are left out."""
    from peg_ctrl.experiments.report import write_report

    _write_csv(tmp_path, _contact_rows())
    report = write_report(tmp_path).read_text()
    for name in ("success_vs_disturbance.png", "peak_force.png", "failures.png"):
        assert (tmp_path / name).stat().st_size > 10_000, name
        assert f"({name})" in report
    for name in ("force_profiles.png", "force_vs_depth.png", "success_vs_clearance.png"):
        assert not (tmp_path / name).exists(), name
    assert "force traces (`episodes/<key>/forces.npz`) are not in this directory" in report
    assert "| pd/spiral | 8/8, 33.5 N | 2/8, 33.5 N |" in report  # the grid-cell table


def _sensor_rows() -> list[dict]:
    """_contact_rows with a linked sensor axis (preset names, and the hole noise that goes with
    them), friction and tilt set by the seed: 16 cells per arm, one episode each."""
    rows = []
    for row in _contact_rows():
        seed = int(row["seed"])
        sensor = ("ideal", "forge")[seed % 2]
        won = row["status"] == "success" and not (sensor == "forge" and row["arm"].startswith("pd"))
        rows.append(
            {
                **row,
                "status": "success" if won else "failure",
                "contact_to_seat_s": str(2.0 + seed) if won else "",
                "scene.friction": ("0.3", "0.9")[(seed // 2) % 2],
                "task.tilt_error": ("0.0", "0.035")[seed // 4],
                "domain.ft_sensor": sensor,
                "task.position_noise": ("0.0", "0.0005")[seed % 2],
            }
        )
    return rows


def test_a_named_linked_axis_is_one_condition_and_a_large_grid_folds_onto_its_axes(tmp_path: Path) -> None:
    from peg_ctrl.experiments.report import swept_conditions, write_report
    from peg_ctrl.experiments.stats import episodes_frame, success_by_level

    df = episodes_frame(_sensor_rows())
    # The sensor is a condition (named levels); the hole noise moves with it, so it is left out.
    assert swept_conditions(df) == [
        "task.lateral_error",
        "task.tilt_error",
        "scene.friction",
        "domain.ft_sensor",
        "friction_scale",
    ]
    df["won"] = df["status"] == "success"
    table = success_by_level(df, "domain.ft_sensor")
    assert table.attrs["labels"] == ["ideal", "forge"]
    forge = table[(table["arm"] == "pd/spiral") & (table["x"] == 1.0)].iloc[0]
    assert (forge["k"], forge["n"]) == (0, 8)
    _write_csv(tmp_path, _sensor_rows())
    report = write_report(tmp_path).read_text()
    assert "## Success per condition" in report and "## Success per grid cell" not in report
    # pd/spiral with the ideal sensor (even seeds): 0, 2, 4, 6 at 0.5 mm and 0 at 3 mm won;
    # peak forces 30-36 N (median 33), contact-to-seated 2, 4, 6, 8 and 2 s (median 4).
    lines = report.splitlines()
    at = next(i for i, x in enumerate(lines) if x.startswith("| arm | lateral_error="))
    header, line = lines[at], next(x for x in lines[at:] if x.startswith("| pd/spiral | "))
    cell = line.split(" | ")[header.split(" | ").index("ft_sensor=ideal")]
    assert cell == "5/8, 33.0 N, 4.0 s", cell
    assert (tmp_path / "success_vs_disturbance.png").stat().st_size > 10_000


def test_where_the_time_goes_is_the_median_phase_time_of_the_successes(tmp_path: Path) -> None:
    import json

    from peg_ctrl.experiments.report.sections import phase_section

    rows = []
    for i, (status, touch) in enumerate(
        [("success", 0.2), ("success", 0.4), ("success", 0.9), ("failure", 5.0)]
    ):
        log = f"episodes/k{i}/log.jsonl"
        (tmp_path / log).parent.mkdir(parents=True)
        phases = [
            {"phase": "settle", "t_start": 0.0, "t_end": 0.3},
            {"phase": "touch", "t_start": 0.3, "t_end": 0.3 + touch},
            {"phase": "insert", "t_start": 0.3 + touch, "t_end": 1.3 + touch},
            {"phase": "hold", "t_start": 1.3 + touch, "t_end": 2.3 + touch},
        ]
        (tmp_path / log).parent.joinpath("summary.json").write_text(json.dumps({"phases": phases}))
        rows.append({"arm": "mpc/probe", "controller": "mpc", "status": status, "log_path": log})
    lines = phase_section(tmp_path, rows)
    assert "| mpc/probe | 3 | touch 0.40, insert 1.00 |" in lines  # settle and hold left out
    assert phase_section(tmp_path, [{**rows[0], "log_path": "episodes/gone/log.jsonl"}]) == []


def test_contact_hard_gives_each_controller_its_strategies_and_sweeps_friction() -> None:
    exp = load_experiment(CONFIGS / "contact_hard.yaml")
    jobs = expand(exp)
    arms = list(dict.fromkeys(j.arm for j in jobs))
    assert arms == [
        "pd/straight",
        "pd/spiral",
        "pd/align",
        "impedance/spiral",
        "impedance/align",
        "admittance/spiral",
        "admittance/align",
        "mpc/align",
        "diffik/align",
        "sampling_mpc/align",
    ]
    cells = {tuple(sorted(j.cell.items())) for j in jobs}
    assert len(cells) == 8 and {c[0] for c in cells} == {("scene.friction", 0.3), ("scene.friction", 0.9)}
    assert len(jobs) == len(arms) * 8 * len(exp.seeds) == 400
    job = next(j for j in jobs if j.arm == "mpc/align" and j.cell["scene.friction"] == 0.9)
    assert job.config.scene.friction == 0.9 and job.config.scene.assets.clearance == 0.00005
    assert job.config.controller.formulation == "contact"  # type: ignore[attr-defined]


def test_a_float_field_added_to_the_result_reaches_episodes_csv_and_the_summary(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """One field with its metadata is all a new metric needs: the sweep's table, summary.csv
    and the report's summary table follow from it."""
    import dataclasses
    import json

    from peg_ctrl.experiments.report import write_report
    from peg_ctrl.experiments.runner import collect_rows, write_tables
    from peg_ctrl.run import result
    from peg_ctrl.run.result import EpisodeResult, Summary, metric

    extended = dataclasses.make_dataclass(
        "Extended",
        [
            (
                "squeeze_n",
                float,
                dataclasses.field(
                    default=0.0, metadata=metric(unit="N", summary=Summary("squeeze", ("median", "p95")))
                ),
            ),
            ("wobble_m", float, dataclasses.field(default=0.0)),  # no metadata: a column, not summarised
        ],
        bases=(EpisodeResult,),
    )
    monkeypatch.setattr(result, "EpisodeResult", extended)
    jobs = expand(
        experiment_from_mapping({"name": "extended", "controllers": ["pd", "impedance"], "seeds": 3})
    )
    blank = {"number": 0.0, "text": "", "flag": False}
    for i, job in enumerate(jobs):
        fields: dict = {f.name: blank.get(f.kind) for f in result.metric_fields() if f.kind != "other"}
        fields.update(
            status="success",
            seed=job.seed,
            total_timesteps=10,
            phantom_contacts=0,
            trace_path="forces.npz",
            squeeze_n=float(i + 1) * (10.0 if job.controller == "impedance" else 1.0),
            wobble_m=0.001 * i,
        )
        record = extended(**fields)
        (tmp_path / "episodes" / job.key).mkdir(parents=True)
        (tmp_path / "episodes" / job.key / "summary.json").write_text(json.dumps(record.to_dict()))
    write_tables(collect_rows(jobs, tmp_path), tmp_path)
    with open(tmp_path / "episodes.csv", newline="") as fh:
        reader = csv.DictReader(fh)
        header, rows = list(reader.fieldnames or []), list(reader)
    assert header[header.index("environment") + 1 :] == ["squeeze_n", "wobble_m", "log_path"]
    assert [float(r["squeeze_n"]) for r in rows] == [1.0, 2.0, 3.0, 40.0, 50.0, 60.0]
    with open(tmp_path / "summary.csv", newline="") as fh:
        summary = {r["controller"]: r for r in csv.DictReader(fh)}
    assert float(summary["pd"]["squeeze_median_n"]) == 2.0
    assert float(summary["impedance"]["squeeze_p95_n"]) == pytest.approx(59.0)
    assert not any("wobble" in name for name in summary["pd"])
    report = write_report(tmp_path).read_text().splitlines()
    head = next(line for line in report if line.startswith("| arm | planner |")).split(" | ")
    pd_row = next(line for line in report if line.startswith("| pd | ruckig |")).split(" | ")
    assert pd_row[head.index("squeeze median [N]")] == "2" and pd_row[head.index("squeeze p95 [N]")] == "2.9"


def test_the_run_time_is_summed_over_the_invocations(tmp_path: Path) -> None:
    from peg_ctrl.experiments.report.header import header_section
    from peg_ctrl.experiments.report.run_time import RUN_TIME_FILE, add_run_time, run_time

    assert run_time(tmp_path) is None
    assert add_run_time(tmp_path, 100.0) == (100.0, 1)
    assert add_run_time(tmp_path, 25.5) == (125.5, 2)
    assert run_time(tmp_path) == (125.5, 2)
    rows = [{"controller": "pd"}]
    assert header_section({}, "x", rows, run_time(tmp_path))[2].endswith(
        " Run time 126 s over 2 invocations."
    )
    assert header_section({}, "x", rows, (9.0, 1))[2].endswith(" Run time 9 s.")
    assert "Run time" not in header_section({}, "x", rows, None)[2]
    # a comparison's experiment keeps --set seeds=1 as a count
    assert "; 1 seeds;" in header_section({"seeds": 1}, "x", rows, None)[2]
    assert "; 2 seeds;" in header_section({"seeds": [3, 4]}, "x", rows, None)[2]
    (tmp_path / RUN_TIME_FILE).write_text("{")  # damaged: not known, and replaced
    assert run_time(tmp_path) is None and add_run_time(tmp_path, 1.0) == (1.0, 1)


def test_the_report_names_the_task_from_the_data() -> None:
    from peg_ctrl.experiments.report.plots import caption
    from peg_ctrl.experiments.report.sections import comparison_section

    rows = _contact_rows()
    text = "\n".join(comparison_section(rows))
    assert "(successes only; for held insertion the time from the first contact to seated)" in text
    renamed = [{**r, "task": "peg_in_bore"} for r in rows]
    assert "for peg in bore the time from the first contact" in "\n".join(comparison_section(renamed))
    assert "aligned at the first peg-block contact (peg in bore) or at the start" in caption(
        "force_profiles.png", renamed
    )
    plain = [{**r, "task": "pick_and_place", "strategy": ""} for r in rows]  # no strategy: from the start
    assert "(successes only): Mann-Whitney U" in "\n".join(comparison_section(plain))
    assert "aligned at the start of the insert (else release) phase" in caption("force_profiles.png", plain)


def test_the_header_names_a_friction_time_with_the_profile() -> None:
    """A run with ``physics.friction_time`` is not the profile's physics: its report says so."""
    from peg_ctrl.experiments.report.header import header_section

    rows = [{"controller": "pd"}]
    plain = header_section({"physics": {"profile": "precision", "friction_time": None}}, "x", rows, None)[2]
    assert plain.endswith("physics profile `precision`.")
    slow = header_section({"physics": {"profile": "precision", "friction_time": 0.005}}, "x", rows, None)[2]
    assert slow.endswith(
        "physics profile `precision` with the peg's friction time constant 5 ms (`physics.friction_time`)."
    )


def test_the_header_says_what_the_arms_sensed() -> None:
    """Every report names its sensor model: the F/T sensor, the hand's position, velocity and
    orientation, the camera's noise on the hole, the drawing; a key the grid sweeps varies per
    cell, and results without a recorded domain say so."""
    from peg_ctrl.experiments.report.header import header_section

    rows = [{"controller": "pd"}]
    real = {
        "domain": {"position_noise": 3e-5, "velocity_noise": 0.001, "ft_sensor": ""},
        "task": {"position_noise": 0.0, "drawing_tolerance": 1.5e-4},
        "grid": {"sensor": {"domain.ft_sensor": ["wrist", "forge"], "task.position_noise": [5e-4, 1e-3]}},
    }
    assert header_section(real, "x", rows, None)[4] == (
        "Sensed (docs/sensing.md): the wrist F/T sensor per cell (the grid sweeps it); the hand's "
        "position σ 0.03 mm, velocity σ 1 mm/s (1 mrad/s), orientation exact; the camera's noise on "
        "the hole's position per cell; the drawing ±0.15 mm."
    )
    fields = {
        "domain": {
            "force_noise": 0.5,
            "torque_noise": 0.005,
            "ft_latency": 0.005,
            "ft_bias_drift": 0.005,
            "ft_rate": 100.0,
            "orientation_noise": 1e-4,
        },
        "task": {"position_noise": 7.5e-4},
    }
    assert header_section(fields, "x", rows, None)[4] == (
        "Sensed (docs/sensing.md): the wrist F/T sensor σ 0.5 N and 0.005 N m, 5 ms late, bias drift "
        "0.005 N/√s, 100 Hz; the hand's position exact, velocity exact, orientation σ 0.1 mrad; the "
        "camera's noise on the hole's position σ 0.75 mm per axis; the drawing exact."
    )
    swept = {**fields, "grid": {"domain.ft_latency": [0.0, 0.01], "domain.orientation_noise": [0.0, 1e-4]}}
    line = header_section(swept, "x", rows, None)[4]
    assert "F/T sensor per cell (the grid sweeps it);" in line and "orientation per cell;" in line
    assert header_section({"domain": {"ft_sensor": "wrist"}}, "x", rows, None)[4].startswith(
        "Sensed (docs/sensing.md): the wrist F/T sensor `wrist` (a preset); the hand's position exact"
    )
    assert "F/T sensor ideal;" in header_section({"domain": {}}, "x", rows, None)[4]
    assert (
        header_section({}, "x", rows, None)[4] == "Sensed (docs/sensing.md): not recorded with these results."
    )


def test_a_row_takes_the_friction_time_from_its_job_even_from_an_older_summary(tmp_path: Path) -> None:
    """An episode summary written before ``friction_time_s`` existed still yields the job's
    friction time in its episodes.csv row (a rebuilt table, a resumed sweep)."""
    import json

    from peg_ctrl.experiments.runner import collect_rows

    exp = {"name": "old", "controllers": ["pd"], "seeds": 2, "physics": {"profile": "precision"}}
    for physics, expected in (({"profile": "precision", "friction_time": 0.005}, 0.005), (None, None)):
        jobs = expand(experiment_from_mapping({**exp, **({"physics": physics} if physics else {})}))
        out = tmp_path / str(expected)
        for job in jobs:
            (out / "episodes" / job.key).mkdir(parents=True)
            summary = {"status": "success", "trace_path": "forces.npz"}  # no friction_time_s
            (out / "episodes" / job.key / "summary.json").write_text(json.dumps(summary))
        rows = collect_rows(jobs, out)
        assert len(rows) == 2 and all(r["friction_time_s"] == expected for r in rows)
