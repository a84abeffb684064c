"""The phantom-contact guard: MuJoCo's multiccd now and then answers a flat peg end resting on
flat faces with a contact as deep as a block part is wide; the loop recomputes that step without
multiccd (``peg_ctrl.run.loop.PhantomGuard``), and a step without a phantom is the plain ``mj_step``."""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np
import pytest

from peg_ctrl.run.loop import PhantomGuard
from peg_ctrl.sim.assets import AssetParams
from peg_ctrl.sim.physics import PRECISION
from peg_ctrl.sim.scene import SceneConfig, build_model

PHANTOM_SEEN_IN = "4.0.0"  # the MuJoCo release whose collider returns the phantom below

# A diffik episode's state (align strategy, friction 0.3, seed 1), one step before its collider
# returned a 9.5 mm phantom contact and its solver a 1768 N force: the peg's end lies flat on the
# datum, across several of the block's parts. That was the precision block of 71 wedge-shaped
# parts reaching the block's walls; today's puts the datum on one slab (AssetParams.hole_ring),
# where the collider returns no phantom at this state, so the guard is tested on the old block.
QPOS = [
    0.17760205753350183,
    -0.02148048180820112,
    0.10000002674582369,
    -2.813846682909245e-06,
    -0.9879118618056398,
    0.15501662263945695,
    -1.1187216134551582e-06,
    0.1745411200143541,
    -0.03099349986258342,
    0.11995055520734778,
    -0.6985739201739763,
    -0.6985441004244377,
    0.1096120761575191,
    0.10961665281979352,
    0.6352112986008253,
    0.0005738819472962637,
    0.6309306929988368,
    -0.6253948239085968,
    0.6352112335980742,
    0.0005737090530937482,
    0.6309305429599349,
    -0.625391886648442,
]
QVEL = [
    -9.767558041803539e-06,
    6.007571782578208e-06,
    6.255523111737289e-08,
    0.00021742035038914623,
    0.0004825744075806173,
    0.0013113170366160433,
    -1.4994838475395473e-05,
    8.02010884368696e-06,
    -3.901320069630429e-06,
    3.13743061116904e-05,
    1.3204364820514402e-05,
    -2.1393802740370524e-05,
    1.0573765560274837e-05,
    3.7423587791719486e-06,
    2.7597156074499147e-05,
    -7.22818364564253e-05,
    3.936111232416794e-06,
    -1.8538494703374472e-06,
    -1.1918088338865182e-05,
    3.7607906728172486e-05,
]
CTRL = [
    255.0,
    0.002979721994884789,
    0.005615988823120827,
    11.001296083762558,
    -1.1179262451078258,
    -0.00018880989327030198,
    -0.0006284422999320082,
]


# The precision profile with the block it had then: 71 parts to the walls, no slabs.
WEDGES = dataclasses.replace(PRECISION, name="precision-71", hole_play_tolerance=None, hole_ring_wall=None)


@pytest.fixture(scope="module")
def model() -> mujoco.MjModel:
    scene = SceneConfig(assets=AssetParams(clearance=5e-5, chamfer=0.001, n_parts=71), friction=0.3)
    return build_model(scene, WEDGES)


def test_todays_block_puts_that_datum_on_a_slab_without_a_phantom() -> None:
    scene = SceneConfig(assets=AssetParams(clearance=5e-5, chamfer=0.001), friction=0.3)
    today = build_model(scene, "precision")
    data = _at_the_state(today)
    mujoco.mj_forward(today, data)
    peg, block = today.body("peg").id, today.body("block").id
    parts = [today.geom(g).name for g in range(today.ngeom) if today.geom_bodyid[g] == block]
    slabs = set(parts[-4:])  # the block's last four collision parts
    touched = {
        today.geom(int(g)).name
        for c in data.contact[: data.ncon]
        for g in (c.geom1, c.geom2)
        if today.geom_bodyid[g] == block and peg in (today.geom_bodyid[c.geom1], today.geom_bodyid[c.geom2])
    }
    assert touched and touched <= slabs
    assert -_deepest_peg_block(today, data) < 1e-6


def _at_the_state(model: mujoco.MjModel) -> mujoco.MjData:
    data = mujoco.MjData(model)
    data.qpos[:] = QPOS
    data.qvel[:] = QVEL
    data.ctrl[:] = CTRL
    return data


def _deepest_peg_block(model: mujoco.MjModel, data: mujoco.MjData) -> float:
    peg, block = model.body("peg").id, model.body("block").id
    deepest = 0.0
    for i in range(data.ncon):
        c = data.contact[i]
        bodies = {int(model.geom_bodyid[c.geom1]), int(model.geom_bodyid[c.geom2])}
        if bodies == {peg, block}:
            deepest = min(deepest, float(c.dist))
    return deepest


def test_the_collider_returns_a_phantom_here_and_the_guard_removes_it(model: mujoco.MjModel) -> None:
    data = _at_the_state(model)
    mujoco.mj_forward(model, data)
    depth = -_deepest_peg_block(model, data)
    if mujoco.__version__ != PHANTOM_SEEN_IN and depth <= PRECISION.phantom_depth:
        pytest.skip(f"MuJoCo {mujoco.__version__}'s collider returns no phantom at this state")
    assert depth > PRECISION.phantom_depth, f"no phantom in MuJoCo {PHANTOM_SEEN_IN}: deepest {depth} m"
    plain = _at_the_state(model)
    mujoco.mj_step(model, plain)
    guarded = _at_the_state(model)
    guard = PhantomGuard(model, PRECISION.phantom_depth)
    guard.step(model, guarded)
    assert guard.count == 1
    # The plain step answers the phantom with a kick; the guarded one barely moves the peg (for
    # that one step the pads, too, have single contacts).
    peg = model.joint("peg_free").dofadr[0]
    assert np.linalg.norm(plain.qvel[peg : peg + 3]) > 0.1
    assert np.linalg.norm(guarded.qvel[peg : peg + 3]) < 0.01
    assert model.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_MULTICCD == 0  # restored


