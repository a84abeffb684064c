"""A phase machine driven by a declarative table.

Each phase is one row, :class:`PhaseSpec`: how it is entered (a planned trajectory), the
guard that ends it (returning an outcome such as ``"ok"`` or ``None`` while it runs), its
:class:`Timeout`, optional ``tick`` and ``exit`` hooks, and the next phase. The machine plays
the phase's trajectory, and on leaving a phase closes its :class:`~peg_ctrl.tasks.base.PhaseRecord`
with the outcome (``"timeout"`` when the time budget ran out first, after which the machine goes on).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping

from peg_ctrl.commands import GripperTarget
from peg_ctrl.planners.base import MotionLimits, Planner, Trajectory, Waypoint
from peg_ctrl.tasks.base import Observation, PhaseRecord, close_open_record

__all__ = ["DONE", "Motion", "PlannedMoves", "Timeout", "PhaseSpec", "PhaseMachine", "TrajectorySequence"]

DONE = "done"


class TrajectorySequence:
    """Trajectories played one after another."""

    def __init__(self, parts: list[Trajectory]) -> None:
        self.parts = parts
        self.duration = sum(p.duration for p in parts)

    def sample(self, t: float) -> GripperTarget:
        for part in self.parts[:-1]:
            if t < part.duration:
                return part.sample(t)
            t -= part.duration
        return self.parts[-1].sample(t)


Motion = Trajectory | TrajectorySequence  # what a phase plays


class PlannedMoves:
    """A task's moves from goal to goal: each planned from the last goal (not from where the
    gripper is), with the task's motion limits unless others are given."""

    planner: Planner
    limits: MotionLimits
    _goal: Waypoint

    def _move(self, goal: Waypoint, limits: MotionLimits | None = None) -> Motion:
        """Plan from the last goal to ``goal``, which becomes the last goal."""
        trajectory = self.planner.plan(self._goal, goal, limits or self.limits)
        self._goal = goal
        return trajectory


@dataclasses.dataclass(frozen=True)
class Timeout:
    """A phase's time budget [s].

    ``after_motion``: the budget starts when the phase's motion ends (a settling allowance);
    otherwise it is a total from the phase's start, never shorter than the motion itself.
    """

    seconds: float
    after_motion: bool = False

    def expired(self, elapsed: float, motion_duration: float) -> bool:
        if self.after_motion:
            return elapsed > motion_duration + self.seconds
        return elapsed > max(self.seconds, motion_duration)


Guard = Callable[[Observation], "str | None"]
Hook = Callable[[Observation], None]


@dataclasses.dataclass(frozen=True)
class PhaseSpec:
    """One row of the phase table."""

    enter: Callable[[Observation], Motion]
    guard: Guard  # outcome when the phase is complete, else None
    next: str | Callable[[Observation], str]  # the phase that follows (or DONE)
    timeout: Timeout | None = None
    tick: Hook | None = None  # every control step while the phase runs, before the guard
    exit: Hook | None = None  # once, when the phase is left (may raise EpisodeFailure)


class PhaseMachine:
    """Runs a phase table: at most one transition per control step."""

    def __init__(self, table: Mapping[str, PhaseSpec]) -> None:
        self.table = table
        self.phase = DONE
        self.records: list[PhaseRecord] = []
        self.motion: Motion | None = None
        self._t0 = 0.0

    def elapsed(self, t: float) -> float:
        """Time [s] since the current phase started."""
        return t - self._t0

    def motion_over(self, t: float) -> bool:
        assert self.motion is not None
        return self.elapsed(t) >= self.motion.duration

    def start(self, phase: str, obs: Observation) -> None:
        self.records = [PhaseRecord("start", obs.t, obs.t, "ok")]
        self._enter(phase, obs)

    def _enter(self, phase: str, obs: Observation) -> None:
        self.motion = self.table[phase].enter(obs)
        self.phase = phase
        self._t0 = obs.t
        self.records.append(PhaseRecord(phase, obs.t))

    def close_record(self, t: float, outcome: str) -> None:
        """End the open record at ``t``; an outcome set earlier is kept."""
        close_open_record(self.records, t, outcome)

    def update(self, obs: Observation) -> GripperTarget:
        """Advance the phase if its guard holds or its time is up; the target for ``obs.t``."""
        if self.phase != DONE:
            spec = self.table[self.phase]
            if spec.tick is not None:
                spec.tick(obs)
            outcome = spec.guard(obs)
            if outcome is None and spec.timeout is not None:
                assert self.motion is not None
                if spec.timeout.expired(self.elapsed(obs.t), self.motion.duration):
                    outcome = "timeout"
            if outcome is not None:
                self._leave(spec, outcome, obs)
        return self.target(obs.t)

    def _leave(self, spec: PhaseSpec, outcome: str, obs: Observation) -> None:
        if spec.exit is not None:
            spec.exit(obs)
        self.records[-1].outcome = outcome
        self.close_record(obs.t, outcome)
        following = spec.next if isinstance(spec.next, str) else spec.next(obs)
        if following == DONE:
            self.phase = DONE  # the last motion keeps being tracked
        else:
            self._enter(following, obs)

    def target(self, t: float) -> GripperTarget:
        assert self.motion is not None
        return self.motion.sample(self.elapsed(t))
