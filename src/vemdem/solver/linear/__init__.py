"""The linear-solver room: `make_linear_solver(name)` -> a solver of Newton systems.

    direct        dense LU (small) or SuperLU of the assembled matrix (direct.py)
    grain-block   GMRES + two-level grain-block preconditioner (grain_block.py)
    auto          direct up to DENSE_LIMIT dofs (a dense LU: a few grains), grain-block above
                  (measured: docs/linear-solvers.md)
"""

from .base import LinearSolveDiverged, LinearSolver, NewtonSystem, SingularSystemError, SolverStats
from .direct import DENSE_LIMIT, DirectSolver, pypardiso, solve, sparse_backend
from .grain_block import GrainBlockSolver, rigid_modes

NAMES = ("auto", "direct", "grain-block")

_BLAS_LIMIT = []


def single_threaded_blas() -> None:
    """Run BLAS/LAPACK on one thread from now on, once per process. The Newton loop alternates
    compiled parallel kernels (numba's threads) with small LAPACK calls; OpenBLAS's own threads
    keep spinning between calls and take the cores from numba's: a 64-grain implicit slump ran 4x
    slower (10.1 s against 2.5 s, docs/linear-solvers.md). Our dense problems are small (a
    grain's block, the coarse matrix of a few hundred unknowns), so one thread loses nothing."""
    if not _BLAS_LIMIT:
        from threadpoolctl import threadpool_limits

        _BLAS_LIMIT.append(threadpool_limits(limits=1, user_api="blas"))


class AutoSolver:
    """Picks direct (dense LU) or grain-block per system by its size (the measured crossover), and
    hands a system to the direct solver when the grain-block path fails on it: a coarse matrix
    too ill-conditioned to factor, or GMRES not reaching its tolerance. Both were seen under a lid
    at the real density, where contacts at nanometre gaps are 1e2-1e3 times stiffer than the
    grains (docs/linear-solvers.md); the direct solve does not depend on that ratio."""

    name = "auto"

    def __init__(self):
        self.direct, self.block = DirectSolver(), GrainBlockSolver()
        self.stats = self.block.stats
        self._current = self.block

    def factor(self, system: NewtonSystem) -> None:
        self._system = system
        self._current = self.block if system.n > DENSE_LIMIT and system.n_bodies > 1 else self.direct
        try:
            self._current.factor(system)
        except SingularSystemError:
            if self._current is self.direct:
                raise
            self.stats.last_iterations = 0
            self._fall_back()

    def solve(self, rhs, rtol: float = 1e-10):
        try:
            return self._current.solve(rhs, rtol)
        except LinearSolveDiverged:
            self._fall_back()
            return self.direct.solve(rhs, rtol)

    def _fall_back(self) -> None:
        self.stats.fallbacks += 1
        self._current = self.direct
        self.direct.factor(self._system)


def make_linear_solver(name: str = "auto") -> LinearSolver:
    single_threaded_blas()
    if name == "direct":
        return DirectSolver()
    if name == "grain-block":
        return GrainBlockSolver()
    if name == "auto":
        return AutoSolver()
    raise ValueError(f"linear solver must be one of {NAMES}, got {name!r}")


__all__ = [
    "DENSE_LIMIT",
    "NAMES",
    "AutoSolver",
    "DirectSolver",
    "GrainBlockSolver",
    "LinearSolveDiverged",
    "LinearSolver",
    "NewtonSystem",
    "SingularSystemError",
    "SolverStats",
    "make_linear_solver",
    "single_threaded_blas",
    "pypardiso",
    "rigid_modes",
    "solve",
    "sparse_backend",
]
