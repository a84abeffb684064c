"""The cross-check battery: every situation in every contact model, and what each measured.

:data:`MODELS` are the contact models compared: MuJoCo's precision profile as the studies run it
and with the peg's friction given more time to react (``physics.friction_time``), the same in
the project's scene with the gripper's grasp, and Drake's point contact under its lagged and
convex approximations, with stiffness and dissipation chosen for steel parts (:data:`STEEL`).

:func:`measure` reduces a :class:`~peg_ctrl.tools.crosscheck.rig.Trace` to the table's numbers;
:func:`run_battery` runs every (situation, model) on worker processes.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from peg_ctrl.errors import UnknownComponent
from peg_ctrl.sim.force_metric import SUSTAIN_WINDOW, sustained_peak
from peg_ctrl.tools.crosscheck.drake_rig import DrakeContact
from peg_ctrl.tools.crosscheck.rig import Engine, Rig, Trace, run_situation, study_rig
from peg_ctrl.tools.crosscheck.situations import SITUATIONS, Situation, coulomb_slide_force, situation

__all__ = [
    "Model",
    "MODELS",
    "BY_NAME",
    "STEEL",
    "REFERENCE",
    "CHOSEN",
    "CHOSEN_GRASP",
    "model",
    "measure",
    "run_one",
    "run_battery",
    "WINDOWS",
]

# Drake's contact for steel on steel. Stiffness: Hertz's contact of an edge broken to a 0.5 mm
# radius on a flat (E* = 110 GPa) is 3e6 N/m at 1 N and 7e6 N/m at 10 N; a sharper edge is
# softer, a flat patch stiffer. Dissipation: Hunt-Crossley's restitution 1 - 2/3 d v is 0.9 at
# 0.5 m/s for d = 0.3 s/m (steel spheres, 0.1-0.3 s/m): at the situations' 5-30 mm/s steel
# bounces almost elastically.
STEEL = DrakeContact(stiffness=1.0e7, dissipation=0.3)
WINDOWS = (0.005, SUSTAIN_WINDOW)  # the sustained force's windows [s]
REFERENCE = "drake_lagged"  # the contact model without the convex models' gliding
CHOSEN = "mujoco_friction5ms"  # the model the studies run
CHOSEN_GRASP = "mujoco_grasp_friction5ms"  # ... in the project's scene, the gripper's grasp


@dataclasses.dataclass(frozen=True)
class Model:
    """A contact model: ``engine`` ``"mujoco"`` (the rig), ``"mujoco-grasp"`` (the project's
    scene, the gripper holding the peg) or ``"drake"`` (the rig, ``drake`` its contact)."""

    name: str
    engine: str
    friction_time: float | None = None  # MuJoCo: the peg's pairs' friction reference [s]
    options: tuple[tuple[str, Any], ...] = ()  # MuJoCo: PhysicsProfile fields set otherwise
    drake: DrakeContact | None = None
    note: str = ""

    def build(self, rig: Rig, s: Situation) -> Engine:
        """The engine's rig at the situation's start."""
        if self.engine == "drake":
            from peg_ctrl.tools.crosscheck.drake_rig import DrakeRig

            assert self.drake is not None
            return DrakeRig(rig, s, self.drake)
        from peg_ctrl.sim.physics import with_friction_time
        from peg_ctrl.tools.crosscheck.mujoco_rig import MujocoGrasp, MujocoRig

        physics = with_friction_time(
            dataclasses.replace(rig.profile, **dict(self.options)), self.friction_time
        )
        return MujocoGrasp(rig, s, physics) if self.engine == "mujoco-grasp" else MujocoRig(rig, s, physics)


MODELS: tuple[Model, ...] = (
    Model("mujoco", "mujoco", note="the precision profile as the studies run it (solref 1 ms)"),
    Model("mujoco_friction2ms", "mujoco", friction_time=0.002, note="the peg's friction reference 2 ms"),
    Model("mujoco_friction5ms", "mujoco", friction_time=0.005, note="the peg's friction reference 5 ms"),
    Model("mujoco_friction10ms", "mujoco", friction_time=0.01, note="the peg's friction reference 10 ms"),
    Model("mujoco_friction20ms", "mujoco", friction_time=0.02, note="the peg's friction reference 20 ms"),
    Model(
        "mujoco_step0.1ms",
        "mujoco",
        options=(("timestep", 1.0e-4),),
        note="a 0.1 ms step (the contact's 1 ms time constant kept)",
    ),
    Model(
        "mujoco_impratio10", "mujoco", options=(("impratio", 10.0),), note="impratio 10 (the profile's 100)"
    ),
    Model("mujoco_grasp", "mujoco-grasp", note="precision, the Menagerie gripper's grasp"),
    Model("mujoco_grasp_friction5ms", "mujoco-grasp", friction_time=0.005, note="friction 5 ms, the grasp"),
    Model("drake_lagged", "drake", drake=STEEL, note="Drake kLagged, 1e7 N/m, 0.3 s/m, 0.5 ms"),
    Model(
        "drake_lagged_0.1ms",
        "drake",
        drake=dataclasses.replace(STEEL, timestep=1.0e-4),
        note="kLagged at a 0.1 ms step (convergence)",
    ),
    Model(
        "drake_lagged_1e6",
        "drake",
        drake=dataclasses.replace(STEEL, stiffness=1.0e6),
        note="kLagged, ten times softer (sensitivity)",
    ),
    Model(
        "drake_similar", "drake", drake=dataclasses.replace(STEEL, approximation="similar"), note="kSimilar"
    ),
    Model("drake_sap", "drake", drake=dataclasses.replace(STEEL, approximation="sap"), note="kSap"),
)


#: The models by name.
BY_NAME: dict[str, Model] = {m.name: m for m in MODELS}


def model(name: str) -> Model:
    """The model called ``name``; an unknown name lists the known ones."""
    if name not in BY_NAME:
        raise UnknownComponent("contact model", name, BY_NAME)
    return BY_NAME[name]


def measure(s: Situation, trace: Trace, rig: Rig) -> dict[str, float]:
    """The numbers of one run: the peak, 99th percentile and sustained forces [N], the wrist's
    peak [N], the depths [m]. Percentiles are over the steps in contact."""
    net, normal = trace.net, trace.normal
    touching = normal > 0.0
    row: dict[str, float] = {
        "peak_normal_n": float(normal.max(initial=0.0)),
        "peak_net_n": float(net.max(initial=0.0)),
        "p99_net_n": float(np.percentile(net[touching], 99)) if touching.any() else 0.0,
        "wrist_peak_n": float(trace.wrist.max(initial=0.0)),
        "depth_final_m": float(trace.depth[-1]),
        "depth_max_m": float(trace.depth.max()),
        "contact_steps": int(touching.sum()),
        "steps": len(net),
        "overlap_max_m": float(trace.overlap.max(initial=0.0)),
        "wall_time_s": trace.wall_time_s,
    }
    for w in WINDOWS:
        row[f"sustained_{w * 1e3:g}ms_n"] = sustained_peak(net, trace.dt, w)
    if s.touch_depth is not None:
        row["coulomb_n"] = coulomb_slide_force(s, rig.k_lin, float(trace.depth.max()))
    return row


@functools.lru_cache(maxsize=1)
def _rig() -> Rig:
    return study_rig()


def run_one(situation_name: str, model_name: str, keep_trace: bool = False) -> dict[str, Any]:
    """Run one situation in one model (in a worker); its numbers, and the trace if asked."""
    s, m, rig = situation(situation_name), model(model_name), _rig()
    trace = run_situation(m.build(rig, s), rig, s)
    out: dict[str, Any] = {"situation": s.name, "model": m.name, **measure(s, trace, rig)}
    if keep_trace:
        out["trace"] = trace.columns
    return out


def run_battery(
    situations: Sequence[Situation] = SITUATIONS,
    models: Sequence[Model] = MODELS,
    *,
    workers: int = 1,
    keep_traces: bool = False,
    on_result: Callable[[dict[str, Any]], None] | None = None,
) -> list[dict[str, Any]]:
    """Every (situation, model) pair, on ``workers`` processes; rows in the order given."""
    from peg_ctrl.run.workers import worker_pool

    pairs = [(s.name, m.name) for s in situations for m in models]
    rows: dict[tuple[str, str], dict[str, Any]] = {}
    if workers <= 1:
        for pair in pairs:
            rows[pair] = run_one(*pair, keep_trace=keep_traces)
            if on_result is not None:
                on_result(rows[pair])
    else:
        from concurrent.futures import as_completed

        with worker_pool(workers) as pool:
            futures = {pool.submit(run_one, *pair, keep_traces): pair for pair in pairs}
            for future in as_completed(futures):
                rows[futures[future]] = future.result()
                if on_result is not None:
                    on_result(rows[futures[future]])
    return [rows[pair] for pair in pairs]
