"""``align``: turn the peg flat on a datum, then hop to the hole and let the chamfer guide it in.

Phases:

- ``approach`` a datum on the block's top face ``datum_offset`` beside the observed hole (along
  the diagonal towards -x, -y, where the face is widest), the lower end ``touch_gap`` above it;
- ``touch`` it: a light force-controlled press (``touch_force``) until the push lasts;
- ``align``: press with ``align_force`` with the tilt axes moment-controlled at zero about the
  believed lower end, so the peg turns about its tip until its end lies flat on the face (the
  moment falls below ``align_tolerance``); the gripper's orientation then tells the peg's true
  axis in the hand, and the task revises its belief (:meth:`HeldInsertion.recalibrate`: the
  lower end, the face's height, where the hole is);
- ``transfer`` over the hole keeping that orientation;
- ``search``: hops over a hexagonal lattice (:mod:`peg_ctrl.tasks.strategies.hop_search`)
  until the peg drops onto the chamfer, then onto the hole's axis with the chamfer guiding it;
- ``insert`` with the lateral axes free, pushing down.

The peg's tilt is corrected *before* it meets the bore: at μ = 0.9 a 0.05 mm clearance wedges
any peg that enters tilted by more than about 0.3° (Whitney's wedging condition, two-point
contact shallower than μ times the diameter).
"""

from __future__ import annotations

import dataclasses
import math
from typing import ClassVar

import numpy as np

from peg_ctrl.commands import GripperTarget
from peg_ctrl.errors import ConfigError
from peg_ctrl.planners.base import Waypoint
from peg_ctrl.sim.scene import SceneConfig
from peg_ctrl.sim.sensing import within
from peg_ctrl.tasks.base import Observation
from peg_ctrl.tasks.phases import DONE, Motion, PhaseSpec, Timeout, TrajectorySequence
from peg_ctrl.tasks.strategies.base import (
    HeldInsertion,
    PushIn,
    Strategy,
    StrategyConfig,
    TaskDisturbance,
    never,
)
from peg_ctrl.tasks.strategies.hop_search import GUIDE_AXES, HexLattice, HopSearch, HopSettings
from peg_ctrl.tasks.strategies.motions import Hold, down

__all__ = ["AlignConfig", "AlignStrategy"]

_ALIGN_AXES = (False, False, True, True, True, False)  # press along z, tilt axes moment-free
_PRESS_AXES = (False, False, True, False, False, False)  # press along z, pose held otherwise


@dataclasses.dataclass(frozen=True)
class AlignConfig(StrategyConfig):
    """The datum, the alignment, the hop search and the push: distances [m], forces [N],
    moments [N m], speeds [m/s], times [s]."""

    name: ClassVar[str] = "align"
    phases: ClassVar[tuple[str, ...]] = ("approach", "touch", "align", "transfer", "search", "insert")
    datum_offset: float = 0.03  # the datum touch, this far from the observed hole towards -x, -y [m]
    touch_gap: float = 0.0012  # the approach stops the lower end this far above the face [m]
    touch_force: float = 0.6  # light press: touching the datum, every search hop [N] (more with a
    # noisy sensor: twice what the contact detection needs)
    align_force: float = 3.0  # press while the peg turns flat [N]
    align_tolerance: float = 0.002  # flat once the moment about the tip stays below this, or
    # within 3 sigma of its noise where that is wider [N m]
    align_time: float = 4.0  # budget of the alignment [s]
    search_pitch: float = 0.0016  # hexagonal lattice pitch [m] (<= sqrt(3) x the capture range)
    search_radius: float = 0.0045  # the lattice's radius about the observed hole [m]
    hop_lift: float = 0.0002  # lift between hops [m]
    hop_hover: float = 0.00008  # the press starts this far above the face [m]
    hop_speed: float = 0.02  # lateral hop speed [m/s]
    hop_lower_speed: float = 0.003  # descent to the hover height [m/s]
    drop_min: float = 0.00003  # a press this far below the face is on the chamfer [m]
    search_time: float = 10.0  # budget of the hop search [s]
    insert_force: float = 3.0  # the guided push [N]
    insert_speed: float = 0.01  # above this descent speed the push eases off, to 0 N at twice it [m/s]
    insert_time: float = 8.0  # budget of the push [s]

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.drop_min >= self.hop_hover + 0.001:
            raise ConfigError(
                f"task.strategy.drop_min must be below hop_hover + 1 mm ({self.hop_hover + 0.001:.4g} m), "
                f"got {self.drop_min!r}"
            )

    def build(self, task: HeldInsertion) -> AlignStrategy:
        return AlignStrategy(task, self)

    def check(self, scene: SceneConfig, task: TaskDisturbance) -> None:
        """The datum must lie on the top face, clear of the hole and its chamfer whatever the
        lateral error, the tilt (which moves the believed lower end) and the noise; the lattice
        must leave no gap in the chamfer's capture range."""
        a = scene.assets
        half = 0.5 * min(a.block_size[0], a.block_size[1])
        reach = self.datum_offset / math.sqrt(2.0) + a.peg_radius  # along x and y (a diagonal)
        if reach >= half - 0.002:
            raise ConfigError(
                f"task.strategy.datum_offset: the datum touch reaches {reach * 1e3:.1f} mm from the hole "
                f"along x and y, beyond the block's top face ({half * 1e3:.1f} mm); must be < "
                f"{(half - 0.002 - a.peg_radius) * math.sqrt(2.0):.4g} m"
            )
        mouth = a.peg_radius + a.clearance + a.chamfer
        lean = (task.grip_above_centre + 0.5 * a.peg_length) * math.sin(task.tilt_error)
        error = task.lateral_error + lean + 3.0 * task.position_noise
        if self.datum_offset - a.peg_radius - error <= mouth + 0.001:
            raise ConfigError(
                f"task.strategy.datum_offset: {self.datum_offset!r} m puts the datum touch within 1 mm of "
                f"the hole's mouth (radius {mouth * 1e3:.2f} mm) for a lateral error of "
                f"{error * 1e3:.2f} mm (lateral error, tilt, noise); must be > "
                f"{mouth + 0.001 + a.peg_radius + error:.4g} m"
            )
        capture = a.clearance + a.chamfer
        if self.search_pitch > math.sqrt(3.0) * (capture - self.drop_min):
            raise ConfigError(
                f"task.strategy.search_pitch: {self.search_pitch!r} m leaves gaps in the chamfer's capture "
                f"range ({capture * 1e3:.2f} mm); must be <= "
                f"{math.sqrt(3.0) * (capture - self.drop_min):.4g} m"
            )


