"""TOML configs, checked against a schema before anything runs.

A bad config stops the run with one line naming the key and the problem (exit status 2):
unknown keys, missing required keys, wrong types and impossible values.
"""

from __future__ import annotations

import hashlib
import json
import math
import re
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

REQUIRED = object()


class ConfigError(ValueError):
    """A config problem; str(e) is the one line shown to the user."""


@dataclass(frozen=True)
class Field:
    """One config key: its type (or the tuple of allowed strings), default, check and meaning."""
    kind: type | tuple  # float, int, str, bool, list, or a tuple of allowed str values
    default: Any = REQUIRED
    check: Callable[[Any], str | None] | None = None  # returns a problem or None
    doc: str = ""


class AutoOrNumber:
    """The kind of a key that takes "auto" (the package chooses, and records its choice) or a number."""


@dataclass(frozen=True)
class TableList:
    """An array of tables (`[[grains]]`), each checked against `schema`."""

    schema: dict
    min_items: int = 0


def positive(v):
    """Check: the value is > 0."""
    return None if v > 0 else "must be > 0"


def non_negative(v):
    """Check: the value is >= 0."""
    return None if v >= 0 else "must be >= 0"


def unit_interval(v):
    """Check: the value is in [0, 1]."""
    return None if 0 <= v <= 1 else "must be in [0, 1]"


def open_unit_interval(v):
    """Check: the value is in (0, 1)."""
    return None if 0 < v < 1 else "must be in (0, 1)"


def poisson(v):
    """Check: a Poisson's ratio in (-1, 0.5)."""
    return None if -1 < v < 0.5 else "must be in (-1, 0.5) (nu >= 0.5 is incompressible)"


def _finite_number(c) -> bool:
    # bool is an int to Python: `[true, false, 0]` is no vector
    return isinstance(c, (int, float)) and not isinstance(c, bool) and math.isfinite(c)


def vector3(v):
    """Check: a list of 3 finite numbers."""
    return None if len(v) == 3 and all(_finite_number(c) for c in v) else "must be a list of 3 finite numbers"


def finite_numbers(v):
    """Check: a list of finite numbers."""
    return None if all(_finite_number(c) for c in v) else "must be a list of finite numbers"


def vectors3(v):
    """Check: a list of [x, y, z] lists of finite numbers."""
    ok = all(isinstance(d, list) and vector3(d) is None for d in v)
    return None if ok else "must be a list of [x, y, z] lists of finite numbers"


def _type_name(kind) -> str:
    if isinstance(kind, tuple):
        return "one of " + ", ".join(repr(k) for k in kind)
    if kind is AutoOrNumber:
        return '"auto" or a number'
    return {float: "a number", int: "an integer", str: "a string", bool: "true or false", list: "a list"}[kind]


def _coerce(key: str, value, kind):
    if isinstance(kind, tuple):
        if value not in kind:
            raise ConfigError(f"{key}: {value!r} is not {_type_name(kind)}")
        return value
    if kind is AutoOrNumber:
        if value == "auto":
            return value
        if not (isinstance(value, (int, float)) and not isinstance(value, bool)):
            raise ConfigError(f"{key}: expected {_type_name(kind)}, got {value!r}")
        kind = float
    ok = {
        float: isinstance(value, (int, float)) and not isinstance(value, bool),
        int: isinstance(value, int) and not isinstance(value, bool),
        str: isinstance(value, str),
        bool: isinstance(value, bool),
        list: isinstance(value, list),
    }[kind]
    if not ok:
        raise ConfigError(f"{key}: expected {_type_name(kind)}, got {value!r}")
    if kind is float:
        value = float(value)
        if not math.isfinite(value):
            raise ConfigError(f"{key}: must be finite, got {value!r}")
    return value


# Other spellings of a key, refused with a line that names it where the table has it: a target
# stress is `stress` in every table that loads a wall (CHANGELOG.md)
SPELLINGS = dict.fromkeys(("target", "target_stress", "pressure", "sigma", "confining_stress", "normal_stress"),
                          "stress")  # fmt: skip


