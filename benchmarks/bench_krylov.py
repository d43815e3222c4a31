"""GMRES iterations on one Newton matrix under other coarse spaces than the shipped one
(docs/linear-solvers.md).

    python benchmarks/bench_krylov.py [--state benchmarks/data/lid515_jam.npz] [--dt 1e-5,1e-6,1e-4]

In the lid's jam the grain-block solver needs 8 GMRES iterations per Newton iteration where a
settled pack needs 2 (docs/linear-solvers.md): is a richer coarse space the lever? For each step
size this builds the Newton matrix of the state (as bench_newton.py does) and counts the
right-preconditioned GMRES iterations to a relative residual 1e-8, one cycle of at most 200, for:

    shipped     the grain-block solver itself (6 rigid modes per grain, multiplicative)
    block LU    the exact inverse of the grain blocks alone, no coarse space
    rigid 6     the same multiplicative two-level form with the solver's own rigid modes, written
                here with SciPy (checks the harness: it must count what `shipped` counts)
    affine 12   translations and the 9 linear modes e_k (x - c)_j / s of every grain: each grain's
                homogeneous deformations too, the modes of its VEM consistency term

with the coarse matrix's size, the non-zeros of its LU and SciPy's factorisation time (SuperLU,
as the shipped solver uses beyond 40 grains). Nothing is asserted; results in
docs/linear-solvers.md.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

import bench_newton as bn
from vemdem.solver.explicit import FEATURE_SKIN_GAPS
from vemdem.solver.linear import make_linear_solver
from vemdem.solver.linear.grain_block import _arnoldi
from vemdem.solver.linear.modes import rigid_modes
from vemdem.solver.newmark import newton_system

HERE = Path(__file__).resolve().parent
RTOL, BUDGET = 1e-8, 200


def coarse_modes(x: np.ndarray, vertex_ptr: np.ndarray, affine: bool) -> sp.csr_matrix:
    """Z (3N x m G): per grain g, columns m g .. m g + m - 1: the solver's own six rigid modes
    (solver.linear.modes.rigid_modes: translations, rotations e_k x r), or the translations and the
    nine linear modes e_k r_j, r = (x - c_g) / s_g (c_g the vertex average, s_g the RMS radius, as there)."""
    grain = np.repeat(np.arange(len(vertex_ptr) - 1), np.diff(vertex_ptr))
    if affine:
        counts = np.diff(vertex_ptr)[:, None]
        c = np.add.reduceat(x, vertex_ptr[:-1]) / counts
        s = np.sqrt(np.add.reduceat(((x - c[grain]) ** 2).sum(1), vertex_ptr[:-1]) / counts[:, 0])
        r = (x - c[grain]) / s[grain, None]
        rows = np.zeros((len(x), 3, 12))  # vertex, dof k, mode
        for k in range(3):
            rows[:, k, k] = 1.0
            rows[:, k, 3 + 3 * k : 6 + 3 * k] = r
        rows = rows.reshape(3 * len(x), 12)
    else:
        rows = rigid_modes(x, vertex_ptr)
    m = rows.shape[1]
    dof_grain = np.repeat(grain, 3)
    cols = m * dof_grain[:, None] + np.arange(m)[None, :]
    dofs = np.repeat(np.arange(3 * len(x)), m)
    return sp.csr_matrix((rows.ravel(), (dofs, cols.ravel())), shape=(3 * len(x), m * (len(vertex_ptr) - 1)))


def gmres_iterations(K, precondition, b) -> tuple[int, float]:
    """Iterations of one GMRES cycle to RTOL (BUDGET at most) and the true relative residual."""
    beta = np.linalg.norm(b)

    def pc(v):
        z = precondition(v)
        return z, K @ z

    x, k = _arnoldi(pc, b.copy(), beta, BUDGET, RTOL * beta)
    return k, float(np.linalg.norm(b - K @ x) / beta)


def two_level(K, block_lu, Z):
    """Multiplicative, coarse first: y = Z A_c^-1 Z^T r, then y + B^-1 (r - K y)."""
    t0 = time.perf_counter()
    coarse = spla.splu(sp.csc_matrix(Z.T @ K @ Z))
    seconds = time.perf_counter() - t0

    def precondition(r):
        y = Z @ coarse.solve(Z.T @ r)
        return y + block_lu.solve(r - K @ y)

    return precondition, coarse, seconds


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--state", type=Path, default=HERE / "data" / "lid515_jam.npz")
    p.add_argument("--dt", default="1e-5,1e-6,1e-4")
    args = p.parse_args()
    if not args.state.is_file():
        p.error(f"--state: no file {args.state}")
    name, scene, state = bn.state_case(args.state)
    contact = scene.contact
    contact.keep_feature_list(FEATURE_SKIN_GAPS * contact.law.activation_gap)
    candidates = contact.search(state.x, state.t)
    rhs = None
    print(f"{name}: GMRES iterations to {RTOL:g} (at most {BUDGET})")
    print(f"{'dt':>7} {'preconditioner':>12} {'it.':>4} {'residual':>9} {'coarse n':>8} {'LU nnz':>10} {'factor ms':>9}")
    for dt in (float(d) for d in args.dt.split(",")):
        a1, a4 = 1 / (bn.BETA * dt * dt), bn.GAMMA / (bn.BETA * dt)
        cr = contact.evaluate(state.x, state.t, candidates, state.history, v=state.v, a4=a4, tangent=True)
        el = scene.bodies.evaluate(state.x, tangent=True, mass_shift=a1, rotated_strain=0.0)
        system = newton_system(scene, el, cr, state.x, a1)
        K = system.to_csr()
        rhs = np.random.default_rng(0).normal(size=system.n) if rhs is None or len(rhs) != system.n else rhs
        shipped = make_linear_solver("grain-block")
        shipped.factor(system)
        x = shipped.solve(rhs, RTOL)
        print(f"{dt:7.0e} {'shipped':>12} {shipped.stats.last_iterations:4d} "
              f"{np.linalg.norm(rhs - K @ x) / np.linalg.norm(rhs):9.1e}")  # fmt: skip
        blocks = K - system.coupling if system.coupling is not None else K
        block_lu = spla.splu(sp.csc_matrix(blocks))
        k, res = gmres_iterations(K, block_lu.solve, rhs)
        print(f"{dt:7.0e} {'block LU':>12} {k:4d} {res:9.1e}")
        for label, affine in (("rigid 6", False), ("affine 12", True)):
            Z = coarse_modes(system.positions, system.dof_ptr // 3, affine)
            precondition, coarse, seconds = two_level(K, block_lu, Z)
            k, res = gmres_iterations(K, precondition, rhs)
            print(f"{dt:7.0e} {label:>12} {k:4d} {res:9.1e} {Z.shape[1]:8d} {coarse.L.nnz + coarse.U.nnz:10d} "
                  f"{seconds * 1e3:9.0f}")  # fmt: skip


if __name__ == "__main__":
    main()
