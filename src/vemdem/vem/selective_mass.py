"""Selective mass scaling: mass added to each grain's deformation modes only (docs/selective-mass-scaling.md).

With lumped vertex masses m and the grain's rigid-body modes Phi (three translations, three
rotations about its centroid), Olovsson, Simonsson and Unosson (2005) scale the deformation part:

    M_s = M + lambda (M - M Phi (Phi^T M Phi)^-1 Phi^T M)
    M_s^-1 f = (M^-1 f + lambda Phi (Phi^T M Phi)^-1 Phi^T f) / (1 + lambda)

Phi^T f is the grain's net force F and torque T about its centroid, Phi^T M Phi its mass M_g and
inertia tensor I (of the lumped masses, about the current centroid), so the second term is the
rigid-body acceleration A + alpha x r_i of the vertex at r_i from the centroid, and

    a_i = (f_i / m_i + lambda a_rigid,i) / (1 + lambda).

The modes are taken in the grain's current placement, and the rigid acceleration carries the
rigid motion's own centripetal part, omega x (omega x r), with Euler's equations for alpha:

    A = F / M_g,   omega = I^-1 L,   alpha = I^-1 (T - omega x I omega),
    a_rigid,i = A + alpha x r_i + omega x (omega x r_i),

L the angular momentum about the centroid. With modes fixed in space a grain spinning at omega
needs its centripetal force from the deformation modes, which carry (1 + lambda) times its real
inertia there: it stretches (1 + lambda) times more than a real grain does. Rotating the modes
with the grain asks the deformation modes only for deviations from the rigid motion, so a grain
spinning rigidly stretches as a real one (tests/test_selective_mass.py measures both).

Sums over a grain's vertices give back its net force, torque and momenta unchanged for every
lambda: translations and rotations keep their real inertia; only the periods of the deformation
modes grow, by sqrt(1 + lambda) (the deformation modes are M-orthogonal to the rigid ones, on
which M_s acts as (1 + lambda) M).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ..geometry.rotation import free_rotation_step


@njit(cache=True)
def _inverse_3x3(J: np.ndarray) -> np.ndarray:
    """The inverse of a symmetric positive definite 3x3 matrix, by cofactors."""
    c = np.empty((3, 3))
    c[0, 0] = J[1, 1] * J[2, 2] - J[1, 2] * J[2, 1]
    c[0, 1] = J[0, 2] * J[2, 1] - J[0, 1] * J[2, 2]
    c[0, 2] = J[0, 1] * J[1, 2] - J[0, 2] * J[1, 1]
    c[1, 0] = J[1, 2] * J[2, 0] - J[1, 0] * J[2, 2]
    c[1, 1] = J[0, 0] * J[2, 2] - J[0, 2] * J[2, 0]
    c[1, 2] = J[0, 2] * J[1, 0] - J[0, 0] * J[1, 2]
    c[2, 0] = J[1, 0] * J[2, 1] - J[1, 1] * J[2, 0]
    c[2, 1] = J[0, 1] * J[2, 0] - J[0, 0] * J[2, 1]
    c[2, 2] = J[0, 0] * J[1, 1] - J[0, 1] * J[1, 0]
    det = J[0, 0] * c[0, 0] + J[0, 1] * c[1, 0] + J[0, 2] * c[2, 0]
    return c / det


@njit(cache=True)
def _grain_motion(x, v, m, lo, hi, J):
    """(centroid, velocity, angular momentum about the centroid) of the vertices lo:hi, and their
    inertia tensor about the centroid into J. Written with scalars: small arrays made per vertex
    cost more than the sums."""
    mass = 0.0
    c0 = c1 = c2 = u0 = u1 = u2 = 0.0
    for i in range(lo, hi):
        mi = m[i]
        mass += mi
        c0 += mi * x[i, 0]
        c1 += mi * x[i, 1]
        c2 += mi * x[i, 2]
        u0 += mi * v[i, 0]
        u1 += mi * v[i, 1]
        u2 += mi * v[i, 2]
    c0, c1, c2, u0, u1, u2 = c0 / mass, c1 / mass, c2 / mass, u0 / mass, u1 / mass, u2 / mass
    L0 = L1 = L2 = 0.0
    J[:] = 0.0
    for i in range(lo, hi):
        mi = m[i]
        r0, r1, r2 = x[i, 0] - c0, x[i, 1] - c1, x[i, 2] - c2
        w0, w1, w2 = v[i, 0] - u0, v[i, 1] - u1, v[i, 2] - u2
        L0 += mi * (r1 * w2 - r2 * w1)
        L1 += mi * (r2 * w0 - r0 * w2)
        L2 += mi * (r0 * w1 - r1 * w0)
        r2sum = r0 * r0 + r1 * r1 + r2 * r2
        J[0, 0] += mi * (r2sum - r0 * r0)
        J[1, 1] += mi * (r2sum - r1 * r1)
        J[2, 2] += mi * (r2sum - r2 * r2)
        J[0, 1] -= mi * r0 * r1
        J[0, 2] -= mi * r0 * r2
        J[1, 2] -= mi * r1 * r2
    J[1, 0], J[2, 0], J[2, 1] = J[0, 1], J[0, 2], J[1, 2]
    return np.array([c0, c1, c2]), np.array([u0, u1, u2]), np.array([L0, L1, L2]), mass


@njit(cache=True)
def _cross(a, b):
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


@njit(cache=True)
def _grain_rigid_terms(f, x, v, m, lo, hi, out):
    """The rigid-body acceleration's parts of the vertices lo:hi into out (5, 3): centroid, A,
    omega, J^-1 T (the torque's angular acceleration), J^-1 (omega x J omega) (the free rotation's,
    with a minus sign)."""
    J = np.empty((3, 3))
    c, _, L, mass = _grain_motion(x, v, m, lo, hi, J)
    F0 = F1 = F2 = T0 = T1 = T2 = 0.0
    for i in range(lo, hi):
        r0, r1, r2 = x[i, 0] - c[0], x[i, 1] - c[1], x[i, 2] - c[2]
        F0 += f[i, 0]
        F1 += f[i, 1]
        F2 += f[i, 2]
        T0 += r1 * f[i, 2] - r2 * f[i, 1]
        T1 += r2 * f[i, 0] - r0 * f[i, 2]
        T2 += r0 * f[i, 1] - r1 * f[i, 0]
    Jinv = _inverse_3x3(J)
    omega = Jinv @ L
    out[0] = c
    out[1, 0], out[1, 1], out[1, 2] = F0 / mass, F1 / mass, F2 / mass
    out[2] = omega
    out[3] = Jinv @ np.array([T0, T1, T2])
    out[4] = Jinv @ _cross(omega, J @ omega)


@njit(parallel=True, cache=True)
def selective_accelerations(f: np.ndarray, x: np.ndarray, v: np.ndarray, m: np.ndarray, vertex_ptr: np.ndarray,
                            lam: float) -> np.ndarray:  # fmt: skip
    """The kick of the co-rotational step: a = M_s^-1 f less the free rotation's acceleration
    omega x (omega x r) - (J^-1 (omega x J omega)) x r, which `corotational_drift` carries out
    exactly (the module's formulas). f (N, 3) the forces, x and v the vertices' positions and
    velocities (the rigid motion's angular velocity), m (N,) the lumped masses, lam the
    deformation modes' added mass factor lambda >= 0."""
    a = np.empty_like(f)
    share = lam / (1.0 + lam)
    for g in prange(len(vertex_ptr) - 1):
        lo, hi = vertex_ptr[g], vertex_ptr[g + 1]
        t = np.empty((5, 3))
        _grain_rigid_terms(f, x, v, m, lo, hi, t)
        o0, o1, o2 = t[2, 0], t[2, 1], t[2, 2]
        b0, b1, b2 = t[3, 0], t[3, 1], t[3, 2]
        e0, e1, e2 = t[4, 0], t[4, 1], t[4, 2]
        for i in range(lo, hi):
            r0, r1, r2 = x[i, 0] - t[0, 0], x[i, 1] - t[0, 1], x[i, 2] - t[0, 2]
            s0, s1, s2 = o1 * r2 - o2 * r1, o2 * r0 - o0 * r2, o0 * r1 - o1 * r0  # omega x r
            # the free rotation's acceleration of this vertex: omega x (omega x r) - e x r
            free0 = o1 * s2 - o2 * s1 - (e1 * r2 - e2 * r1)
            free1 = o2 * s0 - o0 * s2 - (e2 * r0 - e0 * r2)
            free2 = o0 * s1 - o1 * s0 - (e0 * r1 - e1 * r0)
            inverse = 1.0 / ((1.0 + lam) * m[i])
            a[i, 0] = f[i, 0] * inverse + share * (t[1, 0] + b1 * r2 - b2 * r1) - free0 / (1.0 + lam)
            a[i, 1] = f[i, 1] * inverse + share * (t[1, 1] + b2 * r0 - b0 * r2) - free1 / (1.0 + lam)
            a[i, 2] = f[i, 2] * inverse + share * (t[1, 2] + b0 * r1 - b1 * r0) - free2 / (1.0 + lam)
    return a


@njit(cache=True)
def _drift_rotation(J, L, h):
    """The world rotation Q of h of torque-free motion at angular momentum L of a body of
    inertia J (geometry/rotation.py, in the principal frame of J)."""
    moments, axes = np.linalg.eigh(J)
    if np.linalg.det(axes) < 0:  # a right-handed frame: the flows turn by the right-hand rule
        axes[:, 2] = -axes[:, 2]
    R = axes.copy()
    free_rotation_step(R, L, moments, h)
    return R @ axes.T


@njit(parallel=True, cache=True)
def corotational_drift(x: np.ndarray, v: np.ndarray, m: np.ndarray, vertex_ptr: np.ndarray,
                       h: float) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Positions and velocities after a drift of h: each grain's rigid motion exactly (its centroid
    at its velocity V, a torque-free rotation Q at its angular momentum L), its deformation
    velocity d = v - V - omega x r carried along and turned with it:
        x_i <- c + h V + Q (r_i + h d_i),   v_i <- V + omega' x r_i' + Q d_i,
    omega' = J'^-1 L with the inertia J' of the new placement, so that V and L are kept exactly and
    |d| too. A grain at rest stays where it is, to the bit."""
    x1 = np.empty_like(x)
    v1 = np.empty_like(v)
    for g in prange(len(vertex_ptr) - 1):
        lo, hi = vertex_ptr[g], vertex_ptr[g + 1]
        J = np.empty((3, 3))
        c, V, L, _ = _grain_motion(x, v, m, lo, hi, J)
        o0, o1, o2 = _inverse_3x3(J) @ L
        turning = L[0] != 0.0 or L[1] != 0.0 or L[2] != 0.0
        Q = _drift_rotation(J, L, h) if turning else np.eye(3)
        # scalars: per-vertex small arrays and 3x3 products cost more than the rest of the step
        for i in range(lo, hi):
            r0, r1, r2 = x[i, 0] - c[0], x[i, 1] - c[1], x[i, 2] - c[2]
            d0 = v[i, 0] - V[0] - (o1 * r2 - o2 * r1)
            d1 = v[i, 1] - V[1] - (o2 * r0 - o0 * r2)
            d2 = v[i, 2] - V[2] - (o0 * r1 - o1 * r0)
            y0, y1, y2 = r0 + h * d0, r1 + h * d1, r2 + h * d2
            if turning:
                y0, y1, y2 = (Q[0, 0] * y0 + Q[0, 1] * y1 + Q[0, 2] * y2, Q[1, 0] * y0 + Q[1, 1] * y1 + Q[1, 2] * y2,
                              Q[2, 0] * y0 + Q[2, 1] * y1 + Q[2, 2] * y2)  # fmt: skip
                d0, d1, d2 = (Q[0, 0] * d0 + Q[0, 1] * d1 + Q[0, 2] * d2, Q[1, 0] * d0 + Q[1, 1] * d1 + Q[1, 2] * d2,
                              Q[2, 0] * d0 + Q[2, 1] * d1 + Q[2, 2] * d2)  # fmt: skip
            x1[i, 0] = x[i, 0] + h * V[0] + (y0 - r0)
            x1[i, 1] = x[i, 1] + h * V[1] + (y1 - r1)
            x1[i, 2] = x[i, 2] + h * V[2] + (y2 - r2)
            v1[i, 0], v1[i, 1], v1[i, 2] = d0, d1, d2
        c1, _, _, _ = _grain_motion(x1, x1, m, lo, hi, J)
        p0, p1, p2 = _inverse_3x3(J) @ L
        for i in range(lo, hi):
            r0, r1, r2 = x1[i, 0] - c1[0], x1[i, 1] - c1[1], x1[i, 2] - c1[2]
            v1[i, 0] += V[0] + (p1 * r2 - p2 * r1)
            v1[i, 1] += V[1] + (p2 * r0 - p0 * r2)
            v1[i, 2] += V[2] + (p0 * r1 - p1 * r0)
    return x1, v1


@njit(parallel=True, cache=True)
def deformation_kinetic_energy(x: np.ndarray, v: np.ndarray, m: np.ndarray, vertex_ptr: np.ndarray) -> float:
    """1/2 sum m |v - V - omega x r|^2: the kinetic energy of the grains' deformation modes (their
    velocity less its rigid part, omega = I^-1 L); selective mass scaling weighs it by lambda."""
    total = np.zeros(len(vertex_ptr) - 1)
    for g in prange(len(vertex_ptr) - 1):
        lo, hi = vertex_ptr[g], vertex_ptr[g + 1]
        J = np.empty((3, 3))
        c, u, L, _ = _grain_motion(x, v, m, lo, hi, J)
        o0, o1, o2 = _inverse_3x3(J) @ L
        u0, u1, u2 = u[0], u[1], u[2]
        e = 0.0
        for i in range(lo, hi):
            r0, r1, r2 = x[i, 0] - c[0], x[i, 1] - c[1], x[i, 2] - c[2]
            d0 = v[i, 0] - u0 - (o1 * r2 - o2 * r1)
            d1 = v[i, 1] - u1 - (o2 * r0 - o0 * r2)
            d2 = v[i, 2] - u2 - (o0 * r1 - o1 * r0)
            e += m[i] * (d0 * d0 + d1 * d1 + d2 * d2)
        total[g] = 0.5 * e
    return total.sum()


def _lumped_inertia(x: np.ndarray, m: np.ndarray, vertex_ptr: np.ndarray):
    """(masses (G,), centroids (G, 3), squared distances of the vertices from their centroid (N,),
    inertia tensors about the centroids (G, 3, 3)) of every grain's lumped masses at x."""
    starts = vertex_ptr[:-1]
    mass = np.add.reduceat(m, starts)
    grain = np.repeat(np.arange(len(mass)), np.diff(vertex_ptr))
    c = np.add.reduceat(m[:, None] * x, starts, axis=0) / mass[:, None]
    r = x - c[grain]
    r2 = np.sum(r * r, axis=1)
    J = np.add.reduceat(m[:, None, None] * (r2[:, None, None] * np.eye(3) - r[:, :, None] * r[:, None, :]), starts)
    return mass, c, r2, J


