"""What an integrator carries from step to step, and what it reports.

`State` is the whole dynamic state of a run (a checkpoint writes exactly these arrays, so a resumed
run continues bit for bit); `StepControl` the adaptive step (docs/dynamics.md: halve on rejection,
grow after easy steps); `RunStats` the counters every summary reports.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..contact.model import ContactHistory
from .defaults import default


class StepRejected(RuntimeError):
    """This step cannot be accepted; the caller restores the state and halves the step."""


class TimeStepTooSmall(RuntimeError):
    """The step fell below dt_min: the run stops with the cause of the last rejection."""


@dataclass
class State:
    """The whole dynamic state of a run at time `t`: positions, velocities, friction history, energy books."""
    t: float
    x: np.ndarray  # body coordinates (flexible grains: vertex positions, (N, 3))
    v: np.ndarray
    a: np.ndarray
    history: ContactHistory = field(default_factory=ContactHistory.empty)
    dissipated: float = 0.0
    power: float = 0.0
    # body-model coordinates beyond the vertices (rigid grains: centre, rotation, velocity,
    # momentum, force, torque); checkpoints save them too
    bodies: dict = field(default_factory=dict)

    def copy(self) -> "State":
        return replace(self, x=self.x.copy(), v=self.v.copy(), a=self.a.copy(),
                       bodies={k: v.copy() for k, v in self.bodies.items()})  # fmt: skip


@dataclass
class StepInfo:
    """What an accepted step reports: Newton iterations, contacts, energies and the walls' reactions."""
    iterations: int
    n_contacts: int
    contact_energy: float
    strain_energy: float
    wall_reactions: np.ndarray
    ints: np.ndarray
    floats: np.ndarray
    contact: object = None  # the ContactResult at the accepted state (frames write it)
    krylov_iterations: int = 0  # linear-solver iterations of the step (iterative solvers)
    frozen_pairs: int = 0  # implicit: pairs Newton kept in its set for cycling (NewmarkParameters.freeze_cycles)
    broken_pairs: int = 0  # implicit: pairs judged by mu_d after stick-slip cycles (break_stick_cycles)
    undamped_pairs: int = 0  # implicit: pairs undamped after cycles on the damping's clamp (hold_damping_cycles)
    tangent_blocks: int = 0  # implicit: grain blocks of the step's Newton matrices
    exact_blocks: int = 0  # implicit: of those, the exact element tangent's (not rotated: rotated_tangent)


@dataclass
class StepControl:
    """Adaptive step (docs/dynamics.md): halve on rejection, grow after easy steps. The defaults
    are the `[solver]` keys' (config/tables.py)."""

    dt: float = default("dt")
    dt_min: float = default("dt_min")
    dt_max: float = default("dt_max")
    grow: float = 1.5
    # a step is "easy" when Newton converged in at most this many iterations: settling packs need
    # 5-8 on the barrier law, so a smaller bound never let the step grow back after a rejection
    # (measured with benchmarks/bench_dynamics.py, docs/dynamics.md)
    easy_iterations: int = default("easy_iterations")
    grow_after: int = default("grow_after")
    easy_streak: int = 0  # state: consecutive easy steps so far (kept here so a resumed run continues exactly)
    impact_steps: float = default("impact_steps")  # > 0: contact-impact step control on (docs/dynamics.md)
    # implicit, impact control: share of the activation gap an approaching pair may close per step
    entry_fraction: float = default("entry_fraction")
    energy_growth: float = default("energy_growth")  # implicit: largest energy gain of a step, in sum m g d (0: off)

    def rejected(self, h: float, t: float, cause: BaseException) -> None:
        """A step of length h from time t was rejected: the next try is half as long, and none may
        be below dt_min (TimeStepTooSmall, naming the cause)."""
        self.dt = 0.5 * h
        self.easy_streak = 0
        if self.dt < self.dt_min:
            raise TimeStepTooSmall(f"time step {self.dt:.3g} s fell below the minimum {self.dt_min:.3g} s at "
                                   f"t = {t:.6g} s (last rejection: {cause})") from None

    def accepted(self, h: float, iterations: int) -> None:
        """A step of length h was accepted after `iterations` Newton iterations: after grow_after
        easy steps in a row at the full step, the step grows by `grow` (up to dt_max)."""
        self.easy_streak = self.easy_streak + 1 if iterations <= self.easy_iterations else 0
        if self.easy_streak >= self.grow_after and h == self.dt:
            self.dt = min(self.dt * self.grow, self.dt_max)
            self.easy_streak = 0


@dataclass
class RunStats:
    """The counters every summary reports: steps accepted and rejected (by cause), Newton and Krylov iterations."""
    accepted: int = 0
    rejected: int = 0
    newton_iterations: int = 0
    krylov_iterations: int = 0
    last_rejection: str = ""
    energy_gains: int = 0  # implicit: steps accepted although the energy grew (below 1e-3 dt_max, or not shrunk by halving)
    frozen_pair_steps: int = 0  # implicit: steps that converged with cycling pairs kept (freeze_cycles)
    stick_break_steps: int = 0  # implicit: steps with pairs judged by mu_d after stick-slip cycles (break_stick_cycles)
    damping_hold_steps: int = 0  # implicit: steps with pairs undamped after cycles on the damping's clamp
    tangent_blocks: int = 0  # implicit: grain blocks of the accepted steps' Newton matrices
    exact_tangent_blocks: int = 0  # implicit: of those, the exact element tangent's (rotated_tangent)
    rejections: dict = field(default_factory=dict)  # rejected steps by cause (rejection_cause)

    def accept(self, info: StepInfo) -> None:
        """Count an accepted step and what its Newton needed (an explicit step: no iterations, no rules)."""
        self.accepted += 1
        self.newton_iterations += info.iterations
        self.krylov_iterations += info.krylov_iterations
        self.frozen_pair_steps += info.frozen_pairs > 0
        self.stick_break_steps += info.broken_pairs > 0
        self.damping_hold_steps += info.undamped_pairs > 0
        self.tangent_blocks += info.tangent_blocks
        self.exact_tangent_blocks += info.exact_blocks

    def reject(self, exc: BaseException) -> None:
        """Count a rejected step under its cause."""
        self.rejected += 1
        self.last_rejection = str(exc)
        cause = rejection_cause(exc)
        self.rejections[cause] = self.rejections.get(cause, 0) + 1


def rejection_cause(exc: BaseException) -> str:
    """A short name for why a step was rejected (summary.json "rejections")."""
    text = str(exc)
    for cause, marker in (("newton", "Newton did not converge"), ("energy", "total energy grew"),
                          ("missed_pairs", "appeared inside the activation gap"), ("behind_wall", "behind wall"),
                          ("inverted_element", "invert"), ("gap_closed", "gap closed"), ("non_finite", "non-finite")):  # fmt: skip
        if marker in text:
            return cause
    return "linear_solver" if isinstance(exc, ArithmeticError) else "other"
