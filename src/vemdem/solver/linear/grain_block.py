"""Right-preconditioned GMRES with a two-level grain-block preconditioner (docs/linear-solvers.md).

K = blockdiag(B_g) + C (base.NewtonSystem). The preconditioner P^-1 is multiplicative, coarse first
(../shared/docs/performance.md, "measured on vemdem's own Newton systems": 2 GMRES iterations to
1e-10 at 515 and 4096 grains, at steps from 1e-4 to 1e-2 s; block LU alone stalls beyond 1e-3 s,
the additive coarse space barely helps):

    Z      (n x 6G): the 6 rigid modes of every grain, translations e_k and rotations
                     e_k x (x_i - c_g) / s_g on its vertices (s_g: the grain's size)
    A_c    = Z^T K Z (6G x 6G: grain 6 x 6 blocks + the coupling's), LAPACK LU up to
                     DENSE_COARSE_BODIES (40) bodies, SuperLU beyond; there the LU of an
                     earlier Newton matrix is kept while it pays, as the preconditioner of a
                     short inner GMRES on A_c (KEPT_COARSE_*)
    y_1    = Z A_c^-1 Z^T r                       coarse correction
    y      = y_1 + B^-1 (r - K y_1)               block solve of what is left

B^-1 is a batched dense LU of every grain's block (LAPACK's dgetrf per block, parallel over
grains: 55 ms for 515 blocks of 90 x 90 on one thread against 90-107 ms for our own compiled LU and
160 ms for NumPy's batched inverse, docs/linear-solvers.md; refactorised at every Newton
iteration: a kept one costs 17-26 GMRES iterations), except where a grain's block is its rotated
reference one with few dofs touched by contacts: there Woodbury's formula from the grain's
reference modes (woodbury.py; its Z_g are then its rotated reference's rigid modes). GMRES solves
K P^-1 u = b, x = P^-1 u, to ||b - K x|| <= rtol ||b||, the tolerance the caller ties to Newton's
progress.
"""

from __future__ import annotations

import warnings
from contextlib import contextmanager

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
from numba import njit, prange

from .base import CountersCarried, LinearSolveDiverged, NewtonSystem, SingularSystemError, SolverStats
from .direct import superlu
from .lapack import _DOUBLE, _GETRF
from .modes import rigid_modes
from . import woodbury
from .woodbury import WoodburyBlocks, modal_basis




@njit(parallel=True, cache=True, error_model="numpy")
def _lu_blocks(blocks, block_ptr, dof_ptr, lu, piv, bad, z, local, bz, skip):
    """LU with partial pivoting of every block (LAPACK dgetrf on a copy) but those marked in skip
    (the Woodbury path's: woodbury.py); bad[g] = 1 marks a singular block (a pivot below 1e-15 of
    the block's largest entry, or not finite).

    The blocks are stored by rows and LAPACK reads by columns, so each factorisation is of the
    block's transpose, B_g^T = P L U; `_lu_solve_blocks` solves with B_g = U^T L^T P^T.

    With rigid modes z (rows of Z; none: z.shape[0] == 0) the copy also forms the coarse space's
    products, bz's rows of grain g = B_g Z_g and local[g] = Z_g^T B_g Z_g, while each row of the
    block is in cache: one pass over the blocks (33 MB at 515 grains) instead of a second one for
    two BLAS products per grain (docs/linear-solvers.md)."""
    one = np.ones(1)
    one_piv = np.empty(1, np.int32)
    _GETRF(_DOUBLE, 1, 1, one.ctypes, 1, one_piv.ctypes)
    products = z.shape[0] > 0
    for g in prange(len(dof_ptr) - 1):
        if skip[g]:
            continue
        n = dof_ptr[g + 1] - dof_ptr[g]
        b0, p0 = block_ptr[g], dof_ptr[g]
        scale = 0.0
        if products:
            for i in range(n):
                r0 = b0 + i * n
                s0 = s1 = s2 = s3 = s4 = s5 = 0.0  # six sums, not a 6-vector: the row loop vectorises
                for j in range(n):
                    v = blocks[r0 + j]
                    lu[r0 + j] = v
                    scale = max(scale, abs(v))
                    zj = z[p0 + j]
                    s0 += v * zj[0]
                    s1 += v * zj[1]
                    s2 += v * zj[2]
                    s3 += v * zj[3]
                    s4 += v * zj[4]
                    s5 += v * zj[5]
                q = bz[p0 + i]
                q[0], q[1], q[2], q[3], q[4], q[5] = s0, s1, s2, s3, s4, s5
            for a in range(6):
                for k in range(6):
                    c = 0.0
                    for i in range(p0, p0 + n):
                        c += z[i, a] * bz[i, k]
                    local[g, a, k] = c
        else:
            for k in range(n * n):
                v = blocks[b0 + k]
                lu[b0 + k] = v
                scale = max(scale, abs(v))
        _GETRF(_DOUBLE, n, n, lu[b0 : b0 + n * n].ctypes, n, piv[p0 : p0 + n].ctypes)
        for k in range(n):
            if not abs(lu[b0 + k * (n + 1)]) > 1e-15 * scale:
                bad[g] = 1
                break


