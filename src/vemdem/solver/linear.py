"""Sparse linear solves for Newton steps.

Small systems (a single grain, a few grains) are solved densely, larger ones with SciPy's SuperLU.
Measured on real Newton systems of settling packs (docs/dynamics-benchmark.md): SuperLU 0.36 s
against MKL PARDISO 0.63 s at 46,350 dofs, 2.2-2.5 s against 5.5-6.3 s at 368,640 dofs (the
nearly block-diagonal tangent creates no fill, and PARDISO's analysis phase dominates). PARDISO
was faster only on the single-grain FE reference meshes (docs/fem_comparison.md), so it stays an
option: `pip install vemdem[pardiso]` and `VEMDEM_LINEAR_SOLVER=pardiso`. CHOLMOD (scikit-sparse)
does not install from pip on a fresh machine.
"""

from __future__ import annotations

import os
import warnings

import numpy as np
import scipy.linalg as la
import scipy.sparse as sp
import scipy.sparse.linalg as spla

DENSE_LIMIT = 600

try:
    import pypardiso
except ImportError:  # optional (vemdem[pardiso])
    pypardiso = None


class SingularSystemError(np.linalg.LinAlgError):
    pass


def solve(K, b: np.ndarray) -> np.ndarray:
    n = K.shape[0]
    try:
        if n <= DENSE_LIMIT:
            A = K.toarray() if sp.issparse(K) else np.asarray(K)
            return la.solve(A, b, assume_a="sym")
        x = _sparse_solve(K, b)
    except (
        la.LinAlgError,
        RuntimeError,
        ValueError,
        spla.MatrixRankWarning,
    ) as exc:  # pypardiso reports empty rows as ValueError
        raise SingularSystemError(f"singular tangent ({exc}); is every rigid-body mode constrained?") from None
    if not np.all(np.isfinite(x)):
        raise SingularSystemError("singular tangent: the solve returned non-finite values")
    return x


def sparse_backend() -> str:
    if pypardiso is not None and os.environ.get("VEMDEM_LINEAR_SOLVER", "scipy") == "pardiso":
        return "pardiso"
    return "scipy"


def _sparse_solve(K, b: np.ndarray) -> np.ndarray:
    if sparse_backend() == "pardiso":
        K = sp.csr_matrix(K)
        x = pypardiso.spsolve(K, np.asarray(b, float))
        # PARDISO's pivot perturbation returns a finite answer even for a singular matrix
        if np.linalg.norm(K @ x - b) > 1e-6 * max(np.linalg.norm(b), 1e-300):
            raise RuntimeError("PARDISO's solution does not satisfy the system")
        return x
    with warnings.catch_warnings():
        warnings.simplefilter("error", spla.MatrixRankWarning)  # SuperLU warns and returns NaN
        return spla.spsolve(sp.csc_matrix(K), b)
