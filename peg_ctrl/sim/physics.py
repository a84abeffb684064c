"""Physics profiles: the solver options and the peg-block contact model, chosen by name.

``seed``
    SPEC §3 exactly: 1 ms RK4, CG with 20 noslip iterations, per-geom ``solref``/``solimp``, a
    1 mm contact margin on the block (the hole is widened by it), a 10-sided hole and a 32-sided
    mesh peg. Every bar measured before the profiles existed holds with it.

``precision``
    For studies in which clearance, chamfer and tilt must act as they do on real parts
    (docs/physics.md has the measurements behind each value):

    - the peg is a primitive cylinder, exact to the collider's tolerance;
    - the hole is a polygon with its flats at the nominal radius and as many sides as it takes
      for the peg to move in it as in a round hole, to within ``hole_play_tolerance`` (5 µm):
      a round peg touches the flats, so its axis is free in the same polygon shrunk by the
      peg's radius, whose corners stand ``play * (sec(pi/n) - 1)`` beyond a circle (``play``:
      clearance plus chamfer, the reach at the mouth's outer edge). At least 24 sides, so the
      face around the mouth a peg end rests on is within 0.6 % of a round mouth's;
    - the hole's parts stop 3 mm outside the mouth (``hole_ring_wall``); the rest of the block
      is four slabs;
    - the peg's contacts with the block and the table are explicit pairs with no margin (they
      act when the surfaces meet), a time constant of two physics steps and impedance
      0.99..0.999, so 10 N of steady contact penetrates a few µm;
    - those pairs use ``condim`` 3: sliding friction only. Torsional and rolling friction
      model a contact patch, which between rigid metal parts is microns wide; the seed's 0.1 m
      torsional coefficient (a patch ~20 cm across) resists the peg straightening in the hole;
    - the convex collider (GJK/EPA) works to 1 nm (``ccd_tolerance``; MuJoCo's default 1 µm
      let a flat peg end resting across the hole's convex parts report a bogus 1 mm overlap
      now and then: a 180 N spike out of a 4 N push);
    - the Newton solver runs to convergence (tolerance 1e-10) at a 0.5 ms step with the
      ``implicitfast`` integrator; ``impratio`` 100 keeps the grasp without noslip, whose cost
      grows with the square of the contact count.

    - a peg-block contact deeper than 0.1 mm is a collider artifact (a flat face resting on a
      flat face can make multiccd return a phantom contact as deep as the part is wide): that
      step's collisions are recomputed without multiccd (``phantom_depth``; the episode counts
      them in ``phantom_contacts``).

``fast``
    The ``seed`` contact model (geometry, margins, per-geom ``solref``/``solimp``, CG with 20
    noslip iterations) integrated with ``implicitfast`` at a 2.5 ms step instead of RK4 at
    1 ms: one forward pass per 2.5 ms of simulated time instead of four per millisecond.
    MuJoCo's safety floor raises every contact time constant below two steps (the pads' 4 ms)
    to 5 ms, so the grasp is softer. Validated against ``seed`` by ``peg-sim
    validate-profile fast`` (docs/performance.md): what it may and may not be used for is
    stated there.

A profile changes the compiled model only: tasks, controllers and the loop do not know which
one is in use (the control period must be a whole number of physics steps: the default 200 Hz
is 5, 10 and 2 of them in ``seed``, ``precision`` and ``fast``).
"""

from __future__ import annotations

import dataclasses
import math

import mujoco

from peg_ctrl.errors import ConfigError, UnknownComponent
from peg_ctrl.sim.assets import AssetParams

__all__ = [
    "PegContactParams",
    "PhysicsProfile",
    "PhysicsConfig",
    "PROFILES",
    "SEED",
    "PRECISION",
    "FAST",
    "profile",
    "with_friction_time",
    "parts_for_play",
    "MIN_HOLE_SIDES",
]

MIN_HOLE_SIDES = 24  # a round mouth's outline within 0.6 % of its area (n tan(pi/n) / pi - 1)