@njit(parallel=True, cache=True, fastmath=True, error_model="numpy")
def _lu_solve_blocks(lu, piv, block_ptr, dof_ptr, r, out, skip):
    """out_g = B_g^-1 r_g from `_lu_blocks`' factors (the grains not marked in skip): U^T y = r (U^T
    is the lower triangle of the stored rows), L^T z = y (the strict upper one, unit diagonal),
    then LAPACK's row interchanges undone in reverse order."""
    for g in prange(len(dof_ptr) - 1):
        if skip[g]:
            continue
        n = dof_ptr[g + 1] - dof_ptr[g]
        b0, p0 = block_ptr[g], dof_ptr[g]
        A = lu[b0 : b0 + n * n].reshape(n, n)
        y = r[p0 : p0 + n].copy()
        for i in range(n):  # row views and a separate sum: the dot products vectorise
            row = A[i]
            s = 0.0
            for j in range(i):
                s += row[j] * y[j]
            y[i] = (y[i] - s) / row[i]
        for i in range(n - 1, -1, -1):
            row = A[i]
            s = 0.0
            for j in range(i + 1, n):
                s += row[j] * y[j]
            y[i] -= s
        for k in range(n - 1, -1, -1):
            p = piv[p0 + k] - 1  # LAPACK's pivots count from 1
            if p != k:
                t = y[k]
                y[k] = y[p]
                y[p] = t
        out[p0 : p0 + n] = y


@njit(cache=True)
def _coupling_pattern(indptr, indices, dof_ptr, dof_body):
    """The coarse matrix's block pattern: body-pair keys a G + b in increasing order (each body's
    own block included), the slot of every body's diagonal block and of every coupling entry.
    O(nnz) with one marker array, in place of np.unique on the entries' keys (a sort of every
    coupling entry: 10 ms at 515 grains and 110,000 entries)."""
    G = len(dof_ptr) - 1
    mark = np.full(G, -1, np.int64)
    pos = np.zeros(G, np.int64)
    count = np.zeros(G + 1, np.int64)
    for a in range(G):
        mark[a] = a
        count[a + 1] = 1
        for i in range(dof_ptr[a], dof_ptr[a + 1]):
            for p in range(indptr[i], indptr[i + 1]):
                b = dof_body[indices[p]]
                if mark[b] != a:
                    mark[b] = a
                    count[a + 1] += 1
    offset = np.cumsum(count)
    keys = np.empty(offset[G], np.int64)
    diagonal = np.empty(G, np.int64)
    slot = np.empty(len(indices), np.int64)
    mark[:] = -1
    for a in range(G):
        o, m = offset[a], 1
        mark[a] = a
        keys[o] = a
        for i in range(dof_ptr[a], dof_ptr[a + 1]):
            for p in range(indptr[i], indptr[i + 1]):
                b = dof_body[indices[p]]
                if mark[b] != a:
                    mark[b] = a
                    keys[o + m] = b
                    m += 1
        neighbours = np.sort(keys[o : o + m])
        for q in range(m):
            keys[o + q] = neighbours[q]
        for q in range(m):
            pos[keys[o + q]] = o + q
            keys[o + q] += a * G
        diagonal[a] = pos[a]
        for i in range(dof_ptr[a], dof_ptr[a + 1]):
            for p in range(indptr[i], indptr[i + 1]):
                slot[p] = pos[dof_body[indices[p]]]
    return keys, diagonal, slot


