"""A run's identity for --resume and for reusing a settled stage: the config keys it does not take
from their defaults (config.choices) and their digest."""

from __future__ import annotations

from ..config import Field, choices, digest
from ..config.tables import NEWTON_ITERATIONS, RIGID_NEWTON_ITERATIONS
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
        adjustable = {f"solver.{k}": _step_default(k, fields[k], cfg) for k in STEP_CONTROL
                      if isinstance(fields.get(k), Field)}  # fmt: skip
    return RunIdentity(digest(picked), picked, legacy=digest(cfg), adjustable=adjustable)


def _step_default(key: str, field: Field, cfg: dict):
    """The value a step-control key has where the config leaves it out, as a resume reports it: for
    `max_iterations` (not set: the integrator's own budget) the budget of the run's grains."""
    if key == "max_iterations" and field.default is None:
        rigid = cfg.get("model", {}).get("grains") == "rigid"
        return RIGID_NEWTON_ITERATIONS if rigid else NEWTON_ITERATIONS
    return field.default
