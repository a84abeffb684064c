"""``peg-sim validity`` and ``peg-sim bench --physics``: arguments, outputs, the report's content."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from peg_ctrl.sim.validity import CLEARANCES
from peg_ctrl.tools.bench import bench_profiles

from ..conftest import assert_one_line_error, peg_sim, peg_sim_here


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["validity", "--profile", "exact"], "unknown physics profile 'exact'"),
        (["validity", "--trials", "0"], "--trials must be >= 1, got 0"),
        (["validity", "--trials", "many"], "argument --trials: invalid int value"),
        (["validity", "--friction-time", "0.0001"], "--friction-time must be a time constant of at least"),
        (["validity", "--friction-time", "soon"], "argument --friction-time: invalid float value"),
    ],
)
def test_bad_validity_arguments_fail_in_one_line(tmp_path: Path, argv: list[str], message: str) -> None:
    assert_one_line_error(peg_sim_here([*argv, "--out", "v"], cwd=tmp_path), message)
    assert not (tmp_path / "v").exists()


@pytest.mark.slow
def test_validity_battery_writes_its_tables_and_plots(tmp_path: Path) -> None:
    proc = peg_sim(["validity", "--profile", "precision", "--trials", "1", "--out", "v"], cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    out = tmp_path / "v"
    data = json.loads((out / "validity.json").read_text())
    rows = data["profiles"]["precision"]["clearance"]
    assert [r["case_clearance"] for r in rows] == list(CLEARANCES)
    assert [r["inserted"] for r in rows] == [True, True, True, True, False, False]
    md = (out / "validity.md").read_text()
    assert "| +0.250 | 1/1 |" in md and "| -0.020 | 0/1 |" in md
    for name in ("clearance.png", "force_depth.png"):
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.slow
def test_validity_battery_runs_precision_with_a_slower_friction_too(tmp_path: Path) -> None:
    """``--friction-time``: the battery on precision with the peg's friction at that time
    constant, under its own name. Its insertion and chamfer bars hold; its entry bar does not
    (at 0 mm the aligned push enters 2 mm: docs/physics.md, "Known limits")."""
    argv = ["validity", "--profile", "precision", "--friction-time", "0.005", "--trials", "1", "--out", "v"]
    proc = peg_sim(argv, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    data = json.loads((tmp_path / "v" / "validity.json").read_text())
    assert list(data["profiles"]) == ["precision", "precision, friction 5 ms"]
    slow = data["profiles"]["precision, friction 5 ms"]
    assert [r["inserted"] for r in slow["clearance"]] == [True, True, True, True, False, False]
    expected = [r for r in slow["chamfer"] if r["expected_capture"] is not None]
    assert [r["depth"] > 0.001 for r in expected] == [True, True, True, False, False]  # past the chamfer


@pytest.mark.slow
def test_bench_physics_times_each_profile_in_each_situation() -> None:
    result = bench_profiles(n_steps=20, repeats=1)
    rows = result["rows"]
    assert {(r["profile"], r["situation"]) for r in rows} == {
        (p, s)
        for p in ("seed", "precision")
        for s in ("on top face", "0 clearance", "1 deg tilt", "chamfer rim")
    }
    for r in rows:
        assert r["contacts"] > 0 and r["step_us_median"] > 0
        assert r["us_per_simulated_ms"] == pytest.approx(r["step_us_median"] / r["timestep_ms"])
    assert all(r["cost_vs_seed"] == 1.0 for r in rows if r["profile"] == "seed")
