"""Typed, validated configuration loading (YAML or TOML into frozen dataclasses).

``load(cls, mapping)`` builds a dataclass from plain data: unknown fields, wrong types and
values a dataclass's own ``__post_init__`` rejects all raise :class:`ConfigError` naming the
field by its dotted path (``task.lift_height``).

A *selectable* config family (the controllers) is a base dataclass with a ``select(data,
prefix=...)`` classmethod: a field typed with the base class takes a mapping with a ``name``
key (``{name: impedance, k_pos: [1200, 1200, 1200]}``) or a bare name, and the family picks
the concrete class. :func:`to_dict` writes the ``name`` back, so saved configs load again.
"""

from __future__ import annotations

import copy
import dataclasses
import json
import re
import types
import typing
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, TypeVar, Union

from peg_ctrl.errors import ConfigError

__all__ = [
    "ConfigError",
    "load",
    "load_file",
    "read_mapping",
    "to_dict",
    "is_selectable",
    "apply_overrides",
    "named_fields",
]

T = TypeVar("T")


def read_mapping(path: Path) -> dict[str, Any]:
    """Parse a ``.yaml``/``.yml``, ``.toml`` or ``.json`` file into a dict."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"config file {str(path)!r} does not exist")
    suffix = path.suffix.lower()
    if suffix not in (".yaml", ".yml", ".toml", ".json"):
        raise ConfigError(
            f"config file {str(path)!r}: unsupported suffix {suffix!r}; use .yaml, .toml or .json"
        )
    import yaml

    try:
        import tomllib
    except ImportError:  # Python 3.10
        import tomli as tomllib  # type: ignore[no-redef]

    try:
        text = path.read_text(encoding="utf-8")
        if suffix in (".yaml", ".yml"):
            data = yaml.load(text, Loader=_yaml_loader())  # noqa: S506 - a SafeLoader subclass
        elif suffix == ".toml":
            data = tomllib.loads(text)
        else:
            data = json.loads(text)
    except (yaml.YAMLError, tomllib.TOMLDecodeError, json.JSONDecodeError, UnicodeDecodeError) as exc:
        # Parser errors carry line numbers; keep them, in one line.
        raise ConfigError(
            f"config file {str(path)!r} is not valid {suffix[1:].upper()}: {exc}".replace("\n", " ")
        ) from None
    except OSError as exc:
        raise ConfigError(f"config file {str(path)!r} cannot be read: {exc.strerror}") from None
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ConfigError(f"config file {str(path)!r} must hold a mapping at the top level")
    return data


def _yaml_loader() -> type:
    """``yaml.SafeLoader`` that also reads ``1e-5`` as a number (YAML 1.2 does, PyYAML's 1.1 not)."""
    import yaml

    class Loader(yaml.SafeLoader):
        pass

    Loader.add_implicit_resolver(
        "tag:yaml.org,2002:float",
        re.compile(r"^[-+]?(?:\d+\.?\d*|\.\d+)[eE][-+]?\d+$"),
        list("-+0123456789."),
    )
    return Loader


def parse_value(text: str) -> Any:
    """A command-line value parsed as YAML, except that ``1e-5`` is a number (YAML 1.1 reads a
    mantissa without a dot as a string)."""
    import yaml

    try:
        return yaml.load(text, Loader=_yaml_loader())  # noqa: S506 - a SafeLoader subclass
    except yaml.YAMLError as exc:
        raise ConfigError(f"value {text!r} is not valid YAML: {' '.join(str(exc).split())}") from None


def apply_overrides(data: dict[str, Any], assignments: Sequence[str]) -> dict[str, Any]:
    """``data`` with each ``KEY=VALUE`` of ``assignments`` set (``--set`` on the command line).

    KEY is a dotted path into the nested mapping (``physics.profile``, ``scene.assets.clearance``,
    ``controller.kp_pos``); VALUE is parsed as YAML (``[1, 2]``, ``true``, ``1e-5``). Missing
    levels are created; whether the path names a real field is checked when the result is
    loaded, with the field's dotted path in the error. ``data`` itself is not changed.
    """
    result = copy.deepcopy(data)
    for item in assignments:
        key, sep, raw = item.partition("=")
        key = key.strip()
        parts = key.split(".")
        if not sep or not all(parts):
            raise ConfigError(
                f"--set {item!r}: expected KEY=VALUE with a dotted KEY, e.g. physics.profile=precision"
            )
        try:
            value = parse_value(raw)
        except ConfigError as exc:
            raise ConfigError(f"--set {key}: {exc}") from None
        node = result
        for depth, part in enumerate(parts[:-1]):
            child = node.get(part)
            if child is None:
                child = node[part] = {}
            elif isinstance(child, str):  # a selectable chosen by bare name: controller: pd
                child = node[part] = {"name": child}
            elif not isinstance(child, dict):
                where = ".".join(parts[: depth + 1])
                raise ConfigError(f"--set {key}: {where} is {child!r}, not a mapping")
            node = child
        node[parts[-1]] = value
    return result


def load_file(cls: type[T], path: Path) -> T:
    return load(cls, read_mapping(path))


def load(cls: type[T], data: Mapping[str, Any], *, prefix: str = "") -> T:
    """Build dataclass ``cls`` from ``data`` (missing fields take their defaults)."""
    if not isinstance(data, Mapping):
        raise ConfigError(f"{prefix.rstrip('.') or 'config'}: expected a mapping, got {type(data).__name__}")
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}  # type: ignore[arg-type]
    unknown = sorted(set(data) - set(fields))
    if unknown:
        raise ConfigError(f"{prefix}{unknown[0]}: unknown field; known: {', '.join(sorted(fields))}")
    kwargs = {}
    for name, value in data.items():
        kwargs[name] = _convert(hints[name], value, f"{prefix}{name}")
    try:
        return cls(**kwargs)
    except ConfigError:
        raise
    except (TypeError, ValueError) as exc:
        message = str(exc)
        where = prefix.rstrip(".") or cls.__name__
        raise ConfigError(f"{where}: {message}") from None


