"""Normal damping and Coulomb friction with static and dynamic coefficients
(formulation.md sections 2 and 3).

Per pair, with current contact point weights w(c), normal n, gap d and velocities v:

    damping   F_d = -2 zeta sqrt(k(d) m_eq) (n . v_rel)     while d < gbar; never adhesive:
              if f_n + F_d < 0 then F_d = -f_n (the total normal force F_N is then 0)
    friction  g_t = (I - n n) [ sum_i w_i(c_prev) x_i + g_t,stored ]       (trial tangential gap)
              f_try = eps_t g_t + c_t (I - n n) v_rel
              stick if |f_try| <= mu F_N, mu = mu_s after stick, mu_d after slip: f_t = f_try
              slip otherwise:                                    f_t = mu_d F_N f_try / |f_try|
    history   after a converged step: stick flag; g_t,stored = g_t, or (mu_d F_N / eps_t) g_t/|g_t|
              when |eps_t g_t| > mu F_N (return map); c_prev = c. A new pair starts from g_t = 0.

The force on side A is F_d n - f_t, applied with the weights w_i(c) (the reaction goes to B).
Our choice: the stored slip is carried to the new tangent plane by the projection (I - n n)
rather than GIRAFFE's rotation Q; the two differ at second order in the normal's rotation per
step, and the projection keeps the tangent simple.

The tangent of these dissipative terms is the complex-step derivative of this same function
(exact to round-off, not a finite difference): every quantity, the contact point c included, is
recomputed from the perturbed positions, so the linearisation is consistent by construction.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit, prange

from .law import normal_force
from .narrow import (
    EDGE_EDGE,
    N_NODES,
    VERTEX_EDGE,
    VERTEX_FACE,
    edge_edge_coords,
    pair_weights,
    vertex_edge_coord,
    vertex_face_coords,
)
from .pairs import KIND, NODE0

COMPLEX_STEP = 1e-30


@dataclass(frozen=True)
class FrictionLaw:
    mu_s: float = 0.0
    mu_d: float = 0.0
    tangential_penalty: float = 0.0  # eps_t (N/m)
    tangential_viscosity: float = 0.0  # c_t (N s/m)
    damping_ratio: float = 0.0  # zeta

    def __post_init__(self):
        if not (self.mu_s >= 0 and self.mu_d >= 0):
            raise ValueError("friction: mu_s and mu_d must be >= 0")
        if self.mu_d > self.mu_s:
            raise ValueError(f"friction: mu_d ({self.mu_d}) must not exceed mu_s ({self.mu_s})")
        if self.tangential_penalty < 0 or self.tangential_viscosity < 0 or self.damping_ratio < 0:
            raise ValueError("friction: penalty, viscosity and damping ratio must be >= 0")
        if (self.mu_s > 0 or self.mu_d > 0) and self.tangential_penalty == 0:
            raise ValueError("friction: a friction coefficient needs tangential_penalty > 0")

    @property
    def active(self) -> bool:
        return self.mu_s > 0 or self.mu_d > 0 or self.damping_ratio > 0 or self.tangential_viscosity > 0

    def packed(self) -> np.ndarray:
        return np.array([self.mu_s, self.mu_d, self.tangential_penalty, self.tangential_viscosity, self.damping_ratio])


MU_S, MU_D, EPS_T, C_T, ZETA = range(5)


@njit(cache=True)
def _lcp_coords(kind, xs):
    """The LCP solution (c0, c1) for real or complex positions (no range test)."""
    zero = 0.0 * xs[0, 0]
    if kind == VERTEX_FACE:
        u, v, _ = vertex_face_coords(xs[0], xs[1], xs[2], xs[3])
        return u, v
    if kind == EDGE_EDGE:
        s, t, _, _ = edge_edge_coords(xs[0], xs[1], xs[2], xs[3])
        return s, t
    if kind == VERTEX_EDGE:
        return vertex_edge_coord(xs[0], xs[1], xs[2]), zero
    return zero, zero


@njit(cache=True)
def dissipative_force(kind, xs, v0, x0, a4, c_prev, gt_prev, was_active, was_stick, law, fr, m_eq, out):
    """Damping and friction residual (dPhi/dx sign: minus the force) of one pair into out (6, 3).

    xs: node positions (real or complex); velocities v = v0 + a4 (xs - x0). Returns
    (stick, slip_magnitude_limit_hit, g_t to store) evaluated on the real parts."""
    nn = N_NODES[kind]
    w0 = np.empty(6)
    D = np.empty((6, 2))
    c0, c1 = _lcp_coords(kind, xs)
    pair_weights(kind, 0.0, 0.0, w0, D)  # w(c) = w0 + D c
    w = np.zeros(6, dtype=xs.dtype)
    for i in range(6):
        w[i] = w0[i] + D[i, 0] * c0 + D[i, 1] * c1
    g = np.zeros(3, dtype=xs.dtype)
    vrel = np.zeros(3, dtype=xs.dtype)
    for i in range(nn):
        vi = v0[i] + a4 * (xs[i] - x0[i])
        g += w[i] * xs[i]
        vrel += w[i] * vi
    d = np.sqrt(np.sum(g * g))
    n = g / d
    fn, k = normal_force(d, law)
    gn_dot = np.sum(n * vrel)
    c_n = 2.0 * fr[ZETA] * np.sqrt(k * m_eq)
    f_damp = -c_n * gn_dot
    if (fn + f_damp).real < 0.0:
        f_damp = -fn
    f_normal = fn + f_damp
    gt = np.zeros(3, dtype=xs.dtype)
    if was_active:
        wp = pair_weights(kind, c_prev[0], c_prev[1], np.empty(6), np.empty((6, 2)))  # material points of c_prev
        a = np.zeros(3, dtype=xs.dtype)
        for i in range(nn):
            a += wp[i] * xs[i]
        a += gt_prev
        gt = a - np.sum(n * a) * n
    vt = vrel - gn_dot * n
    f_try = fr[EPS_T] * gt + fr[C_T] * vt
    mu = fr[MU_S] if was_stick else fr[MU_D]
    f_try_norm = np.sqrt(np.sum(f_try * f_try))
    stick = f_try_norm.real <= mu * f_normal.real
    if stick:
        ft = f_try
    else:
        ft = fr[MU_D] * f_normal * f_try / f_try_norm
    force_on_a = f_damp * n - ft
    for i in range(6):
        for a in range(3):
            out[i, a] = -w[i] * force_on_a[a] if i < nn else 0.0
    # history to store if this state converges (return map on the elastic part)
    elastic = fr[EPS_T] * gt
    elastic_norm = np.sqrt(np.sum(elastic * elastic)).real
    store = np.empty(3)
    limit = mu * f_normal.real
    for a in range(3):
        store[a] = gt[a].real
    if elastic_norm > limit and elastic_norm > 0.0:
        scale = fr[MU_D] * f_normal.real / elastic_norm
        for a in range(3):
            store[a] = gt[a].real * scale
    return stick, store


@njit(cache=True)
def _pair_force(c, x, v, a4, ints, c_prev, gt_prev, was_active, was_stick, law, fr, m_eq, local_force, stick_out,
                gt_out):  # fmt: skip
    """dissipative_force of pair c into row c of the outputs; returns its gathered node positions
    and velocities."""
    kind = ints[c, KIND]
    xs = np.zeros((6, 3))
    vs = np.zeros((6, 3))
    for i in range(N_NODES[kind]):
        for a in range(3):
            xs[i, a] = x[ints[c, NODE0 + i], a]
            vs[i, a] = v[ints[c, NODE0 + i], a]
    out = np.zeros((6, 3))
    stick, store = dissipative_force(kind, xs, vs, xs, a4, c_prev[c], gt_prev[c], was_active[c], was_stick[c],
                                     law, fr, m_eq[c], out)  # fmt: skip
    stick_out[c] = stick
    # element loops, not slice assignments: numba compiles those with a string-formatting error
    # path, seconds of a fresh install's first run
    for a in range(3):
        gt_out[c, a] = store[a]
    for i in range(6):
        for a in range(3):
            local_force[c, i, a] = out[i, a]
    return xs, vs


# Two kernels rather than one with a tangent flag: numba compiles every branch of a kernel, and
# the complex-step branch compiles a complex copy of the friction code, which explicit runs never
# call (a fresh install's first explicit run compiles only dissipative_forces).
@njit(parallel=True, cache=True)
def dissipative_forces(x, v, a4, ints, c_prev, gt_prev, was_active, was_stick, law, fr, m_eq, local_force,
                       stick_out, gt_out):  # fmt: skip
    """Damping + friction residual of every pair (no tangent)."""
    for c in prange(len(ints)):
        _pair_force(c, x, v, a4, ints, c_prev, gt_prev, was_active, was_stick, law, fr, m_eq, local_force, stick_out,
                    gt_out)  # fmt: skip


@njit(parallel=True, cache=True)
def dissipative_terms(x, v, a4, ints, c_prev, gt_prev, was_active, was_stick, law, fr, m_eq, local_force,
                      local_tangent, stick_out, gt_out):  # fmt: skip
    """Damping + friction residual of every pair and its complex-step Jacobian (18 x 18)."""
    for c in prange(len(ints)):
        xs, vs = _pair_force(c, x, v, a4, ints, c_prev, gt_prev, was_active, was_stick, law, fr, m_eq, local_force,
                             stick_out, gt_out)  # fmt: skip
        kind = ints[c, KIND]
        nn = N_NODES[kind]
        scale = 0.0
        for i in range(nn):
            for a in range(3):
                scale = max(scale, abs(xs[i, a]))
        h = COMPLEX_STEP * max(scale, 1e-300)
        xc = np.zeros((6, 3), dtype=np.complex128)
        outc = np.zeros((6, 3), dtype=np.complex128)
        for j in range(3 * nn):
            for i in range(nn):
                for a in range(3):
                    xc[i, a] = xs[i, a]
            xc[j // 3, j % 3] += 1j * h
            dissipative_force(kind, xc, vs, xs, a4, c_prev[c], gt_prev[c], was_active[c], was_stick[c],
                              law, fr, m_eq[c], outc)  # fmt: skip
            for r in range(3 * nn):
                local_tangent[c, r, j] = outc[r // 3, r % 3].imag / h
