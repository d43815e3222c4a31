"""The linear-solver room: `make_linear_solver(name)` -> a solver of Newton systems.

    direct        dense LU (small) or SuperLU of the assembled matrix (direct.py)
    grain-block   GMRES + two-level grain-block preconditioner (grain_block.py)
    auto          direct up to DENSE_LIMIT dofs (a dense LU: a few grains), grain-block above
                  (measured: docs/linear-solvers.md)
"""

from .base import CountersCarried, LinearSolveDiverged, LinearSolver, NewtonSystem, SingularSystemError, SolverStats
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


class AutoSolver(CountersCarried):
    """Picks direct (dense LU) or grain-block per system by its size (the measured crossover), and
    hands a system to the direct solver when the grain-block path fails on it: a coarse matrix
    too ill-conditioned to factor, or GMRES not reaching its tolerance. Both were seen under a lid
    at the real density, where contacts at nanometre gaps are 1e2-1e3 times stiffer than the
    grains (docs/linear-solvers.md); the direct solve does not depend on that ratio.

    A failure is followed by like systems (a jammed pack stays jammed for many Newton iterations),
    and each costs GMRES its whole iteration budget before the direct solve: after a hand-over the
    next `hold` systems go straight to the direct solver. The hold doubles while the grain-block
    path keeps failing when tried again (up to MAX_HOLD) and falls back to HOLD when it succeeds."""

    name = "auto"
    HOLD = 4
    MAX_HOLD = 256

    def __init__(self, woodbury_dofs: int | None = None):
        self.direct, self.block = DirectSolver(), GrainBlockSolver(woodbury_max_dofs=woodbury_dofs)
        self.stats = self.block.stats
        self._current = self.block
        self._hold, self._skip = self.HOLD, 0

    def factor(self, system: NewtonSystem) -> None:
        self._system = system
        iterative = system.n > DENSE_LIMIT and system.n_bodies > 1
        if iterative and self._skip > 0:
            self._skip -= 1
            self.stats.held += 1
            iterative = False
        self._current = self.block if iterative else self.direct
        try:
            self._current.factor(system)
        except SingularSystemError:
            if self._current is self.direct:
                raise
            self.stats.last_iterations = 0
            self._fall_back()

    def forget(self) -> None:
        """The grain-block solver's kept coarse LU; the hold after a hand-over is kept (see above)."""
        self.block.forget()

    def carried(self) -> dict:
        """The hold spans steps, so a checkpoint carries it: a run resumed during a hold sends the
        same systems to the direct solver as the uninterrupted run, and continues to its bits."""
        return {**super().carried(), "hold": self._hold, "skip": self._skip}

    def carry_on(self, carried: dict) -> None:
        super().carry_on(carried)
        self._hold, self._skip = int(carried.get("hold", self.HOLD)), int(carried.get("skip", 0))

    def solve(self, rhs, rtol: float = 1e-10):
        if self._current is self.direct:
            self.stats.last_iterations = 0
            return self.direct.solve(rhs, rtol)
        try:
            x = self._current.solve(rhs, rtol)
        except (LinearSolveDiverged, SingularSystemError):  # the latter: a coarse matrix factorised in the solve
            self._fall_back()
            return self.direct.solve(rhs, rtol)
        self._hold = self.HOLD
        return x

    def _fall_back(self) -> None:
        self.stats.fallbacks += 1
        self._skip, self._hold = self._hold, min(2 * self._hold, self.MAX_HOLD)
        self._current = self.direct
        self.direct.factor(self._system)


def make_linear_solver(name: str = "auto", woodbury_dofs: int | None = None) -> LinearSolver:
    """woodbury_dofs: the grain-block solver's bound for its Woodbury path (None: the default,
    woodbury.WOODBURY_MAX_DOFS; 0: every block its LU)."""
    single_threaded_blas()
    if name == "direct":
        return DirectSolver()
    if name == "grain-block":
        return GrainBlockSolver(woodbury_max_dofs=woodbury_dofs)
    if name == "auto":
        return AutoSolver(woodbury_dofs)
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