def _convert(hint: Any, value: Any, path: str) -> Any:
    origin = typing.get_origin(hint)
    args = typing.get_args(hint)
    if origin in (Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        non_none = [a for a in args if a is not type(None)]
        errors = []
        for arg in non_none:
            try:
                return _convert(arg, value, path)
            except ConfigError as exc:
                errors.append(str(exc))
        raise ConfigError(errors[0] if errors else f"{path}: invalid value {value!r}")
    if is_selectable(hint):
        return hint.select(value, prefix=f"{path}.")
    if dataclasses.is_dataclass(hint):
        return load(hint, value, prefix=f"{path}.")  # type: ignore[arg-type]
    if hint is Any:
        return value
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{path}: expected a number, got {value!r}")
        return float(value)
    if hint is int:
        if isinstance(value, float) and value.is_integer():  # 1e6 in YAML is a float
            return int(value)
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{path}: expected an integer, got {value!r}")
        return value
    if hint is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{path}: expected true or false, got {value!r}")
        return value
    if hint is str:
        if not isinstance(value, str):
            raise ConfigError(f"{path}: expected a string, got {value!r}")
        return value
    if origin is tuple:
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"{path}: expected a list, got {value!r}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_convert(args[0], v, f"{path}[{i}]") for i, v in enumerate(value))
        if len(value) != len(args):
            raise ConfigError(f"{path}: expected {len(args)} entries, got {len(value)}")
        return tuple(_convert(a, v, f"{path}[{i}]") for i, (a, v) in enumerate(zip(args, value, strict=True)))
    if origin in (dict, Mapping) or hint is dict:
        if not isinstance(value, Mapping):
            raise ConfigError(f"{path}: expected a mapping, got {value!r}")
        return dict(value)
    if origin is typing.Literal:
        if value not in args:
            raise ConfigError(f"{path}: must be one of {', '.join(map(repr, args))}, got {value!r}")
        return value
    return value


def named_fields(data: object, *, kind: str, default: str, prefix: str) -> tuple[str, dict[str, Any]]:
    """The ``name`` and the other fields of a selectable config written as a bare name or as a
    mapping with a ``name`` key (``default`` when it has none); errors name ``prefix``."""
    if isinstance(data, str):
        data = {"name": data}
    if not isinstance(data, Mapping):
        where = prefix.rstrip(".") or kind
        raise ConfigError(f"{where}: expected a {kind} name or a mapping, got {data!r}")
    fields = dict(data)
    name = fields.pop("name", default)
    if not isinstance(name, str):
        raise ConfigError(f"{prefix}name: expected a string, got {name!r}")
    return name, fields


def is_selectable(hint: Any) -> bool:
    """Whether ``hint`` is the base of a config family chosen by a ``name`` key."""
    return (
        isinstance(hint, type) and dataclasses.is_dataclass(hint) and callable(getattr(hint, "select", None))
    )


def to_dict(cfg: Any) -> Any:
    """Plain data (dicts, lists, numbers, strings) for a dataclass config, for saving as JSON/YAML."""
    if dataclasses.is_dataclass(cfg) and not isinstance(cfg, type):
        fields = {f.name: to_dict(getattr(cfg, f.name)) for f in dataclasses.fields(cfg) if f.init}
        return {"name": cfg.name, **fields} if is_selectable(type(cfg)) else fields  # type: ignore[attr-defined]
    if isinstance(cfg, (list, tuple)):
        return [to_dict(v) for v in cfg]
    if isinstance(cfg, dict):
        return {k: to_dict(v) for k, v in cfg.items()}
    return cfg
