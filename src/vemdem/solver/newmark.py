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

from dataclasses import dataclass

import numpy as np

from ..contact.ccd import (
    free_distance_ratio,
    impact_step_limit,
    missed_pairs,
    pairwise_distance_ratio,
    plane_distances,
    surface_displacements,
)
from ..contact.model import PenetrationError
from ..model.bodies import InvertedElementError
from ..model.motion import RigidRetraction
from ..model.scene import Scene
from .linear import NewtonSystem, make_linear_solver, solve
from .state import RunStats, State, StepControl, StepInfo, StepRejected, TimeStepTooSmall

__all__ = ["NewmarkParameters", "advance", "initial_state", "newmark_step", "step_limit"]


@dataclass
class NewmarkParameters:
    beta: float = 0.3
    gamma: float = 0.5
    rtol: float = 1e-6  # residual, relative to the largest of gravity, inertia and contact forces
    xtol: float = 1e-8  # correction, relative to the step's displacement (floor: 1e-6 grain size)
    max_iterations: int = 15
    ccd_fraction: float = 0.8  # share of the free distance a Newton update may use
    mass_damping: float = 0.0  # alpha (1/s): Rayleigh mass-proportional damping force alpha M v
    predictor: str = "rest"  # first iterate: "rest" (x_n) or "acceleration" (x_n + dt v_n + dt^2/2 a_n, CCD-bounded)
    linear: object = None  # a solver.linear LinearSolver, made once per run (None: "auto")
    krylov_rtol: float = 1e-8  # relative residual of iterative linear solves (inexact Newton)
    line_search: bool = False  # backtrack on the incremental potential (IPC's merit) while the update is large
    ccd: str = "global"  # Newton update bound: "global" (one bound for all pairs) or "pairwise" (contact.ccd)
    accuracy: float = 0.0  # > 0: converged when a1 |dx| <= accuracy |g| (the step's own accuracy); 0: strict test
    trace: object = None  # callable(iteration, residual / tolerance, correction / tolerance, alpha): diagnostics
    update: str = "rigid"  # "rigid": each grain's rigid part as a finite rotation (model.motion); "linear": x + alpha dx


def initial_state(scene: Scene, x0=None, v0=None, t0: float = 0.0) -> State:
    """Rest or prescribed velocities; the initial acceleration solves M a0 = f_g - f_int - r_c."""
    x = scene.bodies.reference.copy() if x0 is None else np.array(x0, float)
    v = np.zeros_like(x) if v0 is None else np.array(v0, float)
    f_int = scene.bodies.evaluate(x).force
    cand = scene.contact.search(x, t0)
    contact = scene.contact.evaluate(x, t0, cand, v=v)
    rhs = (scene.gravity_force() - f_int - contact.force).ravel()
    a = solve(scene.mass_matrix(), rhs).reshape(-1, 3)
    return State(t0, x, v, a, contact.trial_history)


def _n_surfaces(scene: Scene) -> int:
    return len(scene.contact.topology.grain_vertex_ptr) - 1 + len(scene.contact.planes)




class _UpdatePath:
    """One Newton update dx at x: `at(alpha)` the positions after alpha of it, and every surface's
    motion bound at alpha = 1 as contact.ccd wants it (trans, spread; walls: 0)."""

    def __init__(self, scene: Scene, x, dx, update: str):
        vptr = scene.bodies.vertex_ptr
        n_walls = _n_surfaces(scene) - scene.bodies.n_bodies
        if update == "linear":
            self.at = lambda alpha: x + alpha * dx
            spread = surface_displacements(dx, vptr, scene.bodies.n_bodies)
            trans = np.zeros((len(spread), 3))
        else:
            move = RigidRetraction(x, dx, scene.bodies.lumped, vptr)
            self.at = move.at
            spread = move.bounds - np.linalg.norm(move.t, axis=1)
            trans = move.t
        self.trans = np.concatenate([trans, np.zeros((n_walls, 3))])
        self.spread = np.concatenate([spread, np.zeros(n_walls)])


def _ccd_ratio(scene: Scene, path: _UpdatePath, mode: str, ints, floats, du, x, t, candidates, margin) -> float:
    """contact.ccd's bound on the share of an update that keeps every pair apart: one bound for
    the scene ("global") or one per pair ("pairwise"; du: the step's displacement so far, for
    pairs outside the step's search)."""
    contact = scene.contact
    gbar = contact.law.activation_gap
    if mode != "pairwise":
        return free_distance_ratio(path.trans, path.spread, ints, floats, gbar)
    vptr = scene.bodies.vertex_ptr
    moved = surface_displacements(du, vptr, _n_surfaces(scene))
    planes = [p for p in contact.planes if p.motion.active(t)]
    dist = np.column_stack([plane_distances(x, vptr, p.point_at(t), p.normal) for p in planes]) if planes else np.zeros((0, 0))
    return pairwise_distance_ratio(path.trans, path.spread, moved, ints, floats, candidates, gbar, margin, dist)


