"""``peg-sim crosscheck``: the same situations in MuJoCo and in Drake (installed: the dev extra),
physics run. What it must show: the rig is one mechanical system in both engines, a tilted slide
touches where its geometry says, MuJoCo's convex contact kicks where Drake's lagged contact
slides (and the studies' model and metric agree with the latter), an impact is an impact in
every model, and a peg with no clearance enters under the lagged contact."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from peg_ctrl.errors import ConfigError
from peg_ctrl.tools.crosscheck import drake_rig
from peg_ctrl.tools.crosscheck.battery import CHOSEN, REFERENCE, measure, model
from peg_ctrl.tools.crosscheck.report import agrees
from peg_ctrl.tools.crosscheck.rig import Rig, Trace, run_situation, study_rig
from peg_ctrl.tools.crosscheck.situations import Situation, coulomb_slide_force, situation

from ..conftest import assert_one_line_error, peg_sim, peg_sim_here

SLIDE = "slide_30mms_1.5mrad_mu0.9"


@pytest.fixture(scope="module")
def rig() -> Rig:
    return study_rig()


@pytest.fixture(scope="module")
def slide(rig: Rig) -> dict[str, tuple[Trace, dict[str, float]]]:
    s = situation(SLIDE)
    out = {}
    for name in ("mujoco", CHOSEN, REFERENCE, "drake_similar"):
        trace = run_situation(model(name).build(rig, s), rig, s)
        out[name] = (trace, measure(s, trace, rig))
    return out


def test_the_rig_holds_the_touch_of_the_study_controller(rig: Rig) -> None:
    # The contact MPC's inner loop on contact_real's scene (docs/contact_real.md: 3828 N/m).
    assert rig.k_lin == pytest.approx(3828.3, abs=1.0)
    assert 1.1 < rig.mass < 1.2 and 1000.0 < rig.k_rot < 1300.0
    assert rig.d_lin > 100.0  # the LQR's damping on top of the slides' 100 N s/m


def test_without_contact_both_engines_move_the_hand_alike(rig: Rig) -> None:
    """The same law on the same hand: out of contact, the trajectories agree to a nanometre."""
    s = Situation(
        name="air",
        kind="slide",
        description="in the air",
        friction=0.9,
        clearance=0.05e-3,
        chamfer=1e-3,
        tilt=0.0,
        start=(0.0, 0.0, 0.02),
        velocity=(0.0, 0.0, -0.03),
        travel=0.003,
        hold=0.4,
        press_x=2.0,  # the reference 0.52 mm aside: the hand swings over and settles there
    )
    ends = {}
    for name in ("mujoco", REFERENCE):
        trace = run_situation(model(name).build(rig, s), rig, s)
        assert not trace.normal.any()
        ends[name] = np.column_stack([trace.x, trace.depth])
    assert np.abs(ends["mujoco"] - ends[REFERENCE]).max() < 1e-9
    assert ends["mujoco"][-1, 0] == pytest.approx(2.0 / rig.k_lin, rel=0.02)  # settled: 2 N of stiffness


def test_a_tilted_slide_touches_where_its_geometry_says(
    slide: dict[str, tuple[Trace, dict[str, float]]], rig: Rig
) -> None:
    s = situation(SLIDE)
    trace, numbers = slide[REFERENCE]
    first = int(np.argmax(trace.normal > 0.0))
    assert trace.depth[first] == pytest.approx(s.touch_depth, abs=0.3e-3)
    # the lagged contact slides as quasi-static rigid Coulomb contact would
    normal_at_end = coulomb_slide_force(s, rig.k_lin, float(trace.depth[-1]))
    assert trace.normal[-50:].mean() == pytest.approx(normal_at_end, rel=0.3)
    assert numbers["sustained_10ms_n"] == pytest.approx(normal_at_end * math.hypot(1.0, s.friction), rel=0.3)


def test_the_convex_models_kick_where_the_lagged_contact_slides(
    slide: dict[str, tuple[Trace, dict[str, float]]],
) -> None:
    lagged = slide[REFERENCE][1]
    assert lagged["peak_net_n"] < 1.0 and lagged["contact_steps"] > 500  # one continuous slide
    for convex in ("mujoco", "drake_similar"):  # one-step kicks, tens of newtons
        kicked = slide[convex][1]
        assert kicked["peak_net_n"] > 30.0 * lagged["peak_net_n"], convex
        assert kicked["contact_steps"] < 0.2 * lagged["contact_steps"], convex
    # the precision profile's kicks hold the peg off the wall: even over 10 ms they are no slide
    assert not agrees(slide["mujoco"][1]["sustained_10ms_n"], lagged["sustained_10ms_n"])
    # the studies' model and force: the peg's friction at 5 ms, the force sustained over 10 ms
    chosen = slide[CHOSEN][1]
    assert agrees(chosen["sustained_10ms_n"], lagged["sustained_10ms_n"])
    assert chosen["peak_net_n"] > 10.0 * lagged["peak_net_n"]  # its one-step peak does not agree


def test_an_impact_is_an_impact_in_every_model(rig: Rig) -> None:
    s = situation("land_face_30mms")
    got = {}
    for name in ("mujoco", REFERENCE):
        trace = run_situation(model(name).build(rig, s), rig, s)
        got[name] = measure(s, trace, rig)
    for numbers in got.values():
        assert numbers["peak_net_n"] > 40.0  # a stiff landing at 30 mm/s: tens of newtons
        assert numbers["sustained_10ms_n"] > 10.0  # the 10 N push and the landing's momentum
    assert agrees(got["mujoco"]["sustained_10ms_n"], got[REFERENCE]["sustained_10ms_n"])


def test_a_peg_with_no_clearance_enters_under_the_lagged_contact(rig: Rig) -> None:
    """An exact fit is no obstacle to rigid Coulomb contact: the aligned 0 mm push enters in
    Drake's lagged contact, where MuJoCo's precision profile holds it at the mouth."""
    s = situation("entry_0mm")
    depth = {}
    for name in ("mujoco", REFERENCE):
        trace = run_situation(model(name).build(rig, s), rig, s)
        depth[name] = float(trace.depth.max())
    assert depth[REFERENCE] > 0.005 and depth["mujoco"] < 0.001


def test_without_drake_the_crosscheck_says_how_to_install_it(monkeypatch: pytest.MonkeyPatch) -> None:
    assert drake_rig.drake_available()  # the dev extra installs it: the tests above ran it
    monkeypatch.setattr(drake_rig, "drake_available", lambda: False)
    with pytest.raises(
        ConfigError, match=r"needs Drake, which is not installed: pip install 'peg-ctrl\[crosscheck\]'"
    ):
        drake_rig.require_drake()


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--situation", "slide_fast"], "unknown situation 'slide_fast'; known: entry_-0.02mm"),
        (["--model", "bullet"], "unknown contact model 'bullet'; known: drake_lagged"),
        (["--workers", "0"], "--workers must be >= 1, got 0"),
    ],
)
def test_bad_crosscheck_arguments_fail_in_one_line(tmp_path: Path, argv: list[str], message: str) -> None:
    assert_one_line_error(peg_sim_here(["crosscheck", *argv, "--out", "c"], cwd=tmp_path), message)
    assert not (tmp_path / "c").exists()


def test_crosscheck_writes_its_table_record_and_plots(tmp_path: Path) -> None:
    argv = ["crosscheck", "--situation", SLIDE, "--workers", "1", "--out", "c"]
    for name in ("mujoco", CHOSEN, REFERENCE):
        argv += ["--model", name]
    proc = peg_sim(argv, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    out = tmp_path / "c"
    data = json.loads((out / "crosscheck.json").read_text())
    assert [(r["situation"], r["model"]) for r in data["rows"]] == [
        (SLIDE, "mujoco"),
        (SLIDE, CHOSEN),
        (SLIDE, REFERENCE),
    ]
    assert data["environment"]["drake"] != "not installed" and data["rig"]["k_lin"] > 3000.0
    md = (out / "crosscheck.md").read_text()
    assert f"| {SLIDE} | " in md and f"| {CHOSEN} | 1 of 1 | – |" in md and "| mujoco | 0 of 1 |" in md
    for name in ("sustained.png", "traces.png"):
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
