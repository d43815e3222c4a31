"""The grain-block solver's rotated-block Woodbury path against every block's LU, by the number of
dofs the contacts touch per grain (docs/linear-solvers.md; solver/linear/woodbury.py).

    python benchmarks/bench_woodbury.py [--grains 515] [--vertices 30] [--touched 0,12,21,33,39,48,60] [--repeat 7]

Random grains of the shipped block structure: each grain's reference tangent K_g symmetric
positive semi-definite with the rigid modes of its reference vertices as null space, a consistent-
like mass M_g, a random rotation R_g, and contact terms (random, non-symmetric) on k dofs of
whole vertices, so that B_g = Q (K_g + s M_g) Q^T + E_T C_TT E_T^T exactly as the Newton
matrices of grains near a rigid motion are made (no coupling between grains: the block part is
what is measured). For each k the shipped GrainBlockSolver factorises the system and applies its
preconditioner once with `woodbury_max_dofs` = k (every grain on the Woodbury path) and = 0 (every
grain's LU); best of `--repeat`, milliseconds, with the threads numba is given. Both GMRES
solutions are checked against each other. Nothing is asserted; results in docs/linear-solvers.md.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from vemdem.model.bodies import RotationReference
from vemdem.solver.linear import GrainBlockSolver, NewtonSystem, rigid_modes


def grains_system(n_grains: int, nv: int, k: int, shift: float, rng) -> NewtonSystem:
    n = 3 * nv
    vertex_ptr = np.arange(n_grains + 1, dtype=np.int64) * nv
    dof_ptr, block_ptr = 3 * vertex_ptr, np.arange(n_grains + 1, dtype=np.int64) * n * n
    X = rng.normal(size=(n_grains * nv, 3)) + np.repeat(10.0 * np.arange(n_grains)[:, None], nv, axis=0)
    z_ref = rigid_modes(X, vertex_ptr)
    tangent, mass = np.empty(block_ptr[-1]), np.empty(n_grains * nv * nv)
    blocks, x = np.empty(block_ptr[-1]), np.empty_like(X)
    rotations = np.empty((n_grains, 3, 3))
    touched = np.zeros(n_grains * nv, np.bool_)
    for g in range(n_grains):
        d = slice(dof_ptr[g], dof_ptr[g + 1])
        Z = z_ref[d]
        P = np.eye(n) - Z @ np.linalg.solve(Z.T @ Z, Z.T)  # K Z_ref = 0: a free grain's tangent
        A = rng.normal(size=(n, n))
        K = P @ (A @ A.T) @ P
        m = 0.1 * rng.random((nv, nv))
        M = m @ m.T + np.eye(nv)
        R = np.linalg.qr(rng.normal(size=(3, 3)))[0]
        Q = np.kron(np.eye(nv), R)
        B = Q @ (K + shift * np.kron(M, np.eye(3))) @ Q.T
        verts = np.sort(rng.choice(nv, k // 3, replace=False))
        T = (3 * verts[:, None] + np.arange(3)).ravel()
        B[np.ix_(T, T)] += 0.1 * shift * rng.normal(size=(len(T), len(T)))
        tangent[block_ptr[g] : block_ptr[g + 1]] = K.ravel()
        mass[g * nv * nv : (g + 1) * nv * nv] = M.ravel()
        blocks[block_ptr[g] : block_ptr[g + 1]] = B.ravel()
        rotations[g] = R
        touched[vertex_ptr[g] + verts] = True
        x[vertex_ptr[g] : vertex_ptr[g + 1]] = X[vertex_ptr[g] : vertex_ptr[g + 1]] @ R.T
    reference = RotationReference(tangent, mass, vertex_ptr * nv, X, vertex_ptr, block_ptr)
    return NewtonSystem(blocks, block_ptr, dof_ptr, None, x, rotated=np.ones(n_grains, np.bool_),
                        rotations=rotations, touched=touched, mass_shift=shift, reference=reference)  # fmt: skip


def best(f, repeat: int) -> float:
    f()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        f()
        times.append(time.perf_counter() - t0)
    return 1e3 * min(times)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--grains", type=int, default=515)
    ap.add_argument("--vertices", type=int, default=30)
    ap.add_argument("--touched", default="0,12,21,33,39,48,60", help="dofs touched by contacts per grain (k)")
    ap.add_argument("--repeat", type=int, default=7)
    args = ap.parse_args(argv)
    rng = np.random.default_rng(1)
    print(f"{args.grains} grains of {args.vertices} vertices; best of {args.repeat}, ms")
    print(f"{'k':>3} | {'LU factor':>9} | {'Woodbury':>8} | {'ratio':>5} | {'LU apply':>8} | {'Woodbury':>8} | "
          f"{'ratio':>5} | solutions agree")  # fmt: skip
    for k in [int(v) for v in args.touched.split(",")]:
        system = grains_system(args.grains, args.vertices, k, 1e3, rng)
        r = rng.normal(size=system.n)
        row, solutions = [], []
        for bound in (0, max(k, 1)):
            solver = GrainBlockSolver(woodbury_max_dofs=bound)
            row.append(best(lambda: (solver.forget(), solver.factor(system)), args.repeat))
            row.append(best(lambda: solver.precondition(r), args.repeat))
            solutions.append(solver.solve(r, 1e-10))
        agree = np.abs(solutions[0] - solutions[1]).max() / np.abs(solutions[0]).max()
        print(f"{k:3d} | {row[0]:9.2f} | {row[2]:8.2f} | {row[2] / row[0]:5.2f} | {row[1]:8.2f} | {row[3]:8.2f} | "
              f"{row[3] / row[1]:5.2f} | {agree:.1e}")  # fmt: skip


if __name__ == "__main__":
    main()
