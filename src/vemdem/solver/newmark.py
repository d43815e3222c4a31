"""Implicit Newmark time stepping with full Newton on elements + contact (docs/dynamics.md).

    a = a1 du - a2 v_n - a3 a_n,   v = a4 du + a5 v_n + a6 a_n,   du = x - x_n
    a1 = 1/(beta dt^2), a2 = 1/(beta dt), a3 = 1/(2 beta) - 1,
    a4 = gamma/(beta dt), a5 = 1 - gamma/beta, a6 = dt (1 - gamma/(2 beta))
    R(x) = M a + f_int(x) + r_contact(x, v) - f_gravity = 0,   K = a1 M + K_int + K_contact

Each Newton update moves every grain along its fitted rigid motion, the rotation applied as a
finite rotation (model/motion.py: a linearised rotation stretches a 90 GPa grain and costs Newton
iterations), and is shortened, if needed, so that no surface can reach another within it:
additive CCD for every feature pair the update can bring near (contact.ccd.accd_alpha), a bound
from the start of the update for the rest (_update_share); an accepted state never crosses the
barrier. A step is rejected when Newton does not converge, a value is not finite, the search at
the end of the step finds a new pair already inside the activation gap, or (advance) the total
energy grew (docs/dynamics.md).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..contact.ccd import (
    accd_alpha,
    update_reach,
    free_distance_ratio,
    impact_step_limit,
    missed_pairs,
    plane_distances,
    surface_displacements,
)
from ..contact.model import FrozenPairs, PenetrationError, pair_keys
from ..model.bodies import InvertedElementError
from ..model.motion import RigidRetraction, rigid_part
from ..model.scene import Scene
from .cycles import HeldPairs
from .defaults import NEWTON_ITERATIONS, default
from .linear import NewtonSystem, make_linear_solver, solve
from .state import RunStats, State, StepControl, StepInfo, StepRejected

__all__ = ["NewmarkParameters", "advance", "energy_tolerance", "initial_state", "newmark_step", "step_limit", "total_energy"]


@dataclass
class NewmarkParameters:
    """Newmark's constants and Newton's rules; the defaults of those a `[solver]` key sets are the
    key's (config/tables.py)."""

    beta: float = default("beta")
    gamma: float = default("gamma")
    rtol: float = 1e-6  # residual, relative to the largest of gravity, inertia and contact forces
    # correction, relative to the step's displacement (floor: 1e-12 grain sizes): `newton_xtol`
    xtol: float = default("newton_xtol")
    max_iterations: int = NEWTON_ITERATIONS
    ccd_fraction: float = 0.8  # share of the free distance a Newton update may use
    mass_damping: float = default("mass_damping")  # alpha (1/s): Rayleigh mass-proportional damping force alpha M v
    linear: object = None  # a solver.linear LinearSolver, made once per run (None: "auto")
    krylov_rtol: float = 1e-8  # relative residual of iterative linear solves (inexact Newton)
    # > 0: Eisenstat-Walker forcing, the Krylov tolerance of iteration k is
    # min(krylov_forcing, max(krylov_rtol, 0.9 (|R_k| / |R_k-1|)^2)) (safeguarded); 0: krylov_rtol always.
    # 0.1 against 0 (every solve to krylov_rtol): GMRES iterations 1,068 -> 299 over 1e-4 s of the 515-grain
    # lid jam (Newton 214 -> 218, wall -20 %), 6,406 -> 3,258 over the 30-grain lid cycle (same force
    # curve to 5e-7; docs/linear-solvers.md)
    krylov_forcing: float = 0.1
    trace: object = None  # callable(iteration, residual / tolerance, correction / tolerance, alpha): diagnostics
    stall_share: float = 0.5  # share of a full update taken when Newton stalls or cycles (from the 4th iteration)
    # A stalled iteration (from the 4th) also ends when its residual is within stall_rtol of the residual
    # tolerance and its correction below stall_xtol of the step's displacement (floor: 1e-9 grain sizes;
    # the same whatever xtol is): a pair creeping along its friction cone's edge switches between stick
    # and slip every iteration there, and the correction cycles without going below 1e-8
    # (docs/dynamics.md). 0: off.
    stall_rtol: float = 10.0
    stall_xtol: float = 1e-5
    # A pair that leaves and re-enters the eligible set every other iteration (a vertex-edge pair at its
    # edge's end, where no other record takes its force over: the narrow phase's selection rules make
    # the contact force jump there) leaves Newton with no root to find: the residual cycles between two
    # values and the step is rejected. With freeze_cycles such pairs are kept in the set for the rest of
    # the step (contact.model.FrozenPairs), the iteration converges, and the next step's search decides
    # afresh. (Leaving them out instead let Newton push their features together against the update
    # bound: stuck at an update share of 1e-9, seen in the 515-grain lid jam.) A kept pair that twins a
    # found record (the same touching spot: a force handed over) is not added, and one the narrow
    # phase finds twinning a record outside the frozen set is held out (contact.model._with_frozen):
    # an edge-edge record at its edge's end beside its end vertex's vertex-face record doubled that
    # spot's force at every other iterate and stalled a settling 110-grain pack at steps of 1e-7 s.
    freeze_cycles: bool = default("freeze_cycles")
    # A pair that sticks at the step's start is judged by mu_s, and its force drops from mu_s F_N to
    # mu_d F_N where the trial force passes mu_s F_N. Where the drop pulls the trial force back below
    # mu_s F_N the law has no root: Newton flips the pair between stick and slip every iterate or two
    # until its 15 iterations run out, and halving the step does not remove a jump of the force
    # (the 515-grain implicit pack: one pair flipping, rejected 5 times in a row down to 8e-7 s).
    # With break_stick_cycles a pair that has flipped three times in a step (not counting the first
    # update's, the predictor's miss) is held to mu_d for the rest of it: its static friction broke,
    # and the pair goes on as one that slid (continuous at mu_d F_N).
    break_stick_cycles: bool = default("break_stick_cycles")
    # A pair whose normal damping switched on and off at three iterates of a step (not counting the
    # first update's) is undamped for the rest of it: at the outer edge of the layer the damping,
    # 2 zeta sqrt(k m) |g_n dot| with k -> 0 like (gbar - g), outweighs the elastic force by 1e5,
    # and the no-adhesion clamp F_N = max(f_n + F_d, 0) is a kink Newton crossed both ways every
    # other iterate until its 15 iterations ran out (all three Newton rejections traced in the
    # 515-grain collapse; docs/dynamics.md). Taking a pair's damping away never adds energy.
    hold_damping_cycles: bool = default("hold_damping_cycles")
    # A grain whose pieces' deformation gradients all lie within this strain of its projection's
    # rotation R gets Newton's block as its reference tangent rotated by R (vem.element.evaluate):
    # 4.7-5.1 ms against 13.9-14.0 ms for the element kernel at 515 grains, a matrix off by O(strain)
    # (1e-9-1e-5 for grains at the real density), the residual exact. 0: the exact tangent always.
    rotated_tangent: float = default("rotated_tangent")


