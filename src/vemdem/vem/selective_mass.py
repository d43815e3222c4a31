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
def _cross(a, b):
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


@njit(cache=True)
def _grain_rigid_terms(f, x, v, m, lo, hi):
    """(centroid, A, omega, alpha) of the vertices lo:hi: the rigid-body acceleration's parts."""
    mass = 0.0
    c = np.zeros(3)
    vc = np.zeros(3)
    F = np.zeros(3)
    for i in range(lo, hi):
        mass += m[i]
        for k in range(3):
            c[k] += m[i] * x[i, k]
            vc[k] += m[i] * v[i, k]
            F[k] += f[i, k]
    c /= mass
    vc /= mass
    T = np.zeros(3)
    L = np.zeros(3)
    J = np.zeros((3, 3))
    for i in range(lo, hi):
        r = x[i] - c
        T += _cross(r, f[i])
        L += m[i] * _cross(r, v[i] - vc)
        r2 = r[0] * r[0] + r[1] * r[1] + r[2] * r[2]
        for a in range(3):
            J[a, a] += m[i] * r2
            for b in range(3):
                J[a, b] -= m[i] * r[a] * r[b]
    Jinv = _inverse_3x3(J)
    omega = Jinv @ L
    alpha = Jinv @ (T - _cross(omega, J @ omega))
    return c, F / mass, omega, alpha


@njit(parallel=True, cache=True)
def selective_accelerations(f: np.ndarray, x: np.ndarray, v: np.ndarray, m: np.ndarray, vertex_ptr: np.ndarray,
                            lam: float) -> np.ndarray:  # fmt: skip
    """a = M_s^-1 f for every vertex (the module's formulas): f (N, 3) the forces, x and v the
    vertices' positions and velocities (the rigid motion's angular velocity), m (N,) the lumped
    masses, lam the deformation modes' added mass factor lambda >= 0."""
    a = np.empty_like(f)
    for g in prange(len(vertex_ptr) - 1):
        lo, hi = vertex_ptr[g], vertex_ptr[g + 1]
        c, A, omega, alpha = _grain_rigid_terms(f, x, v, m, lo, hi)
        for i in range(lo, hi):
            r = x[i] - c
            rigid = A + _cross(alpha, r) + _cross(omega, _cross(omega, r))
            for k in range(3):
                a[i, k] = (f[i, k] / m[i] + lam * rigid[k]) / (1.0 + lam)
    return a


@njit(parallel=True, cache=True)
def deformation_kinetic_energy(x: np.ndarray, v: np.ndarray, m: np.ndarray, vertex_ptr: np.ndarray) -> float:
    """1/2 sum m |v - V - omega x r|^2: the kinetic energy of the grains' deformation modes (their
    velocity less its rigid part, omega = I^-1 L); selective mass scaling weighs it by lambda."""
    total = np.zeros(len(vertex_ptr) - 1)
    zero = np.zeros_like(v)
    for g in prange(len(vertex_ptr) - 1):
        lo, hi = vertex_ptr[g], vertex_ptr[g + 1]
        c, _, omega, _ = _grain_rigid_terms(zero, x, v, m, lo, hi)
        mass = 0.0
        vc = np.zeros(3)
        for i in range(lo, hi):
            mass += m[i]
            vc += m[i] * v[i]
        vc /= mass
        e = 0.0
        for i in range(lo, hi):
            d = v[i] - vc - _cross(omega, x[i] - c)
            e += m[i] * (d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
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
