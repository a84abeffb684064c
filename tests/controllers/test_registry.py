"""The controller registry: names, selection from plain data, errors that name what is wrong."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import ClassVar

import mujoco
import pytest

from peg_ctrl.config import load, to_dict
from peg_ctrl.controllers import (
    REGISTRY,
    AdmittanceConfig,
    ControllerConfig,
    ImpedanceConfig,
    PDConfig,
    PDController,
    UnknownController,
    controller_names,
    make_controller,
)
from peg_ctrl.errors import ConfigError, UnknownComponent

from ..conftest import FirstImports
from .conftest import NAMES

KNOWN = "known: admittance, diffik, impedance, mpc, pd"


def test_registry_is_derived_from_the_config_classes() -> None:
    assert tuple(controller_names()) == NAMES
    for name, config_cls in REGISTRY.items():
        assert issubclass(config_cls, ControllerConfig)
        assert config_cls.name == name


@pytest.mark.parametrize("name", NAMES)
def test_every_config_builds_its_controller(name: str, model: mujoco.MjModel) -> None:
    controller = REGISTRY[name]().build(model)
    assert controller.name == name
    assert controller.config == REGISTRY[name]()  # type: ignore[attr-defined]


def test_make_controller_unknown_name_lists_the_known_ones(model: mujoco.MjModel) -> None:
    with pytest.raises(UnknownComponent, match=KNOWN):
        make_controller("lqg", model)
    assert UnknownController is UnknownComponent


def test_make_controller_from_name_and_fields(model: mujoco.MjModel) -> None:
    c = make_controller("pd", model, kp_pos=2000.0, control_dt=0.002)
    assert isinstance(c, PDController)
    assert c.config == PDConfig(kp_pos=2000.0, control_dt=0.002)
    assert c.control_dt == 0.002


def test_make_controller_from_a_config(model: mujoco.MjModel) -> None:
    cfg = PDConfig(kp_pos=2000.0)
    assert make_controller(cfg, model).config == cfg  # type: ignore[attr-defined]
    with pytest.raises(ConfigError, match="kp_pos"):
        make_controller(cfg, model, kp_pos=1.0)


@pytest.mark.parametrize(
    ("params", "where"),
    [
        ({"kp_pos": -1.0}, r"controller\.kp_pos: must be finite and > 0"),
        ({"kp_pos": "stiff"}, r"controller\.kp_pos: expected a number"),
        ({"not_a_gain": 1.0}, r"controller\.not_a_gain: unknown field"),
    ],
)
def test_make_controller_bad_fields_are_named(model: mujoco.MjModel, params: dict, where: str) -> None:
    with pytest.raises(ConfigError, match=where):
        make_controller("pd", model, **params)


def test_select_unknown_name_lists_all_five() -> None:
    with pytest.raises(UnknownComponent, match=KNOWN) as info:
        ControllerConfig.select({"name": "lqg"})
    assert info.value.name == "lqg"


def test_select_tuple_gains_from_lists_and_scale_them() -> None:
    """An experiment's ``{name: impedance, k_pos: [1200, 1200, 1200]}`` with a gain scale."""
    cfg = ControllerConfig.select({"name": "impedance", "k_pos": [1200, 1200, 1200]})
    assert cfg == ImpedanceConfig(k_pos=(1200.0, 1200.0, 1200.0))
    assert cfg.scaled(1.1).k_pos == (1200.0 * 1.1,) * 3  # type: ignore[attr-defined]


def test_select_accepts_a_name_a_config_or_no_name() -> None:
    assert ControllerConfig.select("mpc") == REGISTRY["mpc"]()
    cfg = PDConfig(kp_pos=10.0)
    assert ControllerConfig.select(cfg) is cfg
    assert ControllerConfig.select({"kp_pos": 10.0}) == cfg  # the default controller is pd


