"""The sparse solve behind every Newton step: both back ends against the system itself."""

import numpy as np
import pytest
import scipy.sparse as sp

from vemdem.solver import linear


def grain_like_system(n=3000, seed=0):
    """Symmetric positive definite, block-sparse like a tangent: dense 30 x 30 blocks, weak coupling."""
    rng = np.random.default_rng(seed)
    blocks = []
    for _ in range(n // 30):
        B = rng.standard_normal((30, 30))
        blocks.append(B @ B.T + 30 * np.eye(30))
    K = sp.block_diag(blocks, format="csr")
    C = sp.random(n, n, density=2e-4, random_state=seed)
    return (K + C + C.T).tocsr(), rng.standard_normal(n)


@pytest.mark.parametrize("backend", ["pardiso", "scipy"])
def test_sparse_solve_satisfies_the_system(monkeypatch, backend):
    if backend == "pardiso" and linear.pypardiso is None:
        pytest.skip("pypardiso is not installed on this platform")
    monkeypatch.setenv("VEMDEM_LINEAR_SOLVER", backend)
    assert linear.sparse_backend() == backend
    K, b = grain_like_system()
    x = linear.solve(K, b)
    assert np.linalg.norm(K @ x - b) < 1e-10 * np.linalg.norm(b)


@pytest.mark.parametrize("backend", ["pardiso", "scipy"])
def test_singular_system_is_named(monkeypatch, backend):
    """A free rigid mode (a zero row and column): a clear error, never a silent answer."""
    if backend == "pardiso" and linear.pypardiso is None:
        pytest.skip("pypardiso is not installed on this platform")
    monkeypatch.setenv("VEMDEM_LINEAR_SOLVER", backend)
    K, b = grain_like_system()
    K = K.tolil()
    K[5, :] = 0.0
    K[:, 5] = 0.0
    with pytest.raises(linear.SingularSystemError, match="singular tangent"):
        linear.solve(K.tocsr(), b)