@njit(cache=True)
def _coupling_blocks(indptr, indices, data, z, slot, out):
    """out[slot[p]] += z_i^T c_ij z_j (6 x 6) for every coupling entry p = (i, j)."""
    for i in range(len(indptr) - 1):
        for p in range(indptr[i], indptr[i + 1]):
            j, c, b = indices[p], data[p], slot[p]
            for a in range(6):
                za = z[i, a] * c
                if za != 0.0:
                    for k in range(6):
                        out[b, a, k] += za * z[j, k]


@njit(cache=True, parallel=True)
def _restrict(z, dof_ptr, r, out):
    """out[g] = Z_g^T r_g (6 per body)."""
    for g in prange(len(dof_ptr) - 1):
        for a in range(6):
            s = 0.0
            for i in range(dof_ptr[g], dof_ptr[g + 1]):
                s += z[i, a] * r[i]
            out[6 * g + a] = s


@njit(cache=True, parallel=True)
def _prolong(z, dof_ptr, c, out):
    """out_g = Z_g c_g."""
    for g in prange(len(dof_ptr) - 1):
        for i in range(dof_ptr[g], dof_ptr[g + 1]):
            s = 0.0
            for a in range(6):
                s += z[i, a] * c[6 * g + a]
            out[i] = s


# Up to this many bodies the coarse matrix is factorised dense (LAPACK), beyond by SuperLU. Build,
# factorise and solve, one BLAS thread, block-sparse coarse matrices with 3 coupled neighbours per
# body (benchmarks/bench_coarse.py, 2 cores): dense 0.17 / 0.75 / 1.6 / 5.6 / 20.3 ms at
# 24 / 40 / 64 / 100 / 150 bodies, SuperLU 0.74 / 1.0 / 1.1 / 1.9 / 3.1 ms: the crossover lies
# between 40 and 64 (it was 150, set from a faster machine's 24-grain figure).
DENSE_COARSE_BODIES = 40

# GMRES's attainable accuracy. Its residual estimate keeps falling where the true residual b - K x
# cannot: the preconditioner's block solves amplify round-off along each grain's rigid modes by the
# ratio of its stiffness to its mass term, a1 m against E d (1e9 at dt = 1e-3 s for the paper's
# grains). On the settled 515-grain pack at dt = 1e-3 s the solve reaches 1e-7 in 2 iterations and
# then stands at 1.2e-8 through its whole budget of 200 (3e-3 s: 1.6e-7, 1e-2 s: 1.5e-5;
# docs/linear-solvers.md). A restart cycle that does not halve the true residual ends the solve:
# accepted when within STALL_ACCEPT of the right-hand side (Newton's forcing term asks 0.1 to 1e-8,
# and its own tests judge the iterate), a failure otherwise, at once rather than after the budget.
STALL_FACTOR = 0.5
STALL_ACCEPT = 1e-6

# A coarse LU kept from an earlier Newton matrix preconditions GMRES on this one's coarse matrix,
# solved to KEPT_COARSE_RTOL in at most KEPT_COARSE_MAX iterations (else this matrix's own LU is
# made on the spot); the next matrix keeps it while this one spent at most KEPT_COARSE_BUDGET.
# An inner iteration (the kept LU's triangular solves, 1.1 ms, and a product with the 3,090-row
# coarse matrix, 0.1 ms, at 515 grains) against 30-40 ms for the SuperLU it saves. Measured on
# 1e-3 s of the falling 515-grain implicit pack (docs/linear-solvers.md), the LU kept across
# steps: 206 coarse matrices, 18 SuperLU factorisations and 1,401 inner iterations at 1e-4 (at
# 1e-8: 59 and 1,713; at 1e-2: 9 and 1,066 but 271 outer GMRES iterations against 227-233); the
# same steps and Newton iterations as with every matrix factorised. newmark_step drops the LU at
# each step (forget), for bitwise resume: 37 factorisations and 1,078 inner iterations there.
KEPT_COARSE_RTOL = 1e-4
KEPT_COARSE_MAX = 10
KEPT_COARSE_BUDGET = 12


