"""Configs: the schema machinery (schema.py), every table (tables.py; the laboratory tests':
lab_tables.py) with its checks (checks.py), the cross-field rules (rules.py) and the step from a
checked config to typed options and a scene (build.py).

Only `config` and `scenarios` hold config dicts; everything below them takes typed values."""

from .schema import (
    REQUIRED,
    ConfigError,
    Field,
    TableList,
    apply_schema,
    choices,
    digest,
    load_toml,
    non_negative,
    open_unit_interval,
    poisson,
    positive,
    unit_interval,
    vector3,
)

__all__ = [
    "REQUIRED",
    "ConfigError",
    "Field",
    "TableList",
    "apply_schema",
    "choices",
    "digest",
    "load_toml",
    "non_negative",
    "open_unit_interval",
    "poisson",
    "positive",
    "unit_interval",
    "vector3",
]
