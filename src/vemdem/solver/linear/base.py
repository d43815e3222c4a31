"""The linear-solver room: one interface for every solver of the Newton systems.

A Newton system keeps the structure the physics gives it (docs/linear-solvers.md): the dense block of every body
(element tangent + a1 M + the contact terms within the body) and one sparse coupling matrix (the
contact terms between bodies), plus the positions that define each body's rigid modes:

    K = blockdiag(B_1 .. B_G) + C

A `LinearSolver` is made once per run (`make_linear_solver`), is handed each Newton matrix
(`factor`), may keep state across iterations, and solves to a relative residual the caller asks
for (`solve(rhs, rtol)`: inexact Newton). No solver assumes symmetry: friction makes K
non-symmetric.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Protocol

import numpy as np
import scipy.sparse as sp
from numba import njit, prange


class SingularSystemError(np.linalg.LinAlgError):
    """The matrix cannot be solved: str(e) names the cause (a free rigid mode, a singular body)."""


class LinearSolveDiverged(np.linalg.LinAlgError):
    """An iterative solve did not reach its tolerance: str(e) gives the residual and iterations."""


@njit(parallel=True, cache=True, fastmath=True)
def _block_matvec(blocks, block_ptr, dof_ptr, u, out):
    # fastmath lets the row sums vectorise (reassociated): 3.9 -> 1.8 ms for 515 blocks of 90 x 90
    # on one thread, the same to 4e-16 (docs/linear-solvers.md)
    for g in prange(len(dof_ptr) - 1):
        d0, n = dof_ptr[g], dof_ptr[g + 1] - dof_ptr[g]
        b0 = block_ptr[g]
        A = blocks[b0 : b0 + n * n].reshape(n, n)
        x = u[d0 : d0 + n]
        for i in range(n):
            row = A[i]
            s = 0.0
            for j in range(n):
                s += row[j] * x[j]
            out[d0 + i] = s


@dataclass
class NewtonSystem:
    blocks: np.ndarray  # flat dense row-major block of each body at block_ptr[g]
    block_ptr: np.ndarray  # (G+1,)
    dof_ptr: np.ndarray  # (G+1,) body g owns dofs dof_ptr[g]:dof_ptr[g+1]
    coupling: sp.csr_matrix | None = None  # entries between different bodies only
    positions: np.ndarray | None = None  # (N, 3) vertex positions (flexible bodies: rigid modes)
    _csr: sp.csr_matrix | None = field(default=None, repr=False)
    # Rotated blocks (docs/linear-solvers.md, "The rotated-block Woodbury path"): where rotated[g],
    # B_g = Q (K_g + mass_shift M_g) Q^T + the contact terms on the dofs of the `touched` vertices,
    # Q = I (x) rotations[g], K_g and M_g the body model's `reference` (model.bodies.RotationReference)
    rotated: np.ndarray | None = None  # (G,) bool
    rotations: np.ndarray | None = None  # (G, 3, 3)
    touched: np.ndarray | None = None  # (N,) bool
    mass_shift: float = 0.0
    reference: object | None = None

    @property
    def n(self) -> int:
        return int(self.dof_ptr[-1])

    @property
    def n_bodies(self) -> int:
        return len(self.dof_ptr) - 1

    def matvec(self, u: np.ndarray) -> np.ndarray:
        out = np.empty(self.n)
        _block_matvec(self.blocks, self.block_ptr, self.dof_ptr, np.ascontiguousarray(u, float), out)
        if self.coupling is not None and self.coupling.nnz:
            out += self.coupling @ u
        return out

    def to_csr(self) -> sp.csr_matrix:
        """The exact global matrix (block data are the CSR data of the block diagonal)."""
        if self._csr is None:
            n = self.n
            sizes = np.diff(self.dof_ptr)
            indptr = np.zeros(n + 1, np.int64)
            np.cumsum(np.repeat(sizes, sizes), out=indptr[1:])
            indices = np.concatenate([np.tile(np.arange(d0, d0 + s), s) for d0, s in zip(self.dof_ptr[:-1], sizes)])
            K = sp.csr_matrix((self.blocks, indices, indptr), shape=(n, n))
            if self.coupling is not None and self.coupling.nnz:
                K = K + self.coupling
            self._csr = K.tocsr()
        return self._csr

    @classmethod
    def from_csr(cls, K, dof_ptr, positions=None) -> "NewtonSystem":
        """Split a global matrix into body blocks and coupling (tests, benchmarks, old callers)."""
        K = sp.csr_matrix(K)
        dof_ptr = np.asarray(dof_ptr, np.int64)
        body = np.repeat(np.arange(len(dof_ptr) - 1), np.diff(dof_ptr))
        coo = K.tocoo()
        inside = body[coo.row] == body[coo.col]
        sizes = np.diff(dof_ptr)
        block_ptr = np.concatenate([[0], np.cumsum(sizes**2)]).astype(np.int64)
        blocks = np.zeros(block_ptr[-1])
        r, c, v = coo.row[inside], coo.col[inside], coo.data[inside]
        g = body[r]
        np.add.at(blocks, block_ptr[g] + (r - dof_ptr[g]) * sizes[g] + (c - dof_ptr[g]), v)
        out = ~inside
        coupling = sp.csr_matrix((coo.data[out], (coo.row[out], coo.col[out])), shape=K.shape)
        return cls(blocks, block_ptr, dof_ptr, coupling, positions)


@dataclass
class SolverStats:
    factorisations: int = 0
    solves: int = 0
    iterations: int = 0  # Krylov iterations, all solves
    last_iterations: int = 0
    fallbacks: int = 0  # auto: systems handed to the direct solver after the iterative one failed
    held: int = 0  # auto: systems sent straight to the direct solver after a hand-over (AutoSolver)
    stalled: int = 0  # grain-block: solves ended at GMRES's attainable accuracy (grain_block.STALL_ACCEPT)
    coarse_factorisations: int = 0  # grain-block: SuperLU factorisations of the coarse matrix
    coarse_iterations: int = 0  # grain-block: inner GMRES iterations on coarse matrices with a kept LU
    woodbury_blocks: int = 0  # grain-block: grain blocks solved by Woodbury's formula (woodbury.py), all matrices

    def restore(self, counts: dict) -> None:
        """Counters from a checkpoint (asdict of an earlier SolverStats), in place: a solver may
        share its counters with another (AutoSolver and its grain-block solver)."""
        for key in asdict(self):
            setattr(self, key, int(counts.get(key, 0)))


class LinearSolver(Protocol):
    name: str
    stats: SolverStats

    def factor(self, system: NewtonSystem) -> None: ...

    def forget(self) -> None:
        """Drop what was kept from earlier matrices (newmark_step calls it at each step)."""

    def solve(self, rhs: np.ndarray, rtol: float = 1e-10) -> np.ndarray: ...

    def carried(self) -> dict:
        """What a checkpoint must hold for a resumed run to solve its next systems as the
        uninterrupted run would, and to go on counting (JSON-able; `carry_on` takes it back)."""

    def carry_on(self, carried: dict) -> None: ...


class CountersCarried:
    """`carried`/`carry_on` of a solver that keeps nothing across steps but its counters."""

    stats: SolverStats

    def carried(self) -> dict:
        return {"stats": asdict(self.stats)}

    def carry_on(self, carried: dict) -> None:
        self.stats.restore(carried.get("stats", {}))
