"""``--set KEY=VALUE``: the override function, and the command line that exports or runs with it."""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
import pytest

from peg_ctrl.config import apply_overrides, parse_value
from peg_ctrl.errors import ConfigError

from ..conftest import assert_one_line_error, peg_sim_here

PRECISION_SETTINGS = ["physics.profile=precision", "scene.assets.clearance=5e-5"]


# --- apply_overrides ---------------------------------------------------------------------------


def test_missing_levels_are_created() -> None:
    assert apply_overrides({}, ["physics.profile=precision"]) == {"physics": {"profile": "precision"}}
    assert apply_overrides({"seed": 3}, ["scene.assets.clearance=0.002"]) == {
        "seed": 3,
        "scene": {"assets": {"clearance": 0.002}},
    }


def test_input_is_not_changed() -> None:
    data: dict[str, Any] = {"scene": {"assets": {"clearance": 0.001}}, "controller": "pd"}
    before = copy.deepcopy(data)
    result = apply_overrides(data, ["scene.assets.clearance=5e-5", "controller.kp_pos=[1, 2, 3]"])
    assert data == before
    assert result["scene"]["assets"]["clearance"] == 5e-5
    assert result["scene"] is not data["scene"]


def test_a_selectable_named_by_a_bare_string_keeps_its_name() -> None:
    assert apply_overrides({"controller": "pd"}, ["controller.kp_pos=[1,2,3]"]) == {
        "controller": {"name": "pd", "kp_pos": [1, 2, 3]}
    }


def test_the_last_assignment_wins() -> None:
    assert apply_overrides({"seed": 1}, ["seed=2", "seed=5"]) == {"seed": 5}


def test_config_files_read_exponents_as_numbers(tmp_path: Path) -> None:
    from peg_ctrl.config import read_mapping

    (tmp_path / "c.yaml").write_text("scene: {assets: {clearance: 5e-5}}\ngains: [1e3, 2E+2]\nname: 1e3x\n")
    assert read_mapping(tmp_path / "c.yaml") == {
        "scene": {"assets": {"clearance": 5e-5}},
        "gains": [1000.0, 200.0],
        "name": "1e3x",
    }


def test_an_integral_exponent_fills_an_integer_field(tmp_path: Path) -> None:
    from peg_ctrl.config import read_mapping
    from peg_ctrl.run.episode import episode_config_from_mapping

    (tmp_path / "c.yaml").write_text("max_steps: 1e5\nsuccess: {force_spike: 1e9}\n")
    cfg = episode_config_from_mapping(read_mapping(tmp_path / "c.yaml"))
    assert cfg.max_steps == 100_000 and type(cfg.max_steps) is int
    assert cfg.success.force_spike == 1e9
    with pytest.raises(ConfigError, match=r"max_steps: expected an integer, got 1500.5"):
        episode_config_from_mapping({"max_steps": 1.5e3 + 0.5})


@pytest.mark.parametrize(
    "text, value, kind",
    [
        ("1e-5", 1e-5, float),
        ("5e-5", 5e-5, float),  # YAML 1.1 alone would read these two as strings
        ("-2E+3", -2000.0, float),
        ("0.002", 0.002, float),
        ("3", 3, int),
        ("true", True, bool),
        ("[0.1, 0.2]", [0.1, 0.2], list),
        ("[1e3, 2e-5]", [1000.0, 2e-5], list),  # exponents inside lists and mappings too
        ("{a: 5e-5}", {"a": 5e-5}, dict),
        ("precision", "precision", str),
    ],
)
def test_values_are_yaml_with_exponent_floats(text: str, value: Any, kind: type) -> None:
    parsed = apply_overrides({}, [f"x={text}"])["x"]
    assert parsed == value and type(parsed) is kind
    assert type(parse_value(text)) is kind


@pytest.mark.parametrize("item", ["foo", "=3", "a..b=1", ".a=1", "a.=1"])
def test_malformed_assignments_are_rejected(item: str) -> None:
    with pytest.raises(ConfigError, match="KEY=VALUE"):
        apply_overrides({}, [item])


def test_a_path_through_a_scalar_names_the_scalar() -> None:
    with pytest.raises(ConfigError, match=r"seed is 3, not a mapping"):
        apply_overrides({"seed": 3}, ["seed.x=1"])


