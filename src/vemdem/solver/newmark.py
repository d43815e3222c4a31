"""Implicit Newmark time stepping with full Newton on elements + contact (formulation.md 5).

    a = a1 du - a2 v_n - a3 a_n,   v = a4 du + a5 v_n + a6 a_n,   du = x - x_n
    a1 = 1/(beta dt^2), a2 = 1/(beta dt), a3 = 1/(2 beta) - 1,
    a4 = gamma/(beta dt), a5 = 1 - gamma/beta, a6 = dt (1 - gamma/(2 beta))
    R(x) = M a + f_int(x) + r_contact(x, v) - f_gravity = 0,   K = a1 M + K_int + K_contact

Every Newton update is shortened, if needed, so that no vertex can reach another grain or a wall
within the step (a conservative continuous-collision bound: the distance between two grains is at
least their smallest active gap, or the activation gap when none is active), so an accepted state
never crosses the barrier. A step is rejected when Newton does not converge, a value is not finite,
or the search at the end of the step finds a new pair already inside the activation gap.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..contact.law import normal_stiffness
from ..contact.model import ContactHistory, PenetrationError
from ..contact.pairs import GAP, GRAIN_A, GRAIN_B, find_contacts
from ..scene import Scene
from ..vem.element import InvertedElementError, evaluate, tangent_matrix
from .linear import solve


class StepRejected(RuntimeError):
    """This step cannot be accepted; the caller restores the state and halves the step."""


@dataclass
class NewmarkParameters:
    beta: float = 0.3
    gamma: float = 0.5
    rtol: float = 1e-6  # residual, relative to the largest of gravity, inertia and contact forces
    xtol: float = 1e-8  # correction, relative to the step's displacement (floor: 1e-6 grain size)
    max_iterations: int = 15
    ccd_fraction: float = 0.8  # share of the free distance a Newton update may use
    mass_damping: float = 0.0  # alpha (1/s): Rayleigh mass-proportional damping force alpha M v


@dataclass
class State:
    t: float
    x: np.ndarray
    v: np.ndarray
    a: np.ndarray
    history: ContactHistory = field(default_factory=ContactHistory.empty)
    dissipated: float = 0.0
    power: float = 0.0

    def copy(self) -> "State":
        return replace(self, x=self.x.copy(), v=self.v.copy(), a=self.a.copy())


@dataclass
class StepInfo:
    iterations: int
    n_contacts: int
    contact_energy: float
    strain_energy: float
    wall_reactions: np.ndarray
    ints: np.ndarray
    floats: np.ndarray
    contact: object = None  # the ContactResult at the accepted state (frames write it)


def initial_state(scene: Scene, x0=None, v0=None, t0: float = 0.0) -> State:
    """Rest or prescribed velocities; the initial acceleration solves M a0 = f_g - f_int - r_c."""
    x = scene.elements.reference.copy() if x0 is None else np.array(x0, float)
    v = np.zeros_like(x) if v0 is None else np.array(v0, float)
    f_int = evaluate(scene.elements, x).force
    cand = scene.contact.search(x, t0)
    contact = scene.contact.evaluate(x, t0, cand, v=v)
    rhs = (scene.gravity_force() - f_int - contact.force).ravel()
    a = solve(scene.mass_matrix(), rhs).reshape(-1, 3)
    return State(t0, x, v, a, contact.trial_history)


def free_distance_ratio(scene: Scene, dx, ints, floats):
    """Largest alpha such that x + alpha dx cannot bring two surfaces (grains, walls) into contact
    (conservative advancement): two surfaces with active pairs are at least their smallest active
    gap apart; any other two are at least the activation gap apart."""
    G = scene.n_grains
    gbar = scene.contact.law.activation_gap
    step = np.linalg.norm(dx, axis=1)
    grain_step = np.maximum.reduceat(step, scene.elements.vertex_ptr[:-1])
    n_surfaces = len(scene.contact.topology.grain_vertex_ptr) - 1 + len(scene.contact.planes)
    disp = np.concatenate([grain_step, np.zeros(n_surfaces - G)])  # walls move between steps only
    ratio = np.inf
    if len(ints):
        move = disp[ints[:, GRAIN_A]] + disp[ints[:, GRAIN_B]]
        moving = move > 0
        if moving.any():
            ratio = float(np.min(floats[moving, GAP] / move[moving]))
    top2 = np.sort(disp)[-2:].sum() if n_surfaces > 1 else 0.0
    if top2 > 0:
        ratio = min(ratio, gbar / top2)
    return ratio


def newmark_step(scene: Scene, state: State, dt: float, params: NewmarkParameters) -> tuple[State, StepInfo]:
    b, gam = params.beta, params.gamma
    a1, a2, a3 = 1 / (b * dt * dt), 1 / (b * dt), 1 / (2 * b) - 1
    a4, a5, a6 = gam / (b * dt), 1 - gam / b, dt * (1 - gam / (2 * b))
    t1 = state.t + dt
    M = scene.mass_matrix()
    f_grav = scene.gravity_force().ravel()
    contact = scene.contact
    # search once per step, widened by twice the predicted travel so that pairs the step closes in on
    # are candidates from the start (without it, a grain could only creep towards the gap)
    travel = np.sqrt(np.max(np.sum((state.v * dt + 0.5 * state.a * dt * dt) ** 2, axis=1), initial=0.0))
    candidates = contact.search(state.x, t1, margin=2.0 * travel)
    x = state.x.copy()
    size = float(np.cbrt(scene.elements.volume.mean()))
    for it in range(1, params.max_iterations + 1):
        du = x - state.x
        acc = a1 * du - a2 * state.v - a3 * state.a
        vel = a4 * du + a5 * state.v + a6 * state.a
        try:
            el = evaluate(scene.elements, x, tangent=True)
            cr = contact.evaluate(x, t1, candidates, state.history, v=vel, a4=a4, tangent=True)
        except (InvertedElementError, PenetrationError) as exc:
            raise StepRejected(str(exc)) from None
        inertia = M @ (acc.ravel() + params.mass_damping * vel.ravel())
        R = inertia + el.force.ravel() + cr.force.ravel() - f_grav
        if not np.all(np.isfinite(R)):
            raise StepRejected("non-finite residual")
        scale = max(np.abs(f_grav).max(), np.abs(inertia).max(), np.abs(cr.force).max(), 1e-300)
        K = (a1 + params.mass_damping * a4) * M + tangent_matrix(scene.elements, el.blocks) + cr.tangent
        dx = -solve(K, R).reshape(-1, 3)
        alpha = min(1.0, params.ccd_fraction * free_distance_ratio(scene, dx, cr.ints, cr.floats))
        x = x + alpha * dx
        # With E ~ 1e11 Pa the internal forces carry round-off far above the gravity of a grain, so
        # the residual test alone can be out of reach: a full Newton correction that is tiny against
        # the step's displacement (quadratic convergence) also ends the iteration.
        small_r = np.abs(R).max() <= params.rtol * scale
        small_dx = np.abs(dx).max() <= params.xtol * max(np.abs(du).max(), 1e-6 * size)
        if alpha == 1.0 and small_dx and (small_r or it > 1):
            break
    else:
        raise StepRejected(f"Newton did not converge in {params.max_iterations} iterations")
    du = x - state.x
    acc = a1 * du - a2 * state.v - a3 * state.a
    vel = a4 * du + a5 * state.v + a6 * state.a
    try:
        el = evaluate(scene.elements, x)
        cr = contact.evaluate(x, t1, candidates, state.history, v=vel, a4=a4)
    except (InvertedElementError, PenetrationError) as exc:
        raise StepRejected(str(exc)) from None
    _night_owl_check(scene, x, t1, candidates)
    power = cr.dissipation_power + params.mass_damping * 2.0 * scene.kinetic_energy(vel)
    new = State(t1, x, vel, acc, cr.trial_history, state.dissipated + 0.5 * dt * (state.power + power), power)
    info = StepInfo(it, cr.n_contacts, cr.energy, el.total_energy, cr.wall_reactions, cr.ints, cr.floats, cr)
    return new, info


def _night_owl_check(scene: Scene, x, t, candidates):
    """A pair that appears only in the end-of-step search and is already inside the activation gap
    was missed during the step: reject it (formulation.md 4.5)."""
    fresh = scene.contact.search(x, t)
    if len(fresh) == 0:
        return
    width = int(max(fresh.max(), candidates.max() if len(candidates) else 0)) + 1
    new = fresh[~np.isin(fresh[:, 0] * width + fresh[:, 1], candidates[:, 0] * width + candidates[:, 1])]
    if len(new) == 0:
        return
    ints, _ = find_contacts(scene.contact.all_positions(x, t), new, scene.contact.topology,
                            scene.contact.law.activation_gap)  # fmt: skip
    if len(ints):
        raise StepRejected(f"{len(ints)} contact pairs appeared inside the activation gap during the step")


class TimeStepTooSmall(RuntimeError):
    pass


@dataclass
class StepControl:
    """Adaptive step (formulation.md 5): halve on rejection, grow after easy steps."""

    dt: float = 1e-5
    dt_min: float = 1e-10
    dt_max: float = 1e-4
    grow: float = 1.5
    # a step is "easy" when Newton converged in at most this many iterations: settling packs need
    # 5-8 on the barrier law, so a smaller bound never let the step grow back after a rejection
    # (measured with benchmarks/bench_dynamics.py, docs/dynamics.md)
    easy_iterations: int = 8
    grow_after: int = 3
    easy_streak: int = 0  # state: consecutive easy steps so far (kept here so a resumed run continues exactly)
    impact_steps: float = 0.0  # > 0: impact step control on (formulation.md 5), see step_limit
    entry_fraction: float = 0.05  # share of the activation gap a pair may enter in one step

    def step_limit(self, scene: Scene, state: State) -> float:
        """Contact-impact step control (formulation.md 5), from the state at the start of a step:
        - an approaching pair (rate -dg/dt) may close at most `entry_fraction` f of the activation
          gap inside the layer in one step: dt <= (max(g - gbar, 0) + f gbar) / (-dg/dt);
        - an active pair resolves half its contact oscillation in `impact_steps` steps:
          dt <= pi sqrt(m_eq / k(g)) / N_impact, k(g) the stiffness at the current gap.
        Without it a step may jump deep into the layer, where the trapezoidal rule's energy error
        at a stiff nonlinear spring is largest (measured in docs/dynamics.md). Floor: 10 dt_min."""
        if self.impact_steps <= 0:
            return np.inf
        contact = scene.contact
        gbar = contact.law.activation_gap
        wall_speed = max((np.linalg.norm(w.motion.velocity(state.t)) for w in contact.planes + contact.meshes),
                         default=0.0)  # fmt: skip
        speed = np.sqrt(np.max(np.sum(state.v**2, axis=1))) + wall_speed
        gap, rate, m_eq = contact.approaching(state.x, state.v, state.t, gbar + 2.0 * speed * self.dt_max)
        limit = np.inf
        closing = rate < 0
        if closing.any():
            depth = np.maximum(gap[closing] - gbar, 0.0) + self.entry_fraction * gbar
            limit = np.min(depth / -rate[closing])
        k = normal_stiffness(np.ascontiguousarray(gap), contact.law_params)
        loaded = k > 0
        if loaded.any():
            limit = min(limit, np.pi * np.sqrt(np.min(m_eq[loaded] / k[loaded])) / self.impact_steps)
        return max(limit, 10.0 * self.dt_min)


@dataclass
class RunStats:
    accepted: int = 0
    rejected: int = 0
    newton_iterations: int = 0
    last_rejection: str = ""


def advance(scene: Scene, state: State, t_end: float, control: StepControl, params: NewmarkParameters,
            on_step=None, stats: RunStats | None = None) -> tuple[State, RunStats]:  # fmt: skip
    """Integrate from state.t to t_end; on_step(state, info, dt) after each accepted step."""
    stats = stats or RunStats()
    limit = control.step_limit(scene, state)
    while state.t < t_end * (1 - 1e-12):
        h = min(control.dt, limit, t_end - state.t)
        try:
            new, info = newmark_step(scene, state, h, params)
        except (StepRejected, np.linalg.LinAlgError) as exc:
            stats.rejected += 1
            stats.last_rejection = str(exc)
            control.dt = 0.5 * h
            control.easy_streak = 0
            if control.dt < control.dt_min:
                raise TimeStepTooSmall(
                    f"time step {control.dt:.3g} s fell below the minimum {control.dt_min:.3g} s at t = {state.t:.6g} s "
                    f"(last rejection: {exc})"
                ) from None
            continue
        state = new
        limit = control.step_limit(scene, state)
        stats.accepted += 1
        stats.newton_iterations += info.iterations
        control.easy_streak = control.easy_streak + 1 if info.iterations <= control.easy_iterations else 0
        if control.easy_streak >= control.grow_after and h == control.dt:
            control.dt = min(control.dt * control.grow, control.dt_max)
            control.easy_streak = 0
        if on_step is not None:
            on_step(state, info, h)
    return state, stats
