"""The rotated-block Woodbury path of the grain-block preconditioner (docs/linear-solvers.md).

A grain within `rotated_tangent` of a rotation R has the Newton block (vem.element.evaluate)

    B_g = Q (K_g + s M_g) Q^T + E_T C_TT E_T^T,    Q = I (x) R,

K_g its reference tangent, M_g its mass (times I_3), s the Newmark mass shift, and C_TT the
contact terms on the k dofs T that its contacts touch. With the generalised eigenvectors of
(K_g, M_g), made once per run (Phi^T M Phi = I, Phi^T K Phi = Lambda), A = Q (K + s M) Q^T has
the inverse Q Phi D Phi^T Q^T, D = (Lambda + s)^-1, for every step size, and Woodbury's formula
adds C_TT through a k x k matrix:

    W = (Q Phi)_T,  S = I + C_TT W D W^T
    B^-1 r = Q Phi D (p - W^T w),  p = Phi^T Q^T r,  S w = C_TT W D p

against the LU of the whole block (n = 90 dofs for the paper's grains): cheaper while k is small
(WOODBURY_MAX_DOFS, measured with benchmarks/bench_woodbury.py). The coarse space of such a grain
takes its rotated reference's rigid modes, Z_g = Q Z_ref, which K_g annihilates, so that
B_g Z_g = s M_g Z_g + E_T C_TT Z_T needs no pass over the dense block. C_TT is read off the dense
block (B_g - A on T x T): the block is still made, for GMRES's products and the direct solver.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit, prange

from ..defaults import default
from .lapack import _DOUBLE, _GETRF
from .modes import rigid_modes

# Grains whose contacts touch more dofs than this take the LU (`[solver] woodbury_dofs`, its default; T holds
# whole vertices, so k counts in threes). benchmarks/bench_woodbury.py, 515 grains of 30 vertices,
# 2 threads: the factorisation 0.48 of the LU's at k = 21, 0.79 at 33, 0.97 at 39, 1.22 at 48; one
# application 0.76, 1.04, 1.12, 1.27 (docs/linear-solvers.md).
WOODBURY_MAX_DOFS = default("woodbury_dofs")


BASIS_BATCH = 1024  # grains per batched eigh in modal_basis (about 330 MB of temporaries at 90 dofs)


@dataclass
class ModalBasis:
    """Per grain, the generalised eigenvectors of (K_g, M_g (x) I_3), at the blocks' offsets."""

    phi: np.ndarray  # flat n x n per grain (block_ptr), rows = dofs, columns = modes
    lam: np.ndarray  # (3N,) eigenvalues per grain (dof_ptr), round-off negatives set to 0
    z_ref: np.ndarray  # (3N, 6) the reference configuration's rigid modes
    mz_ref: np.ndarray  # (3N, 6) (M_g (x) I_3) Z_ref
    zmz: np.ndarray  # (G, 6, 6) Z_ref^T (M_g (x) I_3) Z_ref


