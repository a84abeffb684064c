"""CI keeps the committed studies honest: one episode of each committed study (its cheapest that
touches the block) rerun on this machine and classed under the rule ``peg-sim compare`` applies
(peg_ctrl.experiments.baseline), and bit for bit where this machine's environment is one the study
records as reproducing it: a change that moves a study fails here, at landing, not on a user's
machine. And every study records what it was made with, and every arm its calibration."""

from __future__ import annotations

import functools
import json

import pytest

from peg_ctrl.environment import ENVIRONMENT_FILE, differences, environment
from peg_ctrl.experiments.baseline import CLASSES, classify, committed_studies, load_calibration, tolerance
from peg_ctrl.experiments.config import Job
from peg_ctrl.experiments.reproduction import Study, load_study
from peg_ctrl.experiments.runner import collect_rows, run_jobs

#: Committed studies that no longer run on this code, and why: kept as the record of what they found.
HISTORICAL = {
    "contact": "its experiment.json sets task.contact_force, which the estimation refactor removed (the "
    "force strategies test against the sensor's noise since): its episodes cannot be rerun as they ran",
    "plan": "its sampling_mpc arms ran the hand-over strategy when it was named plan (now handover; plan "
    "is the planner over skills): its experiment.json and episode keys name plan, so a rerun would run "
    "the other strategy (experiments/configs/plan.yaml runs the study again, as handover)",
}
#: How each historical study fails to load as it ran (a rename loads, as something else).
_NO_LONGER = {"contact": "unknown field"}
STUDIES = {name: path for name, path in committed_studies().items() if name not in HISTORICAL}


@functools.cache
def _study(name: str) -> Study:
    """The study with every committed episode of every arm (read once: it expands the grid)."""
    return load_study(name, per_arm=10**6)


def _cheapest(name: str) -> tuple[Job, dict[str, str]]:
    """The study's committed episode that touched the block in the least wall time."""
    study = _study(name)
    touched = [
        (float(row["wall_time_s"]), job.key, job)
        for jobs in study.sample.values()
        for job in jobs
        if (row := study.committed[job.key]).get("first_contact_s")
    ]
    job = min(touched, key=lambda t: t[:2])[2]
    return job, study.committed[job.key]


@pytest.fixture(scope="module")
def reruns(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[Job, dict[str, str], dict]]:
    out = tmp_path_factory.mktemp("committed")
    picked = {name: _cheapest(name) for name in STUDIES}
    run_jobs([job for job, _ in picked.values()], out, workers=2, progress=False, record_time=False)
    return {name: (job, row, collect_rows([job], out)[0]) for name, (job, row) in picked.items()}


def test_the_committed_studies_are_found() -> None:
    assert {"contact_hard", "contact_real"} <= set(STUDIES) and len(STUDIES) >= 10


@pytest.mark.parametrize("name", sorted(_NO_LONGER))
def test_only_the_historical_studies_no_longer_load(name: str) -> None:
    from peg_ctrl.errors import ConfigError

    with pytest.raises(ConfigError, match=_NO_LONGER[name]):
        load_study(name, per_arm=1)


def test_the_plan_study_ran_the_strategy_now_named_handover() -> None:
    """Its sampling_mpc arms name ``plan``, the hand-over that is ``handover`` now."""
    path = committed_studies()["plan"] / "experiment.json"
    arms = json.loads(path.read_text())["arms"]
    assert arms["sampling_mpc(hypotheses=4)"] == ["plan"] and arms["mpc"] == ["locate"]


@pytest.mark.parametrize("name", sorted(STUDIES))
def test_a_rerun_of_each_committed_study_is_not_classed_differs(reruns: dict, name: str) -> None:
    job, committed, fresh = reruns[name]
    verdict = classify(committed, fresh, tolerance(name, job.arm))
    assert verdict.cls in CLASSES
    assert verdict.cls != "differs", f"{name} {job.arm} episode {job.key}: {verdict.detail()}"
    # In an environment the study records as reproducing it, nothing may move at all: a change
    # that moves only what follows the first contact fails here too.
    records = json.loads((STUDIES[name] / ENVIRONMENT_FILE).read_text()).values()
    if any(not differences(record, environment()) for record in records):
        assert verdict.cls == "reproduced", f"{name} {job.arm} episode {job.key}: {verdict.detail()}"


@pytest.mark.parametrize("name", sorted(STUDIES))
def test_each_committed_study_records_its_environment_and_lock(name: str) -> None:
    records = json.loads((STUDIES[name] / ENVIRONMENT_FILE).read_text())
    assert records, name
    for record in records.values():
        assert record["packages"]["mujoco"] and record["blas"]["kernels"]
        assert record["lock"]["file"] == "requirements/lock.txt" and record["lock"]["off_lock"] == []


def test_every_committed_study_arm_has_measured_tolerances() -> None:
    studies = load_calibration()["studies"]
    for name in STUDIES:
        arms = set(_study(name).sample)
        assert arms <= set(studies.get(name, {})), (
            f"{name}: uncalibrated arms {arms - set(studies.get(name, {}))}"
        )
        for arm in arms:
            assert studies[name][arm]["episodes"] >= 6 and tolerance(name, arm).source == "calibrated"