def _refuse_unknown(data: dict, schema: dict, prefix: str, removed: dict) -> None:
    """A ConfigError for the first key of `data` that `schema` does not know: one the package
    removed (`removed`: dotted key, without table indices, -> why) is named as removed, another
    spelling of a key the table has (SPELLINGS) names that key."""
    unknown = sorted(set(data) - set(schema))
    for key in unknown:
        why = removed.get(re.sub(r"\[\d+\]", "", prefix + key))
        if why:
            raise ConfigError(f"{prefix}{key}: this key was removed ({why}); delete it")
    if unknown:
        key = unknown[0]
        if SPELLINGS.get(key) in schema:
            raise ConfigError(f"{prefix}{key}: unknown key; a target stress is spelled {prefix}{SPELLINGS[key]} (Pa)")
        raise ConfigError(f"{prefix}{key}: unknown key (allowed here: {', '.join(sorted(schema))})")


def apply_schema(data: dict, schema: dict, prefix: str = "", removed: dict | None = None) -> dict:
    """Check `data` against `schema` (nested dicts of Field) and fill defaults. `removed`: the
    dotted names of keys the package no longer has (-> why), refused as such."""
    if not isinstance(data, dict):
        raise ConfigError(f"{prefix.rstrip('.') or 'config'}: expected a table, got {data!r}")
    removed = removed or {}
    _refuse_unknown(data, schema, prefix, removed)
    out = {}
    for key, spec in schema.items():
        name = prefix + key
        if isinstance(spec, dict):
            out[key] = apply_schema(data.get(key, {}), spec, name + ".", removed)
            continue
        if isinstance(spec, TableList):
            items = data.get(key, [])
            if not isinstance(items, list):
                raise ConfigError(f"{name}: expected an array of tables ([[{key}]]), got {items!r}")
            if len(items) < spec.min_items:
                raise ConfigError(f"{name}: at least {spec.min_items} [[{key}]] table(s) required")
            out[key] = [apply_schema(item, spec.schema, f"{name}[{i}].", removed) for i, item in enumerate(items)]
            continue
        if key not in data:
            if spec.default is REQUIRED:
                raise ConfigError(f"{name}: required key is missing")
            out[key] = spec.default
            continue
        value = _coerce(name, data[key], spec.kind)
        if spec.check is not None:
            problem = spec.check(value)
            if problem:
                raise ConfigError(f"{name}: {problem}, got {value!r}")
        out[key] = value
    return out


def choices(cfg: dict, schema: dict) -> dict:
    """The keys of a checked config that the run does not take from their defaults.

    This is what makes a run this run, for `--resume` and for reusing a pack stage: a key added to
    the schema later comes with the default that keeps the old behaviour, so the choices of an
    unchanged config stay the same as the schema grows (a whole-config hash changed with every
    new key and refused checkpoints of runs whose config nobody touched). Keys the schema does
    not know (a stage's own bookkeeping) are kept."""
    out = {}
    for key, value in cfg.items():
        spec = schema.get(key)
        if isinstance(spec, dict) and isinstance(value, dict):
            inner = choices(value, spec)
            if inner:
                out[key] = inner
        elif isinstance(spec, TableList) and isinstance(value, list):
            out[key] = [choices(item, spec.schema) for item in value]  # the count of tables is a choice too
        elif not isinstance(spec, Field) or spec.default is REQUIRED or value != spec.default:
            out[key] = value
    return out


def digest(obj) -> str:
    """sha256 of a config-like object (sorted keys, so the order of keys in a file does not matter)."""
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()


def load_toml(path: str | Path) -> dict:
    """Read a TOML config file; a missing, unreadable or invalid file is a ConfigError naming it."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"{path}: config file not found")
    try:
        with path.open("rb") as fh:
            return tomllib.load(fh)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from None
    except UnicodeDecodeError:
        raise ConfigError(f"{path}: not a text file in UTF-8 (a TOML config is expected)") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read the config ({exc.strerror or exc})") from None