def initial_state(scene: Scene, x0=None, v0=None, t0: float = 0.0, history=None, mass_damping: float = 0.0) -> State:
    """Rest or prescribed velocities; the initial acceleration solves M a0 = f_g - f_int - r_c - alpha M v0
    (friction from `history`, a handed-over ContactHistory, when given). The dissipative residual
    there starts the energy books (step_dissipation)."""
    x = scene.bodies.reference.copy() if x0 is None else np.array(x0, float)
    v = np.zeros_like(x) if v0 is None else np.array(v0, float)
    f_int = scene.bodies.evaluate(x).force
    cand = scene.contact.search(x, t0)
    contact = scene.contact.evaluate(x, t0, cand, history, v=v)
    M = scene.mass_matrix()
    damping = mass_damping * (M @ v.ravel()).reshape(-1, 3)
    rhs = (scene.gravity_force() - f_int - contact.force - damping).ravel()
    a = solve(M, rhs).reshape(-1, 3)
    power = contact.dissipation_power + float(np.sum(damping * v))
    return State(t0, x, v, a, contact.trial_history, power=power, bodies={"dissipative": contact.dissipative + damping})


def _n_surfaces(scene: Scene) -> int:
    return len(scene.contact.topology.grain_vertex_ptr) - 1 + len(scene.contact.planes)




class _UpdatePath:
    """One Newton update dx at x: `at(alpha)` the positions after alpha of it, and what contact.ccd
    needs to bound it: every surface's motion (trans, spread; walls: 0) and each grain's path
    (centroid c, translation t, rotation phi; all 0 for the straight update) with its per-vertex
    excess over x + alpha dx."""

    def __init__(self, scene: Scene, x, dx):
        vptr = scene.bodies.vertex_ptr
        G = scene.bodies.n_bodies
        n_walls = _n_surfaces(scene) - G
        self.x, self.dx = x, np.ascontiguousarray(dx)
        move = RigidRetraction(x, dx, scene.bodies.lumped, vptr)
        self.at = move.at
        spread = move.bounds - np.linalg.norm(move.t, axis=1)
        self.c, self.t, self.phi = move.c, move.t, move.phi
        self.excess = move.excess()
        self.trans = np.concatenate([self.t, np.zeros((n_walls, 3))])
        self.spread = np.concatenate([spread, np.zeros(n_walls)])


