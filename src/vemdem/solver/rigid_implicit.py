"""Implicit integration of rigid grains (model/rigid.py): Newmark on the centroids and on the
angular momenta, the rotations by the same exact free-rotation flow as the explicit integrator
(solver/rigid.py), Newton on the six dofs of every grain (docs/dynamics.md, "Rigid grains").

Per step of length h, with beta and gamma as the flexible integrator's (0.3025 and 0.6), force F
and torque T (contact, gravity at the centroid, mass damping) at the end of the step:

    c_n+1 = c_n + h v_n + h^2 [(1/2 - beta) a_n + beta a_n+1],   a = F / m
    v_n+1 = v_n + h [(1 - gamma) a_n + gamma a_n+1]
    L*    = L_n + h [(1/2 - beta) T_n + beta T_n+1]               R_n+1 = flow(R_n, L*, h)
    L_n+1 = L_n + h [(1 - gamma) T_n + gamma T_n+1]

flow(R, L, h) is the torque-free rotation of solver/rigid.py (the Dullweber-Reich-Leimkuhler
splitting): without torque L* = L_n and the rotation is the explicit integrator's, so a spinning
grain keeps its energy exactly as there. The unknowns are c_n+1 and L*; the residuals, per grain,

    r_c = m a_n+1 - F(x_n+1, v_n+1),    r_L = T_kin - T(x_n+1, v_n+1),
    T_kin = (L* - L_n - h (1/2 - beta) T_n) / (beta h)              (the torque the motion implies)

and Newton's matrix, in the increments (dc, dphi) of the centroid and of the rotation vector
(dL* = I_w dphi / h, I_w = R diag(I) R^T),

    J = diag(m I_3, I_w) (1/(beta h^2) + alpha gamma/(beta h)) + Z^T K Z + diag(0, -sum [f_i]x [r_i]x),

K the contact tangent at the vertices (the pairs' own 18 x 18 blocks, friction and damping with
dv/dx = gamma/(beta h) as in the flexible integrator), Z_i = [I_3, -[r_i]x] a vertex's rigid
modes (dx_i = dc + dphi x r_i), the last term the lever arms turning at fixed forces. J leaves out
the flow's exact linearisation (dphi = h I_w^-1 dL* to first order) and the change of I_w: a
quasi-Newton, converging fast at the small rotations of a step. J is 6G x 6G with the grains' contact graph as its pattern: dense
LU up to a few hundred unknowns, SuperLU above (solver/linear/direct.py).

Step control: the explicit loop's (solver/explicit.py advance_explicit) with the step grown by
1.5 after a step that converged in few iterations, up to dt_max, and bounded by the approach
limits of the explicit integrator (no pair closes more than a quarter of its gap in one step),
which keep the barrier out of reach; a step whose Newton does not converge is halved. A pair
whose friction or damping flips at three iterates is held on one branch for the rest of the step
(solver/cycles.py, `[solver] break_stick_cycles` and `hold_damping_cycles`, as for flexible grains).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
from numba import njit

from ..contact.forces import rigid_pair_blocks
from ..contact.model import PenetrationError
from ..model.scene import Scene
from .cycles import HeldPairs
from .defaults import RIGID_NEWTON_ITERATIONS, default
from .explicit import ExplicitParameters
from .linear.direct import superlu
from .rigid import RigidExplicit, _force_and_torque, angular_velocity, free_rotation
from .state import State, StepInfo, StepRejected

DENSE_UNKNOWNS = 600


@njit(cache=True)
def geometric_blocks(x, force, centre, vertex_ptr):
    """d(-T)/dphi from the vertices' lever arms turning with the grain at fixed forces:
    T = sum r_i x f_i, dr_i = dphi x r_i, so d(-T) = -sum [f_i]x [r_i]x dphi (3 x 3 per grain)."""
    G = len(vertex_ptr) - 1
    out = np.zeros((G, 3, 3))
    for g in range(G):
        for i in range(vertex_ptr[g], vertex_ptr[g + 1]):
            r0, r1, r2 = x[i, 0] - centre[g, 0], x[i, 1] - centre[g, 1], x[i, 2] - centre[g, 2]
            f0, f1, f2 = force[i, 0], force[i, 1], force[i, 2]
            # -[f]x [r]x = -(r f^T - (f . r) I)
            fr = f0 * r0 + f1 * r1 + f2 * r2
            out[g, 0, 0] -= r0 * f0 - fr
            out[g, 0, 1] -= r0 * f1
            out[g, 0, 2] -= r0 * f2
            out[g, 1, 0] -= r1 * f0
            out[g, 1, 1] -= r1 * f1 - fr
            out[g, 1, 2] -= r1 * f2
            out[g, 2, 0] -= r2 * f0
            out[g, 2, 1] -= r2 * f1
            out[g, 2, 2] -= r2 * f2 - fr
    return out


def world_inertia(rotation: np.ndarray, moments: np.ndarray) -> np.ndarray:
    """I_w = R diag(I) R^T of every grain."""
    return np.einsum("gik,gk,gjk->gij", rotation, moments, rotation)


class RigidNewmark(RigidExplicit):
    """The implicit integrator of rigid grains (module docstring); the explicit one's contact
    candidates, approach limits, loads and vertex motion."""

    easy_iterations = 6
    grow = 1.5

    def __init__(self, scene: Scene, params: ExplicitParameters = ExplicitParameters(), beta: float = default("beta"),
                 gamma: float = default("gamma"), max_iterations: int = RIGID_NEWTON_ITERATIONS, tolerance: float = 1e-6,
                 break_stick_cycles: bool = default("break_stick_cycles"),
                 hold_damping_cycles: bool = default("hold_damping_cycles")):  # fmt: skip
        """beta, gamma, max_iterations and the two rules: `[solver]` keys (config/tables.py; Newton's
        budget here RIGID_NEWTON_ITERATIONS where `max_iterations` is not set). break_stick_cycles, hold_damping_cycles: the flexible integrator's rules for a pair whose
        friction flips between stick and slip, or whose damping switches on and off, at three
        iterates of a step (solver/newmark.py NewmarkParameters): the law has no root there, and
        halving the step does not remove a jump of the force."""
        super().__init__(scene, params)
        self.beta, self.gamma = beta, gamma
        self.break_stick_cycles, self.hold_damping_cycles = break_stick_cycles, hold_damping_cycles
        self.max_iterations, self.tolerance = max_iterations, tolerance
        self.next_dt = np.inf  # set from the step control at every advance (checkpointed there)
        b = self.bodies
        self._weight = b.mass * max(float(np.linalg.norm(scene.gravity)), 1.0)
        self._size = np.cbrt(6.0 * b.volume / np.pi)

    def stable_step(self, state: State, ints, floats) -> float:
        return min(self.next_dt, self.approach_limit(state, ints, floats))

    # ------------------------------------------------------------------ Newton's pieces
    def _loads_with_tangent(self, x, v, centre, velocity, momentum, t, history, a4, held: HeldPairs):
        b = self.bodies
        cr = self.scene.contact.evaluate(x, t, self.candidates(x, t), history, v=v, a4=a4, tangent=True,
                                         **held.held())  # fmt: skip
        F, T = _force_and_torque(x, -cr.force, centre, b.vertex_ptr)
        Fd, Td = _force_and_torque(x, -cr.dissipative, centre, b.vertex_ptr)
        alpha = self.params.mass_damping
        F += b.mass[:, None] * self.scene.gravity[None, :] - alpha * b.mass[:, None] * velocity
        T -= alpha * momentum
        Fd -= alpha * b.mass[:, None] * velocity
        Td -= alpha * momentum
        if not (np.all(np.isfinite(F)) and np.all(np.isfinite(T))):
            raise StepRejected("non-finite force")
        return F, T, Fd, Td, cr

    def _matrix(self, cr, x, t, centre, rotation, h) -> np.ndarray:
        b = self.bodies
        G = b.n_bodies
        shift = 1.0 / (self.beta * h * h) + self.params.mass_damping * self.gamma / (self.beta * h)
        diag = np.zeros((G, 6, 6))
        diag[:, 0, 0] = diag[:, 1, 1] = diag[:, 2, 2] = b.mass * shift
        diag[:, 3:, 3:] = world_inertia(rotation, b.moments) * shift
        diag[:, 3:, 3:] += geometric_blocks(x, -cr.force, centre, b.vertex_ptr)
        rows, cols = np.arange(G), np.arange(G)
        blocks = diag
        if len(cr.ints):
            x_all = self.scene.contact.all_positions(x, t)
            r, c, blk = rigid_pair_blocks(cr.ints, cr.pair_tangent, x_all, centre, b.vertex_grain, b.n_vertices)
            keep = r >= 0
            rows, cols = np.concatenate([rows, r[keep]]), np.concatenate([cols, c[keep]])
            blocks = np.concatenate([blocks, blk[keep]])
        k = np.arange(6)
        R = (6 * rows[:, None, None] + k[None, :, None]).repeat(6, axis=2)
        C = (6 * cols[:, None, None] + k[None, None, :]).repeat(6, axis=1)
        return sp.csc_matrix((blocks.ravel(), (R.ravel(), C.ravel())), shape=(6 * G, 6 * G))

    def _solve(self, J, rhs):
        try:
            if J.shape[0] <= DENSE_UNKNOWNS:
                return sla.solve(J.toarray(), rhs, check_finite=False)
            return superlu(J).solve(rhs)
        except (RuntimeError, np.linalg.LinAlgError, ValueError) as exc:
            raise StepRejected(f"Newton did not converge: singular rigid-grain matrix ({exc})") from None

    def _converged(self, r_c, r_L) -> bool:
        scale = self.tolerance * self._weight
        return bool(np.all(np.linalg.norm(r_c, axis=1) <= scale)
                    and np.all(np.linalg.norm(r_L, axis=1) <= scale * self._size))  # fmt: skip

    def _stalled(self, du) -> bool:
        """The last update moved no vertex by more than 1e-12 of its grain's size: the residual is
        at its round-off floor (contact forces of many weights in a barrier)."""
        if du is None:
            return False
        reach = np.linalg.norm(du[:, :3], axis=1) + np.linalg.norm(du[:, 3:], axis=1) * self._size
        return bool(np.all(reach <= 1e-12 * self._size))

    # ------------------------------------------------------------------ the step
    def step(self, state: State, dt: float) -> tuple[State, StepInfo]:
        b = self.bodies
        s = state.bodies
        h, beta, gamma = dt, self.beta, self.gamma
        m = b.mass[:, None]
        c_n, R_n, v_n, L_n = s["centre"], s["rotation"], s["velocity"], s["momentum"]
        a_n, T_n = s["force"] / m, s["torque"]
        t1 = state.t + h
        a4 = gamma / (beta * h)
        # predictor: the loads of the step's start held over it. The unknown is the centroid's
        # displacement dc, not c: (c - c_n) / h^2 loses the digits of c (a residual floor of 1e-6
        # of the weight at h = 1e-7 s, measured), dc keeps its own
        dc = h * v_n + 0.5 * h * h * a_n
        L_star = L_n + 0.5 * h * T_n
        du = None
        held = HeldPairs(self.break_stick_cycles, self.hold_damping_cycles)
        for iteration in range(1, self.max_iterations + 1):
            c = c_n + dc
            R = free_rotation(R_n, L_star, b.moments, h)
            a1 = (dc - h * v_n) / (beta * h * h) - (0.5 - beta) / beta * a_n
            velocity = v_n + h * ((1.0 - gamma) * a_n + gamma * a1)
            T_kin = (L_star - L_n - h * (0.5 - beta) * T_n) / (beta * h)
            momentum = L_n + h * ((1.0 - gamma) * T_n + gamma * T_kin)
            x, v = self.vertex_motion(c, R, velocity, momentum)
            try:
                F, T, Fd, Td, cr = self._loads_with_tangent(x, v, c, velocity, momentum, t1, state.history, a4, held)
            except PenetrationError as exc:
                raise StepRejected(str(exc)) from None
            held.update(cr)
            r_c = m * a1 - F
            r_L = T_kin - T
            if self._converged(r_c, r_L) or self._stalled(du):
                break
            J = self._matrix(cr, x, t1, c, R, h)
            du = self._solve(J, -np.concatenate([r_c, r_L], axis=1).ravel()).reshape(-1, 6)
            dc = dc + du[:, :3]
            L_star = L_star + np.einsum("gij,gj->gi", world_inertia(R, b.moments), du[:, 3:]) / h
        else:
            raise StepRejected(f"Newton did not converge in {self.max_iterations} iterations (rigid grains)")
        if len(cr.ints) and np.min(cr.floats[:, 2]) <= 0:
            raise StepRejected("a contact gap closed")
        omega_n = angular_velocity(R_n, L_n, b.moments)
        omega = angular_velocity(R, momentum, b.moments)
        # work of the dissipative loads over the step, trapezoidal in time
        work = 0.5 * h * float(np.sum((s["damping_force"] + Fd) * 0.5 * (v_n + velocity))
                               + np.sum((s["damping_torque"] + Td) * 0.5 * (omega_n + omega)))  # fmt: skip
        power = -float(np.sum(Fd * velocity) + np.sum(Td * omega))
        bodies = {"centre": c, "rotation": R, "velocity": velocity, "momentum": momentum,
                  "force": F, "torque": T, "damping_force": Fd, "damping_torque": Td}  # fmt: skip
        new = State(t1, x, v, np.zeros_like(x), cr.trial_history, state.dissipated - work, power, bodies)
        self.next_dt = h * self.grow if iteration <= self.easy_iterations else h
        broken, undamped = held.counts()
        return new, StepInfo(iteration, cr.n_contacts, cr.energy, 0.0, cr.wall_reactions, cr.ints, cr.floats, cr,
                             broken_pairs=broken, undamped_pairs=undamped)  # fmt: skip
