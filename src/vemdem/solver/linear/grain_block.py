"""Right-preconditioned GMRES with a two-level grain-block preconditioner (issue 14).

K = blockdiag(B_g) + C (base.NewtonSystem). The preconditioner P^-1 is multiplicative, coarse first
(../shared/docs/performance.md, round 2: 2 GMRES iterations to 1e-10 at 515 and 4096 grains, at
steps from 1e-4 to 1e-2 s; block LU alone stalls beyond 1e-3 s, the additive coarse space barely
helps):

    Z      (n x 6G): the 6 rigid modes of every grain, translations e_k and rotations
                     e_k x (x_i - c_g) / s_g on its vertices (s_g: the grain's size)
    A_c    = Z^T K Z (6G x 6G, sparse: grain 6 x 6 blocks + the coupling's), SuperLU
    y_1    = Z A_c^-1 Z^T r                       coarse correction
    y      = y_1 + B^-1 (r - K y_1)               block solve of what is left

B^-1 is a batched dense LU of every grain's block (compiled, parallel over grains: 100 ms for 515
blocks of 90 x 90 on 2 cores (60 ms standalone), against 160 ms for NumPy's batched inverse and 250 ms for LAPACK
called per block from numba; refactorised at every Newton iteration: a kept one costs 17-26
GMRES iterations). GMRES solves K P^-1 u = b, x = P^-1 u,
to ||b - K x|| <= rtol ||b||, the tolerance the caller ties to Newton's progress.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numba import njit, prange

from .base import LinearSolveDiverged, NewtonSystem, SingularSystemError, SolverStats


@njit(parallel=True, cache=True, fastmath=True, error_model="numpy")
def _lu_blocks(blocks, block_ptr, dof_ptr, lu, piv, bad):
    """In-place LU with partial pivoting of a copy of every block (2D views: the row updates
    vectorise); bad[g] = 1 marks a singular block."""
    for g in prange(len(dof_ptr) - 1):
        n = dof_ptr[g + 1] - dof_ptr[g]
        b0, p0 = block_ptr[g], dof_ptr[g]
        A = lu[b0 : b0 + n * n].reshape(n, n)
        A[:, :] = blocks[b0 : b0 + n * n].reshape(n, n)
        scale = np.abs(A).max()
        for k in range(n):
            p = k
            best = abs(A[k, k])
            for i in range(k + 1, n):
                if abs(A[i, k]) > best:
                    best = abs(A[i, k])
                    p = i
            piv[p0 + k] = p
            if not best > 1e-15 * scale:
                bad[g] = 1
                break
            if p != k:
                for j in range(n):
                    t = A[k, j]
                    A[k, j] = A[p, j]
                    A[p, j] = t
            inv = 1.0 / A[k, k]
            for i in range(k + 1, n):
                A[i, k] *= inv
            pivot_row = A[k, k + 1 :].copy()  # a separate array: the row updates vectorise (1.7x)
            for i in range(k + 1, n):
                f = A[i, k]
                row = A[i, k + 1 :]
                for j in range(n - k - 1):
                    row[j] -= f * pivot_row[j]


@njit(parallel=True, cache=True, fastmath=True, error_model="numpy")
def _lu_solve_blocks(lu, piv, block_ptr, dof_ptr, r, out):
    for g in prange(len(dof_ptr) - 1):
        n = dof_ptr[g + 1] - dof_ptr[g]
        b0, p0 = block_ptr[g], dof_ptr[g]
        A = lu[b0 : b0 + n * n].reshape(n, n)
        y = r[p0 : p0 + n].copy()
        for k in range(n):
            p = piv[p0 + k]
            if p != k:
                t = y[k]
                y[k] = y[p]
                y[p] = t
        for i in range(n):
            s = y[i]
            for j in range(i):
                s -= A[i, j] * y[j]
            y[i] = s
        for i in range(n - 1, -1, -1):
            s = y[i]
            for j in range(i + 1, n):
                s -= A[i, j] * y[j]
            y[i] = s / A[i, i]
        out[p0 : p0 + n] = y


@njit(parallel=True, cache=True)
def _coarse_blocks(blocks, block_ptr, dof_ptr, z, out):
    """out[g] = Z_g^T B_g Z_g (6 x 6) for every grain; z (n, 6) holds Z's rows."""
    for g in prange(len(dof_ptr) - 1):
        n = dof_ptr[g + 1] - dof_ptr[g]
        b0, p0 = block_ptr[g], dof_ptr[g]
        bz = np.zeros((n, 6))
        for i in range(n):
            for j in range(n):
                b = blocks[b0 + i * n + j]
                if b != 0.0:
                    for k in range(6):
                        bz[i, k] += b * z[p0 + j, k]
        for a in range(6):
            for k in range(6):
                s = 0.0
                for i in range(n):
                    s += z[p0 + i, a] * bz[i, k]
                out[g, a, k] = s