def test_invalid_yaml_value_is_a_config_error() -> None:
    with pytest.raises(ConfigError, match="not valid YAML"):
        apply_overrides({}, ["x=[1, 2"])


# --- the command line --------------------------------------------------------------------------


@pytest.fixture(scope="module")
def study_model() -> mujoco.MjModel:
    """The model a study with the precision settings runs."""
    from peg_ctrl.run.episode import compiled_model, episode_config_from_mapping

    cfg = episode_config_from_mapping(
        {"physics": {"profile": "precision"}, "scene": {"assets": {"clearance": 5e-5}}}
    )
    return compiled_model(cfg.scene, cfg.physics.profile)


@pytest.fixture(scope="module", params=["set", "config"])
def exported(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> mujoco.MjModel:
    """``peg-sim model`` with the precision settings given by ``--set`` or in a ``--config`` file."""
    work = tmp_path_factory.mktemp(f"export-{request.param}")
    if request.param == "set":
        options = [arg for item in PRECISION_SETTINGS for arg in ("--set", item)]
    else:
        # 5e-5 without a dot: config files read it as a number (plain YAML 1.1 would not).
        (work / "precision.yaml").write_text(
            "physics: {profile: precision}\nscene:\n  assets: {clearance: 5e-5}\n"
        )
        options = ["--config", "precision.yaml"]
    proc = peg_sim_here(["model", "--out", "scene", *options], cwd=work)
    assert proc.returncode == 0, proc.stderr
    return mujoco.MjModel.from_xml_path(str(work / "scene" / "scene.xml"))


def test_exported_model_is_the_precision_scene(exported: mujoco.MjModel) -> None:
    from peg_ctrl.sim.physics import parts_for_play

    assert exported.opt.timestep == 0.0005
    parts = [g for g in range(exported.ngeom) if exported.geom(g).name.startswith("object_")]
    assert len(parts) == parts_for_play(5e-5, 5e-6) + 4  # the hole's sides and the ring's slabs
    assert exported.npair == len(parts) + 1  # each block part and the table


@pytest.mark.parametrize(
    "field",
    [
        "geom_type",
        "geom_size",
        "geom_margin",
        "pair_dim",
        "pair_geom1",
        "pair_geom2",
        "pair_friction",
        "pair_solref",
        "pair_solimp",
        "pair_margin",
        "pair_gap",
    ],
)
def test_exported_model_is_the_one_a_study_runs(
    exported: mujoco.MjModel, study_model: mujoco.MjModel, field: str
) -> None:
    assert exported.ngeom == study_model.ngeom and exported.npair == study_model.npair
    np.testing.assert_array_equal(getattr(exported, field), getattr(study_model, field))


def test_exported_solver_options_are_the_study_ones(
    exported: mujoco.MjModel, study_model: mujoco.MjModel
) -> None:
    for name in ("timestep", "integrator", "solver", "tolerance", "iterations", "impratio", "cone"):
        assert getattr(exported.opt, name) == getattr(study_model.opt, name), name


@pytest.mark.parametrize(
    "item, message",
    [
        ("physics.profile=precise", "unknown physics profile 'precise'"),
        ("scene.asset.clearance=1", "scene.asset"),
        ("foo", "KEY=VALUE"),
        ("scene.assets.clearance=-0.002", "clearance"),
    ],
)
def test_bad_model_override_is_one_line_with_exit_2(item: str, message: str, tmp_path: Path) -> None:
    assert_one_line_error(peg_sim_here(["model", "--out", "X", "--set", item], cwd=tmp_path), message)
    assert not (tmp_path / "X").exists(), "bad input must be rejected before any output is created"


@pytest.mark.parametrize(
    "argv, message",
    [
        (["run", "--set", "physics.profile=nope", "--out", "X"], "physics.profile"),
        (["sweep", "quick", "--set", "physics.profile=nope", "--out", "X"], "physics.profile"),
        (["sweep", "quick", "--set", "clearances=[-0.002]", "--out", "X"], "clearances[0]"),
        (
            [
                "run",
                "--set",
                "physics.profile=precision",
                "--set",
                "scene.contact_override=true",
                "--out",
                "X",
            ],
            "scene.contact_override",
        ),
        (["run", "--set", "seed=[1, 2", "--out", "X"], "--set seed: value '[1, 2' is not valid YAML"),
        (["validity", "--seed", "-1", "--out", "X"], "--seed must be >= 0, got -1"),
        (["validity", "--profile", "exact", "--out", "X"], "--profile: unknown physics profile 'exact'"),
        (["bench", "--physics", "--sweep", "--out", "X"], "--physics, --sweep and --qp are separate"),
    ],
)
def test_bad_run_and_sweep_overrides_are_one_line_with_exit_2(
    argv: list[str], message: str, tmp_path: Path
) -> None:
    assert_one_line_error(peg_sim_here(argv, cwd=tmp_path), message)
    assert not (tmp_path / "X").exists()


# --- --controller beside --set controller.* and a config file ----------------------------------

MPC_FILE = "controller: {name: mpc, formulation: contact, force_limit: 7.0}\n"


def _run_controller(argv: list[str], cwd: Path) -> dict[str, Any]:
    """The controller section ``peg-sim run ARGV`` would run (parsed, merged and loaded as ``run``
    does, nothing run); a file named in ARGV is in ``cwd``."""
    from peg_ctrl.cli.app import _parser
    from peg_ctrl.cli.run import _config
    from peg_ctrl.config import to_dict

    argv = [str(cwd / a) if a.endswith(".yaml") else a for a in argv]
    return to_dict(_config(_parser().parse_args(["run", *argv])).controller)


@pytest.mark.parametrize(
    "argv, expected",
    [
        # the flag and --set on the same controller: both kept, in either order
        (["--controller", "pd", "--set", "controller.kp_pos=2000"], {"name": "pd", "kp_pos": 2000.0}),
        (["--set", "controller.kp_pos=2000", "--controller", "pd"], {"name": "pd", "kp_pos": 2000.0}),
        (
            [
                "--controller",
                "impedance",
                "--set",
                "controller.name=impedance",
                "--set",
                "controller.control_dt=0.01",
            ],
            {"name": "impedance", "control_dt": 0.01},
        ),
        # a file's fields are kept for its controller, --set on top of them
        (["--config", "mpc.yaml", "--set", "controller.force_limit=5"], {"name": "mpc", "force_limit": 5.0}),
        (["--config", "mpc.yaml", "--controller", "mpc"], {"name": "mpc", "force_limit": 7.0}),
        # ... and dropped when the command line names another controller, whose --set fields stay
        (
            ["--config", "mpc.yaml", "--controller", "pd", "--set", "controller.kp_pos=2000"],
            {"name": "pd", "kp_pos": 2000.0},
        ),
        (
            ["--config", "mpc.yaml", "--set", "controller.kp_pos=2000", "--controller", "pd"],
            {"name": "pd", "kp_pos": 2000.0},
        ),
        (
            ["--config", "mpc.yaml", "--set", "controller.name=pd", "--set", "controller.kp_pos=2000"],
            {"name": "pd", "kp_pos": 2000.0},
        ),
    ],
)
def test_controller_flag_set_and_file_merge(
    argv: list[str], expected: dict[str, Any], tmp_path: Path
) -> None:
    (tmp_path / "mpc.yaml").write_text(MPC_FILE)
    controller = _run_controller(argv, tmp_path)
    assert {k: controller[k] for k in expected} == expected
    if controller["name"] == "mpc":
        assert controller["formulation"] == "contact"  # the file's other field


@pytest.mark.parametrize(
    "options",
    [
        ["--controller", "pd", "--set", "controller.name=impedance"],
        ["--set", "controller.name=impedance", "--controller", "pd"],
        ["--config", "mpc.yaml", "--controller", "pd", "--set", "controller.name=impedance"],
        ["--config", "mpc.yaml", "--set", "controller=impedance", "--controller", "pd"],
    ],
)
def test_a_flag_and_a_set_naming_different_controllers_are_refused(
    options: list[str], tmp_path: Path
) -> None:
    (tmp_path / "mpc.yaml").write_text(MPC_FILE)
    proc = peg_sim_here(["run", *options, "--out", "X"], cwd=tmp_path)
    assert_one_line_error(
        proc,
        "--controller pd and --set controller.name=impedance name different controllers; give one of them",
    )
    assert not (tmp_path / "X").exists()
