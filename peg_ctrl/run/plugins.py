"""Controllers and strategies from a user's own file: ``PATH.py:ClassName``.

``peg-sim compare --controller my_ctrl.py:MyConfig`` names a config class in a file outside the
package. :func:`load_plugin` imports the file as a module of its own, checks that the class is
a :class:`~peg_ctrl.controllers.base.ControllerConfig` or a
:class:`~peg_ctrl.tasks.strategies.StrategyConfig` subclass, and registers it under its
``name``. Sweep workers are new processes: the plugins travel with each episode's job and every
worker loads them before it builds the episode (a file is executed once per process: its module
stays in ``sys.modules``).
"""

from __future__ import annotations

import dataclasses
import hashlib
import importlib.util
import sys
from pathlib import Path
from typing import Any

from peg_ctrl.controllers import ControllerConfig, register_controller
from peg_ctrl.errors import ConfigError
from peg_ctrl.tasks.strategies import StrategyConfig, register_strategy

__all__ = ["Plugin", "is_plugin", "load_plugin", "load_plugins"]

#: What a plugin can be: its kind and the base class its config must extend.
KINDS = {"controller": ControllerConfig, "strategy": StrategyConfig}


@dataclasses.dataclass(frozen=True)
class Plugin:
    """A config class loaded from a user's file: its ``spec`` (``PATH.py:ClassName``, the path
    resolved), its ``kind`` (controller or strategy) and the class."""

    spec: str
    kind: str
    cls: type

    @property
    def name(self) -> str:
        """The name the class registers under."""
        return str(self.cls.name)  # type: ignore[attr-defined]


def is_plugin(value: str) -> bool:
    """Whether ``value`` names a class in a file (``PATH.py:ClassName``) rather than a
    registered name."""
    path, sep, _ = value.rpartition(":")
    return bool(sep) and path.endswith(".py")


def _split(spec: str) -> tuple[Path, str]:
    path, sep, cls_name = spec.rpartition(":")
    if not (sep and path.endswith(".py") and cls_name.isidentifier()):
        raise ConfigError(f"plugin {spec!r}: expected PATH.py:ClassName (a config class in a Python file)")
    return Path(path).expanduser().resolve(), cls_name


def load_plugin(spec: str, kind: str | None = None) -> Plugin:
    """Import ``PATH.py`` and register its ``ClassName`` (a controller or strategy config).

    Args:
        spec: ``PATH.py:ClassName``; a relative path is taken from the working directory.
        kind: ``"controller"`` or ``"strategy"`` to require that kind; None accepts either.

    Raises:
        ConfigError: the file does not exist or fails to import, it has no such class, the class
            is not of the kind asked for, or its name is taken by a registered class (the
            message names the file, the class and what is allowed).
    """
    path, cls_name = _split(spec)
    plugin = _import(path, cls_name, spec)  # a file is executed once per process (sys.modules)
    register = register_controller if plugin.kind == "controller" else register_strategy
    register(plugin.cls)  # type: ignore[arg-type]  # the same class again is a no-op
    if kind is not None and plugin.kind != kind:
        raise ConfigError(f"{spec}: {cls_name} is a {plugin.kind} config; a {kind} config is needed here")
    return plugin


def load_plugins(specs: tuple[str, ...] | list[str]) -> list[Plugin]:
    """:func:`load_plugin` each of ``specs`` (a worker's first step, before its episode)."""
    return [load_plugin(spec) for spec in specs]


def _import(path: Path, cls_name: str, spec: str) -> Plugin:
    if not path.is_file():
        raise ConfigError(f"plugin {spec!r}: there is no file {path}")
    # A module name of its own per file: two users' my_ctrl.py never collide, nor shadow ours.
    digest = hashlib.sha1(str(path).encode()).hexdigest()[:10]
    module_name = f"peg_ctrl_plugin_{path.stem}_{digest}"
    module = sys.modules.get(module_name)  # a file naming two classes is imported once
    if module is None:
        module = _exec(path, module_name, spec)
    cls = getattr(module, cls_name, None)
    if cls is None:
        raise ConfigError(f"plugin {spec!r}: {path} defines no {cls_name}")
    for kind, base in KINDS.items():
        if isinstance(cls, type) and issubclass(cls, base):
            if "name" not in vars(cls):
                raise ConfigError(
                    f"plugin {spec!r}: {cls_name} has no name of its own (set name: ClassVar[str] = "
                    "'...' on the class)"
                )
            return Plugin(f"{path}:{cls_name}", kind, cls)
    raise ConfigError(
        f"plugin {spec!r}: {cls_name} is not a ControllerConfig or StrategyConfig subclass "
        "(a config class naming a controller or a strategy)"
    )


def _exec(path: Path, module_name: str, spec: str) -> Any:
    """Import ``path`` as the module ``module_name``."""
    module_spec = importlib.util.spec_from_file_location(module_name, path)
    if module_spec is None or module_spec.loader is None:
        raise ConfigError(f"plugin {spec!r}: {path} cannot be imported as a Python module")
    module = importlib.util.module_from_spec(module_spec)
    sys.modules[module_name] = module  # dataclasses look their module up while the class is made
    try:
        module_spec.loader.exec_module(module)
    except Exception as exc:
        del sys.modules[module_name]
        raise ConfigError(
            f"plugin {spec!r}: importing {path} failed: {type(exc).__name__}: {' '.join(str(exc).split())}"
        ) from exc
    return module
