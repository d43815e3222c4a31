"""Strength envelopes through a sweep's failure states, shared by the triaxial test (Mohr-Coulomb
through principal stresses) and the direct shear (Coulomb through tau against sigma_n)."""

from __future__ import annotations

from typing import Callable

import numpy as np


def failure_pairs(summaries: list[dict], x_key: str, y_key: str) -> tuple[np.ndarray, np.ndarray]:
    """The tests' two stresses at one failure state, the tests that did not reach it left out."""
    have = [s for s in summaries if isinstance(s.get(x_key), float) and isinstance(s.get(y_key), float)]
    return np.array([s[x_key] for s in have]), np.array([s[y_key] for s in have])


def fit_envelopes(summaries: list[dict], states: tuple, fit: Callable[..., dict]) -> dict:
    """Two envelopes per failure state `(name, x_key, y_key)`, `fit(x, y, through_origin)` giving
    phi_deg, cohesion_Pa, r2 and n. The envelope through the origin, a cohesionless material's,
    is the default: envelope_phi_{name}_deg, envelope_cohesion_{name}_Pa (0), envelope_r2_{name}
    and envelope_tests_{name}. The free line beside it: envelope_phi_{name}_free_deg,
    envelope_cohesion_{name}_free_Pa and envelope_r2_{name}_free; with three tests or fewer its
    cohesion is mostly the tests' scatter. An envelope that cannot be fitted is reported as
    envelope_{name}_error (envelope_{name}_free_error)."""
    out: dict = {}
    for name, x_key, y_key in states:
        x, y = failure_pairs(summaries, x_key, y_key)
        for through_origin, tail in ((True, ""), (False, "_free")):
            try:
                line = fit(x, y, through_origin=through_origin)
            except ValueError as error:
                out[f"envelope_{name}{tail}_error"] = str(error)
                continue
            out.update({f"envelope_phi_{name}{tail}_deg": line["phi_deg"],
                        f"envelope_cohesion_{name}{tail}_Pa": line["cohesion_Pa"],
                        f"envelope_r2_{name}{tail}": line["r2"]})  # fmt: skip
            if through_origin:
                out[f"envelope_tests_{name}"] = line["n"]
    return out


def line_fit(x: np.ndarray, y: np.ndarray, through_origin: bool) -> tuple[float, float, float]:
    """The least-squares line y = a + b x: (a, b, r2), a = 0 through the origin. r2 is
    1 - SS_res / SS_tot about the mean of y either way (a line through the origin can score below
    zero where the points ask for an intercept); NaN where y does not vary."""
    if through_origin:
        a, b = 0.0, float(x @ y / (x @ x))
    else:
        dx = x - x.mean()
        b = float(dx @ (y - y.mean()) / (dx @ dx))
        a = float(y.mean() - b * x.mean())
    residual = y - (a + b * x)
    total = float(np.sum((y - y.mean()) ** 2))
    return a, b, 1.0 - float(residual @ residual) / total if total > 0 else float("nan")
