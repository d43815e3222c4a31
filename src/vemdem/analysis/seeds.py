"""Mean and spread over seeds: the same case run from several random packs.

A granular result (an angle of repose, a runout) is one draw from the packs a seed can make; what
a reader needs is its mean and spread over seeds. `seed_statistics` groups result rows by the
settings other than the seed and returns, per group, the count of successful seeds, the mean and
the sample standard deviation (ddof = 1; NaN for a single seed, whose spread is unknown) of every
numeric field all of them report.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class SeedGroup:
    setting: dict  # the non-seed swept keys and their values
    n: int  # successful seeds in the group
    mean: dict[str, float]
    std: dict[str, float]


def _numeric(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def seed_statistics(rows: list[dict], group_keys: list[str]) -> list[SeedGroup]:
    """Rows: one per successful case, holding the group keys and the case's numeric results.
    Groups come in the order their first row appears."""
    groups: dict[tuple, list[dict]] = {}
    for row in rows:
        groups.setdefault(tuple(row[k] for k in group_keys), []).append(row)
    out = []
    for setting, members in groups.items():
        fields = [k for k in members[0] if k not in group_keys and all(_numeric(m.get(k)) for m in members)]
        values = {k: np.array([m[k] for m in members], dtype=float) for k in fields}
        mean = {k: float(v.mean()) for k, v in values.items()}
        std = {k: float(v.std(ddof=1)) if len(v) > 1 else float("nan") for k, v in values.items()}
        out.append(SeedGroup(dict(zip(group_keys, setting)), len(members), mean, std))
    return out


def varies(values, rel: float = 1e-9) -> bool:
    """Whether numbers differ by more than round-off (0.004999999999999994 and 0.005 do not)."""
    v = np.asarray(values, dtype=float)
    if v.size < 2 or not np.all(np.isfinite(v)):
        return v.size > 1 and len({float(x) for x in v}) > 1
    return float(v.max() - v.min()) > rel * max(float(np.abs(v).max()), 1e-300)
