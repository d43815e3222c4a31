"""Explicit integration of rigid grains (model/rigid.py): velocity Verlet for the centroids and a
symplectic splitting for the rotations (docs/dynamics.md, "Rigid grains").

Per step of length h, with force F and torque T (about the centroid) from contact, gravity at the
centroid and mass damping alpha:

    v_c += h/2 F/m,   L += h/2 T                      (half kick; L the angular momentum, world frame)
    c += h v_c,       R <- free rotation of R for h at angular momentum L
    F, T at the new placement (contact sees the vertices x_i = c + R X_i, moving at v_c + w x r_i)
    v_c += h/2 F/m,   L += h/2 T

The free rotation is the splitting of Dullweber, Reich and Leimkuhler (1997), geometry/rotation.py:
the kinetic energy of a spinning grain oscillates within O(h^2) and does not drift, and a spin
about a principal axis is exact (tests/test_rigid.py).

Stable step: the contact pairs' springs on the grains' effective masses along the pair's normal
at the contact point, 1/m_eff = sum over the two sides of 1/m + (r x n) . I^-1 (r x n), with their
damping ratios as in the flexible integrator, and the same approach limits (solver/explicit.py).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ..contact.ccd import damped_pair_step, rigid_pair_inverse_masses
from ..contact.model import PenetrationError
from ..geometry.rotation import free_rotation_step
from ..model.rigid import RigidBodies, fit_rigid, place_vertex
from ..model.scene import Scene
from .explicit import ExplicitIntegrator, ExplicitParameters
from .state import State, StepInfo, StepRejected


@njit(cache=True, parallel=True)
def free_rotation(rotation, momentum, moments, h):
    """R after h of torque-free motion at world angular momentum L (DLM splitting)."""
    out = rotation.copy()
    for g in prange(len(rotation)):
        free_rotation_step(out[g], momentum[g], moments[g], h)
    return out


@njit(cache=True)
def _omega(R, L, moments, out):
    """omega = R I^-1 R^T L, in place."""
    w0 = (R[0, 0] * L[0] + R[1, 0] * L[1] + R[2, 0] * L[2]) / moments[0]
    w1 = (R[0, 1] * L[0] + R[1, 1] * L[1] + R[2, 1] * L[2]) / moments[1]
    w2 = (R[0, 2] * L[0] + R[1, 2] * L[1] + R[2, 2] * L[2]) / moments[2]
    for a in range(3):
        out[a] = R[a, 0] * w0 + R[a, 1] * w1 + R[a, 2] * w2


@njit(cache=True, parallel=True)
def angular_velocity(rotation, momentum, moments):
    """omega = R I^-1 R^T L (world frame) of every grain."""
    out = np.empty_like(momentum)
    for g in prange(len(rotation)):
        _omega(rotation[g], momentum[g], moments[g], out[g])
    return out


@njit(cache=True, parallel=True)
def rigid_vertex_motion(centre, rotation, velocity, momentum, moments, body, vertex_ptr):
    """Vertex positions x_i = c + R X_i (model.rigid.place_vertex) and velocities
    v_c + omega x (x_i - c) of every grain, in one pass."""
    x = np.empty_like(body)
    v = np.empty_like(body)
    for g in prange(len(vertex_ptr) - 1):
        w = np.empty(3)
        _omega(rotation[g], momentum[g], moments[g], w)
        for i in range(vertex_ptr[g], vertex_ptr[g + 1]):
            place_vertex(x, i, centre, rotation, body, np.int64(g))  # np.int64: g is uint64 in the parallel body
            r0, r1, r2 = x[i, 0] - centre[g, 0], x[i, 1] - centre[g, 1], x[i, 2] - centre[g, 2]
            v[i, 0] = velocity[g, 0] + (w[1] * r2 - w[2] * r1)
            v[i, 1] = velocity[g, 1] + (w[2] * r0 - w[0] * r2)
            v[i, 2] = velocity[g, 2] + (w[0] * r1 - w[1] * r0)
    return x, v


@njit(cache=True)
def _force_and_torque(x, force, centre, vertex_ptr):
    """Sum of the vertex forces and their moment about each grain's centroid."""
    G = len(vertex_ptr) - 1
    F = np.zeros((G, 3))
    T = np.zeros((G, 3))
    for g in range(G):
        for i in range(vertex_ptr[g], vertex_ptr[g + 1]):
            r0, r1, r2 = x[i, 0] - centre[g, 0], x[i, 1] - centre[g, 1], x[i, 2] - centre[g, 2]
            f0, f1, f2 = force[i, 0], force[i, 1], force[i, 2]
            F[g, 0] += f0
            F[g, 1] += f1
            F[g, 2] += f2
            T[g, 0] += r1 * f2 - r2 * f1
            T[g, 1] += r2 * f0 - r0 * f2
            T[g, 2] += r0 * f1 - r1 * f0
    return F, T