@dataclasses.dataclass(frozen=True)
class PegContactParams:
    """Contact parameters of the peg against each block part and the table (explicit ``pair``s)."""

    condim: int = 3  # sliding friction; the coefficient is the larger of the scene's peg and
    # block sliding frictions, as MuJoCo would mix them (SceneConfig.peg_friction/block_friction)
    solref: tuple[float, float] = (0.001, 1.0)  # [s, damping ratio]
    solimp: tuple[float, float, float, float, float] = (0.99, 0.999, 1e-4, 0.5, 2.0)
    margin: float = 0.0  # [m]
    # The friction rows' own reference [s, damping ratio] (MuJoCo's pair ``solreffriction``);
    # None: the normal's ``solref`` (``physics.friction_time``, docs/physics.md "Known limits").
    solreffriction: tuple[float, float] | None = None


@dataclasses.dataclass(frozen=True)
class PhysicsProfile:
    """Solver options and the peg-block contact model. ``pair=None`` keeps the per-geom values."""

    name: str
    timestep: float  # [s]
    integrator: str  # mjtIntegrator name without prefix: "RK4", "IMPLICITFAST", "EULER"
    solver: str  # "CG" or "NEWTON"
    iterations: int
    tolerance: float
    ls_iterations: int
    noslip_iterations: int
    impratio: float
    peg_geom: str  # "mesh" (the 32-sided prism of the seed) or "cylinder" (primitive)
    # The hole's sides: None keeps the assets' n_parts; else as many as keep a round peg's play
    # within this of a round hole's [m] (parts_for_play).
    hole_play_tolerance: float | None
    contact_margin: float | None  # block geoms' margin, added to the hole [m]; None: the assets'
    pair: PegContactParams | None = None
    hole_ring_wall: float | None = None  # the hole's parts end this far outside the mouth [m];
    # the rest of the block is slabs. None: the parts reach the block's walls.
    ccd_tolerance: float | None = None  # convex collision (GJK/EPA) tolerance [m]; None: MuJoCo's
    ccd_iterations: int | None = None  # ... and iteration cap; None: MuJoCo's
    # A peg-block contact deeper than this [m] is a collider artifact, not physics: MuJoCo 4.0's
    # multi-contact convex collision (multiccd) now and then returns a phantom contact, as deep
    # as the part is wide, for a flat face resting on a flat face (it answers the phantom with
    # kN). The loop then recomputes that step's collisions without multiccd (peg_ctrl.run.loop).
    # None: no check (RK4 cannot split its step to recompute).
    phantom_depth: float | None = None

    def __post_init__(self) -> None:
        if self.peg_geom not in ("mesh", "cylinder"):
            raise ConfigError(f"peg_geom must be 'mesh' or 'cylinder', got {self.peg_geom!r}")

    def assets(self, params: AssetParams) -> AssetParams:
        """The geometry this profile builds for the requested ``params``: its margin, its hole."""
        if self.contact_margin is not None:
            params = dataclasses.replace(params, contact_margin=self.contact_margin)
        if self.hole_play_tolerance is not None:
            play = abs(params.hole_inradius - params.peg_radius) + params.chamfer
            params = dataclasses.replace(params, n_parts=parts_for_play(play, self.hole_play_tolerance))
        if self.hole_ring_wall is not None:
            mouth = params.hole_circumradius + params.chamfer / math.cos(math.pi / params.n_parts)
            params = dataclasses.replace(params, hole_ring=mouth + self.hole_ring_wall)
        return params

    def apply_options(self, opt: mujoco.MjOption) -> None:
        opt.timestep = self.timestep
        opt.integrator = getattr(mujoco.mjtIntegrator, f"mjINT_{self.integrator}")
        opt.solver = getattr(mujoco.mjtSolver, f"mjSOL_{self.solver}")
        opt.iterations = self.iterations
        opt.tolerance = self.tolerance
        opt.ls_iterations = self.ls_iterations
        opt.noslip_iterations = self.noslip_iterations
        opt.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
        opt.impratio = self.impratio
        if self.ccd_tolerance is not None:
            opt.ccd_tolerance = self.ccd_tolerance
        if self.ccd_iterations is not None:
            opt.ccd_iterations = self.ccd_iterations


def parts_for_play(play: float, tolerance: float, minimum: int = MIN_HOLE_SIDES) -> int:
    """Fewest polygon sides (at least ``minimum``) for which a round peg with ``play`` [m] of
    lateral freedom moves within ``tolerance`` [m] of how it would in a round hole.

    The peg touches the flats, so its axis is confined to the hole polygon shrunk by its radius:
    a polygon of inradius ``play`` whose corners lie ``play * (sec(pi/n) - 1)`` beyond the circle.
    """
    if not (math.isfinite(tolerance) and tolerance > 0.0):
        raise ConfigError(f"hole play tolerance must be > 0 m, got {tolerance!r}")
    if not (math.isfinite(play) and play >= 0.0):
        raise ConfigError(f"play must be >= 0 m, got {play!r}")
    n = minimum
    while play * (1.0 / math.cos(math.pi / n) - 1.0) > tolerance:
        n += 1
    return n


