"""The task interface: what each task declares it offers, and the check of that declaration."""

from __future__ import annotations

import dataclasses
import re
from typing import Any, ClassVar

import mujoco
import numpy as np
import pytest

from peg_ctrl.commands import GripperTarget
from peg_ctrl.controllers import make_controller
from peg_ctrl.gym.env import AgentTask
from peg_ctrl.run.episode import build_loop, episode_config_from_mapping
from peg_ctrl.run.loop import Loop
from peg_ctrl.sim.scene import SceneConfig
from peg_ctrl.tasks import TASKS, TrackingTask
from peg_ctrl.tasks.base import (
    BeliefTask,
    Capabilities,
    InsertionTask,
    SkillTask,
    TaskContext,
    TaskSpec,
    belief_task,
    check_capabilities,
    insertion_task,
)
from peg_ctrl.teleop.task import TeleopTask

HOME = GripperTarget(p_world=np.array([-0.2, 0.0, 0.2]), quat_world=np.array([1.0, 0, 0, 0]), jaw_sep_m=0.085)

#: What each registered task offers beyond the Task protocol.
REGISTERED = {
    "pick_and_place": Capabilities(insertion=True),
    "held_insertion": Capabilities(insertion=True, belief=True, skills=True),
}


@pytest.fixture(scope="module")
def loops() -> dict[str, Loop]:
    """A loop of each registered task (building it checks the task's declaration)."""
    return {name: build_loop(episode_config_from_mapping({"task": {"name": name}})) for name in TASKS}


@pytest.mark.parametrize("name", sorted(REGISTERED))
def test_each_registered_task_declares_what_it_offers(name: str, loops: dict[str, Loop]) -> None:
    assert set(TASKS) == set(REGISTERED)
    task = loops[name].task
    declared = REGISTERED[name]
    assert task.capabilities == declared
    assert (insertion_task(task) is task) is declared.insertion
    assert (belief_task(task) is task) is declared.belief


def test_an_insertion_task_reaches_its_measure_and_its_seated_hold(loops: dict[str, Loop]) -> None:
    loop = loops["held_insertion"]
    loop.reset(np.random.default_rng(0))
    inserting = insertion_task(loop.task)
    assert inserting is not None
    m = inserting.insertion.measure(loop.peg)  # type: ignore[arg-type]
    assert m.depth_m == pytest.approx(-0.003, abs=5e-4)  # task.start_height above the mouth
    assert m.lateral_error_m == pytest.approx(0.0015, abs=2e-4)  # task.lateral_error
    assert inserting.time_to_insert is None and inserting.seated.since is None


def test_the_drivers_own_tasks_declare_theirs(loops: dict[str, Loop]) -> None:
    """Tracking and teleoperation offer nothing beyond the protocol (teleoperation's settled
    check is the session's, not a seated hold); the Gymnasium env's agent task offers the
    insertion check of the task it wraps."""
    tracking = TrackingTask(HOME)
    agent = AgentTask(loops["pick_and_place"].task)
    for task, declared in [(tracking, Capabilities()), (agent, Capabilities(insertion=True))]:
        check_capabilities(task)
        assert task.capabilities == declared
    assert TeleopTask.capabilities == Capabilities()
    assert insertion_task(agent) is agent and belief_task(agent) is None
    assert agent.insertion is loops["pick_and_place"].task.insertion  # type: ignore[attr-defined]


def test_each_capability_is_a_protocol_s_members() -> None:
    assert [f.name for f in dataclasses.fields(Capabilities)] == ["insertion", "belief", "skills"]
    assert {"insertion", "seated", "time_to_insert"} <= set(vars(InsertionTask)) | set(
        InsertionTask.__annotations__
    )
    assert "belief" in vars(BeliefTask)
    assert {"readings", "skill_log"} <= set(vars(SkillTask))


class Boasting(TrackingTask):
    """Claims an insertion check it does not have."""

    capabilities: ClassVar[Capabilities] = Capabilities(insertion=True)


class Secretive(TrackingTask):
    """Has a belief it does not declare."""

    @property
    def belief(self) -> Any:
        raise AssertionError("the check must not evaluate a property")


class Silent:
    """A task from before capabilities were declared."""

    name = "silent"
    phases = ("silent",)


@dataclasses.dataclass(frozen=True)
class BoastingConfig(TaskSpec):
    name: ClassVar[str] = "boasting"

    def build(self, context: TaskContext) -> Boasting:
        return Boasting(HOME)


def test_a_task_claiming_a_capability_it_lacks_is_refused_when_its_episode_is_built() -> None:
    cfg = dataclasses.replace(episode_config_from_mapping({}), task=BoastingConfig())
    with pytest.raises(TypeError) as caught:
        build_loop(cfg)
    assert str(caught.value) == (
        "task Boasting declares capability 'insertion' but lacks insertion, seated, time_to_insert"
    )


@pytest.mark.parametrize(
    ("task", "message"),
    [
        (
            Secretive(HOME),
            r"^task Secretive has belief but does not declare capability 'belief' "
            r"\(capabilities = Capabilities\(belief=True\)\)$",
        ),
        (Silent(), r"^task Silent does not declare its capabilities"),
    ],
)
def test_a_task_with_undeclared_members_or_no_declaration_is_refused_by_the_loop(
    model: mujoco.MjModel, task: Any, message: str
) -> None:
    with pytest.raises(TypeError, match=message):
        check_capabilities(task)
    with pytest.raises(TypeError, match=message):
        Loop(model=model, controller=make_controller("pd", model), task=task, scene=SceneConfig())


def test_strategy_name_is_declared_by_the_task_config() -> None:
    held = episode_config_from_mapping({"task": {"name": "held_insertion", "strategy": "tilt"}})
    assert held.task.strategy_name == "tilt"
    assert episode_config_from_mapping({}).task.strategy_name == ""


def test_a_task_config_replaces_its_strategy_or_says_it_has_none() -> None:
    from peg_ctrl.errors import ConfigError
    from peg_ctrl.tasks.held_insertion import HeldInsertionConfig
    from peg_ctrl.tasks.pick_and_place import TaskConfig as PickAndPlaceConfig
    from peg_ctrl.tasks.strategies import STRATEGIES

    spiral = STRATEGIES["spiral"]()
    held = HeldInsertionConfig().with_strategy(spiral)
    assert held.strategy == spiral and held.strategy_name == "spiral"
    assert dataclasses.replace(held, strategy=HeldInsertionConfig().strategy) == HeldInsertionConfig()
    message = "task 'pick_and_place' has no strategy to replace; use task: {name: held_insertion}"
    with pytest.raises(ConfigError, match=f"^{re.escape(message)}$"):
        PickAndPlaceConfig().with_strategy(spiral)