def rigid_modes(x: np.ndarray, vertex_ptr: np.ndarray) -> np.ndarray:
    """(3N, 6) rows of Z: translations and rotations (scaled by the grain's size) about each
    grain's vertex average, dof 3 v + i."""
    x = np.asarray(x, float)
    counts = np.diff(vertex_ptr)
    centre = np.add.reduceat(x, vertex_ptr[:-1], axis=0) / counts[:, None]
    r = x - np.repeat(centre, counts, axis=0)
    size = np.sqrt(np.add.reduceat(np.sum(r * r, axis=1), vertex_ptr[:-1]) / counts)
    r = r / np.repeat(np.maximum(size, 1e-300), counts)[:, None]
    z = np.zeros((len(x), 3, 6))
    for k in range(3):
        z[:, k, k] = 1.0
        e = np.zeros(3)
        e[k] = 1.0
        z[:, :, 3 + k] = np.cross(e, r)
    return z.reshape(-1, 6)


class GrainBlockSolver:
    """GMRES right-preconditioned with the multiplicative two-level grain-block preconditioner."""

    name = "grain-block"

    def __init__(self, restart: int = 40, max_iterations: int = 200, coarse: bool = True):
        self.restart, self.max_iterations, self.coarse = restart, max_iterations, coarse
        self.stats = SolverStats()

    # ------------------------------------------------------------------ set-up per Newton matrix
    def factor(self, system: NewtonSystem) -> None:
        self.system = s = system
        if getattr(self, "_lu", None) is None or self._lu.shape != s.blocks.shape:  # kept: no page faults
            self._lu = np.empty_like(s.blocks)
            self._piv = np.empty(s.n, np.int64)
        bad = np.zeros(s.n_bodies, np.int64)
        _lu_blocks(s.blocks, s.block_ptr, s.dof_ptr, self._lu, self._piv, bad)
        if bad.any():
            raise SingularSystemError(f"singular tangent block of grain {int(np.flatnonzero(bad)[0])}; "
                                      "is every rigid-body mode constrained?")  # fmt: skip
        self._coarse = None
        if self.coarse and s.positions is not None:
            self._coarse = self._coarse_space(s)
        self.stats.factorisations += 1

    def _coarse_space(self, s: NewtonSystem):
        z = rigid_modes(s.positions, s.dof_ptr // 3)
        G = s.n_bodies
        cols = (6 * np.repeat(np.arange(G), np.diff(s.dof_ptr)))[:, None] + np.arange(6)
        Z = sp.csr_matrix((z.ravel(), cols.ravel(), np.arange(0, 6 * s.n + 1, 6)), shape=(s.n, 6 * G))
        local = np.zeros((G, 6, 6))
        _coarse_blocks(s.blocks, s.block_ptr, s.dof_ptr, z, local)
        # the 6 x 6 blocks are the CSR data of the block diagonal (sp.block_diag costs ms per call)
        indptr = np.arange(0, 36 * G + 1, 6)
        indices = np.repeat(6 * np.arange(G)[:, None] + np.arange(6), 6, axis=0).ravel()
        A = sp.csr_matrix((local.ravel(), indices, indptr), shape=(6 * G, 6 * G))
        if s.coupling is not None and s.coupling.nnz:
            A = A + (Z.T @ (s.coupling @ Z)).tocsr()
        try:
            return Z, spla.splu(A.tocsc())
        except RuntimeError as exc:  # the coarse matrix is singular: a free rigid mode
            raise SingularSystemError(f"singular tangent (coarse space: {exc}); is every rigid-body mode constrained?"
                                      ) from None  # fmt: skip

    def precondition(self, r: np.ndarray) -> np.ndarray:
        s = self.system
        y = np.zeros(s.n)
        if self._coarse is not None:
            Z, lu = self._coarse
            y = Z @ lu.solve(Z.T @ r)
            r = r - s.matvec(y)
        out = np.empty(s.n)
        _lu_solve_blocks(self._lu, self._piv, s.block_ptr, s.dof_ptr, np.ascontiguousarray(r), out)
        return y + out

    # ------------------------------------------------------------------ GMRES
    def solve(self, rhs: np.ndarray, rtol: float = 1e-10) -> np.ndarray:
        s = self.system
        b = np.asarray(rhs, float)
        bnorm = np.linalg.norm(b)
        self.stats.solves += 1
        self.stats.last_iterations = 0
        if bnorm == 0.0:
            return np.zeros(s.n)
        x = np.zeros(s.n)
        r = b.copy()
        total = 0
        while True:
            beta = np.linalg.norm(r)
            if beta <= rtol * bnorm:
                break
            m = self.restart
            V = [r / beta]
            H = np.zeros((m + 1, m))
            cs, sn, g = np.zeros(m), np.zeros(m), np.zeros(m + 1)
            g[0] = beta
            Zs = []
            k = 0
            for k in range(m):
                z = self.precondition(V[k])
                Zs.append(z)
                w = s.matvec(z)
                for i in range(k + 1):  # modified Gram-Schmidt
                    H[i, k] = w @ V[i]
                    w -= H[i, k] * V[i]
                H[k + 1, k] = np.linalg.norm(w)
                V.append(w / H[k + 1, k] if H[k + 1, k] > 0 else w)
                for i in range(k):  # Givens rotations
                    t = cs[i] * H[i, k] + sn[i] * H[i + 1, k]
                    H[i + 1, k] = -sn[i] * H[i, k] + cs[i] * H[i + 1, k]
                    H[i, k] = t
                d = np.hypot(H[k, k], H[k + 1, k])
                cs[k], sn[k] = (H[k, k] / d, H[k + 1, k] / d) if d > 0 else (1.0, 0.0)
                H[k, k] = d
                H[k + 1, k] = 0.0
                g[k + 1] = -sn[k] * g[k]
                g[k] = cs[k] * g[k]
                total += 1
                if abs(g[k + 1]) <= rtol * bnorm or total >= self.max_iterations:
                    break
            n_k = k + 1
            y = np.linalg.solve(np.triu(H[:n_k, :n_k]), g[:n_k]) if n_k else np.zeros(0)
            x = x + np.array(Zs[:n_k]).T @ y
            r = b - s.matvec(x)
            if total >= self.max_iterations:
                if np.linalg.norm(r) > rtol * bnorm:
                    raise LinearSolveDiverged(f"GMRES reached a relative residual {np.linalg.norm(r) / bnorm:.2e} "
                                              f"after {total} iterations (asked {rtol:.1e})")  # fmt: skip
                break
        if not np.all(np.isfinite(x)):
            raise SingularSystemError("singular tangent: GMRES returned non-finite values")
        self.stats.iterations += total
        self.stats.last_iterations = total
        return x