def _update_share(scene: Scene, path: _UpdatePath, params, ints, floats, du, t, candidates, margin) -> float:
    """The share alpha <= 1 of an update that keeps every pair apart.

    D = top2 of the surfaces' reach (contact.ccd.update_reach) bounds how much any two surfaces
    can approach at alpha = 1. When the step's search reaches far enough (the surfaces outside
    its candidates were gbar + margin apart at the start of the step and have moved by du since),
    every feature pair closer than gbar + D is found and bounded by additive CCD along the
    update's path (each keeps 1 - ccd_fraction of its distance), and every other pair stays
    outside the activation layer. Otherwise pairs within the layer are bounded by additive CCD
    and all others by contact.ccd's one bound from the start (free_distance_ratio)."""
    contact = scene.contact
    gbar = contact.law.activation_gap
    keep = 1.0 - params.ccd_fraction
    D = update_reach(path.trans, path.spread)
    if D == 0.0:
        return 1.0
    vptr = scene.bodies.vertex_ptr
    moved = surface_displacements(du, vptr, _n_surfaces(scene))
    x_all = contact.all_positions(path.x, t)
    nodes = (x_all, len(path.x), contact.plane_node0, path.dx, contact.topology.vertex_grain, path.c, path.t,
             path.phi, path.excess)  # fmt: skip
    if update_reach(np.zeros((len(moved), 3)), moved) + D <= margin:
        if 2.0 * D < params.ccd_fraction * gbar:
            # A pair farther than gbar cannot close by ccd_fraction of its distance when D is this
            # small, so the pairs within gbar, found at this x and t for the forces (ints), are all
            # the update can bind: the search for gbar + D would only add pairs that give alpha = 1.
            # Most iterations after the first qualify (one narrow phase per iteration instead of two).
            return accd_alpha(ints, *nodes, keep, 1.0) if len(ints) else 1.0
        _, near, _ = contact.pairs(path.x, t, candidates, reach=gbar + D)
        return accd_alpha(near, *nodes, keep, 1.0) if len(near) else 1.0
    none = ints[:0], floats[:0]  # the pairs within the layer are left to the additive CCD below
    ratio = free_distance_ratio(path.trans, path.spread, *none, gbar)
    alpha = min(1.0, params.ccd_fraction * ratio)
    if len(ints):
        alpha = accd_alpha(ints, *nodes, keep, alpha)
    return alpha


def newton_blocks(scene: Scene, el, cr, touched=None):
    """The Newton matrix K = a1 M + K_int + K_contact as the bodies' dense blocks (`el`, evaluated
    with mass_shift a1, plus the contact terms within a grain, added in place by a compiled kernel)
    and one sparse coupling matrix (contact terms between grains): no sparse sums (docs/linear-solvers.md).
    touched (N,) bool, if given, marks the vertices whose blocks received contact terms."""
    blocks = el.blocks  # freshly allocated by evaluate: updated in place
    bodies = scene.bodies
    coupling = cr.add_to_blocks(scene.contact.topology.vertex_grain, bodies.vertex_ptr, bodies.block_ptr, blocks,
                                touched)  # fmt: skip
    return blocks, coupling


def newton_system(scene: Scene, el, cr, x: np.ndarray, mass_shift: float) -> NewtonSystem:
    """newton_blocks as the linear solvers' NewtonSystem (`el` evaluated with this mass_shift),
    with what the grain-block solver's Woodbury path needs of the rotated blocks."""
    bodies = scene.bodies
    touched = np.zeros(bodies.n_vertices, np.bool_)
    blocks, coupling = newton_blocks(scene, el, cr, touched)
    rotating = el.rotated is not None and hasattr(bodies, "rotation_reference")
    reference = bodies.rotation_reference() if rotating else None
    return NewtonSystem(blocks, bodies.block_ptr, bodies.dof_ptr, coupling, x, rotated=el.rotated,
                        rotations=el.rotations, touched=touched, mass_shift=mass_shift,
                        reference=reference)  # fmt: skip


_DEFAULT_LINEAR = []


def _default_linear():
    """The "auto" solver for callers that pass none (one per process: it keeps no state that
    matters between systems)."""
    if not _DEFAULT_LINEAR:
        _DEFAULT_LINEAR.append(make_linear_solver("auto"))
    return _DEFAULT_LINEAR[0]


def wall_time(scene: Scene, x, tw: float, t1: float, share: float) -> float:
    """A time in [tw, t1] to which the moving plane walls can be advanced from x without coming
    closer to any grain than 1 - share of its distance: the latest such time where the motion is
    linear over the interval (a plane's distance is linear in its own displacement, so one ratio
    per plane), an earlier one where the motion has a corner (the ratio is taken over the whole
    interval and the shortened interval checked again)."""
    t = t1
    for _ in range(8):
        s = _wall_share(scene, x, tw, t, share)
        if s >= 1.0 - 1e-9:
            return t
        t = tw + s * (t - tw)
    return tw