def newton_blocks(scene: Scene, el, cr, mass_shift: float):
    """The Newton matrix K = mass_shift M + K_int + K_contact as the bodies' dense blocks (element
    tangent, mass and the contact terms within a grain, assembled in place in compiled kernels) and
    one sparse coupling matrix (contact terms between grains): no sparse sums (issue 14)."""
    blocks = el.blocks  # freshly allocated by evaluate: updated in place
    bodies = scene.bodies
    bodies.add_mass(blocks, mass_shift)
    coupling = cr.add_to_blocks(scene.contact.topology.vertex_grain, bodies.vertex_ptr, bodies.block_ptr, blocks)
    return blocks, coupling


_DEFAULT_LINEAR = []


def _default_linear():
    """The "auto" solver for callers that pass none (one per process: it keeps no state that
    matters between systems)."""
    if not _DEFAULT_LINEAR:
        _DEFAULT_LINEAR.append(make_linear_solver("auto"))
    return _DEFAULT_LINEAR[0]


class _IncrementalPotential:
    """E(x) = a1/2 (x - x~)^T M (x - x~) + W_int(x) + Phi_c(x) - f_g . x, x~ = x_n + dt v_n +
    dt^2 (1/2 - beta) a_n: its gradient is the Newmark residual without the dissipative terms, so a
    backtracking line search on it damps Newton's overshoot into the barrier (as in IPC)."""

    def __init__(self, scene, state, dt, a1, beta, f_grav, t1, candidates):
        self.scene, self.a1, self.f_grav, self.t1, self.candidates = scene, a1, f_grav, t1, candidates
        self.x_tilde = (state.x + dt * state.v + dt * dt * (0.5 - beta) * state.a).ravel()
        self.M = scene.mass_matrix()

    def value(self, x, strain_energy=None, contact_energy=None) -> float:
        s = self.scene
        if strain_energy is None:
            strain_energy = s.bodies.evaluate(x, force=False).total_energy
        if contact_energy is None:
            contact_energy = s.contact.potential(x, self.t1, self.candidates)
        r = x.ravel() - self.x_tilde
        return 0.5 * self.a1 * float(r @ (self.M @ r)) + strain_energy + contact_energy - float(self.f_grav @ x.ravel())

    def backtrack(self, moved, alpha, e0, slope, halvings: int = 6) -> float:
        """Largest alpha 2^-k with an Armijo decrease; alpha itself when the direction does not
        descend (dissipative terms dominate) or no trial decreases E (round-off near convergence)."""
        if not slope < 0:
            return alpha
        trial = alpha
        for _ in range(halvings):
            try:
                e = self.value(moved(trial))
            except (InvertedElementError, PenetrationError):
                e = np.inf
            if e <= e0 + 1e-4 * trial * slope:
                return trial
            trial *= 0.5
        return alpha


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
    if params.predictor == "acceleration":
        guess = state.v * dt + 0.5 * dt * dt * state.a
        _, ints0, floats0 = contact.pairs(state.x, t1, candidates)
        path = _UpdatePath(scene, x, guess, params.update)
        ratio = _ccd_ratio(scene, path, params.ccd, ints0, floats0, guess * 0, x, t1, candidates, 2.0 * travel)
        x = path.at(min(1.0, params.ccd_fraction * ratio))
    size = float(np.cbrt(scene.bodies.volume.mean()))
    linear = params.linear if params.linear is not None else _default_linear()
    krylov = 0
    full_before, dx_before = False, np.inf
    g_norm = float(np.linalg.norm(scene.gravity)) or 9.81
    for it in range(1, params.max_iterations + 1):
        du = x - state.x
        acc = a1 * du - a2 * state.v - a3 * state.a
        vel = a4 * du + a5 * state.v + a6 * state.a
        try:
            el = scene.bodies.evaluate(x, tangent=True)
            cr = contact.evaluate(x, t1, candidates, state.history, v=vel, a4=a4, tangent=True)
        except (InvertedElementError, PenetrationError) as exc:
            raise StepRejected(str(exc)) from None
        inertia = M @ (acc.ravel() + params.mass_damping * vel.ravel())
        R = inertia + el.force.ravel() + cr.force.ravel() - f_grav
        if not np.all(np.isfinite(R)):
            raise StepRejected("non-finite residual")
        scale = max(np.abs(f_grav).max(), np.abs(inertia).max(), np.abs(cr.force).max(), 1e-300)
        blocks, coupling = newton_blocks(scene, el, cr, a1 + params.mass_damping * a4)
        linear.factor(NewtonSystem(blocks, scene.bodies.block_ptr, scene.bodies.dof_ptr, coupling, x))
        dx = -linear.solve(R, params.krylov_rtol).reshape(-1, 3)
        krylov += linear.stats.last_iterations
        path = _UpdatePath(scene, x, dx, params.update)
        ratio = _ccd_ratio(scene, path, params.ccd, cr.ints, cr.floats, du, x, t1, candidates, 2.0 * travel)
        alpha = min(1.0, params.ccd_fraction * ratio)
        if params.line_search and np.abs(dx).max() > 1e3 * params.xtol * max(np.abs(du).max(), 1e-6 * size):
            merit = _IncrementalPotential(scene, state, dt, a1, params.beta, f_grav, t1, candidates)
            alpha = merit.backtrack(path.at, alpha, merit.value(x, el.total_energy, cr.energy), float(R @ dx.ravel()))
        x = path.at(alpha)
        # With E ~ 1e11 Pa the internal forces carry round-off far above the gravity of a grain, so
        # the residual test alone can be out of reach: a full Newton correction that is tiny against
        # the step's displacement (quadratic convergence) also ends the iteration.
        r_tol = params.rtol * scale
        dx_tol = params.xtol * max(np.abs(du).max(), 1e-6 * size)
        if params.accuracy > 0:
            dx_tol = max(dx_tol, params.accuracy * g_norm / a1)
        small_r = np.abs(R).max() <= r_tol
        dx_norm = np.abs(dx).max()
        # Newton converging quadratically leaves an error of about |dx_k|^2 / |dx_k-1| after a full
        # update (the linear-rate estimate, larger than the quadratic one): when that is below the
        # tolerance the next iteration would only confirm it. Trusted only once the residual is
        # near its round-off floor (a few tolerances), where the iteration is quadratic.
        small_dx = dx_norm <= dx_tol or (
            full_before and dx_norm * dx_norm <= dx_tol * dx_before and np.abs(R).max() <= 1e3 * r_tol
        )
        if params.trace is not None:
            params.trace(it, np.abs(R).max() / r_tol, dx_norm / dx_tol, alpha, cr)
        if alpha == 1.0 and small_dx and (small_r or it > 1):
            break
        full_before, dx_before = alpha == 1.0, dx_norm
    else:
        raise StepRejected(f"Newton did not converge in {params.max_iterations} iterations")
    du = x - state.x
    acc = a1 * du - a2 * state.v - a3 * state.a
    vel = a4 * du + a5 * state.v + a6 * state.a
    try:
        el = scene.bodies.evaluate(x)
        cr = contact.evaluate(x, t1, candidates, state.history, v=vel, a4=a4)
    except (InvertedElementError, PenetrationError) as exc:
        raise StepRejected(str(exc)) from None
    missed = missed_pairs(contact, x, t1, candidates)
    if missed:
        raise StepRejected(f"{missed} contact pairs appeared inside the activation gap during the step")
    power = cr.dissipation_power + params.mass_damping * 2.0 * scene.kinetic_energy(vel)
    new = State(t1, x, vel, acc, cr.trial_history, state.dissipated + 0.5 * dt * (state.power + power), power)
    info = StepInfo(it, cr.n_contacts, cr.energy, el.total_energy, cr.wall_reactions, cr.ints, cr.floats, cr, krylov)
    return new, info


