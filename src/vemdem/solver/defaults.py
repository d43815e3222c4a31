"""The `[solver]` keys' defaults for the integrators' parameter classes, read from the schema
(config/tables.py), their one source: a class default typed here by hand could drift from the
config's (tests/test_defaults.py). The only module of solver/ that imports config/."""

from __future__ import annotations

from ..config.tables import NEWTON_ITERATIONS, RIGID_NEWTON_ITERATIONS, SOLVER

__all__ = ["NEWTON_ITERATIONS", "RIGID_NEWTON_ITERATIONS", "default"]


def default(key: str):
    """The schema's default of `[solver] key`."""
    return SOLVER[key].default