def modal_basis(reference) -> ModalBasis:
    """The basis of a model.bodies.RotationReference, made once (cached on it). Grains with the
    same number of vertices are solved as one batch: M = L L^T, eigh of L^-1 K L^-T."""
    cached = reference.cache.get("modal")
    if cached is not None:
        return cached
    vptr, bptr = reference.vertex_ptr, reference.block_ptr
    z_ref = rigid_modes(reference.positions, vptr)
    counts = np.diff(vptr)
    phi = np.empty(bptr[-1])
    lam = np.empty(3 * vptr[-1])
    mz = np.empty_like(z_ref)
    zmz = np.empty((len(counts), 6, 6))
    groups = [np.flatnonzero(counts == nv) for nv in np.unique(counts)]
    # batches of at most BASIS_BATCH grains: five n x n arrays per grain are alive at once
    batches = [grains[i : i + BASIS_BATCH] for grains in groups for i in range(0, len(grains), BASIS_BATCH)]
    for grains in batches:
        nv = int(counts[grains[0]])
        n = 3 * nv
        K = np.stack([reference.tangent[bptr[g] : bptr[g + 1]] for g in grains]).reshape(-1, n, n)
        mptr = reference.mass_ptr
        M = np.stack([reference.mass[mptr[g] : mptr[g + 1]] for g in grains]).reshape(-1, nv, nv)
        Li = np.linalg.inv(np.linalg.cholesky(M))
        Li3 = np.einsum("gij,ab->giajb", Li, np.eye(3)).reshape(-1, n, n)
        A = Li3 @ (0.5 * (K + K.transpose(0, 2, 1))) @ Li3.transpose(0, 2, 1)
        w, V = np.linalg.eigh(A)
        P = Li3.transpose(0, 2, 1) @ V
        for q, g in enumerate(grains):
            phi[bptr[g] : bptr[g + 1]] = P[q].ravel()
            d0 = 3 * vptr[g]
            lam[d0 : d0 + n] = np.maximum(w[q], 0.0)
            zg = z_ref[d0 : d0 + n].reshape(nv, 3, 6)
            mz[d0 : d0 + n] = np.einsum("ij,jam->iam", M[q], zg).reshape(n, 6)
            zmz[g] = z_ref[d0 : d0 + n].T @ mz[d0 : d0 + n]
    out = ModalBasis(phi, lam, z_ref, mz, zmz)
    reference.cache["modal"] = out
    return out


class WoodburyBlocks:
    """The factors of the chosen grains' blocks for one Newton matrix, and their solves."""

    def __init__(self, system, basis: ModalBasis, max_dofs: int):
        s = system
        G = s.n_bodies
        vptr = s.dof_ptr // 3
        touched = np.asarray(s.touched, np.bool_)
        per_grain = np.add.reduceat(touched.astype(np.int64), vptr[:-1])  # touched vertices (grains are never empty)
        self.chosen = np.asarray(s.rotated, np.bool_) & (3 * per_grain <= max_dofs)
        self.grains = np.flatnonzero(self.chosen).astype(np.int64)
        k = 3 * per_grain[self.grains]
        n = np.diff(s.dof_ptr)[self.grains]
        self.tptr = np.concatenate([[0], np.cumsum(k)]).astype(np.int64)
        self.cptr = np.concatenate([[0], np.cumsum(k * k)]).astype(np.int64)
        self.wptr = np.concatenate([[0], np.cumsum(k * n)]).astype(np.int64)
        vertex_grain = np.repeat(np.arange(G), np.diff(vptr))
        v = np.flatnonzero(touched & self.chosen[vertex_grain])  # by grain, then vertex: the T lists
        self.tdof = (3 * (v - vptr[vertex_grain[v]]))[:, None] + np.arange(3)
        self.tdof = self.tdof.ravel().astype(np.int64)
        self.basis, self.shift = basis, float(s.mass_shift)
        self.rotations = np.ascontiguousarray(s.rotations)
        self.c_tt = np.empty(self.cptr[-1])
        self.w = np.empty(self.wptr[-1])
        self.s_lu = np.empty(self.cptr[-1])
        self.s_piv = np.empty(self.tptr[-1], np.int32)

    def factor(self, system, z, local, bz, bad) -> None:
        """C_TT, W, S's LU of the chosen grains; their rows of Z (rotated reference modes), of B Z
        and their Z^T B Z, in place; bad[g] = 1 marks a singular S."""
        s, b, reference = system, self.basis, system.reference
        _woodbury_factor(self.grains, s.blocks, s.block_ptr, s.dof_ptr, reference.tangent, reference.mass,
                         reference.mass_ptr, b.phi, b.lam, self.rotations, self.shift, self.tdof, self.tptr,
                         self.cptr, self.wptr, b.z_ref, b.mz_ref, b.zmz, self.c_tt, self.w, self.s_lu, self.s_piv, z,
                         bz, local, bad)  # fmt: skip

    def solve(self, system, r: np.ndarray, out: np.ndarray) -> None:
        """out_g = B_g^-1 r_g for the chosen grains (the others' rows untouched)."""
        b = self.basis
        _woodbury_solve(self.grains, system.block_ptr, system.dof_ptr, b.phi, b.lam, self.rotations, self.shift,
                        self.tptr, self.cptr, self.wptr, self.c_tt, self.w, self.s_lu, self.s_piv, r, out)  # fmt: skip


