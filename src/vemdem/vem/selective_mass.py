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
def _grain_rigid_terms(f, x, v, m, lo, hi, out):
    """The rigid-body acceleration's parts of the vertices lo:hi into out (4, 3): centroid, A,
    omega, alpha. Written with scalars: small arrays made per vertex cost more than the sums."""
    mass = 0.0
    c0 = c1 = c2 = u0 = u1 = u2 = F0 = F1 = F2 = 0.0
    for i in range(lo, hi):
        mi = m[i]
        mass += mi
        c0 += mi * x[i, 0]
        c1 += mi * x[i, 1]
        c2 += mi * x[i, 2]
        u0 += mi * v[i, 0]
        u1 += mi * v[i, 1]
        u2 += mi * v[i, 2]
        F0 += f[i, 0]
        F1 += f[i, 1]
        F2 += f[i, 2]
    c0, c1, c2, u0, u1, u2 = c0 / mass, c1 / mass, c2 / mass, u0 / mass, u1 / mass, u2 / mass
    T = np.zeros(3)
    L = np.zeros(3)
    J = np.zeros((3, 3))
    for i in range(lo, hi):
        mi = m[i]
        r0, r1, r2 = x[i, 0] - c0, x[i, 1] - c1, x[i, 2] - c2
        w0, w1, w2 = v[i, 0] - u0, v[i, 1] - u1, v[i, 2] - u2
        T[0] += r1 * f[i, 2] - r2 * f[i, 1]
        T[1] += r2 * f[i, 0] - r0 * f[i, 2]
        T[2] += r0 * f[i, 1] - r1 * f[i, 0]
        L[0] += mi * (r1 * w2 - r2 * w1)
        L[1] += mi * (r2 * w0 - r0 * w2)
        L[2] += mi * (r0 * w1 - r1 * w0)
        r2sum = r0 * r0 + r1 * r1 + r2 * r2
        J[0, 0] += mi * (r2sum - r0 * r0)
        J[1, 1] += mi * (r2sum - r1 * r1)
        J[2, 2] += mi * (r2sum - r2 * r2)
        J[0, 1] -= mi * r0 * r1
        J[0, 2] -= mi * r0 * r2
        J[1, 2] -= mi * r1 * r2
    J[1, 0], J[2, 0], J[2, 1] = J[0, 1], J[0, 2], J[1, 2]
    Jinv = _inverse_3x3(J)
    omega = Jinv @ L
    Jw = J @ omega
    gyro = np.array([omega[1] * Jw[2] - omega[2] * Jw[1], omega[2] * Jw[0] - omega[0] * Jw[2],
                     omega[0] * Jw[1] - omega[1] * Jw[0]])  # fmt: skip
    alpha = Jinv @ (T - gyro)
    out[0, 0], out[0, 1], out[0, 2] = c0, c1, c2
    out[1, 0], out[1, 1], out[1, 2] = F0 / mass, F1 / mass, F2 / mass
    out[2] = omega
    out[3] = alpha
    return u0, u1, u2


@njit(parallel=True, cache=True)
def selective_accelerations(f: np.ndarray, x: np.ndarray, v: np.ndarray, m: np.ndarray, vertex_ptr: np.ndarray,
                            lam: float) -> np.ndarray:  # fmt: skip
    """a = M_s^-1 f for every vertex (the module's formulas): f (N, 3) the forces, x and v the
    vertices' positions and velocities (the rigid motion's angular velocity), m (N,) the lumped
    masses, lam the deformation modes' added mass factor lambda >= 0."""
    a = np.empty_like(f)
    share = lam / (1.0 + lam)
    for g in prange(len(vertex_ptr) - 1):
        lo, hi = vertex_ptr[g], vertex_ptr[g + 1]
        t = np.empty((4, 3))
        _grain_rigid_terms(f, x, v, m, lo, hi, t)
        o0, o1, o2 = t[2, 0], t[2, 1], t[2, 2]
        b0, b1, b2 = t[3, 0], t[3, 1], t[3, 2]
        for i in range(lo, hi):
            r0, r1, r2 = x[i, 0] - t[0, 0], x[i, 1] - t[0, 1], x[i, 2] - t[0, 2]
            s0, s1, s2 = o1 * r2 - o2 * r1, o2 * r0 - o0 * r2, o0 * r1 - o1 * r0  # omega x r
            rigid0 = t[1, 0] + b1 * r2 - b2 * r1 + o1 * s2 - o2 * s1
            rigid1 = t[1, 1] + b2 * r0 - b0 * r2 + o2 * s0 - o0 * s2
            rigid2 = t[1, 2] + b0 * r1 - b1 * r0 + o0 * s1 - o1 * s0
            inverse = 1.0 / ((1.0 + lam) * m[i])
            a[i, 0] = f[i, 0] * inverse + share * rigid0
            a[i, 1] = f[i, 1] * inverse + share * rigid1
            a[i, 2] = f[i, 2] * inverse + share * rigid2
    return a


@njit(parallel=True, cache=True)
def deformation_kinetic_energy(x: np.ndarray, v: np.ndarray, m: np.ndarray, vertex_ptr: np.ndarray) -> float:
    """1/2 sum m |v - V - omega x r|^2: the kinetic energy of the grains' deformation modes (their
    velocity less its rigid part, omega = I^-1 L); selective mass scaling weighs it by lambda."""
    total = np.zeros(len(vertex_ptr) - 1)
    zero = np.zeros_like(v)
    for g in prange(len(vertex_ptr) - 1):
        lo, hi = vertex_ptr[g], vertex_ptr[g + 1]
        t = np.empty((4, 3))
        u0, u1, u2 = _grain_rigid_terms(zero, x, v, m, lo, hi, t)
        o0, o1, o2 = t[2, 0], t[2, 1], t[2, 2]
        e = 0.0
        for i in range(lo, hi):
            r0, r1, r2 = x[i, 0] - t[0, 0], x[i, 1] - t[0, 1], x[i, 2] - t[0, 2]
            d0 = v[i, 0] - u0 - (o1 * r2 - o2 * r1)
            d1 = v[i, 1] - u1 - (o2 * r0 - o0 * r2)
            d2 = v[i, 2] - u2 - (o0 * r1 - o1 * r0)
            e += m[i] * (d0 * d0 + d1 * d1 + d2 * d2)
        total[g] = 0.5 * e
    return total.sum()


def rigid_point_mobility(reference: np.ndarray, m: np.ndarray, vertex_ptr: np.ndarray) -> np.ndarray:
    """(G,) 1/M + rho^2 / I_min of every grain: a bound on how fast any of its vertices moves along
    a unit force when the grain moves rigidly (rho its farthest vertex from the centroid, I_min its
    smallest principal moment of the lumped masses). Both are invariant under rotation, so the
    reference placement serves the whole run; a scaled grain's contacts see this mobility as
    lambda grows (ccd.selective_pair_inverse_masses)."""
    starts = vertex_ptr[:-1]
    mass = np.add.reduceat(m, starts)
    grain = np.repeat(np.arange(len(mass)), np.diff(vertex_ptr))
    c = np.add.reduceat(m[:, None] * reference, starts, axis=0) / mass[:, None]
    r = reference - c[grain]
    r2 = np.sum(r * r, axis=1)
    J = np.add.reduceat(m[:, None, None] * (r2[:, None, None] * np.eye(3) - r[:, :, None] * r[:, None, :]), starts)
    return 1.0 / mass + np.maximum.reduceat(r2, starts) / np.linalg.eigvalsh(J)[:, 0]
