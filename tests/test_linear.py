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
        pytest.skip("pypardiso is not installed (the test extra installs it on x86-64 only)")
    monkeypatch.setenv("VEMDEM_LINEAR_SOLVER", backend)
    assert linear.sparse_backend() == backend
    K, b = grain_like_system()
    x = linear.solve(K, b)
    assert np.linalg.norm(K @ x - b) < 1e-10 * np.linalg.norm(b)


@pytest.mark.parametrize("backend", ["pardiso", "scipy"])
def test_singular_system_is_named(monkeypatch, backend):
    """A free rigid mode (a zero row and column): a clear error, never a silent answer."""
    if backend == "pardiso" and linear.pypardiso is None:
        pytest.skip("pypardiso is not installed (the test extra installs it on x86-64 only)")
    monkeypatch.setenv("VEMDEM_LINEAR_SOLVER", backend)
    K, b = grain_like_system()
    K = K.tolil()
    K[5, :] = 0.0
    K[:, 5] = 0.0
    with pytest.raises(linear.SingularSystemError, match="singular tangent"):
        linear.solve(K.tocsr(), b)


def test_superlu_pivots_off_the_diagonal_where_it_must():
    """superlu prefers diagonal pivots (SymmetricMode, threshold 0.01) for speed; a block whose
    diagonal is tiny against its column (a permuted, non-symmetric block) must still be solved
    exactly, on an unsymmetric pattern and unsymmetric values."""
    rng = np.random.default_rng(4)
    n = 900
    K, _ = grain_like_system(n, seed=4)
    K = K.tolil()
    P = np.roll(np.arange(30), 1)  # a cyclic shift: every diagonal entry off the permutation
    B = 10.0 * np.eye(30)[P] + 0.1 * rng.standard_normal((30, 30))
    B[np.arange(30), np.arange(30)] = 1e-9  # a diagonal pivot here would blow up the factors
    K[300:330, 300:330] = B
    K[10, 700] = 3.0  # one-way coupling: an unsymmetric pattern
    K = K.tocsr()
    b = rng.standard_normal(n)
    x = linear.direct.superlu(K).solve(b)
    reference = np.linalg.solve(K.toarray(), b)
    np.testing.assert_allclose(x, reference, rtol=0, atol=1e-10 * np.abs(reference).max())
    assert np.linalg.norm(K @ x - b) < 1e-10 * np.linalg.norm(b)
