"""A run's identity for --resume and for reusing a settled stage: the config keys it does not take
from their defaults (config.choices) and their digest."""

from __future__ import annotations

from ..config import Field, choices, digest
from ..driver.checkpoint import RunIdentity

# The [solver] keys a --resume may change: they decide how the run steps (its first step, its bounds,
# Newton's budget and when a step grows), not what it models. A stalled run is given another budget
# without starting again (docs/errors.md); any other change is still refused.
STEP_CONTROL = ("dt", "dt_min", "dt_max", "max_iterations", "easy_iterations", "grow_after")


def run_identity(cfg: dict, schema: dict | None = None, solver_at: str = "solver") -> RunIdentity:
    """The identity of a checked config (`schema` None: every key counts, for a stage's own
    bookkeeping dict, whose [solver] table is at `solver_at`). `legacy` is the digest the package
    used before, still accepted on resume."""
    picked = choices(cfg, schema) if schema is not None else cfg
    if schema is None:  # every key is written out: no default is needed
        adjustable = dict.fromkeys(f"{solver_at}.{k}" for k in STEP_CONTROL)
    else:
        fields = schema.get("solver", {})
        # a key whose default is left to the integrator (max_iterations) reads "default" in the resume's record
        adjustable = {f"solver.{k}": "default" if fields[k].default is None else fields[k].default
                      for k in STEP_CONTROL if isinstance(fields.get(k), Field)}  # fmt: skip
    return RunIdentity(digest(picked), picked, legacy=digest(cfg), adjustable=adjustable)
