"""Moving stiff grains along a Newton update: rigid part applied as a finite rotation.

A Newton update dx of a grain's vertices carries its rotation linearised, phi x r: applied as
is, it stretches the grain by |phi|^2 |r| / 2, and at E ~ 1e11 Pa that stretch costs more
residual than everything else in the step, so Newton spends iterations pulling it back
(a free grain spinning 0.01 rad per step needed 5 iterations, 0.1 rad per step 9; docs/dynamics.md).

Each grain's update is split, with the vertices' mass weights m_i about the grain's centroid c,
into the rigid motion that fits it best and what remains:

    t = sum m_i dx_i / sum m_i,   J phi = sum m_i r_i x dx_i,   J = sum m_i (|r_i|^2 I - r_i r_i^T)
    d_i = dx_i - t - phi x r_i                                                    (r_i = x_i - c)

and the grain is moved along the curve x_i(alpha) = c + alpha t + Q(alpha phi) (r_i + alpha d_i),
Q the rotation of vector alpha phi (Rodrigues). It agrees with x + alpha dx to first order in
alpha dx, so Newton's fixed point and its quadratic convergence are those of the plain update.
Every point of a grain's surface (a convex combination of its vertices) moves by at most
alpha (|t| + |phi| max|r_i| + max|d_i|), and each vertex departs from x_i + alpha dx_i by at most
alpha e_i (path_excess): the bounds conservative advancement uses.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange


@njit(cache=True)
def _rotate(phi0, phi1, phi2, r0, r1, r2):
    """Q(phi) r by Rodrigues' formula (Q = I for |phi| = 0)."""
    th = np.sqrt(phi0 * phi0 + phi1 * phi1 + phi2 * phi2)
    if th < 1e-300:
        return r0, r1, r2
    k0, k1, k2 = phi0 / th, phi1 / th, phi2 / th
    c, s = np.cos(th), np.sin(th)
    kr = k0 * r0 + k1 * r1 + k2 * r2
    x0, x1, x2 = k1 * r2 - k2 * r1, k2 * r0 - k0 * r2, k0 * r1 - k1 * r0
    return (r0 * c + x0 * s + k0 * kr * (1 - c), r1 * c + x1 * s + k1 * kr * (1 - c), r2 * c + x2 * s + k2 * kr * (1 - c))


@njit(cache=True)
def _split_grain(x, dx, m, lo, hi, out_c, out_t, out_phi):
    """Centroid, translation and rotation vector of vertices lo:hi (writes into the out arrays)."""
    mass = 0.0
    c = np.zeros(3)
    t = np.zeros(3)
    for i in range(lo, hi):
        mass += m[i]
        for k in range(3):
            c[k] += m[i] * x[i, k]
            t[k] += m[i] * dx[i, k]
    c /= mass
    t /= mass
    J = np.zeros((3, 3))
    b = np.zeros(3)
    r = np.empty(3)  # filled per vertex: an array expression x[i] - c would be a heap allocation per vertex
    u = np.empty(3)
    for i in range(lo, hi):
        for k in range(3):
            r[k] = x[i, k] - c[k]
            u[k] = dx[i, k] - t[k]
        rr = r[0] * r[0] + r[1] * r[1] + r[2] * r[2]
        for a in range(3):
            J[a, a] += m[i] * rr
            for k in range(3):
                J[a, k] -= m[i] * r[a] * r[k]
        b[0] += m[i] * (r[1] * u[2] - r[2] * u[1])
        b[1] += m[i] * (r[2] * u[0] - r[0] * u[2])
        b[2] += m[i] * (r[0] * u[1] - r[1] * u[0])
    out_c[:] = c
    out_t[:] = t
    out_phi[:] = np.linalg.solve(J, b)


@njit(cache=True, parallel=True)
def rigid_split(x, dx, m, vertex_ptr):
    """Per grain: centroid c, translation t, rotation vector phi, and the largest surface
    displacement bound |t| + |phi| max|r| + max|d| of the update (see the module docstring)."""
    n = len(vertex_ptr) - 1
    c = np.zeros((n, 3))
    t = np.zeros((n, 3))
    phi = np.zeros((n, 3))
    bound = np.zeros(n)
    for g in prange(n):
        lo, hi = vertex_ptr[g], vertex_ptr[g + 1]
        _split_grain(x, dx, m, lo, hi, c[g], t[g], phi[g])
        p = phi[g]
        rmax, dmax = 0.0, 0.0
        for i in range(lo, hi):
            r0, r1, r2 = x[i, 0] - c[g, 0], x[i, 1] - c[g, 1], x[i, 2] - c[g, 2]  # scalars: no allocation per vertex
            rmax = max(rmax, np.sqrt(r0**2 + r1**2 + r2**2))
            d0 = dx[i, 0] - t[g, 0] - (p[1] * r2 - p[2] * r1)
            d1 = dx[i, 1] - t[g, 1] - (p[2] * r0 - p[0] * r2)
            d2 = dx[i, 2] - t[g, 2] - (p[0] * r1 - p[1] * r0)
            dmax = max(dmax, np.sqrt(d0 * d0 + d1 * d1 + d2 * d2))
        bound[g] = np.sqrt(t[g, 0] ** 2 + t[g, 1] ** 2 + t[g, 2] ** 2) + np.sqrt(p[0] ** 2 + p[1] ** 2 + p[2] ** 2) * rmax + dmax
    return c, t, phi, bound


