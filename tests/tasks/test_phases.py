"""The phase machine on a synthetic table: guards, timeouts, hooks, records (no physics)."""

from __future__ import annotations

import numpy as np
import pytest

from peg_ctrl.commands import GripperTarget
from peg_ctrl.errors import EpisodeFailure
from peg_ctrl.sim.state import ControlState, PegObservation
from peg_ctrl.tasks.base import Observation
from peg_ctrl.tasks.phases import DONE, PhaseMachine, PhaseSpec, Timeout

Z3 = np.zeros(3)
PEG = PegObservation(Z3, np.array([1.0, 0, 0, 0]), np.array([0, 0, 1.0]), Z3, 0.0, 0.0)


def obs(t: float) -> Observation:
    return Observation(t, ControlState(t, Z3, np.array([1.0, 0, 0, 0]), Z3, Z3, 0.0), PEG)


class Hold:
    """A trajectory of fixed duration that rests at one target."""

    def __init__(self, duration: float, z: float) -> None:
        self.duration = duration
        self.z = z

    def sample(self, t: float) -> GripperTarget:
        return GripperTarget(
            p_world=np.array([0.0, 0.0, self.z]), quat_world=np.array([1.0, 0, 0, 0]), jaw_sep_m=0.0
        )


def machine(guard_a=lambda o: None, timeout_a=None, exit_a=None) -> PhaseMachine:  # type: ignore[no-untyped-def]
    return PhaseMachine(
        {
            "a": PhaseSpec(lambda o: Hold(1.0, 1.0), guard_a, "b", timeout_a, exit=exit_a),
            "b": PhaseSpec(lambda o: Hold(0.5, 2.0), lambda o: "ok" if o.t >= 5.0 else None, DONE),
        }
    )


def test_guard_moves_to_the_next_phase_and_closes_the_record() -> None:
    m = machine(guard_a=lambda o: "ok" if o.t >= 0.3 else None)
    m.start("a", obs(0.0))
    assert m.update(obs(0.2)).p_world[2] == 1.0
    assert m.phase == "a"
    target = m.update(obs(0.3))
    assert m.phase == "b" and target.p_world[2] == 2.0
    assert [(r.phase, r.t_start, r.t_end, r.outcome) for r in m.records] == [
        ("start", 0.0, 0.0, "ok"),
        ("a", 0.0, 0.3, "ok"),
        ("b", 0.3, None, ""),
    ]


@pytest.mark.parametrize(
    ("timeout", "last_running", "first_expired"),
    [
        (Timeout(0.5, after_motion=True), 1.5, 1.51),  # 1 s motion + 0.5 s
        (Timeout(0.5), 1.0, 1.01),  # a total budget is never shorter than the motion
        (Timeout(3.0), 3.0, 3.01),
    ],
)
def test_timeouts(timeout: Timeout, last_running: float, first_expired: float) -> None:
    m = machine(timeout_a=timeout)
    m.start("a", obs(0.0))
    m.update(obs(last_running))
    assert m.phase == "a"
    m.update(obs(first_expired))
    assert m.phase == "b"
    assert m.records[1].outcome == "timeout"


def test_done_keeps_the_last_motion_and_stops_advancing() -> None:
    m = machine(guard_a=lambda o: "ok")
    m.start("a", obs(0.0))
    m.update(obs(0.1))
    m.update(obs(5.0))
    assert m.phase == DONE
    assert m.update(obs(9.0)).p_world[2] == 2.0
    assert m.records[-1].t_end == 5.0


def test_an_exit_hook_failure_leaves_the_record_for_finish() -> None:
    def fail(o: Observation) -> None:
        raise EpisodeFailure("grasp_lost", "nothing in the jaw")

    m = machine(guard_a=lambda o: "ok", exit_a=fail)
    m.start("a", obs(0.0))
    with pytest.raises(EpisodeFailure, match="grasp_lost"):
        m.update(obs(0.1))
    assert m.phase == "a" and m.records[-1].t_end is None
    m.close_record(0.1, "grasp_lost")
    assert (m.records[-1].t_end, m.records[-1].outcome) == (0.1, "grasp_lost")