def _fit_motion(x, v, centre, weights, vertex_ptr):
    """(v_c, omega) of every grain: the weighted least-squares rigid fit of vertex velocities."""
    G = len(vertex_ptr) - 1
    vc = np.empty((G, 3))
    omega = np.empty((G, 3))
    for g in range(G):
        sl = slice(vertex_ptr[g], vertex_ptr[g + 1])
        w = weights[sl]
        vc[g] = w @ v[sl] / w.sum()
        r = x[sl] - centre[g]
        J = np.einsum("i,ij,ik->jk", w, r, r)
        J = np.trace(J) * np.eye(3) - J
        omega[g] = np.linalg.solve(J, np.einsum("i,ij->j", w, np.cross(r, v[sl] - vc[g])))
    return vc, omega


class RigidExplicit(ExplicitIntegrator):
    """The explicit integrator of rigid grains; keeps the flexible one's Verlet list of contact
    candidates and approach limits (they only see vertex positions and velocities)."""

    def __init__(self, scene: Scene, params: ExplicitParameters = ExplicitParameters()):
        if not isinstance(scene.bodies, RigidBodies):
            raise TypeError("RigidExplicit integrates rigid grains (Scene.build(..., grain_model='rigid'))")
        super().__init__(scene, params)
        b = scene.bodies
        self.bodies = b
        # a point at distance rho from a grain's centre moves along a normal under a unit force as
        # 1/m + rho^2 / I_min at most; a pair has two such sides
        rho2 = np.maximum.reduceat(np.sum(b.body**2, axis=1), b.vertex_ptr[:-1])
        self.entry_inverse_mass = 2.0 * float(np.max(1.0 / b.mass + rho2 / b.moments.min(axis=1)))

    # ------------------------------------------------------------------ placement <-> vertices
    def vertex_motion(self, centre, rotation, velocity, momentum):
        b = self.bodies
        return rigid_vertex_motion(centre, rotation, velocity, momentum, b.moments, b.body, b.vertex_ptr)

    def loads(self, x, v, centre, velocity, momentum, t, history):
        """(F, T, F_d, T_d, contact result) at a placement: force and torque of contact, gravity
        and mass damping, and their dissipative part (damping, friction, mass damping)."""
        b = self.bodies
        cr = self.scene.contact.evaluate(x, t, self.candidates(x, t), history, v=v)
        F, T = _force_and_torque(x, -cr.force, centre, b.vertex_ptr)
        Fd, Td = _force_and_torque(x, -cr.dissipative, centre, b.vertex_ptr)
        alpha = self.params.mass_damping
        Fd -= alpha * b.mass[:, None] * velocity
        Td -= alpha * momentum
        F += b.mass[:, None] * self.scene.gravity[None, :] - alpha * b.mass[:, None] * velocity
        T -= alpha * momentum
        if not (np.all(np.isfinite(F)) and np.all(np.isfinite(T))):
            raise StepRejected("non-finite force")
        return F, T, Fd, Td, cr

    def initial_state(self, x0=None, v0=None, t0: float = 0.0, history=None) -> State:
        """Placement fitted to x0 (the reference by default), motion fitted to v0 (rest)."""
        b = self.bodies
        if x0 is None:
            centre, rotation = b.centre0.copy(), b.rotation0.copy()
        else:
            centre, rotation = fit_rigid(np.asarray(x0, float), b.body, b.lumped, b.vertex_ptr)
        x = b.positions(centre, rotation)
        if v0 is None:
            velocity, momentum = np.zeros_like(centre), np.zeros_like(centre)
        else:
            velocity, omega = _fit_motion(x, np.asarray(v0, float), centre, b.lumped, b.vertex_ptr)
            body_omega = np.einsum("gji,gj->gi", rotation, omega)
            momentum = np.einsum("gij,gj->gi", rotation, b.moments * body_omega)
        x, v = self.vertex_motion(centre, rotation, velocity, momentum)
        F, T, Fd, Td, cr = self.loads(x, v, centre, velocity, momentum, t0, history)
        bodies = {"centre": centre, "rotation": rotation, "velocity": velocity, "momentum": momentum,
                  "force": F, "torque": T, "damping_force": Fd, "damping_torque": Td}  # fmt: skip
        return State(t0, x, v, np.zeros_like(x), cr.trial_history, bodies=bodies)

    # ------------------------------------------------------------------ the step
    def stable_step(self, state: State, ints, floats) -> float:
        dt = np.inf
        if len(ints):
            dt = self._contact_step(state, ints, floats)
        return min(self.params.safety * dt, self.approach_limit(state, ints, floats))

    def _contact_step(self, state, ints, floats) -> float:
        contact = self.scene.contact
        b = self.bodies
        inv = rigid_pair_inverse_masses(contact.all_positions(state.x, state.t), ints, floats, state.bodies["centre"],
                                        state.bodies["rotation"], b.mass, b.moments)  # fmt: skip
        return damped_pair_step(inv, floats, contact.law_params, contact.masses_of_pairs(ints),
                                contact.friction.damping_ratio)  # fmt: skip

    def step(self, state: State, dt: float) -> tuple[State, StepInfo]:
        b = self.bodies
        s = state.bodies
        velocity = s["velocity"] + 0.5 * dt * s["force"] / b.mass[:, None]
        momentum = s["momentum"] + 0.5 * dt * s["torque"]
        centre = s["centre"] + dt * velocity
        rotation = free_rotation(s["rotation"], momentum, b.moments, dt)
        x, v_half = self.vertex_motion(centre, rotation, velocity, momentum)
        t1 = state.t + dt
        try:
            F, T, Fd, Td, cr = self.loads(x, v_half, centre, velocity, momentum, t1, state.history)
        except PenetrationError as exc:
            raise StepRejected(str(exc)) from None
        if len(cr.ints) and np.min(cr.floats[:, 2]) <= 0:
            raise StepRejected("a contact gap closed")
        # the work of the dissipative loads as the step applies them (velocity Verlet's identity,
        # solver/explicit.py step_dissipation): dt/2 (F_d,n + F_d,n+1) . v_c and the same for the
        # torques with the half-step angular velocity before and after the rotation
        omega_before = angular_velocity(s["rotation"], momentum, b.moments)
        omega_after = angular_velocity(rotation, momentum, b.moments)
        work = 0.5 * dt * float(np.sum((s["damping_force"] + Fd) * velocity)
                                + np.sum(s["damping_torque"] * omega_before) + np.sum(Td * omega_after))  # fmt: skip
        power = -float(np.sum(Fd * velocity) + np.sum(Td * omega_after))
        velocity = velocity + 0.5 * dt * F / b.mass[:, None]
        momentum = momentum + 0.5 * dt * T
        x, v = self.vertex_motion(centre, rotation, velocity, momentum)
        bodies = {"centre": centre, "rotation": rotation, "velocity": velocity, "momentum": momentum,
                  "force": F, "torque": T, "damping_force": Fd, "damping_torque": Td}  # fmt: skip
        new = State(t1, x, v, np.zeros_like(x), cr.trial_history, state.dissipated - work, power, bodies)
        info = StepInfo(0, cr.n_contacts, cr.energy, 0.0, cr.wall_reactions, cr.ints, cr.floats, cr)
        return new, info


def rigid_kinetic_energy(bodies: RigidBodies, state: State) -> float:
    """1/2 m |v_c|^2 + 1/2 omega . L of every grain, from the body arrays."""
    s = state.bodies
    omega = angular_velocity(s["rotation"], s["momentum"], bodies.moments)
    return 0.5 * float(np.sum(bodies.mass * np.sum(s["velocity"] ** 2, axis=1)) + np.sum(omega * s["momentum"]))
