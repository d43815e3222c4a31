"""A run's identity for --resume and for reusing a settled stage: the config keys it does not take
from their defaults (config.choices) and their digest."""

from __future__ import annotations

from ..config import choices, digest
from ..driver.checkpoint import RunIdentity


def run_identity(cfg: dict, schema: dict | None = None) -> RunIdentity:
    """The identity of a checked config (`schema` None: every key counts, for a stage's own
    bookkeeping dict). `legacy` is the digest the package used before, still accepted on resume."""
    picked = choices(cfg, schema) if schema is not None else cfg
    return RunIdentity(digest(picked), picked, legacy=digest(cfg))