@pytest.mark.parametrize(
    ("data", "where"),
    [
        ({"name": "impedance", "k_pos": [1.0, 2.0]}, r"controller\.k_pos: expected 3 entries"),
        ({"name": "impedance", "k_pos": [1.0, -2.0, 3.0]}, r"controller\.k_pos: must be finite"),
        ({"name": "mpc", "horizon": 1}, r"controller\.horizon: must be an integer >= 2"),
        ({"name": "mpc", "mpc_dt": 0.0105}, r"controller\.mpc_dt: must be a whole multiple"),
        ({"name": "mpc", "solver": "gurobi"}, r"controller\.solver: must be one of"),
        ({"name": "diffik", "ik_dt": 0.0105}, r"controller\.ik_dt: must be a whole multiple"),
        ({"name": "diffik", "solver": "nope"}, r"controller\.solver: 'nope' is not installed"),
        ({"name": "admittance", "inner": {"kp_pos": 0}}, r"controller\.inner\.kp_pos: must be finite"),
        ({"name": "admittance", "inner": {"kd": 1}}, r"controller\.inner\.kd: unknown field"),
        ({"name": "admittance", "inner": {"name": "mpc"}}, r"controller\.inner\.name: expected 'pd'"),
        ({"name": 3}, r"controller\.name: expected a string"),
        (["pd"], r"controller: expected a controller name or a mapping"),
    ],
)
def test_select_bad_values_are_named(data: object, where: str) -> None:
    with pytest.raises(ConfigError, match=where):
        ControllerConfig.select(data)


def test_select_uses_the_prefix_it_is_given() -> None:
    with pytest.raises(ConfigError, match=r"run\.ctrl\.kp_pos"):
        ControllerConfig.select({"name": "pd", "kp_pos": -1.0}, prefix="run.ctrl.")


def test_selectable_field_in_an_experiment_config() -> None:
    """``peg_ctrl.config.load`` picks the controller config by name, and saves the name back."""

    @dataclasses.dataclass(frozen=True)
    class Experiment:
        controller: ControllerConfig = PDConfig()

    exp = load(Experiment, {"controller": {"name": "admittance", "inner": {"kp_pos": 2000}}})
    assert exp.controller == AdmittanceConfig(inner=PDConfig(kp_pos=2000.0))
    saved = to_dict(exp)
    assert saved["controller"]["name"] == "admittance"
    assert saved["controller"]["inner"]["name"] == "pd"
    assert load(Experiment, saved) == exp
    with pytest.raises(ConfigError, match=r"^controller\.stiffness: must be finite"):
        load(Experiment, {"controller": {"name": "admittance", "stiffness": -3}})


@pytest.mark.parametrize("name", NAMES)
def test_saved_configs_load_again(name: str) -> None:
    cfg = REGISTRY[name]().scaled(0.9)
    assert ControllerConfig.select(to_dict(cfg)) == cfg


MODULES = ("", ".base", ".pd", ".impedance", ".admittance", ".diffik", ".mpc", ".dynamics")


@pytest.mark.parametrize("module", MODULES)
def test_imports_first_without_higher_layers(
    module: str, tmp_path: Path, first_imports: FirstImports
) -> None:
    code = (
        "import sys\n"
        f"import peg_ctrl.controllers{module}\n"
        "higher = ('peg_ctrl.run', 'peg_ctrl.tasks', 'peg_ctrl.teleop', 'peg_ctrl.gym', 'peg_ctrl.tools',\n"
        "          'peg_ctrl.cli', 'peg_ctrl.experiments')\n"
        "loaded = sorted(m for m in sys.modules if m.startswith(higher))\n"
        "assert not loaded, loaded\n"
    )
    result = first_imports.run(code, cwd=tmp_path)
    assert result.returncode == 0, result.stderr


def test_register_controller_adds_a_name_and_refuses_clashes(monkeypatch: pytest.MonkeyPatch) -> None:
    from peg_ctrl.controllers import register_controller

    monkeypatch.setattr("peg_ctrl.controllers.REGISTRY", dict(REGISTRY))
    from peg_ctrl import controllers

    @dataclasses.dataclass(frozen=True, kw_only=True)
    class SoftPD(PDConfig):
        name: ClassVar[str] = "soft_pd"
        kp_pos: float = 500.0

    register_controller(SoftPD)
    assert controllers.REGISTRY["soft_pd"] is SoftPD
    cfg = ControllerConfig.select({"name": "soft_pd"})
    assert isinstance(cfg, SoftPD) and cfg.kp_pos == 500.0
    register_controller(SoftPD)  # the same class again: no change

    @dataclasses.dataclass(frozen=True, kw_only=True)
    class Other(PDConfig):
        name: ClassVar[str] = "pd"

    with pytest.raises(ConfigError, match="the name 'pd' is taken by PDConfig"):
        register_controller(Other)
    register_controller(Other, replace=True)
    assert controllers.REGISTRY["pd"] is Other
    with pytest.raises(ConfigError, match="expected a ControllerConfig subclass"):
        register_controller(dict)  # type: ignore[arg-type]