def _wall_share(scene: Scene, x, tw: float, t: float, share: float) -> float:
    s = 1.0
    for p in scene.contact.planes:
        if not (p.motion.active(tw) and p.motion.active(t)):
            continue
        approach = float((p.point_at(t) - p.point_at(tw)) @ p.normal)
        if approach <= 0.0:
            continue
        d = float(plane_distances(x, scene.bodies.vertex_ptr, p.point_at(tw), p.normal).min())
        s = min(s, share * max(d, 0.0) / approach)
    return s


def _wall_drive(contact, x, tw: float, t1: float, candidates, history, vel, a4) -> np.ndarray:
    """(t1 - tw) d r_contact / d t_wall at x: the contact forces' change when the walls move on
    from tw to t1, linearised (a backward difference, which moves the walls away from where they
    are going and so never into a grain). Added to the residual, it makes Newton's correction
    carry the grains the walls push (a lid) along with them. Only the walls' pairs are evaluated:
    grain-grain forces do not depend on the walls' time (evaluating them too took a whole narrow
    phase and friction pass, 6 % of the lid jam's time)."""
    h = 1e-3 * (t1 - tw)
    walls = candidates[candidates[:, 1] >= contact.n_grains]  # mesh walls; plane walls are always evaluated
    try:
        now = contact.evaluate(x, tw, walls, history, v=vel, a4=a4).force
        back = contact.evaluate(x, tw - h, walls, history, v=vel, a4=a4).force
    except PenetrationError:
        return np.zeros_like(x)
    return (now - back) * ((t1 - tw) / h)


def newmark_step(scene: Scene, state: State, dt: float, params: NewmarkParameters) -> tuple[State, StepInfo]:
    """One Newmark step of length dt from `state`: the step's pair search and first iterate, Newton
    to convergence (StepRejected when it fails), then the converged state with its books."""
    k = _newmark_constants(params.beta, params.gamma, dt)
    t1 = state.t + dt
    candidates, margin, x = _search_and_predict(scene, state, dt, t1, params)
    M = scene.mass_matrix()
    end = _newton(scene, state, x, dt, t1, k, M, candidates, margin, params)
    return _converged_step(scene, state, dt, t1, k, M, candidates, end, params)


def _newmark_constants(beta: float, gamma: float, dt: float) -> tuple:
    """(a1, ..., a6): a_n+1 = a1 du - a2 v_n - a3 a_n and v_n+1 = a4 du + a5 v_n + a6 a_n, du = x_n+1 - x_n."""
    b, gam = beta, gamma
    a1, a2, a3 = 1 / (b * dt * dt), 1 / (b * dt), 1 / (2 * b) - 1
    a4, a5, a6 = gam / (b * dt), 1 - gam / b, dt * (1 - gam / (2 * b))
    return a1, a2, a3, a4, a5, a6


def _kinematics(state: State, x: np.ndarray, k: tuple):
    """Displacement, acceleration and velocity at the step's end when the grains stand at x."""
    a1, a2, a3, a4, a5, a6 = k
    du = x - state.x
    acc = a1 * du - a2 * state.v - a3 * state.a
    vel = a4 * du + a5 * state.v + a6 * state.a
    return du, acc, vel


class _NewtonEnd(NamedTuple):
    x: np.ndarray  # the converged positions
    iterations: int
    krylov: int  # Krylov iterations over the step's linear solves
    frozen: FrozenPairs | None  # pairs kept in the contact set for the step (freeze_cycles)
    held: HeldPairs  # pairs held on one friction or damping branch (break_stick_cycles, hold_damping_cycles)
    tangent_blocks: int  # grain blocks evaluated, and of them with the exact (not the rotated) tangent
    exact_blocks: int


