"""Strength envelopes through a sweep's failure states, shared by the triaxial test (Mohr-Coulomb
through principal stresses) and the direct shear (Coulomb through tau against sigma_n)."""

from __future__ import annotations

from typing import Callable

import numpy as np


def failure_pairs(summaries: list[dict], x_key: str, y_key: str) -> tuple[np.ndarray, np.ndarray]:
    """The tests' two stresses at one failure state, the tests that did not reach it left out."""
    have = [s for s in summaries if isinstance(s.get(x_key), float) and isinstance(s.get(y_key), float)]
    return np.array([s[x_key] for s in have]), np.array([s[y_key] for s in have])


def fit_envelopes(summaries: list[dict], states: tuple, fit: Callable[[np.ndarray, np.ndarray], dict]) -> dict:
    """One envelope per failure state `(name, x_key, y_key)`, `fit(x, y)` giving phi_deg,
    cohesion_Pa, r2 and n: envelope_phi_{name}_deg, envelope_cohesion_{name}_Pa,
    envelope_r2_{name} and envelope_tests_{name}; an envelope that cannot be fitted is reported
    as envelope_{name}_error."""
    out: dict = {}
    for name, x_key, y_key in states:
        try:
            line = fit(*failure_pairs(summaries, x_key, y_key))
        except ValueError as error:
            out[f"envelope_{name}_error"] = str(error)
            continue
        out.update({f"envelope_phi_{name}_deg": line["phi_deg"], f"envelope_cohesion_{name}_Pa": line["cohesion_Pa"],
                    f"envelope_r2_{name}": line["r2"], f"envelope_tests_{name}": line["n"]})  # fmt: skip
    return out