@njit(cache=True, parallel=True)
def move_rigidly(x, dx, vertex_ptr, c, t, phi, alpha):
    """x(alpha) = c + alpha t + Q(alpha phi) (r + alpha d) for every grain (module docstring)."""
    out = np.empty_like(x)
    n = len(vertex_ptr) - 1
    for g in prange(n):
        p0, p1, p2 = phi[g, 0], phi[g, 1], phi[g, 2]
        for i in range(vertex_ptr[g], vertex_ptr[g + 1]):
            r0, r1, r2 = x[i, 0] - c[g, 0], x[i, 1] - c[g, 1], x[i, 2] - c[g, 2]
            d0 = dx[i, 0] - t[g, 0] - (p1 * r2 - p2 * r1)
            d1 = dx[i, 1] - t[g, 1] - (p2 * r0 - p0 * r2)
            d2 = dx[i, 2] - t[g, 2] - (p0 * r1 - p1 * r0)
            q0, q1, q2 = _rotate(alpha * p0, alpha * p1, alpha * p2, r0 + alpha * d0, r1 + alpha * d1, r2 + alpha * d2)
            out[i, 0] = c[g, 0] + alpha * t[g, 0] + q0
            out[i, 1] = c[g, 1] + alpha * t[g, 1] + q1
            out[i, 2] = c[g, 2] + alpha * t[g, 2] + q2
    return out


@njit(cache=True, parallel=True)
def path_excess(x, dx, vertex_ptr, c, t, phi):
    """Per vertex, e_i with |x_i(alpha) - x_i - alpha dx_i| <= alpha e_i for alpha <= 1:
    (1 - cos th) <= th^2 / 2 and |sin th - th| <= th^3 / 6 give the rotation's departure from its
    tangent, |Q d - d| <= th |d| the rotated deformation's:
        e_i = |phi|^2 |r_i| (1/2 + |phi| / 6) + |phi| |d_i|"""
    out = np.empty(len(x))
    for g in prange(len(vertex_ptr) - 1):
        p = phi[g]
        th = np.sqrt(p[0] ** 2 + p[1] ** 2 + p[2] ** 2)
        for i in range(vertex_ptr[g], vertex_ptr[g + 1]):
            r0, r1, r2 = x[i, 0] - c[g, 0], x[i, 1] - c[g, 1], x[i, 2] - c[g, 2]
            d0 = dx[i, 0] - t[g, 0] - (p[1] * r2 - p[2] * r1)
            d1 = dx[i, 1] - t[g, 1] - (p[2] * r0 - p[0] * r2)
            d2 = dx[i, 2] - t[g, 2] - (p[0] * r1 - p[1] * r0)
            rn = np.sqrt(r0**2 + r1**2 + r2**2)
            out[i] = th * th * rn * (0.5 + th / 6.0) + th * np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    return out


def rigid_part(x, dx, weights, vertex_ptr):
    """t + phi x r of every vertex: the rigid motion that fits dx best, grain by grain."""
    c, t, phi, _ = rigid_split(x, dx, weights, vertex_ptr)
    g = np.repeat(np.arange(len(vertex_ptr) - 1), np.diff(vertex_ptr))
    return t[g] + np.cross(phi[g], x - c[g])


class RigidRetraction:
    """One Newton update dx at x, split once; `at(alpha)` moves the grains along it and `bounds`
    are the surface displacement bounds of alpha = 1 (conservative advancement)."""

    def __init__(self, x: np.ndarray, dx: np.ndarray, weights: np.ndarray, vertex_ptr: np.ndarray):
        self.x, self.dx, self.vertex_ptr = x, dx, vertex_ptr
        self.c, self.t, self.phi, self.bounds = rigid_split(x, dx, weights, vertex_ptr)

    def excess(self) -> np.ndarray:
        """path_excess of this update (per vertex)."""
        return path_excess(self.x, self.dx, self.vertex_ptr, self.c, self.t, self.phi)

    def at(self, alpha: float) -> np.ndarray:
        return move_rigidly(self.x, self.dx, self.vertex_ptr, self.c, self.t, self.phi, float(alpha))