def _search_and_predict(scene: Scene, state: State, dt: float, t1: float, params: NewmarkParameters):
    """The step's candidate pairs, their search margin, and Newton's first iterate (the predictor,
    bounded by CCD)."""
    contact = scene.contact
    # search once per step, widened by twice the predicted travel so that pairs the step closes in on
    # are candidates from the start (without it, a grain could only creep towards the gap)
    motion = state.v * dt + 0.5 * dt * dt * state.a
    # the travel the predictor takes: each grain's rigid part. Flexible grains that start
    # undeformed under a load have vertex accelerations of 1e9 m/s^2 (an elastic vibration of
    # 1e-7 s, not the step's motion): taken whole, the first 1e-5 s step from the 515-grain lid
    # jam searched 0.28 m around every grain (all 132,355 grain pairs; docs/dynamics.md)
    motion = rigid_part(state.x, motion, scene.bodies.lumped, scene.bodies.vertex_ptr)
    travel = np.sqrt(np.max(np.sum(motion**2, axis=1), initial=0.0))
    # (4 travel + gbar: room for Newton's first updates, which carry the whole step's motion, so
    # that _update_share can bound every pair they bring near by additive CCD)
    margin = 4.0 * travel + contact.law.activation_gap
    candidates = contact.search(state.x, t1, margin=margin)
    # the first iterate: each grain's rigid part of its constant-acceleration motion (no elastic
    # noise), bounded against the walls where they stand (they may already be past a grain at t1)
    x = state.x.copy()
    _, ints0, floats0 = contact.pairs(state.x, state.t, candidates)
    path = _UpdatePath(scene, x, motion)
    x = path.at(_update_share(scene, path, params, ints0, floats0, motion * 0, state.t, candidates, margin))
    return candidates, margin, x


def _newton(scene: Scene, state: State, x: np.ndarray, dt: float, t1: float, k: tuple, M, candidates, margin: float,
            params: NewmarkParameters) -> _NewtonEnd:  # fmt: skip
    """Newton's iteration on the step's residual (inertia + internal + contact - gravity) from the
    first iterate x; StepRejected when it does not converge in params.max_iterations."""
    a1, a4 = k[0], k[3]
    f_grav = scene.gravity_force().ravel()
    contact = scene.contact
    # A wall that moves further in a step than its gap to the grains (a lid pressing a pack) would
    # start Newton behind a grain's surface: the walls start where they can go and move on to t1
    # between iterations as the grains give way (wall_time); the step converges only with them at t1.
    tw = wall_time(scene, x, state.t, t1, params.ccd_fraction)
    size = float(np.cbrt(scene.bodies.volume.mean()))
    linear = params.linear if params.linear is not None else _default_linear()
    # nothing kept from an earlier step (a coarse LU): a step is a function of the state and the step
    # control alone, so a run resumed from a checkpoint inside a frame continues to the same bits
    linear.forget()
    krylov = 0
    full_before, dx_before = False, np.inf
    corrections = []
    frozen, key_trail = None, []
    held = HeldPairs(params.break_stick_cycles, params.hold_damping_cycles)
    eta = params.krylov_forcing
    shift = a1 + params.mass_damping * a4  # the Newton matrix's mass term: K + shift M
    tangent_blocks = exact_blocks = 0
    for it in range(1, params.max_iterations + 1):
        du, acc, vel = _kinematics(state, x, k)
        try:
            el = scene.bodies.evaluate(x, tangent=True, mass_shift=shift, rotated_strain=params.rotated_tangent)
            cr = contact.evaluate(x, tw, candidates, state.history, v=vel, a4=a4, tangent=True, frozen=frozen,
                                  **held.held())  # fmt: skip
        except (InvertedElementError, PenetrationError) as exc:
            raise StepRejected(str(exc)) from None
        if el.rotated is not None:
            tangent_blocks += len(el.rotated)
            exact_blocks += len(el.rotated) - int(np.count_nonzero(el.rotated))
        if params.freeze_cycles and tw == t1:
            frozen = _freeze_cycling(key_trail, cr.ints, cr.floats, frozen)
        held.update(cr)
        inertia = M @ (acc.ravel() + params.mass_damping * vel.ravel())
        R = inertia + el.force.ravel() + cr.force.ravel() - f_grav
        at_end = tw == t1
        if not np.all(np.isfinite(R)):
            raise StepRejected("non-finite residual")
        r_norm = np.abs(R).max()
        scale = max(np.abs(f_grav).max(), np.abs(inertia).max(), np.abs(cr.force).max(), 1e-300)
        linear.factor(newton_system(scene, el, cr, x, shift))
        drive = 0.0 if at_end else _wall_drive(contact, x, tw, t1, candidates, state.history, vel, a4).ravel()
        eta = _forcing(params, eta, corrections[-1][1] if corrections else None, r_norm)
        dx = -linear.solve(R + drive, eta).reshape(-1, 3)
        krylov += linear.stats.last_iterations
        path = _UpdatePath(scene, x, dx)
        alpha = _update_share(scene, path, params, cr.ints, cr.floats, du, tw, candidates, margin)
        # A pair that changes type or eligibility between iterations (a vertex crossing a face's
        # edge) changes the tangent discontinuously, and full updates can cycle between two states
        # (seen in a twelve-grain drop: the same |dx| every other iteration, never converging).
        # A full update that has halved neither the correction nor the residual of two iterations
        # before is shortened.
        dx_norm = np.abs(dx).max()
        r_tol = params.rtol * scale
        du_max, dx_floor = np.abs(du).max(), 1e-12 * size
        dx_tol = max(params.xtol * du_max, dx_floor)
        if (at_end and it >= 4 and alpha == 1.0 and dx_norm > max(0.5 * corrections[-2][0], dx_tol)
                and r_norm > 0.5 * corrections[-2][1]):  # fmt: skip
            alpha = params.stall_share
        corrections.append((dx_norm, r_norm))
        x = path.at(alpha)
        if not at_end:
            # dx answers the walls' whole way to t1 (the drive): a shortened update takes them the
            # same share of it. Moving them as far as the gaps allow instead closed a lid's gap to
            # a fifth each iteration while the grain under it moved a third of its way out, and
            # Newton then spent an iteration per factor 1.5 of that gap getting back (docs/dynamics.md)
            tw = min(wall_time(scene, x, tw, t1, params.ccd_fraction), tw + alpha * (t1 - tw))
        # With E ~ 1e11 Pa the internal forces carry round-off far above the gravity of a grain, so
        # the residual test alone can be out of reach: a full Newton correction that is tiny against
        # the step's displacement (quadratic convergence) also ends the iteration.
        small_r = r_norm <= r_tol
        # Newton converging quadratically leaves an error of about |dx_k|^2 / |dx_k-1| after a full
        # update (the linear-rate estimate, larger than the quadratic one): when that is below the
        # tolerance the next iteration would only confirm it. Trusted only once the residual is
        # near its round-off floor (a few tolerances), where the iteration is quadratic.
        small_dx = dx_norm <= dx_tol or (
            full_before and dx_norm * dx_norm <= dx_tol * dx_before and r_norm <= 1e3 * r_tol
        )
        if params.trace is not None:
            params.trace(it, r_norm / r_tol, dx_norm / dx_tol, alpha, cr)
        if at_end and alpha == 1.0 and small_dx and (small_r or it > 1):
            break
        stalled = r_norm <= params.stall_rtol * r_tol and dx_norm <= max(params.stall_xtol * du_max, 1e3 * dx_floor)
        if at_end and it >= 4 and stalled:
            break  # stalled at the tolerance (stall_rtol above)
        full_before, dx_before = alpha == 1.0, dx_norm
    else:
        raise StepRejected(f"Newton did not converge in {params.max_iterations} iterations")
    return _NewtonEnd(x, it, krylov, frozen, held, tangent_blocks, exact_blocks)


