"""``plan``: the planner over skills. No order is written down: at each decision it chooses the
next touch by the expected time to a confident insertion, over the task's belief.

The skills are ``locate``'s and ``probe``'s (:mod:`peg_ctrl.tasks.strategies.skills`), each a
unit with its moves: ``sides`` (the end against two of the block's sides, one touched again with
the hand turned: the end in the hand and the hole in the world), ``rock`` (land on a datum of the
face, turned either way about the pads' normal, and land again: the tilt in the hand and the
face's height), ``mouth`` (landings a particle belief chooses until the end is in the bore),
``centre`` (the end pushed against the mouth's walls: the bore's axis) and ``descent`` (down the
bore, seated). Each reading updates the task's belief
(:class:`~peg_ctrl.tasks.belief.TaskBelief`) through the skill's measurement model
(:mod:`~peg_ctrl.tasks.strategies.skills.models`), which also tells, before a touch, what it
would teach and so how the belief would stand after it.

A decision (:meth:`PlanStrategy.choose`) looks at every sequence of skills that ends in a descent
(each skill at most once before the mouth is found, the mouth found again after a skill that
leaves it, the centring before the descent), rolls the belief's covariance forward through their
models, and takes the first skill of the sequence with the least expected time: the skills'
expected durations (the mouth's by the landings its search is expected to need) plus
``failure_cost`` times the chance that the descent fails for a tilt the belief does not know to
``tilt_tolerance``. It takes the descent when the belief says it will enter the clearance: the
end centred in the mouth and the tilt known to within ``tilt_tolerance`` (95 %). Each decision
is logged with each skill's expected information per expected second (what the belief would
learn of where the end must go and of the tilt, in bits) and its own compute time.

``fixed_order: true`` plays the same skills in ``locate``'s order instead (sides, rock, mouth, centre,
descent): the ablation of the choice.

Phases: ``approach`` (still, over the observed hole), ``skills`` (the planner's), ``hold``.
"""

from __future__ import annotations

import dataclasses
import math
import time
from typing import ClassVar

import numpy as np

from peg_ctrl.commands import GripperTarget
from peg_ctrl.errors import ConfigError
from peg_ctrl.planners.base import Waypoint
from peg_ctrl.sim.belief import HoleBelief
from peg_ctrl.sim.rotations import rotate_inv
from peg_ctrl.sim.scene import SceneConfig
from peg_ctrl.tasks.base import Observation
from peg_ctrl.tasks.belief import Reading, TaskBelief
from peg_ctrl.tasks.phases import DONE, Motion, PhaseMachine, PhaseSpec, Timeout, TrajectorySequence
from peg_ctrl.tasks.strategies.base import HeldInsertion, TaskDisturbance, never
from peg_ctrl.tasks.strategies.locate import LocateConfig, LocateStrategy
from peg_ctrl.tasks.strategies.skills import RockCalibration, SideTouches, upright
from peg_ctrl.tasks.strategies.skills.models import DURATION, LANDING_S, expected_landings, reading_of

__all__ = ["PlanConfig", "PlanStrategy", "SKILLS"]

_Vec = np.ndarray

#: Each skill's phases (``locate``'s rows, ``side_move`` its approach to the first side).
SKILLS: dict[str, tuple[str, ...]] = {
    "sides": ("side_move", "sides"),
    "rock": ("datum", "touch", "rock", "reference"),
    "face": ("face_move", "face"),
    "mouth": ("transfer", "probe"),
    "centre": ("centre",),
    "descent": ("insert",),
}
_FIXED = ("sides", "rock", "mouth", "centre", "descent")
_LEAVES = ("sides", "rock", "face")  # the skills played away from the mouth, once each
_Z95 = 1.96


