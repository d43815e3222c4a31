"""Direct solves: dense LU for small systems, SciPy's SuperLU otherwise (PARDISO optional).

Measured on real Newton systems of settling packs (docs/dynamics-benchmark.md): SuperLU 0.36 s
against MKL PARDISO 0.63 s at 46,350 dofs, 2.2-2.5 s against 5.5-6.3 s at 368,640 dofs (the
nearly block-diagonal tangent creates no fill, and PARDISO's analysis phase dominates). PARDISO
was faster only on the single-grain FE reference meshes (docs/fem_comparison.md), so it stays an
option: `pip install vemdem[pardiso]` and `VEMDEM_LINEAR_SOLVER=pardiso`. CHOLMOD (scikit-sparse)
does not install from pip on a fresh machine, and friction makes the tangent non-symmetric:
nothing here assumes symmetry (the dense path used to call a symmetric solver: wrong with friction).
"""

from __future__ import annotations

import os
import warnings

import numpy as np
import scipy.linalg as la
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .base import CountersCarried, NewtonSystem, SingularSystemError, SolverStats

DENSE_LIMIT = 600

try:
    import pypardiso
except ImportError:  # optional (vemdem[pardiso])
    pypardiso = None

_SINGULAR = (la.LinAlgError, RuntimeError, ValueError, spla.MatrixRankWarning)  # pypardiso: ValueError


def _singular(exc) -> SingularSystemError:
    return SingularSystemError(f"singular tangent ({exc}); is every rigid-body mode constrained?")


def solve(K, b: np.ndarray) -> np.ndarray:
    """One direct solve of K x = b (K dense or sparse, any symmetry)."""
    n = K.shape[0]
    try:
        if n <= DENSE_LIMIT:
            A = K.toarray() if sp.issparse(K) else np.asarray(K)
            x = la.solve(A, b)  # general LU: friction tangents are not symmetric
        else:
            x = _sparse_solve(K, b)
    except _SINGULAR as exc:
        raise _singular(exc) from None
    if not np.all(np.isfinite(x)):
        raise SingularSystemError("singular tangent: the solve returned non-finite values")
    return x


def superlu(K):
    """SuperLU with the options for our matrices: structurally symmetric (a pair's tangent couples
    both grains both ways), values not (friction), diagonals strong (the mass term, each grain's
    own stiffness). A minimum-degree ordering of A^T + A with diagonal pivots preferred
    (SymmetricMode, threshold 0.01: an off-diagonal pivot only where the diagonal is 100 times
    smaller) against SciPy's default COLAMD with full partial pivoting, measured on the settled
    515-grain real-density pack (docs/linear-solvers.md): the whole Newton matrix (46,350 dofs)
    0.53 s against 23.5 s, fill 7.3 M against 84 M; the grain-block coarse matrix (3,090) 16 ms
    against 38 ms; solutions the same to round-off."""
    return spla.splu(sp.csc_matrix(K), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.01,
                     options={"SymmetricMode": True})  # fmt: skip


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
    return superlu(K).solve(np.asarray(b, float))


class DirectSolver(CountersCarried):
    """The Newton matrix factorised once per `factor` (dense LU or SuperLU), solved exactly."""

    name = "direct"

    def __init__(self):
        self.stats = SolverStats()
        self._lu = None

    def forget(self) -> None:
        """Nothing is kept from one matrix to the next."""

    def factor(self, system: NewtonSystem) -> None:
        K = system.to_csr()
        self.stats.factorisations += 1
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("error", spla.MatrixRankWarning)
                warnings.simplefilter("error", la.LinAlgWarning)  # lu_factor: an exactly zero pivot
                if K.shape[0] <= DENSE_LIMIT:
                    self._lu = ("dense", la.lu_factor(K.toarray(), check_finite=True))
                else:
                    self._lu = ("splu", superlu(K))
        except (*_SINGULAR, la.LinAlgWarning) as exc:
            raise _singular(exc) from None

    def solve(self, rhs: np.ndarray, rtol: float = 0.0) -> np.ndarray:
        kind, lu = self._lu
        try:
            x = la.lu_solve(lu, rhs) if kind == "dense" else lu.solve(np.asarray(rhs, float))
        except _SINGULAR as exc:
            raise _singular(exc) from None
        if not np.all(np.isfinite(x)):
            raise SingularSystemError("singular tangent: the solve returned non-finite values")
        self.stats.solves += 1
        return x
