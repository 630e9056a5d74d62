"""The typed codec of ermrl's configs: frozen dataclasses to JSON-ready dicts and back.

:func:`to_dict` and :func:`from_dict` handle nested dataclasses, tuples, unions and literals; ``from_dict``
refuses unknown or mistyped keys with a one-line ConfigError naming the key, which is also how config files are
checked. It imports nothing of ermrl but its errors, so that every config module can use it.
"""

from __future__ import annotations

import dataclasses
import json
import types
import typing
from pathlib import Path

import numpy as np

from ermrl.errors import ConfigError


def json_default(x):
    """``json.dumps``' ``default`` for NumPy scalars and arrays and paths."""
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, Path):
        return str(x)
    raise TypeError(f"not JSON-serializable: {type(x).__name__}")


OMIT_WHEN_DEFAULT = "ermrl_omit_when_default"
"""Field metadata key: a config field marked with it is left out of :func:`to_dict` while it has its default.
For fields added after results were recorded: a config that does not use one keeps the record, and so the
identity (study resumption, snapshots, stored baselines), it had before the field existed."""


def to_dict(config) -> dict:
    """A JSON-ready dict of a (nested) frozen dataclass config, less the fields marked
    :data:`OMIT_WHEN_DEFAULT` that have their default value."""
    return json.loads(json.dumps(_fields(config), default=json_default))


def _fields(obj):
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: _fields(getattr(obj, f.name)) for f in dataclasses.fields(obj)
                if not (f.metadata.get(OMIT_WHEN_DEFAULT) and getattr(obj, f.name) == f.default)}
    if isinstance(obj, (list, tuple)):
        return [_fields(v) for v in obj]
    if isinstance(obj, dict):
        return {k: _fields(v) for k, v in obj.items()}
    return obj


def from_dict(cls, data: dict, where: str = ""):
    """The dataclass ``cls`` built from ``data`` (as :func:`to_dict` writes it, or a config file's table).

    Missing keys take the dataclass defaults; unknown keys and values of the wrong type raise ConfigError
    naming the key, e.g. ``train.ppo.n_stpes``.
    """
    if not isinstance(data, dict):
        raise ConfigError(f"{where or cls.__name__} must be a table of keys, got {type(data).__name__}")
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    unknown = sorted(set(data) - set(fields))
    if unknown:
        raise ConfigError(f"unknown key {where + '.' if where else ''}{unknown[0]}; known keys: {', '.join(fields)}")
    kwargs = {name: _decode(hints[name], value, f"{where + '.' if where else ''}{name}") for name, value in data.items()}
    return cls(**kwargs)


def _decode(tp, value, where: str):
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin is typing.Literal:
        if value not in args:
            raise ConfigError(f"{where} must be one of {', '.join(map(repr, args))}, got {value!r}")
        return value
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        errors = []
        for arg in (a for a in args if a is not type(None)):
            try:
                return _decode(arg, value, where)
            except ConfigError as e:
                errors.append(e)
        raise errors[0]
    if dataclasses.is_dataclass(tp):
        return from_dict(tp, value, where)
    if origin is tuple:
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"{where} must be a list, got {value!r}")
        item = args[0] if args else typing.Any
        if len(args) == 2 and args[1] is Ellipsis or len(args) <= 1:
            return tuple(_decode(item, v, where) for v in value)
        if len(value) != len(args):
            raise ConfigError(f"{where} must have {len(args)} values, got {len(value)}")
        return tuple(_decode(a, v, where) for a, v in zip(args, value))
    if tp is typing.Any:
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{where} must be a number, got {value!r}")
        return float(value)
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{where} must be an integer, got {value!r}")
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{where} must be true or false, got {value!r}")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"{where} must be a string, got {value!r}")
        return value
    return value