class AlignStrategy(Strategy):
    cfg: AlignConfig

    def __init__(self, task: HeldInsertion, config: AlignConfig) -> None:
        super().__init__(task, config)
        self.push_in = PushIn(task, config.insert_force, config.insert_speed)
        self._hold = Hold(
            GripperTarget.trusted(np.zeros(3), (1.0, 0.0, 0.0, 0.0), np.zeros(3), np.zeros(3), 0.0)
        )
        self.search: HopSearch | None = None
        self._flat_since: float | None = None
        self._settle_from: float | None = None

    def phase_table(self) -> dict[str, PhaseSpec]:
        c, t = self.cfg, self.task
        return {
            "approach": PhaseSpec(
                self._enter_datum, self._motion_done, "touch", Timeout(1.0, True), tick=t.feel_free
            ),
            "touch": PhaseSpec(
                self._enter_touch, self._touched_datum, self._after_touch, Timeout(2.0), tick=t.feel
            ),
            "align": PhaseSpec(
                self._enter_align, self._aligned, "transfer", Timeout(c.align_time), tick=t.feel
            ),
            "transfer": PhaseSpec(
                self._enter_transfer, self._motion_done, "search", Timeout(1.0, True), tick=t.feel
            ),
            "search": PhaseSpec(
                self._enter_hop_search,
                self._found,
                self._after_search,
                Timeout(c.search_time),
                tick=self._hop,
            ),
            "insert": PhaseSpec(
                self._enter_guided_insert, never, DONE, Timeout(c.insert_time), tick=self.push_in.govern
            ),
        }

    def _tip_waypoint(self, tip: np.ndarray, q: np.ndarray) -> Waypoint:
        return Waypoint.of(self.task.pinch_for(tip, q), q, 0.0)

    def _held(self, target: GripperTarget) -> Hold:
        self._hold.target = target
        return self._hold

    def _press_here(self, obs: Observation, force: float, axes: tuple[bool, ...]) -> GripperTarget:
        """Hold the present pose, pressing down with ``force`` [N] on the flagged ``axes``."""
        s = obs.gripper
        self.task.goal = Waypoint.of(s.p_world, s.quat_world, 0.0)
        return GripperTarget.trusted(
            s.p_world, s.quat_world, np.zeros(3), np.zeros(3), 0.0, down(force), wrench_axes=axes
        )

    def _enter_datum(self, obs: Observation) -> Motion:
        """Over the datum, the lower end ``touch_gap`` above the face."""
        t, c = self.task, self.cfg
        q = np.asarray(t.goal.quat_world)
        off = c.datum_offset / math.sqrt(2.0)  # along the diagonal, where the face is widest
        tip = np.array([t.observed_hole[0] - off, t.observed_hole[1] - off, t.block_top + c.touch_gap])
        return t.move(self._tip_waypoint(tip, q))

    def _press_force(self) -> float:
        """``touch_force``, or more where the sensor is noisier: twice what the contact detection
        needs to see a push [N]."""
        t = self.task
        return max(self.cfg.touch_force, 2.0 * t.contact.k_on * float(t.wrist.sigma_force[2]))

    def _enter_touch(self, obs: Observation) -> Motion:
        self._flat_since = None
        return self._held(self._press_here(obs, self._press_force(), _PRESS_AXES))

    def _touched_datum(self, obs: Observation) -> str | None:
        """Contact: the task's detection holds 10 ms more, 50 ms into the phase (the sensor also
        reads the hand's own accelerations)."""
        t = self.task
        pressed = t.machine.elapsed(obs.t) > 0.05 and t.contact.on
        self._flat_since = (self._flat_since or obs.t) if pressed else None
        return "contact" if self._flat_since is not None and obs.t - self._flat_since >= 0.01 else None

    def _after_touch(self, obs: Observation) -> str:
        return "align" if self._flat_since is not None else DONE

    def _enter_align(self, obs: Observation) -> Motion:
        self._flat_since = self._settle_from = None
        return self._held(self._press_here(obs, self.cfg.align_force, _ALIGN_AXES))

    def _aligned(self, obs: Observation) -> str | None:
        """Flat once the moment about the lower end stays below ``align_tolerance`` for 0.1 s;
        then a light press with the orientation held, 0.15 s, before the belief is updated."""
        t = self.task
        now = obs.t
        if self._settle_from is None:
            w = t.wrist
            m, sigma = w.moment, float(np.hypot(*w.sigma_moment[:2]))
            flat = (
                t.contact.on  # on the face, not in the air
                and t.machine.elapsed(now) > 0.2
                and within(math.hypot(m[0], m[1]), sigma, self.cfg.align_tolerance)
            )
            self._flat_since = (self._flat_since or now) if flat else None
            if self._flat_since is not None and now - self._flat_since >= 0.1:
                self._settle_from = now
                self._hold.target = self._press_here(obs, self._press_force(), _PRESS_AXES)
            return None
        return "flat" if now - self._settle_from >= 0.15 else None

    def _enter_transfer(self, obs: Observation) -> Motion:
        """Up off the datum, over the hole, down to the hover height, keeping the orientation."""
        t, c = self.task, self.cfg
        t.recalibrate(obs)
        s = obs.gripper
        q = s.quat_world
        here = Waypoint.of(s.p_world, q, 0.0)
        up = t.believed_bottom(obs) + np.array([0.0, 0.0, 0.002])
        over = np.array([*t.observed_hole, up[2]])
        hover = np.array([*t.observed_hole, t.z_face + c.hop_hover])
        lower = dataclasses.replace(t.limits, v_lin=c.hop_lower_speed, a_lin=0.5, j_lin=20.0)
        lift = t.planner.plan(here, self._tip_waypoint(up, q), t.limits)
        across = t.planner.plan(self._tip_waypoint(up, q), self._tip_waypoint(over, q), t.limits)
        down_to = t.planner.plan(self._tip_waypoint(over, q), self._tip_waypoint(hover, q), lower)
        t.goal = self._tip_waypoint(hover, q)
        return TrajectorySequence([lift, across, down_to])

    def _enter_hop_search(self, obs: Observation) -> Motion:
        t, c, a = self.task, self.cfg, self.task.scene.assets
        settings = HopSettings(
            press_force=self._press_force(),
            hover=c.hop_hover,
            lift=c.hop_lift,
            hop_speed=c.hop_speed,
            lower_speed=c.hop_lower_speed,
            drop_min=c.drop_min,
            capture=a.clearance + a.chamfer,
            settle_time=0.05,
            guide_time=1.0,
        )
        self.search = HopSearch(
            centre=t.observed_hole,
            z_face=t.z_face,
            quat=np.asarray(t.goal.quat_world),
            lattice=HexLattice(c.search_pitch, c.search_radius),
            settings=settings,
            planner=t.planner,
            limits=t.limits,
            tip_to_pinch=t.pinch_for,
            t0=obs.t,
        )
        return self.search

    def _hop(self, obs: Observation) -> None:
        t = self.task
        t.feel(obs)
        assert self.search is not None
        self.search.step(obs.t, t.believed_bottom(obs), t.wrist.force, t.wrist.moment, t.contact.on)

    def _found(self, obs: Observation) -> str | None:
        if self.task.in_bore(obs):
            return "entered"
        assert self.search is not None
        return "exhausted" if self.search.exhausted else None

    def _after_search(self, obs: Observation) -> str:
        return "insert" if self.task.in_bore(obs) else DONE

    def _enter_guided_insert(self, obs: Observation) -> Motion:
        """Push down with the lateral axes free: the bore guides the peg."""
        return self.push_in.enter(obs, GUIDE_AXES)