@contextmanager
def _singular_coarse():
    """A coarse matrix that LAPACK or SuperLU finds singular: a rigid mode no contact or wall holds."""
    try:
        yield
    except (RuntimeError, np.linalg.LinAlgError) as exc:
        raise SingularSystemError(f"singular tangent (coarse space: {exc}); is every rigid-body mode constrained?"
                                  ) from None  # fmt: skip


class _CoarseSpace:
    """A_c = Z^T K Z in 6 x 6 body blocks (compiled, no sparse products) and its LU, or an LU kept
    from an earlier Newton matrix that preconditions a short inner GMRES on A_c (KEPT_COARSE_*)."""

    def __init__(self, s: NewtonSystem, products, kept=None, stats: SolverStats | None = None):
        """products: (Z's rows, Z_g^T B_g Z_g, B_g Z_g), summed in the block LU's pass (`_lu_blocks`)."""
        G = s.n_bodies
        self.stats = stats if stats is not None else SolverStats()
        self.dof_ptr = s.dof_ptr
        # bz = blockdiag(B_g) Z: K Z = bz + C Z without a pass over the blocks
        self.z, local, self.bz = products
        keys = np.arange(G, dtype=np.int64) * (G + 1)  # the diagonal blocks
        C = s.coupling if s.coupling is not None and s.coupling.nnz else None
        self.coupling = C
        if C is not None:
            dof_body = np.repeat(np.arange(G, dtype=np.int64), np.diff(s.dof_ptr))
            keys, diagonal, slot = _coupling_pattern(C.indptr, C.indices, s.dof_ptr, dof_body)
            blocks = np.zeros((len(keys), 6, 6))
            blocks[diagonal] = local
            _coupling_blocks(C.indptr, C.indices, C.data, self.z, slot, blocks)
        else:
            blocks = local
        rows, cols = keys // G, keys % G
        self.fresh, self.inner_iterations = True, 0  # inner: this matrix's, for the keep-or-refactorise rule
        self._dense = self.matrix = None
        if G <= DENSE_COARSE_BODIES:
            A = np.zeros((G, 6, G, 6))
            A[rows, :, cols, :] = blocks
            with _singular_coarse():
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", sla.LinAlgWarning)
                    self._dense = sla.lu_factor(A.reshape(6 * G, 6 * G), check_finite=False)
                pivots = np.abs(np.diag(self._dense[0]))
                if not np.all(np.isfinite(pivots)) or pivots.min() <= 1e-13 * pivots.max():
                    raise RuntimeError("singular matrix")
            return
        indptr = np.searchsorted(rows, np.arange(G + 1))
        self.matrix = sp.bsr_matrix((blocks, cols, indptr), shape=(6 * G, 6 * G))
        if kept is not None and kept.shape == self.matrix.shape:
            self._lu, self.fresh = kept, False
        else:
            self._factor()

    def correction_and_product(self, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """y = Z c with c = A_c^-1 Z^T r (the coarse correction), and K y = (B Z) c + C y from the
        products kept at set-up."""
        rc = np.empty(6 * (len(self.dof_ptr) - 1))
        _restrict(self.z, self.dof_ptr, r, rc)
        c = sla.lu_solve(self._dense, rc, check_finite=False) if self._dense is not None else self._solve(rc)
        y, ky = np.empty(len(r)), np.empty(len(r))
        _prolong(self.z, self.dof_ptr, c, y)
        _prolong(self.bz, self.dof_ptr, c, ky)
        if self.coupling is not None:
            ky += self.coupling @ y
        return y, ky

    def _factor(self) -> None:
        with _singular_coarse():
            self._lu, self.fresh = superlu(self.matrix), True
        self.stats.coarse_factorisations += 1

    def _solve(self, rc: np.ndarray) -> np.ndarray:
        """A_c^-1 rc: by the LU of A_c itself, or by GMRES on A_c preconditioned with a kept LU,
        to KEPT_COARSE_RTOL; a kept LU that needs more than KEPT_COARSE_MAX iterations is
        replaced by this matrix's own (then exact)."""
        if self.fresh:
            return self._lu.solve(rc)
        A, lu = self.matrix, self._lu

        def precondition(v):
            u = lu.solve(v)
            return u, A @ u

        norm = np.linalg.norm(rc)
        if norm == 0.0:
            return np.zeros_like(rc)
        x, its = _arnoldi(precondition, rc, norm, KEPT_COARSE_MAX, KEPT_COARSE_RTOL * norm)
        self.inner_iterations += its
        self.stats.coarse_iterations += its
        if np.linalg.norm(rc - A @ x) <= KEPT_COARSE_RTOL * norm:
            return x
        self._factor()
        return self._lu.solve(rc)


class GrainBlockSolver(CountersCarried):  # the coarse LU is the step's own (forget)
    """GMRES right-preconditioned with the multiplicative two-level grain-block preconditioner."""

    name = "grain-block"

    def __init__(self, restart: int = 40, max_iterations: int = 200, coarse: bool = True,
                 woodbury_max_dofs: int | None = None):  # fmt: skip
        """woodbury_max_dofs: rotated blocks whose contacts touch at most this many dofs take the
        Woodbury path (0: every block its LU; None: woodbury.WOODBURY_MAX_DOFS as it is now)."""
        self.restart, self.max_iterations, self.coarse = restart, max_iterations, coarse
        self.woodbury_max_dofs = woodbury.WOODBURY_MAX_DOFS if woodbury_max_dofs is None else woodbury_max_dofs
        self.stats = SolverStats()
        self._coarse = None  # the last Newton matrix's coarse space, whose LU the next one may keep
        self._woodbury = None

    # ------------------------------------------------------------------ set-up per Newton matrix
    def factor(self, system: NewtonSystem) -> None:
        self.system = s = system
        if getattr(self, "_lu", None) is None or self._lu.shape != s.blocks.shape:  # kept: no page faults
            self._lu = np.empty_like(s.blocks)
            self._piv = np.empty(s.n, np.int32)
        bad = np.zeros(s.n_bodies, np.int64)
        coarse = self.coarse and s.positions is not None
        z = rigid_modes(s.positions, s.dof_ptr // 3) if coarse else np.empty((0, 6))
        local, bz = np.empty((s.n_bodies if coarse else 0, 6, 6)), np.empty((len(z), 6))
        self._woodbury = self._woodbury_blocks(s, coarse)
        # the Woodbury path's grains, which the LU kernels skip (precondition too)
        self._skip = self._woodbury.chosen if self._woodbury is not None else np.zeros(s.n_bodies, np.bool_)
        _lu_blocks(s.blocks, s.block_ptr, s.dof_ptr, self._lu, self._piv, bad, z, local, bz, self._skip)
        if self._woodbury is not None:
            self._woodbury.factor(s, z, local, bz, bad)
            self.stats.woodbury_blocks += len(self._woodbury.grains)
        if bad.any():
            raise SingularSystemError(f"singular tangent block of grain {int(np.flatnonzero(bad)[0])}; "
                                      "is every rigid-body mode constrained?")  # fmt: skip
        before, self._coarse = self._coarse, None
        if coarse:
            self._coarse = _CoarseSpace(s, (z, local, bz), self._kept_lu(before), self.stats)
        self.stats.factorisations += 1

    def _woodbury_blocks(self, s: NewtonSystem, coarse: bool) -> WoodburyBlocks | None:
        """The Woodbury path's grains of this matrix (None: every block its LU). It needs the
        rotated blocks' reference, a positive mass shift (A = Q (K + s M) Q^T invertible) and the
        coarse space, whose products it makes from the rotated reference modes."""
        if (self.woodbury_max_dofs <= 0 or not coarse or s.rotated is None or s.reference is None
                or s.touched is None or not s.mass_shift > 0.0 or not s.rotated.any()):  # fmt: skip
            return None
        blocks = WoodburyBlocks(s, modal_basis(s.reference), self.woodbury_max_dofs)
        return blocks if len(blocks.grains) else None

    def forget(self) -> None:
        """The next Newton matrix factorises its own coarse LU (newmark_step calls this at each step,
        so that a step depends on its state alone and a resumed run continues to the same bits)."""
        self._coarse = None

    def _kept_lu(self, before):
        """The coarse LU of the last Newton matrix, to precondition this one's coarse solves, while
        it pays: its own or one that needed at most KEPT_COARSE_BUDGET inner iterations there."""
        if before is None or before.matrix is None:
            return None
        return before._lu if before.fresh or before.inner_iterations <= KEPT_COARSE_BUDGET else None

    def precondition(self, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """z = P^-1 r and its product K z. With y = Z A_c^-1 Z^T r, s = r - K y and z = y + B^-1 s:

            K z = K y + B B^-1 s + C B^-1 s = r + C B^-1 s

        so GMRES's product costs a pass over the coupling only, not two over the 33 MB of blocks
        (515 grains) besides the block solve's own; it differs from K z by the block LU's residual
        B (B^-1 s) - s, which the true residual at each restart (a full product) still sees."""
        s = self.system
        r = np.ascontiguousarray(r)
        rest, y = r, None
        if self._coarse is not None:
            y, ky = self._coarse.correction_and_product(r)
            rest = r - ky
        out = np.empty(s.n)
        _lu_solve_blocks(self._lu, self._piv, s.block_ptr, s.dof_ptr, rest, out, self._skip)
        if self._woodbury is not None:
            self._woodbury.solve(s, rest, out)
        w = r + s.coupling @ out if s.coupling is not None and s.coupling.nnz else r.copy()
        return (out if y is None else y + out), w

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
        beta_before = np.inf
        while True:
            beta = np.linalg.norm(r)
            if beta <= rtol * bnorm:
                break
            if beta > STALL_FACTOR * beta_before:  # the true residual stopped falling: see STALL_FACTOR
                if beta <= STALL_ACCEPT * bnorm:
                    self.stats.stalled += 1
                    break
                raise self._failed(total, f"GMRES stalled at a relative residual {beta / bnorm:.2e} after {total} "
                                          f"iterations (asked {rtol:.1e})")  # fmt: skip
            beta_before = beta
            dx, k = _arnoldi(self.precondition, r, beta, min(self.restart, self.max_iterations - total), rtol * bnorm)
            total += k
            x = x + dx
            r = b - s.matvec(x)
            if total >= self.max_iterations:
                if np.linalg.norm(r) > rtol * bnorm:
                    raise self._failed(total, f"GMRES reached a relative residual {np.linalg.norm(r) / bnorm:.2e} "
                                              f"after {total} iterations (asked {rtol:.1e})")  # fmt: skip
                break
        if not np.all(np.isfinite(x)):
            raise SingularSystemError("singular tangent: GMRES returned non-finite values")
        self._count(total)
        return x

    def _count(self, total: int):
        self.stats.iterations += total
        self.stats.last_iterations = total

    def _failed(self, total: int, message: str) -> LinearSolveDiverged:
        """The failure of a solve that spent `total` iterations, counted: spent in vain, they are
        still the run's Krylov work."""
        self._count(total)
        return LinearSolveDiverged(message)


def _arnoldi(precondition, r: np.ndarray, beta: float, m: int, target: float) -> tuple[np.ndarray, int]:
    """One cycle of right-preconditioned flexible GMRES on the residual r (norm beta > 0): at most m
    iterations, fewer once the residual estimate falls to `target`. `precondition(v)` returns
    (z, A z); the correction is sum_k z_k y_k (flexible: the z_k are kept, so a preconditioner that
    is itself an inexact solve is allowed). Returns the correction and the iterations spent."""
    V = [r / beta]
    H = np.zeros((m + 1, m))
    cs, sn, g = np.zeros(m), np.zeros(m), np.zeros(m + 1)
    g[0] = beta
    Zs = []
    k = 0
    for k in range(m):
        z, w = precondition(V[k])
        Zs.append(z)
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
        if abs(g[k + 1]) <= target:
            break
    n_k = k + 1
    y = np.linalg.solve(np.triu(H[:n_k, :n_k]), g[:n_k])
    return np.array(Zs).T @ y, n_k