SEED = PhysicsProfile(
    name="seed",
    timestep=0.001,
    integrator="RK4",
    solver="CG",
    iterations=100,
    tolerance=1e-8,
    ls_iterations=50,
    noslip_iterations=20,
    impratio=10.0,
    peg_geom="mesh",
    hole_play_tolerance=None,
    contact_margin=None,
)

PRECISION = PhysicsProfile(
    name="precision",
    timestep=0.0005,
    integrator="IMPLICITFAST",
    solver="NEWTON",
    iterations=100,
    tolerance=1e-10,
    ls_iterations=50,
    noslip_iterations=0,
    impratio=100.0,
    peg_geom="cylinder",
    hole_play_tolerance=5e-6,
    hole_ring_wall=0.003,
    contact_margin=0.0,
    pair=PegContactParams(),
    ccd_tolerance=1e-9,
    ccd_iterations=100,
    phantom_depth=1e-4,  # 100 um: contacts here penetrate a few um at 10 N
)

FAST = dataclasses.replace(SEED, name="fast", timestep=0.0025, integrator="IMPLICITFAST")

PROFILES: dict[str, PhysicsProfile] = {p.name: p for p in (SEED, PRECISION, FAST)}


def profile(name_or_profile: str | PhysicsProfile, *, where: str = "physics.profile") -> PhysicsProfile:
    """The profile called ``name`` (or the profile itself); an unknown name lists the known,
    naming the field or flag ``where`` it came from."""
    if isinstance(name_or_profile, PhysicsProfile):
        return name_or_profile
    try:
        return PROFILES[name_or_profile]
    except KeyError:
        raise UnknownComponent("physics profile", name_or_profile, PROFILES, where=where) from None


@dataclasses.dataclass(frozen=True)
class PhysicsConfig:
    """``physics.profile``: which :class:`PhysicsProfile` builds the scene.

    ``physics.friction_time`` [s]: the time constant of the peg's friction against the block and
    the table (the explicit pairs' ``solreffriction``, critically damped), in a profile that has
    those pairs (``precision``); None keeps the profile's (the normal's ``solref``, 1 ms in
    ``precision``). A slower friction lets a contact that appears under a fast slide slide at once
    instead of sticking and kicking the peg off (docs/physics.md, "Known limits"). The studies
    run it at 5 ms: the model whose force over 10 ms agrees with Drake's lagged contact
    (docs/physics.md, "Cross-check against Drake"); at 5 ms an exactly aligned peg with no
    clearance enters 2 mm, beyond the validity battery's entry bar, as it does in Drake.
    """

    profile: str = "seed"
    friction_time: float | None = None

    def __post_init__(self) -> None:
        prof = profile(self.profile)
        t = self.friction_time
        if t is None:
            return
        if prof.pair is None:
            raise ConfigError(
                f"physics.friction_time: physics.profile={prof.name} has no explicit peg contact pairs "
                "to set it on; use physics.profile=precision"
            )
        number = not isinstance(t, bool) and isinstance(t, (int, float))
        if not (number and math.isfinite(t) and t >= 2.0 * prof.timestep):
            raise ConfigError(
                f"physics.friction_time must be a time constant of at least two physics steps "
                f"(>= {2.0 * prof.timestep:g} s), got {t!r}"
            )

    def resolved(self) -> PhysicsProfile:
        """The profile as this config builds it: ``profile``, with ``friction_time`` if set."""
        return with_friction_time(profile(self.profile), self.friction_time)


def with_friction_time(prof: PhysicsProfile, friction_time: float | None) -> PhysicsProfile:
    """``prof`` with its peg pairs' friction reference at ``friction_time`` [s], critically
    damped (``physics.friction_time``); None: ``prof`` as it is."""
    if friction_time is None:
        return prof
    if prof.pair is None:
        raise ConfigError(f"physics profile {prof.name} has no explicit peg pairs to set a friction time on")
    pair = dataclasses.replace(prof.pair, solreffriction=(float(friction_time), 1.0))
    return dataclasses.replace(prof, pair=pair)
