"""Each skill's measurement model and expected duration: what its reading is under each state of
the task's belief (:class:`~peg_ctrl.tasks.belief.TaskBelief`), linear in the state, with the
reading's noise; and how long it takes. The planner (``plan``) scores skills by them before it
makes a touch; every strategy that plays a skill updates the task's belief with them after.

The noise comes from the sensing the cell states (``σ_p``: the hand's position repeatability,
``domain.position_noise``, held over a touch: averaging the readings of one touch does not
shrink it) and from the drawing (``task.drawing_tolerance``, uniform: σ = tol/√3).

=========== ======================================= =========================================
skill       reading                                  noise (σ)
=========== ======================================= =========================================
sides       the hole (x, y); the end's offset        hole: √(tol²/3 + 2 σ_p²); offset:
            across the pads                          √2 σ_p / |Δu| (Δu: the turn's change of
                                                     the across direction along the side's axis)
rock_free   the tilt, the end's offset across the    σ_p² (JᵀJ)⁻¹, J the heights' derivatives
            pads and the face's height, fitted       (tilt, offset, face) over five landings
            together from five landings              (the touch, +/- α, +/- 1.6 α)
rock        the tilt in the hand; the face's height  tilt: √2 σ_p / (2 R) and, the end's
                                                     offset across the pads not known, α/R times
                                                     its σ (a landing turned by α about the pads'
                                                     normal lifts an end off by e by e sin α);
                                                     face: σ_p
face        the face's height (one landing beside     √(σ_p² + (R σ_tilt)²): a tilt not known
            the mouth)                               tips the end's rim below its centre
mouth       where the believed end is once the true  √(c² + σ_p²) (c: the radial clearance)
            one is in the bore: hole - end
centre      the bore's axis from its walls:          σ_p (the walls are read within one
            hole - end                               holding of the position error)
=========== ======================================= =========================================

Durations are the medians of contact_real_plan's development episodes (seeds 100-103, mpc/locate
and mpc/plan, every phase of the skill, its moves included); the mouth's grows with the landings
its search is expected to need (:func:`expected_landings`): a landing costs about a second in
those episodes (3.5-6 s for the searches from the camera's prior, 1.1-1.4 s for the first-landing
searches after the side touches).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from numpy.typing import ArrayLike

from peg_ctrl.tasks.belief import Reading, TaskBelief, rows
from peg_ctrl.tasks.strategies.base import HeldInsertion

__all__ = ["DURATION", "LANDING_S", "SkillNoise", "expected_landings", "observe", "reading_of"]

#: Expected seconds per skill (module docstring): sides (3 touches, with the move to the first),
#: rock (the move to the datum, the touch, four turned landings, the turn upright), face
#: (a move beside the mouth and a landing), mouth
#: (the transfer and one landing; :data:`LANDING_S` per landing more), centre, descent (to seated).
DURATION = {"sides": 4.5, "rock": 3.3, "face": 0.7, "mouth": 0.7, "centre": 0.4, "descent": 1.5}
LANDING_S = 1.0  # [s] one more landing of the search (a hop, a landing and, on the face, a bearing press)


@dataclasses.dataclass(frozen=True)
class SkillNoise:
    """What the readings' noise is made of [m, rad]: the hand's position repeatability, the
    drawing's tolerance, the bore's radial clearance, the peg's radius, the rock's angle, the
    side touches' turn."""

    position: float
    drawing: float
    clearance: float
    radius: float
    rock_angle: float
    side_turn: float
    rock_turns: tuple[float, ...] = (1.0, -1.0, 1.6, -1.6)  # the free-end rock's landings, x rock_angle

    @classmethod
    def of(cls, task: HeldInsertion, rock_angle: float, side_turn: float = 0.0) -> SkillNoise:
        """The noise the task's cell states (its repeatability, drawing, clearance, peg)."""
        return cls(
            position=task.pose_repeatability,
            drawing=task.drawing_tolerance,
            clearance=task.hole_radius - task.radius,
            radius=task.radius,
            rock_angle=rock_angle,
            side_turn=side_turn,
        )


