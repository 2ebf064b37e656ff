"""Dataclasses from mappings and YAML files, strictly.

:func:`config_from_mapping` builds a (nested) dataclass from a mapping, refusing unknown
keys with their dotted path; :func:`load_yaml` reads a YAML mapping;
:func:`resolve_config_path` finds a shipped config by name; :func:`as_dict` turns a
dataclass back into plain data. :mod:`swarm_envs.config` applies them to
:class:`~swarm_envs.config.SwarmConfig` (and re-exports them).

>>> from dataclasses import dataclass
>>> @dataclass(frozen=True)
... class Section:
...     r: float = 1.0
>>> config_from_mapping(Section, {"r": 2.0})
Section(r=2.0)
>>> config_from_mapping(Section, {"radius": 2.0})
Traceback (most recent call last):
...
ValueError: unknown config key 'radius'; allowed keys: r
"""

from __future__ import annotations

import dataclasses
import math
import typing
from collections.abc import Mapping
from dataclasses import fields
from pathlib import Path
from typing import Any, TypeVar

__all__ = ["CONFIG_ROOT", "as_dict", "config_from_mapping", "load_yaml", "resolve_config_path"]

T = TypeVar("T")

#: Where the shipped YAML files live: ``configs/`` at the repository root, which the
#: package holds as ``swarm_envs/configs`` (a symbolic link in the repository, the files
#: themselves in an installed wheel), so named configs resolve after any install.
CONFIG_ROOT = Path(__file__).resolve().parent / "configs"


def _field_types(cls: type) -> dict[str, Any]:
    return typing.get_type_hints(cls)


def _fields(cls: type) -> tuple[dataclasses.Field[Any], ...]:
    if not dataclasses.is_dataclass(cls):
        raise TypeError(f"config_from_mapping builds dataclasses, got {cls!r}")
    return fields(cls)


def _is_dataclass_type(tp: Any) -> bool:
    return isinstance(tp, type) and dataclasses.is_dataclass(tp)


def _field_default(f: dataclasses.Field) -> Any:
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    return None if f.default is dataclasses.MISSING else f.default


def config_from_mapping(cls: type[T], data: Mapping[str, Any] | T, *, path: str = "") -> T:
    """Build dataclass ``cls`` from a mapping, strictly.

    Nested dataclass fields accept a mapping (built recursively, on top of the field's
    default: ``{"zone": {"r_o": 2}}`` changes only ``r_o`` of the zone section's
    default) or an instance. Unknown keys raise ``ValueError`` naming the dotted key and
    the allowed keys; a value the dataclass rejects is re-raised with its dotted key in
    front. A class with a ``from_config_mapping(data)`` classmethod reads its mapping
    through it first (the reward weights gather a task's own terms so).
    """
    if isinstance(data, cls):
        return data
    if not isinstance(data, Mapping):
        where = path or cls.__name__
        raise ValueError(f"config section '{where}' must be a mapping, got {type(data).__name__}")
    prepare = getattr(cls, "from_config_mapping", None)
    section: Mapping[str, Any] = data if prepare is None else prepare(data)
    by_name = {f.name: f for f in _fields(cls)}
    names = set(by_name)
    hints = _field_types(cls)
    kwargs: dict[str, Any] = {}
    for key, value in section.items():
        dotted = f"{path}.{key}" if path else str(key)
        if key not in names:
            raise ValueError(
                f"unknown config key '{dotted}'; allowed keys: {', '.join(sorted(names))}"
            )
        tp = hints[key]
        if _is_dataclass_type(tp) and not isinstance(value, tp):
            default = _field_default(by_name[key])
            if isinstance(value, Mapping) and isinstance(default, tp):
                # A partial section changes only the keys it names: the rest keep the
                # field's default (e.g. ZoneParams.navigation()), not the class's.
                prepare = getattr(tp, "from_config_mapping", None)
                value = prepare(value) if prepare is not None else value
                unknown = [k for k in value if k not in {f.name for f in fields(tp)}]
                if not unknown:
                    value = {**{f.name: getattr(default, f.name) for f in fields(tp)}, **value}
            value = config_from_mapping(tp, value, path=dotted)
        kwargs[key] = value
    try:
        return cls(**kwargs)
    except ValueError as err:
        raise ValueError(f"{path + ': ' if path else ''}{err}") from None
    except TypeError as err:  # e.g. a list where a number belongs, caught by the dataclass
        raise ValueError(f"{path + ': ' if path else ''}{err}") from None


def load_yaml(path: str | Path) -> dict[str, Any]:
    """Read a YAML file that must hold a mapping at top level."""
    import yaml

    p = Path(path)
    if not p.is_file():
        raise ValueError(f"config file not found: {p}")
    with p.open() as fh:
        data = yaml.safe_load(fh)
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ValueError(f"config file {p} must hold a mapping, got {type(data).__name__}")
    return data


def resolve_config_path(path: str | Path, section: str = "env", kind: str = "config file") -> Path:
    """Find a config by path, or by a path relative to the shipped ``configs/``.

    ``"configs/env/paper_navigation.yaml"``, ``"env/paper_navigation.yaml"`` and
    ``"paper_navigation"`` (looked up in ``configs/<section>``) all resolve to the same
    file, from any working folder. A file at ``path`` itself comes first. ``kind`` names
    the file in the error (``"train config"``, ...).
    """
    p = Path(path)
    folder = CONFIG_ROOT / section
    candidates = [p, CONFIG_ROOT / p, folder / p, folder / f"{p}.yaml"]
    if p.parts and p.parts[0] == "configs":
        candidates.append(CONFIG_ROOT.joinpath(*p.parts[1:]))
    for c in candidates:
        if c.is_file():
            return c
    raise ValueError(f"{kind} not found: {path} (looked in . and {folder})")


def as_dict(obj: Any) -> Any:
    """A dataclass config as plain, YAML/JSON-ready Python data (non-finite as strings)."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: as_dict(getattr(obj, f.name)) for f in fields(obj)}
    if isinstance(obj, Mapping):
        return {key: as_dict(value) for key, value in obj.items()}
    if isinstance(obj, float) and not math.isfinite(obj):
        return str(obj)
    if isinstance(obj, (list, tuple)):
        return [as_dict(o) for o in obj]
    return obj