@dataclasses.dataclass(frozen=True)
class PlanConfig(LocateConfig):
    """``locate``'s skills' parameters, and the planner's [rad, s]."""

    name: ClassVar[str] = "plan"
    phases: ClassVar[tuple[str, ...]] = ("approach", "skills", "hold")
    fixed_order: bool = False  # the skills in locate's order, no choice (the ablation)
    rock_time: float = 3.0  # probe's budget of the rock, for its five landings
    tilt_tolerance: float = 0.006  # the descent needs the tilt known to this (95 %)
    failure_cost: float = 10.0  # what a failed descent costs, in the expected time [s]
    skills_time: float = 20.0  # budget of the skills

    def build(self, task: HeldInsertion) -> PlanStrategy:
        return PlanStrategy(task, self)

    def check(self, scene: SceneConfig, task: TaskDisturbance) -> None:
        super().check(scene, task)
        for name in ("tilt_tolerance", "failure_cost", "skills_time"):
            if getattr(self, name) <= 0:
                raise ConfigError(f"task.strategy.{name} must be > 0, got {getattr(self, name)!r}")


@dataclasses.dataclass
class _Where:
    """Where the peg stands for a decision: which skills are done, whether the end is in the
    bore's mouth and centred there."""

    done: frozenset[str] = frozenset()
    in_mouth: bool = False
    centred: bool = False

    def after(self, skill: str) -> _Where:
        if skill in _LEAVES:
            return _Where(self.done | {skill}, False, False)
        if skill == "mouth":
            return _Where(self.done, True, False)
        return _Where(self.done, self.in_mouth, self.centred or skill == "centre")

    def options(self) -> tuple[str, ...]:
        """The skills that may come next: those not played yet that leave the mouth, and the
        mouth's search, the centring once in it or the descent once centred."""
        out = [s for s in _LEAVES if s not in self.done]
        out.append("descent" if self.centred else "centre" if self.in_mouth else "mouth")
        return tuple(out)


