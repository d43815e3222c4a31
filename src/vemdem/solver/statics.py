"""Newton's method for static equilibrium with prescribed displacements.

Minimises a potential W(x) over the free dofs: solve K_ff dx_f = -R_f, then a backtracking
line search keeps every iterate admissible (finite energy, no inverted element) and stops
the energy from rising. Convergence: the free residual is small against the reference
force AND the last correction is small against the size of the step (docs/dynamics.md).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..model.bodies import InvertedElementError
from .linear import solve


class NewtonDivergedError(RuntimeError):
    pass


@dataclass
class NewtonResult:
    x: np.ndarray
    iterations: int
    residual_norm: float
    residual: np.ndarray


Assemble = Callable[[np.ndarray, bool], tuple]  # (x, want_tangent) -> (energy, residual, K or None)


def solve_static(
    assemble: Assemble,
    x0: np.ndarray,
    target: np.ndarray,
    free: np.ndarray,
    force_scale: float,
    length_scale: float,
    rtol: float = 1e-9,
    max_iter: int = 40,
) -> NewtonResult:
    """Equilibrium with the prescribed dofs (~free) moved from x0 to target.

    The prescribed increment enters the first Newton step through K_fp (the consistent
    displacement-control predictor), so the free dofs follow the boundary instead of
    inverting the elements next to it.
    """
    x = np.array(x0, dtype=float).ravel()
    target = np.asarray(target, dtype=float).ravel()
    fixed = ~free
    energy, residual, K = _assemble_checked(assemble, x, True)
    step_size = 0.0
    rnorm = np.inf
    for it in range(1, max_iter + 1):
        dx = np.zeros_like(x)
        dx[fixed] = target[fixed] - x[fixed]
        rhs = residual[free]
        if np.any(dx[fixed]):
            rhs = rhs + K[free][:, fixed] @ dx[fixed]
        dx[free] = -solve(K[free][:, free], rhs)
        alpha, x = _line_search(assemble, x, dx, energy, residual, monotone=not np.any(dx[fixed]))
        if alpha == 1.0:
            x[fixed] = target[fixed]  # exactly, not up to round-off of x + (target - x)
        step_size += alpha * np.linalg.norm(dx)
        energy, residual, K = _assemble_checked(assemble, x, True)
        rnorm = np.linalg.norm(residual[free])
        done_bc = np.array_equal(x[fixed], target[fixed])
        if done_bc and rnorm <= rtol * force_scale and alpha * np.linalg.norm(dx) <= rtol * max(length_scale, step_size):
            return NewtonResult(x, it, rnorm, residual)
    raise NewtonDivergedError(
        f"Newton did not converge in {max_iter} iterations (residual {rnorm:.3e}, "
        f"tolerance {rtol * force_scale:.3e}); use smaller load steps"
    )


def _assemble_checked(assemble, x, want_tangent):
    energy, residual, K = assemble(x, want_tangent)
    if not (np.isfinite(energy) and np.all(np.isfinite(residual))):
        raise NewtonDivergedError("non-finite energy or residual during Newton iterations")
    return energy, residual, K


def _line_search(assemble, x, dx, energy, residual, monotone: bool, max_halvings: int = 30):
    """Backtrack until the trial point is admissible and (when no prescribed dof moves) the
    energy has not risen beyond round-off: near equilibrium it is flat to machine precision."""
    alpha = 1.0
    slack = 1e-10 * max(abs(energy), 1e-300) + 1e-4 * abs(residual @ dx)
    for _ in range(max_halvings):
        trial = x + alpha * dx
        try:
            e_trial, _, _ = assemble(trial, False)
        except InvertedElementError:
            e_trial = np.inf
        if np.isfinite(e_trial) and (not monotone or e_trial <= energy + slack):
            return alpha, trial
        alpha *= 0.5
    raise NewtonDivergedError("line search failed: every trial step inverts an element or raises the energy")