def rigid_point_mobility(reference: np.ndarray, m: np.ndarray, vertex_ptr: np.ndarray) -> np.ndarray:
    """(G,) 1/M + rho^2 / I_min of every grain: a bound on how fast any of its vertices moves along
    a unit force when the grain moves rigidly (rho its farthest vertex from the centroid, I_min its
    smallest principal moment of the lumped masses). Both are invariant under rotation, so the
    reference placement serves the whole run: the bound the explicit step's layer entry takes
    (VemBodies.node_inverse_masses); a pair's own step takes its exact rigid response (grain_frames)."""
    mass, _, r2, J = _lumped_inertia(reference, m, vertex_ptr)
    return 1.0 / mass + np.maximum.reduceat(r2, vertex_ptr[:-1]) / np.linalg.eigvalsh(J)[:, 0]


def grain_frames(x: np.ndarray, m: np.ndarray, vertex_ptr: np.ndarray):
    """(masses (G,), centroids (G, 3), principal axes (G, 3, 3) as columns, principal moments
    (G, 3)) of the lumped masses m at positions x: the grains' rigid inertia where they are now,
    the form contact.ccd.rigid_pair_inverse_masses takes."""
    mass, c, _, J = _lumped_inertia(x, m, vertex_ptr)
    moments, axes = np.linalg.eigh(J)
    # contiguous: the compiled pair kernel then takes the rigid grains' array types (one compilation)
    return mass, np.ascontiguousarray(c), np.ascontiguousarray(axes), np.ascontiguousarray(moments)
