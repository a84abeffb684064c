"""The rule that classes a rerun of a committed episode: reproduced, agrees or differs
(peg_ctrl.experiments.baseline)."""

from __future__ import annotations

import pytest

from peg_ctrl.experiments.baseline import Tolerance, Verdict, classify, classify_arm, tolerance

ROW = {
    "key": "k",
    "first_contact_s": "",  # a rerun of an episode that never touched the block
    "status": "success",
    "end_state": "seated",
    "peak_force_10ms_n": "3.5",
    "time_to_insert_s": "11.36",
    "wall_time_s": "4.2",
    "environment": "aaaaaaaaaaaa",
}
TOL = Tolerance({"peak_force_10ms_n": 0.2, "time_to_insert_s": 0.05}, frozenset({"end_state"}))


def _fresh(**changes: object) -> dict[str, object]:
    number = {k: float(v) if k.endswith(("_n", "_s")) and v else v or None for k, v in ROW.items()}
    return {**number, **changes}


def test_the_same_numbers_are_reproduced_whatever_the_wall_clock_and_machine() -> None:
    assert classify(ROW, _fresh(wall_time_s=9.9, environment="bbbbbbbbbbbb"), TOL) == Verdict("reproduced")


def test_a_move_within_the_measured_drift_agrees_and_names_the_closest_column() -> None:
    verdict = classify(ROW, _fresh(peak_force_10ms_n=3.6, time_to_insert_s=11.4), TOL)
    assert verdict.cls == "agrees" and verdict.column == "time_to_insert_s" and verdict.moved == 2
    assert verdict.detail() == "time_to_insert_s was 11.36, is 11.4 (allowed 0.05); 2 columns moved"


def test_a_move_beyond_it_differs() -> None:
    verdict = classify(ROW, _fresh(peak_force_10ms_n=3.75), TOL)
    assert (verdict.cls, verdict.column, verdict.allowed) == ("differs", "peak_force_10ms_n", 0.2)


@pytest.mark.parametrize(
    ("changes", "cls"),
    [
        ({"end_state": "wedged"}, "agrees"),  # the perturbations changed it for this arm
        ({"status": "failure"}, "differs"),  # they never did
        ({"time_to_insert_s": None}, "differs"),  # a number gone: an outcome changed
    ],
)
def test_an_outcome_may_change_only_where_the_perturbations_changed_it(changes: dict, cls: str) -> None:
    assert classify(ROW, _fresh(**changes), TOL).cls == cls


def test_an_arm_is_its_worst_episode() -> None:
    verdicts = [Verdict("reproduced"), Verdict("differs", "x"), Verdict("agrees", "y")]
    assert classify_arm(verdicts).cls == "differs" and classify_arm(verdicts[::2]).cls == "agrees"


CALIBRATION = {
    "factor": 2.0,
    "studies": {
        "s": {
            "quiet": {"drift": {"f": 0.0}, "may_change": [], "episodes": 6},
            "mid": {"drift": {"f": 0.1}, "may_change": [], "episodes": 6},
            "wild": {"drift": {"f": 1.0}, "may_change": ["status"], "episodes": 6},
        }
    },
}


def test_the_tolerance_is_twice_the_largest_drift_of_any_arm_and_outcomes_are_the_arms_own() -> None:
    assert tolerance("s", "wild", CALIBRATION).numbers == {"f": 2.0}
    assert tolerance("s", "wild", CALIBRATION).may_change == {"status"}
    assert tolerance("s", "quiet", CALIBRATION).numbers == {"f": 2.0}  # what chaos did anywhere, not 0
    assert tolerance("s", "quiet", CALIBRATION).may_change == frozenset()
    assert tolerance("s", "quiet", CALIBRATION).source == "calibrated"


def test_an_uncalibrated_arm_gets_the_largest_drift_and_no_outcome_change() -> None:
    tol = tolerance("mine", "pd", CALIBRATION)
    assert tol.numbers == {"f": 2.0} and tol.may_change == frozenset()
    assert tol.source.startswith("uncalibrated")
    assert tolerance("s", "quiet", {}).numbers == {}  # no calibration at all: it must reproduce


TOUCHED = {**ROW, "first_contact_s": "0.9895"}


def test_after_a_contact_anything_agrees_but_the_approach_must_reproduce() -> None:
    chaos = {**_fresh(status="failure", peak_force_10ms_n=40.0), "first_contact_s": 0.9895}
    verdict = classify(TOUCHED, chaos, TOL)
    assert verdict.cls == "agrees" and verdict.allowed is None
    moved = {**chaos, "first_contact_s": 0.99}  # one step later: another approach
    assert classify(TOUCHED, moved, TOL) == Verdict("differs", "first_contact_s", "0.9895", "0.99", 0.0, 3)
    other_physics = {**_fresh(), "first_contact_s": 0.9895, "physics": "seed"}
    assert classify({**TOUCHED, "physics": "precision"}, other_physics, TOL).column == "physics"