def _converged_step(scene: Scene, state: State, dt: float, t1: float, k: tuple, M, candidates, end: _NewtonEnd,
                    params: NewmarkParameters) -> tuple[State, StepInfo]:  # fmt: skip
    """The state at Newton's converged positions: forces without tangents, the end-of-step check for
    pairs the step's search missed, and the dissipation booked over the step."""
    a4, gam, contact = k[3], params.gamma, scene.contact
    x, it, krylov, frozen, held, tangent_blocks, exact_blocks = end
    _, acc, vel = _kinematics(state, x, k)
    try:
        el = scene.bodies.evaluate(x)
        cr = contact.evaluate(x, t1, candidates, state.history, v=vel, a4=a4, **held.held())
    except (InvertedElementError, PenetrationError) as exc:
        raise StepRejected(str(exc)) from None
    missed = missed_pairs(contact, x, t1, candidates)
    if missed:
        raise StepRejected(f"{missed} contact pairs appeared inside the activation gap during the step")
    mass_force = params.mass_damping * (M @ vel.ravel()).reshape(-1, 3)
    dissipative = cr.dissipative + mass_force
    power = cr.dissipation_power + float(np.sum(mass_force * vel))
    dissipated = state.dissipated + step_dissipation(state, dissipative, vel, power, dt, gam)
    new = State(t1, x, vel, acc, cr.trial_history, dissipated, power, {"dissipative": dissipative})
    info = StepInfo(it, cr.n_contacts, cr.energy, el.total_energy, cr.wall_reactions, cr.ints, cr.floats, cr, krylov,
                    0 if frozen is None else len(frozen.keys), *held.counts(), tangent_blocks,
                    exact_blocks)  # fmt: skip
    return new, info


