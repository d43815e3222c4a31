"""Sparse linear solves for Newton steps.

Small systems (a single grain) are solved densely; larger ones with SciPy's sparse direct
solver. The choice for the many-grain implicit integrator is measured in
benchmarks/ and docs/solver.md.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as la
import scipy.sparse as sp
import scipy.sparse.linalg as spla

DENSE_LIMIT = 600


class SingularSystemError(np.linalg.LinAlgError):
    pass


def solve(K, b: np.ndarray) -> np.ndarray:
    n = K.shape[0]
    try:
        if n <= DENSE_LIMIT:
            A = K.toarray() if sp.issparse(K) else np.asarray(K)
            return la.solve(A, b, assume_a="sym")
        x = spla.spsolve(sp.csc_matrix(K), b)
    except (la.LinAlgError, RuntimeError) as exc:
        raise SingularSystemError(f"singular tangent ({exc}); is every rigid-body mode constrained?") from None
    if not np.all(np.isfinite(x)):
        raise SingularSystemError("singular tangent: the solve returned non-finite values")
    return x