@njit(parallel=True, cache=True)
def _woodbury_factor(grains, blocks, block_ptr, dof_ptr, kref, mass, mass_ptr, phi, lam, rotations, s, tdof, tptr,
                     cptr, wptr, z_ref, mz_ref, zmz, c_tt, w_all, s_lu, s_piv, z, bz, local, bad):  # fmt: skip
    one = np.ones(1)
    one_piv = np.empty(1, np.int32)
    _GETRF(_DOUBLE, 1, 1, one.ctypes, 1, one_piv.ctypes)  # LAPACK fetched on this thread first (lapack.py)
    for q in prange(len(grains)):
        g = grains[q]
        n, d0, b0 = dof_ptr[g + 1] - dof_ptr[g], dof_ptr[g], block_ptr[g]
        nv = n // 3
        k = tptr[q + 1] - tptr[q]
        t = tdof[tptr[q] : tptr[q + 1]]
        R = rotations[g]
        B = blocks[b0 : b0 + n * n].reshape(n, n)
        K0 = kref[b0 : b0 + n * n].reshape(n, n)
        Mg = mass[mass_ptr[g] : mass_ptr[g] + nv * nv].reshape(nv, nv)
        P = phi[b0 : b0 + n * n].reshape(n, n)
        C = c_tt[cptr[q] : cptr[q + 1]].reshape(k, k)
        # C_TT = B_TT - (Q K Q^T + s M)_TT: the contact terms, read off the block
        RK = np.empty((3, 3))
        for a in range(0, k, 3):  # T lists whole vertices: 3 dofs each
            i = t[a] // 3
            for c in range(0, k, 3):
                j = t[c] // 3
                for p in range(3):
                    for v in range(3):
                        RK[p, v] = R[p, 0] * K0[3 * i, 3 * j + v] + R[p, 1] * K0[3 * i + 1, 3 * j + v] + \
                            R[p, 2] * K0[3 * i + 2, 3 * j + v]
                for p in range(3):
                    for r in range(3):
                        kr = RK[p, 0] * R[r, 0] + RK[p, 1] * R[r, 1] + RK[p, 2] * R[r, 2]
                        if p == r:
                            kr += s * Mg[i, j]
                        C[a + p, c + r] = B[3 * i + p, 3 * j + r] - kr
        # this grain's rows of Z (Q Z_ref) and of B Z = s Q M Z_ref + E_T C_TT Z_T
        for i in range(nv):
            for m in range(6):
                x0, x1, x2 = z_ref[d0 + 3 * i, m], z_ref[d0 + 3 * i + 1, m], z_ref[d0 + 3 * i + 2, m]
                y0, y1, y2 = mz_ref[d0 + 3 * i, m], mz_ref[d0 + 3 * i + 1, m], mz_ref[d0 + 3 * i + 2, m]
                for a in range(3):
                    z[d0 + 3 * i + a, m] = R[a, 0] * x0 + R[a, 1] * x1 + R[a, 2] * x2
                    bz[d0 + 3 * i + a, m] = s * (R[a, 0] * y0 + R[a, 1] * y1 + R[a, 2] * y2)
        # Z^T B Z = s Z_ref^T M Z_ref (Q^T Q = I: the reference's, made once) + Z_T^T C_TT Z_T
        cz = np.zeros((k, 6))
        for a in range(k):
            for c in range(k):
                cac = C[a, c]
                for m in range(6):
                    cz[a, m] += cac * z[d0 + t[c], m]
        for a in range(k):
            for m in range(6):
                bz[d0 + t[a], m] += cz[a, m]
        for a in range(6):
            for m in range(6):
                acc = s * zmz[g, a, m]
                for c in range(k):
                    acc += z[d0 + t[c], a] * cz[c, m]
                local[g, a, m] = acc
        if k == 0:
            continue
        W = w_all[wptr[q] : wptr[q + 1]].reshape(k, n)
        WD = np.empty((k, n))
        for a in range(k):
            i, p = t[a] // 3, t[a] % 3
            r0, r1, r2 = R[p, 0], R[p, 1], R[p, 2]
            for j in range(n):
                wv = r0 * P[3 * i, j] + r1 * P[3 * i + 1, j] + r2 * P[3 * i + 2, j]
                W[a, j] = wv
                WD[a, j] = wv / (lam[d0 + j] + s)
        S = np.eye(k) + C @ (WD @ W.T)
        L = s_lu[cptr[q] : cptr[q + 1]]
        scale = 0.0
        for a in range(k):
            for c in range(k):
                L[a * k + c] = S[a, c]  # by rows: LAPACK reads columns and factors S^T = P L U
                scale = max(scale, abs(S[a, c]))
        _GETRF(_DOUBLE, k, k, L.ctypes, k, s_piv[tptr[q] : tptr[q + 1]].ctypes)
        for a in range(k):
            if not abs(L[a * (k + 1)]) > 1e-15 * scale:
                bad[g] = 1
                break