def step_dissipation(state: State, r1: np.ndarray, v1: np.ndarray, power1: float, dt: float, gamma: float) -> float:
    """Energy the damping, friction and mass damping took over a Newmark step, as the step applies
    them. The kinetic energy changes by (v_n + v_n+1)/2 . M (v_n+1 - v_n), and Newmark's
    v_n+1 - v_n = h ((1 - gamma) a_n + gamma a_n+1) with M a = -r at both ends, so the dissipative
    residual r_d (minus the force, on the grains' vertices) takes

        h/2 (v_n + v_n+1) . ((1 - gamma) r_d,n + gamma r_d,n+1)

    A trapezoid of the powers, h/2 (r_d,n . v_n + r_d,n+1 . v_n+1), books more whenever the velocity
    changes within the step (for a dashpot at gamma 1/2 by h c |v_n+1 - v_n|^2 / 4), and the energy
    guard read that excess as a gain: in the 515-grain lid jam at the real density the rejected
    steps' gains were 3-40 % of the lid's work there, where the dissipation booked 90 % of it
    (docs/dynamics.md). The walls' nodes move as prescribed, so their share (the power less the
    grains') keeps the trapezoid of the walls' work (ContactModel.wall_work). A state without r_d,n
    (the run's first, a state file's, a checkpoint from before) books the trapezoid of the powers."""
    r0 = state.bodies.get("dissipative")
    if r0 is None:
        return 0.5 * dt * (state.power + power1)
    grains = 0.5 * dt * float(np.sum((state.v + v1) * ((1.0 - gamma) * r0 + gamma * r1)))
    walls = 0.5 * dt * ((state.power - float(np.sum(r0 * state.v))) + (power1 - float(np.sum(r1 * v1))))
    return grains + walls


def _forcing(params: NewmarkParameters, eta: float, r_before: float | None, r_now: float) -> float:
    """The Krylov tolerance of this Newton iteration: Eisenstat and Walker's choice 2 (gamma 0.9,
    exponent 2) with their safeguard against a sudden drop, between krylov_rtol and krylov_forcing;
    a correction far from the root needs no more than the residual's own progress can use."""
    if params.krylov_forcing <= 0.0:
        return params.krylov_rtol
    if r_before is None or r_before <= 0.0:
        return params.krylov_forcing
    new = 0.9 * (r_now / r_before) ** 2
    if 0.9 * eta * eta > 0.1:
        new = max(new, 0.9 * eta * eta)
    return min(params.krylov_forcing, max(params.krylov_rtol, new))


def _freeze_cycling(trail: list, ints: np.ndarray, floats: np.ndarray, frozen: FrozenPairs | None):
    """`frozen` plus the pairs that left or joined the eligible set at this iteration after joining or
    leaving it at the one before (a two-iteration cycle), each with its latest record. `trail` keeps
    the last iterations' (keys, ints, floats)."""
    trail.append((pair_keys(ints), ints, floats))
    if len(trail) < 3:
        return frozen
    (k2, _, _), (k1, i1, f1), (k0, i0, f0) = trail
    del trail[0]
    cycling = np.intersect1d(np.setxor1d(k0, k1), np.setxor1d(k1, k2))
    wanted = cycling if frozen is None else np.union1d(frozen.keys, cycling)
    if not len(wanted):
        return frozen
    now = np.isin(k0, wanted)
    before = np.isin(k1, wanted) & ~np.isin(k1, k0)
    keys, ints_, floats_ = [k0[now], k1[before]], [i0[now], i1[before]], [f0[now], f1[before]]
    if frozen is not None:
        # a frozen pair in neither iterate's records (a twin carries its spot: contact.model._with_frozen)
        # stays frozen with its stored record, which carries the spot if the twin leaves later in the step
        gone = ~np.isin(frozen.keys, np.concatenate(keys))
        keys.append(frozen.keys[gone])
        ints_.append(frozen.ints[gone])
        floats_.append(frozen.floats[gone])
    keys = np.concatenate(keys)
    order = np.argsort(keys)
    return FrozenPairs(keys[order], np.vstack(ints_)[order], np.vstack(floats_)[order])


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


def total_energy(scene: Scene, state: State, strain_energy: float, contact_energy: float) -> float:
    """Kinetic + gravity + strain + contact potential + what damping and friction dissipated: constant
    in a closed system, and the integrator's own (numerical) dissipation can only lower it."""
    return (scene.kinetic_energy(state.v) + scene.gravity_energy(state.x) + strain_energy + contact_energy
            + state.dissipated)  # fmt: skip


def _energy_of(scene: Scene, state: State) -> float:
    strain = scene.bodies.evaluate(state.x, force=False).total_energy
    contact = scene.contact.potential(state.x, state.t, scene.contact.search(state.x, state.t))
    return total_energy(scene, state, strain, contact)


def _wall_reactions_at(scene: Scene, state: State) -> np.ndarray:
    """The grains' force on each wall at a state (its conservative and damping parts)."""
    contact = scene.contact
    return contact.evaluate(state.x, state.t, contact.search(state.x, state.t), state.history, v=state.v).wall_reactions


