"""The grain-block coarse matrix (6 x 6 blocks per body and per coupled pair): dense LAPACK LU
against SuperLU, build + factorise + one solve, against the number of bodies (docs/linear-solvers.md).

    python benchmarks/bench_coarse.py [--bodies 16,24,40,64,100,150] [--neighbours 3] [--repeat 50]

The matrices are made like the Newton systems' coarse matrices (solver/linear/grain_block.py):
a diagonal block per body, two blocks per coupled pair (each body touching `--neighbours` others
on average, pairs drawn at random, seeded), diagonally dominant. One BLAS thread, as in a run.
Prints the best time of each path, their ratio, and the crossover that
grain_block.DENSE_COARSE_BODIES should sit at. Nothing is asserted; results in
docs/linear-solvers.md.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
from threadpoolctl import threadpool_limits

from vemdem.solver.linear.direct import superlu
from vemdem.solver.linear.grain_block import DENSE_COARSE_BODIES


def coarse_blocks(n_bodies: int, neighbours: float, rng):
    """(rows, cols, blocks) of a block-sparse coarse matrix, sorted by row then column."""
    pairs = set()
    while len(pairs) < int(neighbours * n_bodies / 2):
        a, b = rng.integers(0, n_bodies, 2)
        if a != b:
            pairs.add((min(a, b), max(a, b)))
    keys = [g * (n_bodies + 1) for g in range(n_bodies)] + [a * n_bodies + b for a, b in pairs]
    keys = np.array(sorted(keys + [b * n_bodies + a for a, b in pairs]))
    rows, cols = keys // n_bodies, keys % n_bodies
    blocks = 0.1 * rng.normal(size=(len(keys), 6, 6))
    blocks[rows == cols] += 10.0 * np.eye(6)
    return rows, cols, blocks


def best_ms(f, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        f()
        times.append(time.perf_counter() - t)
    return 1e3 * min(times)


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--bodies", default="16,24,40,64,100,150")
    p.add_argument("--neighbours", type=float, default=3.0)
    p.add_argument("--repeat", type=int, default=50)
    args = p.parse_args()
    rng = np.random.default_rng(0)
    print(f"{'bodies':>6} {'dense ms':>9} {'superlu ms':>10} {'dense/superlu':>13}")
    crossover = None
    with threadpool_limits(1, "blas"):
        for G in (int(n) for n in args.bodies.split(",")):
            rows, cols, blocks = coarse_blocks(G, args.neighbours, rng)
            rhs = np.ones(6 * G)

            def dense():
                A = np.zeros((G, 6, G, 6))
                A[rows, :, cols, :] = blocks
                return sla.lu_solve(sla.lu_factor(A.reshape(6 * G, 6 * G), check_finite=False), rhs,
                                    check_finite=False)  # fmt: skip

            def sparse():
                indptr = np.searchsorted(rows, np.arange(G + 1))
                return superlu(sp.bsr_matrix((blocks, cols, indptr), shape=(6 * G, 6 * G))).solve(rhs)

            assert np.allclose(dense(), sparse())  # the same system, both ways
            t_d, t_s = best_ms(dense, args.repeat), best_ms(sparse, args.repeat)
            if crossover is None and t_d > t_s:
                crossover = G
            print(f"{G:6d} {t_d:9.3f} {t_s:10.3f} {t_d / t_s:13.2f}")
    print(f"dense slower from {crossover} bodies on; grain_block.DENSE_COARSE_BODIES = {DENSE_COARSE_BODIES}")


if __name__ == "__main__":
    main()