def step_limit(scene: Scene, state: State, control: StepControl) -> float:
    """Contact-impact step control (contact.ccd.impact_step_limit) from the state at the start of a
    step; off when control.impact_steps is 0. Floor: 10 dt_min."""
    if control.impact_steps <= 0:
        return np.inf
    contact = scene.contact
    gbar = contact.law.activation_gap
    speed = np.sqrt(np.max(np.sum(state.v**2, axis=1))) + contact.max_wall_speed(state.t)
    gap, rate, m_eq = contact.approaching(state.x, state.v, state.t, gbar + 2.0 * speed * control.dt_max)
    limit = impact_step_limit(gap, rate, m_eq, contact.law_params, gbar, control.entry_fraction, control.impact_steps)
    return max(limit, 10.0 * control.dt_min)


def advance(scene: Scene, state: State, t_end: float, control: StepControl, params: NewmarkParameters,
            on_step=None, stats: RunStats | None = None) -> tuple[State, RunStats]:  # fmt: skip
    """Integrate from state.t to t_end; on_step(state, info, dt) after each accepted step."""
    stats = stats or RunStats()
    limit = step_limit(scene, state, control)
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
        limit = step_limit(scene, state, control)
        stats.accepted += 1
        stats.newton_iterations += info.iterations
        stats.krylov_iterations += info.krylov_iterations
        control.easy_streak = control.easy_streak + 1 if info.iterations <= control.easy_iterations else 0
        if control.easy_streak >= control.grow_after and h == control.dt:
            control.dt = min(control.dt * control.grow, control.dt_max)
            control.easy_streak = 0
        if on_step is not None:
            on_step(state, info, h)
    return state, stats