def energy_tolerance(scene: Scene, control: StepControl, load: float = 0.0) -> float:
    """Largest energy gain a step may make: control.energy_growth times W d, the work of lifting
    the load W by a grain size d. W is the grains' own weight sum m g, or the larger load `load`
    the walls carry in the step (a lid's force), up to the weight the contact law was made for
    (n_grains F_ref / 10, ContactModel.reference_weight): a contact energy scales with the force the
    pair carries, and the law's reference force is the largest the law expects. A law made for a
    lid's load judges the pack before the lid arrives by its weight: taken at the law's scale
    there, the tolerance let a grain dropped on the floor gain 140 times its energy (docs/dynamics.md
    "Energy never grows"). 0 turns the check off."""
    g = max(float(np.linalg.norm(scene.gravity)), 9.81)
    weight = scene.total_mass() * g
    law_weight = scene.n_grains * scene.contact.reference_weight()
    return control.energy_growth * max(weight, min(law_weight, load)) * scene.grain_size


def _largest_reaction(reactions) -> float:
    """The largest force the grains exert on one wall (0 without walls)."""
    return float(np.sqrt(np.max(np.sum(np.asarray(reactions).reshape(-1, 3) ** 2, axis=1), initial=0.0)))


def advance(scene: Scene, state: State, t_end: float, control: StepControl, params: NewmarkParameters,
            on_step=None, stats: RunStats | None = None) -> tuple[State, RunStats]:  # fmt: skip
    """Integrate from state.t to t_end; on_step(state, info, dt) after each accepted step.

    A step is rejected (and halved) when Newton fails, and also when the scene's total energy grew
    by more than energy_tolerance beyond the work the moving walls did on the grains: Newmark's
    trapezoidal rule does not conserve the energy of the strongly nonlinear barrier law over a step
    that jumps deep into the layer (docs/dynamics.md), and a system must never gain energy it was
    not given. The check gives way (the step is accepted and counted in stats.energy_gains) below
    1e-3 dt_max, and where the halved step gains within a factor of two of what the rejected one
    did: such a gain does not come from the step's length."""
    stats = stats or RunStats()
    limit = step_limit(scene, state, control)
    guarded = control.energy_growth > 0
    energy = _energy_of(scene, state) if guarded else 0.0
    # one contact evaluation per call: the walls' work is booked, and their load sets the tolerance
    walls = scene.contact.planes or scene.contact.meshes
    reactions = _wall_reactions_at(scene, state) if guarded and walls else np.zeros((0, 3))
    last_gain = (None, 0.0)  # the state a step was last rejected from for its energy gain, and that gain
    while state.t < t_end * (1 - 1e-12):
        h = min(control.dt, limit, t_end - state.t)
        try:
            new, info = newmark_step(scene, state, h, params)
            if guarded:
                new_energy = total_energy(scene, new, info.strain_energy, info.contact_energy)
                load = min(_largest_reaction(reactions), _largest_reaction(info.wall_reactions))
                tolerance = energy_tolerance(scene, control, load)
                # a moving wall (the lid) works on the grains: the energy may grow by that work and
                # no more (the 515-grain lid jam, unchecked, gained 1e-6-5e-4 J per step against
                # the lid's 1e-7 J: docs/dynamics.md "Energy never grows")
                gain = new_energy - energy - scene.contact.wall_work(state.t, new.t, reactions, info.wall_reactions)
                if gain > tolerance:
                    # a gain that halving the step did not shrink is no integration error but a jump
                    # of the contact potential (a record of the pair hierarchy joining inside the
                    # layer: docs/dynamics.md); smaller steps cannot remove it
                    jump = last_gain[0] is state and 0.5 * last_gain[1] <= gain <= 2.0 * last_gain[1]
                    if h > 1e-3 * control.dt_max and not jump:
                        last_gain = (state, gain)
                        raise StepRejected(f"the total energy grew by {gain:.3g} J in one step (tolerance {tolerance:.3g} J)")
                    stats.energy_gains += 1
                energy, reactions = new_energy, info.wall_reactions
        except (StepRejected, np.linalg.LinAlgError) as exc:
            stats.reject(exc)
            control.rejected(h, state.t, exc)
            continue
        state = new
        limit = step_limit(scene, state, control)
        stats.accept(info)
        control.accepted(h, info.iterations)
        if on_step is not None:
            turned = scene.gravity.copy()
            on_step(state, info, h)
            if guarded and not np.array_equal(turned, scene.gravity):
                # a control that turns gravity (the tilting box) works on the grains: not a gain of the step
                energy += -float(np.sum(scene.bodies.load[:, None] * (scene.gravity - turned)[None, :] * state.x))
    return state, stats