def test_without_a_phantom_the_guarded_step_is_the_plain_one(model: mujoco.MjModel) -> None:
    plain, guarded = mujoco.MjData(model), mujoco.MjData(model)
    for data in (plain, guarded):
        mujoco.mj_resetDataKeyframe(model, data, model.key("home").id)
    guard = PhantomGuard(model, PRECISION.phantom_depth)
    rng = np.random.default_rng(0)
    for _ in range(500):
        u = rng.normal(0.0, 3.0, model.nu)
        plain.ctrl[:] = u
        guarded.ctrl[:] = u
        mujoco.mj_step(model, plain)
        guard.step(model, guarded)
    assert guard.count == 0
    assert np.array_equal(plain.qpos, guarded.qpos) and np.array_equal(plain.qvel, guarded.qvel)


def test_rk4_cannot_be_guarded() -> None:
    with pytest.raises(ValueError, match="RK4"):
        PhantomGuard(build_model(SceneConfig(), "seed"), 1e-4)


def _period(model: mujoco.MjModel, data: mujoco.MjData, guard: PhantomGuard, n: int) -> bool:
    """A control period as the loop runs it: plain steps checked afterwards, rerun guarded if
    the check says so; whether it was rerun."""
    rows = np.zeros((n, model.nsensordata))
    guard.begin(model, data)
    for i in range(n):
        mujoco.mj_step(model, data)
        rows[i] = data.sensordata
    rerun = guard.end(model, data, rows)
    assert model.opt.disableflags == 0  # the auto-reset is back
    if rerun:
        for _ in range(n):
            guard.step(model, data)
    return rerun


def _same(a: mujoco.MjData, b: mujoco.MjData) -> bool:
    return (
        a.time == b.time
        and np.array_equal(a.qpos, b.qpos)
        and np.array_equal(a.qvel, b.qvel)
        and np.array_equal(a.sensordata, b.sensordata)
        and np.array_equal(a.warning.number, b.warning.number)
    )


def test_a_period_checked_afterwards_sees_the_phantom_and_is_the_guarded_one(model: mujoco.MjModel) -> None:
    """The peg-block sensor shows the phantom of a plain step; the period is rerun guarded and
    ends exactly where stepping it guarded ends."""
    data = _at_the_state(model)
    mujoco.mj_forward(model, data)
    if -_deepest_peg_block(model, data) <= PRECISION.phantom_depth:
        pytest.skip(f"MuJoCo {mujoco.__version__}'s collider returns no phantom at this state")
    exact, checked = _at_the_state(model), _at_the_state(model)
    guard_exact, guard = (
        PhantomGuard(model, PRECISION.phantom_depth),
        PhantomGuard(model, PRECISION.phantom_depth),
    )
    assert guard.sensor is not None
    for _ in range(3):
        guard_exact.step(model, exact)
    assert _period(model, checked, guard, 3)
    assert guard.count == guard_exact.count == 1 and _same(checked, exact)


def test_periods_without_a_phantom_are_the_guarded_steps(model: mujoco.MjModel) -> None:
    exact, checked = mujoco.MjData(model), mujoco.MjData(model)
    for data in (exact, checked):
        mujoco.mj_resetDataKeyframe(model, data, model.key("home").id)
    guard_exact, guard = (
        PhantomGuard(model, PRECISION.phantom_depth),
        PhantomGuard(model, PRECISION.phantom_depth),
    )
    rng = np.random.default_rng(0)
    for _ in range(250):
        u = rng.normal(0.0, 3.0, model.nu)
        exact.ctrl[:] = u
        checked.ctrl[:] = u
        for _ in range(2):
            guard_exact.step(model, exact)
        assert not _period(model, checked, guard, 2)
    assert guard.count == 0 and _same(checked, exact)


@pytest.mark.parametrize("bad", ["ctrl", "qvel"])
def test_a_period_that_goes_bad_is_rerun_from_its_start(model: mujoco.MjModel, bad: str) -> None:
    """A bad control (a warning) or a velocity over MuJoCo's limit (a warning and, with the
    auto-reset, a reset) in a period: it is put back to its start, warnings included, and rerun
    guarded: the warnings and the state are those of stepping it guarded."""
    exact, checked = mujoco.MjData(model), mujoco.MjData(model)
    for data in (exact, checked):
        mujoco.mj_resetDataKeyframe(model, data, model.key("home").id)
        data.time = 1.0
        if bad == "ctrl":
            data.ctrl[0] = np.nan
        else:
            data.qvel[0] = 1e11
    guard_exact, guard = (
        PhantomGuard(model, PRECISION.phantom_depth),
        PhantomGuard(model, PRECISION.phantom_depth),
    )
    for _ in range(2):
        guard_exact.step(model, exact)
    assert _period(model, checked, guard, 2)
    assert exact.warning.number.any() and _same(checked, exact)
    assert (exact.time < 1.0) is (bad == "qvel")  # the reset