@njit(parallel=True, cache=True, fastmath=True)
def _woodbury_solve(grains, block_ptr, dof_ptr, phi, lam, rotations, s, tptr, cptr, wptr, c_tt, w_all, s_lu, s_piv,
                    r, out):  # fmt: skip
    for q in prange(len(grains)):
        g = grains[q]
        n, d0, b0 = dof_ptr[g + 1] - dof_ptr[g], dof_ptr[g], block_ptr[g]
        k = tptr[q + 1] - tptr[q]
        R = rotations[g]
        P = phi[b0 : b0 + n * n].reshape(n, n)
        p = np.zeros(n)  # p = Phi^T Q^T r_g, row by row of Phi
        for i in range(n // 3):
            x0, x1, x2 = r[d0 + 3 * i], r[d0 + 3 * i + 1], r[d0 + 3 * i + 2]
            for a in range(3):
                qa = R[0, a] * x0 + R[1, a] * x1 + R[2, a] * x2
                row = P[3 * i + a]
                for j in range(n):
                    p[j] += row[j] * qa
        for j in range(n):
            p[j] /= lam[d0 + j] + s  # now D p
        if k > 0:
            W = w_all[wptr[q] : wptr[q + 1]].reshape(k, n)
            C = c_tt[cptr[q] : cptr[q + 1]].reshape(k, k)
            L = s_lu[cptr[q] : cptr[q + 1]].reshape(k, k)
            u = np.empty(k)
            for a in range(k):
                acc = 0.0
                for j in range(n):
                    acc += W[a, j] * p[j]
                u[a] = acc
            y = C @ u
            # S^T = P L U: S y' = y is U^T x = y, L^T x' = x, then the interchanges in reverse
            for i in range(k):
                acc = 0.0
                for j in range(i):
                    acc += L[i, j] * y[j]
                y[i] = (y[i] - acc) / L[i, i]
            for i in range(k - 1, -1, -1):
                acc = 0.0
                for j in range(i + 1, k):
                    acc += L[i, j] * y[j]
                y[i] -= acc
            piv = s_piv[tptr[q] : tptr[q + 1]]
            for i in range(k - 1, -1, -1):
                m = piv[i] - 1
                if m != i:
                    tmp = y[i]
                    y[i] = y[m]
                    y[m] = tmp
            for a in range(k):  # D p - D W^T w
                ya = y[a]
                for j in range(n):
                    p[j] -= W[a, j] * ya / (lam[d0 + j] + s)
        for i in range(n // 3):  # Q Phi v
            y0 = y1 = y2 = 0.0
            r0, r1, r2 = P[3 * i], P[3 * i + 1], P[3 * i + 2]
            for j in range(n):
                y0 += r0[j] * p[j]
                y1 += r1[j] * p[j]
                y2 += r2[j] * p[j]
            for a in range(3):
                out[d0 + 3 * i + a] = R[a, 0] * y0 + R[a, 1] * y1 + R[a, 2] * y2