class PlanStrategy(LocateStrategy):
    """The planner (module docstring). ``skill_log``: per skill played, its name, times,
    outcome, the decision that chose it (each option's expected information per second, the
    chosen sequence and its expected time, the decision's compute time) and the belief's
    spread after it."""

    cfg: PlanConfig

    def __init__(self, task: HeldInsertion, config: PlanConfig) -> None:
        super().__init__(task, config)
        self.end_known = True  # the belief carries the end's offset: the rock turns about the believed end
        self.where = _Where()
        self.inner: PhaseMachine | None = None
        self._skill = ""
        self._target: GripperTarget | None = None
        self._fixed = iter(_FIXED)

    # -- the task's phases -----------------------------------------------------------------------
    def phase_table(self) -> dict[str, PhaseSpec]:
        t, c = self.task, self.cfg
        return {
            "approach": PhaseSpec(
                self._enter_still, self._motion_done, "skills", Timeout(0.5, True), tick=t.feel_free
            ),
            "skills": PhaseSpec(
                self._enter_skills, self._skills_over, "hold", Timeout(c.skills_time), tick=self._tick
            ),
            "hold": PhaseSpec(self._enter_hold, never, DONE, Timeout(c.hold_time), tick=t.feel),
        }

    def _enter_still(self, obs: Observation) -> Motion:
        """Still where the episode starts; the peg upright as believed until a rock says otherwise."""
        s = obs.gripper
        self.quat_upright = upright(self.task.up_body, s.quat_world)
        return self.task.move(Waypoint.of(s.p_world, self.quat_upright, 0.0))

    def _skill_rows(self) -> dict[str, PhaseSpec]:
        """``locate``'s rows, the last of each skill handing back to the planner."""
        t, rows = self.task, LocateStrategy.phase_table(self)
        table = {name: rows[name] for name in ("datum", "touch", "rock", "transfer", "probe", "insert")}
        table["side_move"] = rows["approach"]
        table["sides"] = dataclasses.replace(rows["sides"], next=self._decide)
        # The rock's fit gives the face's height: no reference landing, only the turn upright.
        table["reference"] = PhaseSpec(
            self._enter_upright, self._motion_done, self._decide, Timeout(0.5, True), tick=t.feel
        )
        table["probe"] = dataclasses.replace(rows["probe"], next=self._after_mouth)
        table["centre"] = dataclasses.replace(rows["centre"], next=self._decide)
        table["face_move"] = PhaseSpec(
            self._enter_face_move, self._motion_done, "face", Timeout(0.5, True), tick=t.feel_free
        )
        table["face"] = PhaseSpec(self._enter_touch, self._faced, self._decide, Timeout(1.0), tick=t.feel)
        table["insert"] = dataclasses.replace(rows["insert"], next=DONE)
        return table

    def _enter_skills(self, obs: Observation) -> Motion:
        self.inner = PhaseMachine(self._skill_rows())
        first = self._decide(obs)
        self.inner.start(first, obs)
        self._target = self.inner.target(obs.t)
        return self

    # The skills phase's motion: the inner machine's target, stepped by the tick.
    duration = 0.0

    def sample(self, t: float) -> GripperTarget:
        assert self._target is not None
        return self._target

    def _tick(self, obs: Observation) -> None:
        assert self.inner is not None
        if self.inner.phase != DONE:
            self._target = self.inner.update(obs)

    def _skills_over(self, obs: Observation) -> str | None:
        assert self.inner is not None
        if self.inner.phase != DONE:
            return None
        self._close(obs)
        return self.inner.records[-1].outcome or "done"

    def motion_over(self, obs: Observation) -> bool:
        if self.inner is not None and self.inner.phase != DONE and self.task.machine.phase == "skills":
            return self.inner.motion_over(obs.t)
        return super().motion_over(obs)

    # -- decisions ---------------------------------------------------------------------------------
    def _after_mouth(self, obs: Observation) -> str:
        """The search ended: in the bore (its reading taken by probe's hook), or not: done."""
        if LocateStrategy._after_probe(self, obs) == DONE:
            return DONE
        return self._decide(obs)

    def _close(self, obs: Observation) -> None:
        """The skill that ran has ended: log its end and the belief after it."""
        if not self.skill_log or "t_end" in self.skill_log[-1]:
            return
        assert self.inner is not None
        entry = self.skill_log[-1]
        entry["t_end"] = float(obs.t)
        entry["outcome"] = self.inner.records[-1].outcome
        entry["phases"] = [
            r.to_dict()
            for r in self.inner.records
            if r.phase in SKILLS[self._skill] and r.t_start >= entry["t_start"]
        ]
        entry["after"] = self.task.knowledge.spread()
        self.where = self.where.after(self._skill)

    def _decide(self, obs: Observation) -> str:
        """The next skill's first phase (module docstring)."""
        self._close(obs)
        start = time.perf_counter()
        if self.cfg.fixed_order:
            skill = next(self._fixed)
            scores: dict[str, float] = {}
            best: tuple[float, tuple[str, ...]] = (math.nan, (skill,))
        else:
            skill, best, scores = self.choose(self.task.knowledge, self.where)
        self._skill = skill
        self.skill_log.append(
            {
                "skill": skill,
                "t_start": float(obs.t),
                "before": self.task.knowledge.spread(),
                "plan": list(best[1]),
                "expected_s": best[0],
                "bits_per_s": scores,
                "decision_s": time.perf_counter() - start,  # wall time: the planner's own compute
            }
        )
        return SKILLS[skill][0]

    def choose(
        self, belief: TaskBelief, where: _Where
    ) -> tuple[str, tuple[float, tuple[str, ...]], dict[str, float]]:
        """The next skill, the best sequence (its expected time, its skills) and each option's
        expected information per expected second [bits/s]."""
        scores = {}
        for skill in where.options():
            if skill == "descent":
                continue
            bits = belief.information(
                self._reading(skill, belief), of=("hole_x", "hole_y", "end_x", "end_y", "tilt")
            )
            scores[skill] = bits / self._duration(skill, belief)
        best = min(self._sequences(belief, where, ()), key=lambda pair: pair[0])
        return best[1][0], best, scores

    def _sequences(
        self, belief: TaskBelief, where: _Where, so_far: tuple[str, ...]
    ) -> list[tuple[float, tuple[str, ...]]]:
        """Every sequence of skills to a descent from ``where``, with its expected time."""
        out = []
        for skill in where.options():
            if skill == "descent":
                out.append((self._duration(skill, belief) + self._failure(belief), (*so_far, skill)))
                continue
            if len(so_far) >= 6:
                continue
            after = TaskBelief(belief.mean, belief.posterior_cov(self._reading(skill, belief)))
            dt = self._duration(skill, belief)
            out += [
                (dt + cost, seq) for cost, seq in self._sequences(after, where.after(skill), (*so_far, skill))
            ]
        return out

    def _reading(self, skill: str, belief: TaskBelief) -> Reading:
        model = "rock_free" if skill == "rock" else skill
        return reading_of(model, belief, self.noise(), self.task.knowledge_across)

    def _duration(self, skill: str, belief: TaskBelief) -> float:
        """The skill's expected time [s]; the search's with the chance that it fails, as a
        failed descent's cost: a tilt the belief does not know tips the end's rim below its
        centre by ``radius sin(tilt)``, which the search reads as a drop onto the chamfer
        where it is more than ``drop_min``."""
        if skill != "mouth":
            return DURATION[skill]
        # The search reads each landing's drop below the face: a face known no better than
        # drop_min (the drawing's tolerance before any landing on it) misreads the drops, and
        # a misread search is taken to need its landings again.
        landings = expected_landings(belief.relative()[1], self.capture())
        face = belief.sigma("face_z")
        misread = 1.0 - math.erf(self.cfg.drop_min / (face * math.sqrt(2.0))) if face > 0 else 0.0
        # A tilt not known tips the end's rim below its centre by radius sin(tilt): past
        # drop_min, the search is taken to fail.
        tipped = self._beyond(belief, self.cfg.drop_min / self.task.radius)
        return DURATION["mouth"] + LANDING_S * (landings * (1.0 + misread) - 1.0) + tipped

    def _failure(self, belief: TaskBelief) -> float:
        """The expected cost of a descent's failure: the chance the tilt is off by more than
        ``tilt_tolerance``, times ``failure_cost``."""
        return self._beyond(belief, self.cfg.tilt_tolerance)

    def _beyond(self, belief: TaskBelief, tilt: float) -> float:
        """``failure_cost`` times the chance that the tilt is off by more than ``tilt`` [rad]."""
        sigma = belief.sigma("tilt")
        inside = math.erf(tilt / (sigma * math.sqrt(2.0))) if sigma > 0 else 1.0
        return (1.0 - inside) * self.cfg.failure_cost

    # -- the skills' moves where the planner's order differs from locate's --------------------------------
    def _enter_datum(self, obs: Observation) -> Motion:
        """Up clear of the face from wherever the end is, over the datum, down to it."""
        t, c = self.task, self.cfg
        q = self.quat_upright  # the hand as it started (a side touch may have left it turned)
        tip = t.believed_bottom(obs)
        datum = self.datum_waypoint(q)
        over = t.believed_bottom_of(datum)
        clear = max(tip[2], t.z_face) + c.side_lift + c.hop_lift
        tips = [tip, np.array([*tip[:2], clear]), np.array([*over[:2], clear]), over]
        w = [Waypoint.of(obs.gripper.p_world, obs.gripper.quat_world, 0.0)]
        w += [self.tip_waypoint(p, q) for p in tips[1:]]
        parts = [t.planner.plan(a, b, self.quick()) for a, b in zip(w, w[1:], strict=False)]
        t.goal = w[-1]
        return TrajectorySequence(parts)

    def _enter_face_move(self, obs: Observation) -> Motion:
        """Up clear of the face, over a point of it surely clear of the mouth (the capture and
        three sigma of where the end must go beyond the belief's centre, towards the datum),
        down to ``touch_gap`` above the face as believed."""
        t, c = self.task, self.cfg
        centre, _ = t.knowledge.relative()
        reach = self.capture() + 3.0 * t.knowledge.relative_sigma() + 0.001
        point = centre - reach * np.array([1.0, 1.0]) / math.sqrt(2.0)
        q = np.asarray(t.goal.quat_world)
        tip = t.believed_bottom(obs)
        clear = max(tip[2], t.z_face) + c.side_lift + c.hop_lift
        tips = [
            np.array([*tip[:2], clear]),
            np.array([*point, clear]),
            np.array([*point, t.z_face + c.touch_gap]),
        ]
        w = [Waypoint.of(obs.gripper.p_world, obs.gripper.quat_world, 0.0)]
        w += [self.tip_waypoint(p, q) for p in tips]
        parts = [t.planner.plan(a, b, self.quick()) for a, b in zip(w, w[1:], strict=False)]
        t.goal = w[-1]
        return TrajectorySequence(parts)

    def _enter_rock(self, obs: Observation) -> Motion:
        """The rock with the end's offset across the pads fitted too (five landings; the
        measurement model ``rock_free``)."""
        assert self.landing is not None
        t, noise = self.task, self.noise()
        sigma = math.sqrt(float(t.knowledge_across @ t.knowledge.cov[2:4, 2:4] @ t.knowledge_across))
        self.rock = RockCalibration(
            self,
            self.landing,
            obs,
            angles=[k * self.cfg.rock_angle for k in noise.rock_turns],
            free_end=t.knowledge_across,
            frame=t.knowledge_quat,
            end_range=max(3.0 * sigma, 0.0005),
        )
        return self.rock

    def _enter_upright(self, obs: Observation) -> Motion:
        """The rock's reading into the belief, the grasp revised (the end where the fit puts it,
        the axis turned about it), the face's height the fit's; up clear of the face, the peg
        turned upright."""
        t, c, rock = self.task, self.cfg, self.rock
        assert rock is not None
        if rock.tilt is not None:
            self.observe_rock(obs)
            t.revise_axis(
                rock.axis_body, obs.gripper, grasp_shift=t.grip_length * (rock.axis_body - t.up_body)
            )
            t.z_face = rock.z_face
        q = self.quat_upright = upright(t.up_body, rock.q0)
        s = obs.gripper
        clear = t.radius * math.sin(c.rock_angle + c.max_tilt) + c.hover
        tip = t.believed_bottom(obs)
        w = [
            Waypoint.of(s.p_world, s.quat_world, 0.0),
            self.tip_waypoint(tip + np.array([0.0, 0.0, clear]), s.quat_world),
        ]
        w.append(self.tip_waypoint(np.array([*tip[:2], max(tip[2], t.z_face) + clear]), q))
        t.goal = w[-1]
        return TrajectorySequence(
            [t.planner.plan(a, b, self.quick()) for a, b in zip(w, w[1:], strict=False)]
        )

    def observe_rock(self, obs: Observation) -> None:
        """The rock's reading (tilt, the end's offset, the face), and the end moved to where
        it says (the tilt is revised after, about that end)."""
        t, rock = self.task, self.rock
        assert rock is not None and rock.tilt is not None
        self.observe("rock_free", [rock.tilt, rock.end, rock.z_face], obs)
        shift = rotate_inv(t.knowledge_quat, np.array([*(rock.end * t.knowledge_across), 0.0]))
        t.revise_axis(t.up_body, obs.gripper, grasp_shift=shift)

    def _enter_side(self, obs: Observation) -> Motion:
        """``locate``'s side touches, the first approach starting as far beyond the -x side as
        the belief needs (three sigma of where the end meets it, and a millimetre to get going),
        not farther than ``side_gap``."""
        t, c = self.task, self.cfg
        _, cov = t.knowledge.relative()
        sigma = math.sqrt(float(cov[0, 0]) + t.drawing_tolerance**2 / 3.0 + t.pose_repeatability**2)
        gap = min(c.side_gap, 3.0 * sigma + 0.001)
        self.sides = SideTouches(self, obs, gaps=(gap, c.camera_gap))
        return self.sides.path_to_first(obs)

    def _enter_transfer(self, obs: Observation) -> Motion:
        """``probe``'s transfer, the hand turned back upright on it (the side touches may leave it turned)."""
        g = self.task.goal
        self.task.goal = Waypoint.of(np.asarray(g.p_world), self.quat_upright, 0.0)
        return super()._enter_transfer(obs)

    def _faced(self, obs: Observation) -> str | None:
        """Landed on the face: its height."""
        assert self.landing is not None
        if not self.landing.update(obs):
            return None
        self.observe("face", [self.landing.z], obs)
        self.task.z_face = self.landing.z
        return "landed"

    def search_belief(self) -> HoleBelief:
        """The search's prior: where the task's belief puts the believed end over the hole, with
        its covariance (long across the pads while the end's offset is not known)."""
        centre, cov = self.task.knowledge.relative()
        sigma = self.task.knowledge.relative_sigma()
        radius = min(max(3.0 * sigma, 2.0 * self.capture()), 0.009)
        return HoleBelief(
            (float(centre[0]), float(centre[1])), radius=radius, sigma=sigma, capture=self.capture(), cov=cov
        )