def observe(task: HeldInsertion, skill: str, value: ArrayLike, t: float, noise: SkillNoise) -> None:
    """``skill``'s reading ``value`` at ``t`` [s] into the task's belief, through its measurement model."""
    reading = reading_of(skill, task.knowledge, noise, task.knowledge_across)
    task.knowledge.update(reading.with_value(value), t)


def expected_landings(cov: np.ndarray, capture: float) -> float:
    """Landings a search is expected to need to be caught by the chamfer (``capture`` [m]: how
    far from the axis it catches the end) under a Gaussian of covariance ``cov`` (x, y) over
    where the end must go: landings in order of likelihood each cover a capture disc, and the
    area of a Gaussian's likelihood set holding a draw is on average 2π σ1 σ2, so
    ``1 + 2 σ1 σ2 / capture²``."""
    s1, s2 = (math.sqrt(max(v, 0.0)) for v in np.linalg.eigvalsh(cov))
    return 1.0 + 2.0 * s1 * s2 / (capture * capture)


def reading_of(skill: str, belief: TaskBelief, noise: SkillNoise, across: np.ndarray) -> Reading:
    """``skill``'s reading as a :class:`Reading` without its value (``H``, ``R``), under the
    belief as it is (the rock's noise grows with what the belief does not know of the end).
    ``across``: the unit direction across the pads (world x, y, the belief's orientation)."""
    sp, u = noise.position, np.asarray(across, dtype=float)
    if skill == "sides":
        swing = max(abs(math.sin(noise.side_turn)), 1e-3)
        s_off = math.sqrt(2.0) * sp / swing
        s_hole = math.sqrt(noise.drawing**2 / 3.0 + 2.0 * sp * sp)
        H = np.array([rows(hole_x=1.0), rows(hole_y=1.0), rows(end_x=float(u[0]), end_y=float(u[1]))])
        R = np.diag([s_hole**2, s_hole**2, s_off**2])
        # The hole is read through the offset: their errors go together along ``across``.
        R[0, 2] = R[2, 0] = float(u[0]) * s_off**2
        R[1, 2] = R[2, 1] = float(u[1]) * s_off**2
        R[:2, :2] += np.outer(u, u) * s_off**2
        return Reading("sides", H, R)
    if skill == "rock":
        h_end = rows(end_x=float(u[0]), end_y=float(u[1]))
        e_var = float(h_end @ belief.cov @ h_end)
        lever = math.sin(noise.rock_angle) / noise.radius
        s_tilt2 = 2.0 * sp * sp / (4.0 * noise.radius**2) + lever * lever * e_var
        H = np.array([rows(tilt=1.0), rows(face_z=1.0)])
        return Reading("rock", H, np.diag([s_tilt2, sp * sp]))
    if skill == "rock_free":
        # The rock with the end's offset across the pads fitted too: the touch and the landings
        # turned by rock_turns x rock_angle; each landing's height
        # h = face + R |sin(tilt + b)| + e sin(b), linearised at the tilt the belief expects.
        theta = max(abs(belief.value("tilt")), belief.sigma("tilt"), 1e-3)
        a = noise.rock_angle
        J = np.array(
            [
                [noise.radius * math.copysign(1.0, theta + b) * math.cos(theta + b), math.sin(b), 1.0]
                for b in (0.0, *(k * a for k in noise.rock_turns))
            ]
        )
        H = np.array([rows(tilt=1.0), rows(end_x=float(u[0]), end_y=float(u[1])), rows(face_z=1.0)])
        return Reading("rock_free", H, sp * sp * np.linalg.inv(J.T @ J))
    if skill == "face":
        rim = noise.radius * belief.sigma("tilt")
        return Reading("face", np.array([rows(face_z=1.0)]), np.array([[sp * sp + rim * rim]]))
    if skill in ("mouth", "centre"):
        H = np.array([rows(hole_x=1.0, end_x=-1.0), rows(hole_y=1.0, end_y=-1.0)])
        s2 = noise.clearance**2 + sp * sp if skill == "mouth" else sp * sp
        return Reading(skill, H, s2 * np.eye(2))
    raise ValueError(
        f"no measurement model for the skill {skill!r}; known: sides, rock, rock_free, face, mouth, centre"
    )
