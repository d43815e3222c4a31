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

The tangent of these dissipative terms is analytic (`dissipative_tangent`): forward-mode
derivatives of every quantity above in the 3 nn node coordinates, the contact point c included.
c is the stationary point of q(c) = |g(c)|^2, so implicit differentiation of J^T g = 0
(J = dg/dc = sum_i D_i x_i) gives

    (J^T J) dc = -(D_p g_b + w_p J_b)           for a unit change of node p's coordinate b,
    dg = J dc + w_p e_b,   dd = n . dg,   dn = (dg - n dd) / d,   dw_i = D_i . dc,

and the rest is the chain rule through the branches taken (stick/slip and the damping clamp are
decided on the unperturbed state, as a Newton step must). It replaced the complex-step derivative
of this same function (12 complex evaluations per pair: 2.8x the time; `complex_step_tangent`,
kept as the tests' reference, agrees to 1e-12 relative; docs/results.md "Where the time goes").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit, prange

from .fade import fade_dissipative, fade_dissipative_tangent, is_faded
from .law import normal_force, normal_stiffness_slope
from .narrow import (
    EDGE_EDGE,
    N_COORDS,
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
    (stick, slip_magnitude_limit_hit, g_t to store) evaluated on the real parts.

    Written on scalar components (the same operations in the same order as the vector form
    g = sum w_i x_i, n = g / |g|, ...): numba puts every 3-vector temporary on the heap, and
    those allocations were most of this kernel's 2 us per pair."""
    nn = N_NODES[kind]
    w0 = np.empty(6)
    D = np.empty((6, 2))
    c0, c1 = _lcp_coords(kind, xs)
    pair_weights(kind, 0.0, 0.0, w0, D)  # w(c) = w0 + D c
    w = np.zeros(6, dtype=xs.dtype)
    for i in range(6):
        w[i] = w0[i] + D[i, 0] * c0 + D[i, 1] * c1
    zero = 0.0 * xs[0, 0]
    g0, g1, g2 = zero, zero, zero  # gap vector sum w_i x_i
    r0, r1, r2 = zero, zero, zero  # relative velocity sum w_i v_i
    for i in range(nn):
        g0 += w[i] * xs[i, 0]
        g1 += w[i] * xs[i, 1]
        g2 += w[i] * xs[i, 2]
        r0 += w[i] * (v0[i, 0] + a4 * (xs[i, 0] - x0[i, 0]))
        r1 += w[i] * (v0[i, 1] + a4 * (xs[i, 1] - x0[i, 1]))
        r2 += w[i] * (v0[i, 2] + a4 * (xs[i, 2] - x0[i, 2]))
    d = np.sqrt(g0 * g0 + g1 * g1 + g2 * g2)
    n0, n1, n2 = g0 / d, g1 / d, g2 / d
    fn, k = normal_force(d, law)
    gn_dot = n0 * r0 + n1 * r1 + n2 * r2
    c_n = 2.0 * fr[ZETA] * np.sqrt(k * m_eq)
    f_damp = -c_n * gn_dot
    if (fn + f_damp).real < 0.0:
        f_damp = -fn
    f_normal = fn + f_damp
    t0, t1, t2 = zero, zero, zero  # g_t: the tangential slip since the pair's stick point
    if was_active:
        wp = pair_weights(kind, c_prev[0], c_prev[1], w0, D)  # material points of c_prev
        a0, a1, a2 = zero, zero, zero
        for i in range(nn):
            a0 += wp[i] * xs[i, 0]
            a1 += wp[i] * xs[i, 1]
            a2 += wp[i] * xs[i, 2]
        a0, a1, a2 = a0 + gt_prev[0], a1 + gt_prev[1], a2 + gt_prev[2]
        na = n0 * a0 + n1 * a1 + n2 * a2
        t0, t1, t2 = a0 - na * n0, a1 - na * n1, a2 - na * n2
    vt0, vt1, vt2 = r0 - gn_dot * n0, r1 - gn_dot * n1, r2 - gn_dot * n2
    f0 = fr[EPS_T] * t0 + fr[C_T] * vt0
    f1 = fr[EPS_T] * t1 + fr[C_T] * vt1
    f2 = fr[EPS_T] * t2 + fr[C_T] * vt2
    mu = fr[MU_S] if was_stick else fr[MU_D]
    f_try_norm = np.sqrt(f0 * f0 + f1 * f1 + f2 * f2)
    stick = f_try_norm.real <= mu * f_normal.real
    if not stick:
        f0 = fr[MU_D] * f_normal * f0 / f_try_norm
        f1 = fr[MU_D] * f_normal * f1 / f_try_norm
        f2 = fr[MU_D] * f_normal * f2 / f_try_norm
    fa0, fa1, fa2 = f_damp * n0 - f0, f_damp * n1 - f1, f_damp * n2 - f2  # force on side A
    for i in range(6):
        if i < nn:
            out[i, 0] = -w[i] * fa0
            out[i, 1] = -w[i] * fa1
            out[i, 2] = -w[i] * fa2
        else:
            for a in range(3):
                out[i, a] = 0.0
    # history to store if this state converges (return map on the elastic part)
    e0, e1, e2 = fr[EPS_T] * t0, fr[EPS_T] * t1, fr[EPS_T] * t2
    elastic_norm = np.sqrt(e0 * e0 + e1 * e1 + e2 * e2).real
    store = np.empty(3)
    limit = mu * f_normal.real
    store[0], store[1], store[2] = t0.real, t1.real, t2.real
    if elastic_norm > limit and elastic_norm > 0.0:
        scale = fr[MU_D] * f_normal.real / elastic_norm
        for a in range(3):
            store[a] = store[a] * scale
    return stick, store


@njit(cache=True)
def _pair_force(c, x, v, a4, ints, c_prev, gt_prev, was_active, was_stick, law, fr, m_eq, local_force, stick_out,
                gt_out):  # fmt: skip
    """dissipative_force of pair c into row c of the outputs; returns its gathered node positions
    and velocities. fr: (m, 5) friction parameters per pair (ContactModel.pair_friction)."""
    kind = ints[c, KIND]
    xs = np.zeros((6, 3))
    vs = np.zeros((6, 3))
    for i in range(N_NODES[kind]):
        for a in range(3):
            xs[i, a] = x[ints[c, NODE0 + i], a]
            vs[i, a] = v[ints[c, NODE0 + i], a]
    out = np.zeros((6, 3))
    stick, store = dissipative_force(kind, xs, vs, xs, a4, c_prev[c], gt_prev[c], was_active[c], was_stick[c],
                                     law, fr[c], m_eq[c], out)  # fmt: skip
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
# explicit runs never need the tangent (a fresh install's first explicit run compiles only
# dissipative_forces).
@njit(parallel=True, cache=True)
def dissipative_forces(x, v, a4, ints, c_prev, gt_prev, was_active, was_stick, law, fr, m_eq, local_force,
                       stick_out, gt_out):  # fmt: skip
    """Damping + friction residual of every pair (no tangent)."""
    for c in prange(len(ints)):  # np.int64: c is uint64 in the parallel body, a second compilation of _pair_force
        xs, _ = _pair_force(np.int64(c), x, v, a4, ints, c_prev, gt_prev, was_active, was_stick, law, fr, m_eq,
                            local_force, stick_out, gt_out)  # fmt: skip
        if is_faded(ints[c, KIND], xs, law):
            fade_dissipative(xs, law, np.int64(c), local_force)


@njit(parallel=True, cache=True)
def dissipative_terms(x, v, a4, ints, c_prev, gt_prev, was_active, was_stick, law, fr, m_eq, local_force,
                      local_tangent, stick_out, gt_out):  # fmt: skip
    """Damping + friction residual of every pair, and its analytic Jacobian (18 x 18) added to
    local_tangent (which holds the pairs' conservative tangent: one array, not two and their sum)."""
    for c in prange(len(ints)):
        xs, vs = _pair_force(np.int64(c), x, v, a4, ints, c_prev, gt_prev, was_active, was_stick, law, fr, m_eq,
                             local_force, stick_out, gt_out)  # fmt: skip
        kind = ints[c, KIND]
        if is_faded(kind, xs, law):  # the edge-edge fade weighs this residual and its Jacobian
            own = np.zeros((18, 18))
            dissipative_tangent(kind, xs, vs, a4, c_prev[c], gt_prev[c], was_active[c], was_stick[c], law, fr[c],
                                m_eq[c], own)  # fmt: skip
            fade_dissipative_tangent(xs, law, np.int64(c), local_force, own, local_tangent)
        else:
            dissipative_tangent(kind, xs, vs, a4, c_prev[c], gt_prev[c], was_active[c], was_stick[c], law, fr[c],
                                m_eq[c], local_tangent[c])  # fmt: skip


@njit(cache=True)
def _sub(u, a, v):
    """u - a v for 3-vectors (numba allocates less with these than with array expressions)."""
    return np.array([u[0] - a * v[0], u[1] - a * v[1], u[2] - a * v[2]])


@njit(cache=True)
def _dot3(u, v):  # narrow._dot, inlined here by name for the reader of this kernel
    return u[0] * v[0] + u[1] * v[1] + u[2] * v[2]


@njit(cache=True)
def dissipative_tangent(kind, xs, vs, a4, c_prev, gt_prev, was_active, was_stick, law, fr, m_eq, out):
    """d(residual)/d(x) of `dissipative_force` at xs (velocities vs there, v = vs + a4 dx), added to
    out (18, 18): row 3 i + a the residual of node i's component a, column 3 p + b node p's
    coordinate b. Forward mode, one column per node coordinate (module docstring for dc)."""
    nn = N_NODES[kind]
    m = N_COORDS[kind]
    n3 = 3 * nn
    w0 = np.empty(6)
    D = np.empty((6, 2))
    c0, c1 = _lcp_coords(kind, xs)
    w = pair_weights(kind, c0, c1, w0, D)
    # the unperturbed state, as dissipative_force computes it
    g = np.zeros(3)
    vrel = np.zeros(3)
    J = np.zeros((3, 2))
    for i in range(nn):
        for a in range(3):
            g[a] += w[i] * xs[i, a]
            vrel[a] += w[i] * vs[i, a]
            J[a, 0] += D[i, 0] * xs[i, a]
            J[a, 1] += D[i, 1] * xs[i, a]
    d = np.sqrt(_dot3(g, g))
    n = g / d
    fn, k = normal_force(d, law)
    dk_dd = normal_stiffness_slope(d, law)
    gn_dot = _dot3(n, vrel)
    c_n = 2.0 * fr[ZETA] * np.sqrt(k * m_eq)
    f_damp = -c_n * gn_dot
    clamped = fn + f_damp < 0.0
    if clamped:
        f_damp = -fn
    f_normal = fn + f_damp
    wp = np.zeros(6)
    a_vec = np.zeros(3)
    gt = np.zeros(3)
    if was_active:
        wp = pair_weights(kind, c_prev[0], c_prev[1], np.empty(6), np.empty((6, 2)))
        for i in range(nn):
            for a in range(3):
                a_vec[a] += wp[i] * xs[i, a]
        for a in range(3):
            a_vec[a] += gt_prev[a]
        gt = _sub(a_vec, _dot3(n, a_vec), n)
    vt = _sub(vrel, gn_dot, n)
    f_try = fr[EPS_T] * gt + fr[C_T] * vt
    mu = fr[MU_S] if was_stick else fr[MU_D]
    f_try_norm = np.sqrt(_dot3(f_try, f_try))
    stick = f_try_norm <= mu * f_normal
    u = f_try / f_try_norm if f_try_norm > 0.0 else np.zeros(3)
    force_on_a = f_damp * n
    if stick:
        force_on_a -= f_try
    else:
        force_on_a -= fr[MU_D] * f_normal * u
    # (J^T J)^-1 for dc (m = 0: the vertex-vertex pair has no coordinates)
    H00 = _dot3(J[:, 0], J[:, 0])
    H01 = _dot3(J[:, 0], J[:, 1])
    H11 = _dot3(J[:, 1], J[:, 1])
    det = H00 * H11 - H01 * H01
    # every derivative vector lives in one buffer for all 3 nn columns: an array expression in this
    # loop allocates, and allocations were most of the kernel's time (64 -> 23 ms for the 7,356
    # pairs of the 515-grain lid jam, one thread)
    dc = np.zeros(2)
    dg = np.zeros(3)
    dv = np.zeros(3)
    da = np.zeros(3)
    dn = np.zeros(3)
    dgt = np.zeros(3)  # stays 0 for a pair without history
    dvt = np.zeros(3)
    df_try = np.zeros(3)
    dft = np.zeros(3)
    dF = np.zeros(3)
    n_a = _dot3(n, a_vec)
    for col in range(n3):
        p = col // 3
        b = col % 3
        r0 = D[p, 0] * g[b] + w[p] * J[b, 0]
        r1 = D[p, 1] * g[b] + w[p] * J[b, 1]
        if m == 2:
            dc[0] = -(H11 * r0 - H01 * r1) / det
            dc[1] = -(H00 * r1 - H01 * r0) / det
        elif m == 1:
            dc[0] = -r0 / H00
            dc[1] = 0.0
        else:
            dc[0] = 0.0
            dc[1] = 0.0
        for a in range(3):
            dg[a] = J[a, 0] * dc[0] + J[a, 1] * dc[1]
            dv[a] = 0.0
        dg[b] += w[p]
        dv[b] += a4 * w[p]
        for i in range(nn):
            dwi = D[i, 0] * dc[0] + D[i, 1] * dc[1]
            for a in range(3):
                dv[a] += dwi * vs[i, a]
        dd = _dot3(n, dg)
        for a in range(3):
            dn[a] = (dg[a] - dd * n[a]) / d
        dfn = -k * dd
        dgn = _dot3(dn, vrel) + _dot3(n, dv)
        if clamped:
            df_damp = -dfn
        else:
            dc_n = c_n * dk_dd * dd / (2.0 * k) if k > 0.0 else 0.0
            df_damp = -(dc_n * gn_dot + c_n * dgn)
        df_normal = dfn + df_damp
        if was_active:
            for a in range(3):
                da[a] = 0.0
            da[b] = wp[p]
            dn_a = _dot3(dn, a_vec) + _dot3(n, da)
            for a in range(3):
                dgt[a] = (da[a] - dn_a * n[a]) - n_a * dn[a]
        for a in range(3):
            dvt[a] = (dv[a] - dgn * n[a]) - gn_dot * dn[a]
            df_try[a] = fr[EPS_T] * dgt[a] + fr[C_T] * dvt[a]
        if stick:
            for a in range(3):
                dft[a] = df_try[a]
        else:
            u_df = _dot3(u, df_try)
            for a in range(3):
                dft[a] = fr[MU_D] * (df_normal * u[a] + f_normal * (df_try[a] - u_df * u[a]) / f_try_norm)
        for a in range(3):
            dF[a] = df_damp * n[a] + f_damp * dn[a] - dft[a]
        for i in range(nn):
            dwi = D[i, 0] * dc[0] + D[i, 1] * dc[1]
            for a in range(3):
                out[3 * i + a, col] -= dwi * force_on_a[a] + w[i] * dF[a]


@njit(parallel=True, cache=True)
def complex_step_tangent(x, v, a4, ints, c_prev, gt_prev, was_active, was_stick, law, fr, m_eq, local_tangent):
    """The same Jacobian as the complex-step derivative of `dissipative_force` (exact to round-off,
    12 complex evaluations per pair): the tests' independent reference and the benchmark's baseline."""
    for c in prange(len(ints)):
        kind = ints[c, KIND]
        nn = N_NODES[kind]
        xs = np.zeros((6, 3))
        vs = np.zeros((6, 3))
        scale = 0.0
        for i in range(nn):
            for a in range(3):
                xs[i, a] = x[ints[c, NODE0 + i], a]
                vs[i, a] = v[ints[c, NODE0 + i], a]
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
                              law, fr[c], m_eq[c], outc)  # fmt: skip
            for r in range(3 * nn):
                local_tangent[c, r, j] = outc[r // 3, r % 3].imag / h
