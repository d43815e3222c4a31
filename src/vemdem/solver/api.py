"""THE place where the integrator is chosen: typed solver options -> an `Integrator`.

Every integrator offers the same small interface to the time loop (driver/loop.py): an initial
state, `advance` to a time, its step control (checkpointed), and the energies measured the way it
integrates them (the explicit integrator's lumped mass, the implicit one's consistent mass).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from ..model.scene import Scene
from .defaults import NEWTON_ITERATIONS, RIGID_NEWTON_ITERATIONS, default
from .explicit import (FEATURE_SKIN_GAPS, ExplicitIntegrator, ExplicitParameters, advance_explicit,
                       explicit_initial_state)
from .linear import NAMES as LINEAR_SOLVERS
from .linear import make_linear_solver
from .newmark import NewmarkParameters, advance, initial_state
from .rigid import RigidExplicit
from .rigid_implicit import RigidNewmark
from .state import RunStats, State, StepControl

INTEGRATORS = ("implicit", "explicit")


@dataclass(frozen=True)
class SolverOptions:
    """The `[solver]` table, checked and typed (config/build.py makes it). Every default is the
    key's in the schema (config/tables.py, through solver/defaults.py); what each key does is
    documented there and in docs/reference/config.md."""

    integrator: str = default("integrator")
    beta: float = default("beta")
    gamma: float = default("gamma")
    dt: float = default("dt")
    dt_min: float = default("dt_min")
    dt_max: float = default("dt_max")
    max_iterations: int | None = default("max_iterations")  # None: the integrator's own budget
    newton_xtol: float = default("newton_xtol")  # implicit flexible: NewmarkParameters.xtol
    easy_iterations: int = default("easy_iterations")  # implicit flexible: StepControl
    grow_after: int = default("grow_after")  # implicit flexible: StepControl
    freeze_cycles: bool = default("freeze_cycles")
    break_stick_cycles: bool = default("break_stick_cycles")
    hold_damping_cycles: bool = default("hold_damping_cycles")
    rotated_tangent: float = default("rotated_tangent")
    woodbury_dofs: int = default("woodbury_dofs")
    impact_steps: float = default("impact_steps")  # implicit: StepControl
    entry_fraction: float = default("entry_fraction")  # implicit: StepControl
    energy_growth: float = default("energy_growth")
    safety: float = default("safety")
    mass_damping: float = default("mass_damping")
    linear: str = default("linear")  # implicit: linear solver of the Newton systems (solver/linear/)

    def __post_init__(self):
        if self.integrator not in INTEGRATORS:
            raise ValueError(f"integrator must be one of {INTEGRATORS}, got {self.integrator!r}")
        if self.linear not in LINEAR_SOLVERS:
            raise ValueError(f"linear must be one of {LINEAR_SOLVERS}, got {self.linear!r}")

    def newton_budget(self, rigid: bool) -> int:
        """Newton's iterations per step: `max_iterations`, or where not set the integrator's own
        (NEWTON_ITERATIONS; the rigid grains' quasi-Newton RIGID_NEWTON_ITERATIONS)."""
        if self.max_iterations is not None:
            return self.max_iterations
        return RIGID_NEWTON_ITERATIONS if rigid else NEWTON_ITERATIONS


class Integrator(Protocol):
    """What the time loop asks of an integrator: an initial state, `advance` to a time, its step control."""
    name: str
    lumped: bool  # energies with the lumped mass (the explicit integrator's own)
    control: StepControl
    # whether a run resumed from a checkpoint written between any two steps continues bit for bit
    # (driver/loop.py then checkpoints inside long frames too)
    checkpoints_inside_frames: bool

    def initial_state(self, x0=None, v0=None, history=None) -> State: ...

    def advance(self, state: State, t_end: float, on_step, stats: RunStats) -> tuple[State, RunStats]: ...

    def carried(self) -> dict:
        """What else a checkpoint holds, beyond state and step control, for a resumed run to go on
        as the uninterrupted one (JSON-able; `carry_on` takes it back)."""

    def carry_on(self, carried: dict) -> None: ...


class ImplicitNewmark:
    """Newmark + Newton on elements and contact (solver/newmark.py)."""

    name = "implicit"
    lumped = False
    checkpoints_inside_frames = True  # advance() keeps nothing between steps but state and control

    def __init__(self, scene: Scene, options: SolverOptions):
        self.scene = scene
        self.control = _control(options)
        self.params = NewmarkParameters(beta=options.beta, gamma=options.gamma,
                                        max_iterations=options.newton_budget(rigid=False), xtol=options.newton_xtol,
                                        mass_damping=options.mass_damping,
                                        linear=make_linear_solver(options.linear, options.woodbury_dofs),
                                        freeze_cycles=options.freeze_cycles,
                                        break_stick_cycles=options.break_stick_cycles,
                                        hold_damping_cycles=options.hold_damping_cycles,
                                        rotated_tangent=options.rotated_tangent)  # fmt: skip
        # Newton's iterates move grains a fraction of a gap between narrow phases (one per iteration):
        # on the 515-grain collapse the list takes the narrow phase from 23 to 8.5 ms per Newton
        # iteration, the same records (docs/contact.md)
        scene.contact.keep_feature_list(FEATURE_SKIN_GAPS * scene.contact.law.activation_gap)

    @property
    def linear_stats(self):
        """The linear solver's counters (factorisations, Krylov iterations, hand-overs) since the
        run started: checkpoints carry them (carried)."""
        return self.params.linear.stats

    def initial_state(self, x0=None, v0=None, history=None) -> State:
        return initial_state(self.scene, x0=x0, v0=v0, history=history, mass_damping=self.params.mass_damping)

    def advance(self, state, t_end, on_step, stats):
        return advance(self.scene, state, t_end, self.control, self.params, on_step, stats)

    def carried(self) -> dict:
        return {"linear": self.params.linear.carried()}  # auto's hold after a hand-over spans steps

    def carry_on(self, carried: dict) -> None:
        self.params.linear.carry_on(carried.get("linear", {}))


class ExplicitCentral:
    """Explicit central differences with lumped mass (solver/explicit.py)."""

    name = "explicit"
    lumped = True
    checkpoints_inside_frames = False  # advance() renews the pair search at each call
    integrator_class = ExplicitIntegrator

    def __init__(self, scene: Scene, options: SolverOptions):
        self.scene = scene
        self.control = _control(options)
        self.integrator = self.integrator_class(scene, ExplicitParameters(safety=options.safety,
                                                                          mass_damping=options.mass_damping))  # fmt: skip

    def initial_state(self, x0=None, v0=None, history=None) -> State:
        return explicit_initial_state(self.scene, self.integrator, x0=x0, v0=v0, history=history)

    def advance(self, state, t_end, on_step, stats):
        return advance_explicit(self.integrator, state, t_end, self.control, on_step, stats)

    def carried(self) -> dict:
        return {}  # advance() renews all it keeps at each call

    def carry_on(self, carried: dict) -> None:
        pass


class RigidCentral(ExplicitCentral):
    """Rigid grains: velocity Verlet + symplectic free rotation (solver/rigid.py). Energies with
    the consistent mass, exact for rigid motions."""

    lumped = False
    integrator_class = RigidExplicit

    def initial_state(self, x0=None, v0=None, history=None) -> State:
        return self.integrator.initial_state(x0, v0, history=history)


class RigidImplicit(RigidCentral):
    """Rigid grains, implicit: Newmark on centroids and angular momenta, the exact free rotation,
    Newton on six dofs per grain (solver/rigid_implicit.py), in the explicit loop's step control."""

    name = "implicit"

    def __init__(self, scene: Scene, options: SolverOptions):
        self.scene = scene
        self.control = _control(options)
        self.integrator = RigidNewmark(scene, ExplicitParameters(mass_damping=options.mass_damping),
                                       beta=options.beta, gamma=options.gamma,
                                       max_iterations=options.newton_budget(rigid=True),
                                       break_stick_cycles=options.break_stick_cycles,
                                       hold_damping_cycles=options.hold_damping_cycles)  # fmt: skip

    def advance(self, state, t_end, on_step, stats):
        # the step to try next lives in the (checkpointed) control between calls, not cut short
        # to land on t_end, so that a resumed run takes the same steps
        self.integrator.next_dt = self.control.dt
        state, stats = advance_explicit(self.integrator, state, t_end, self.control, on_step, stats)
        self.control.dt = min(self.integrator.next_dt, self.control.dt_max)
        return state, stats


def _control(o: SolverOptions) -> StepControl:
    return StepControl(dt=o.dt, dt_min=o.dt_min, dt_max=o.dt_max, impact_steps=o.impact_steps,
                       entry_fraction=o.entry_fraction, energy_growth=o.energy_growth,
                       easy_iterations=o.easy_iterations, grow_after=o.grow_after)  # fmt: skip


def make_integrator(options: SolverOptions, scene: Scene) -> Integrator:
    """The integrator for these options and this scene's body model (flexible or rigid grains, implicit or explicit)."""
    if scene.bodies.kind == "rigid":
        return RigidCentral(scene, options) if options.integrator == "explicit" else RigidImplicit(scene, options)
    if options.integrator == "explicit":
        return ExplicitCentral(scene, options)
    return ImplicitNewmark(scene, options)


def kinetic_energy(scene: Scene, integrator: Integrator, v: np.ndarray, x: np.ndarray | None = None) -> float:
    """The grains' kinetic energy with the integrator's own mass (lumped for the explicit one;
    with x, selectively scaled where the grains are: Scene.kinetic_energy)."""
    return scene.kinetic_energy(v, integrator.lumped, x)
