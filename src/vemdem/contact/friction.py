"""Normal damping and Coulomb friction with static and dynamic coefficients
(docs/contact.md).

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

from .law import normal_force, normal_stiffness_slope
from .narrow import (
    EDGE_EDGE,
    N_COORDS,
    N_NODES,
    VERTEX_EDGE,
    VERTEX_FACE,
    edge_edge_coords,
    pair_weights_into,
    vertex_edge_coord,
    vertex_face_coords,
)
from .pairs import KIND, NODE0, PAIR_CHUNKS, chunk_range, pair_nodes

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
def dissipative_force(kind, xs, v0, x0, a4, c_prev, gt_prev, was_active, was_stick, law, fr, m_eq, out,
                      w0, D, wp, w, store):  # fmt: skip
    """Damping and friction residual (dPhi/dx sign: minus the force) of one pair into out (6, 3).

    xs: node positions (real or complex); velocities v = v0 + a4 (xs - x0). Returns the stick flag
    and writes the g_t to store into store (3,), both evaluated on the real parts. w0 (6,), D (6, 2),
    wp (6,) and w (6,) of xs's type are the caller's scratch (pairs.PAIR_CHUNKS: none made per pair).

    Written on scalar components (the same operations in the same order as the vector form
    g = sum w_i x_i, n = g / |g|, ...): numba puts every 3-vector temporary on the heap, and
    those allocations were most of this kernel's 2 us per pair."""
    nn = N_NODES[kind]
    c0, c1 = _lcp_coords(kind, xs)
    pair_weights_into(kind, 0.0, 0.0, w0, D, wp)  # w(c) = w0 + D c
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
        pair_weights_into(kind, c_prev[0], c_prev[1], w0, D, wp)  # material points of c_prev
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
    limit = mu * f_normal.real
    store[0], store[1], store[2] = t0.real, t1.real, t2.real
    if elastic_norm > limit and elastic_norm > 0.0:
        scale = fr[MU_D] * f_normal.real / elastic_norm
        for a in range(3):
            store[a] = store[a] * scale
    return stick


VECTORS = 17  # 3-vectors of dissipative_tangent (rows of its scratch)


@njit(cache=True)
def _pair_force(c, x, v, a4, ints, c_prev, gt_prev, was_active, was_stick, law, fr, m_eq, local_force, stick_out,
                gt_out, xs, vs, out, w0, D, wp, w, store):  # fmt: skip
    """dissipative_force of pair c into row c of the outputs, with its node positions and
    velocities gathered into xs and vs. fr: (m, 5) friction parameters per pair
    (ContactModel.pair_friction)."""
    kind = ints[c, KIND]
    pair_nodes(x, ints, c, N_NODES[kind], xs)
    pair_nodes(v, ints, c, N_NODES[kind], vs)
    stick_out[c] = dissipative_force(kind, xs, vs, xs, a4, c_prev[c], gt_prev[c], was_active[c], was_stick[c],
                                     law, fr[c], m_eq[c], out, w0, D, wp, w, store)  # fmt: skip
    # element loops, not slice assignments: numba compiles those with a string-formatting error
    # path, seconds of a fresh install's first run
    for a in range(3):
        gt_out[c, a] = store[a]
    for i in range(6):
        for a in range(3):
            local_force[c, i, a] = out[i, a]


# Two kernels rather than one with a tangent flag: numba compiles every branch of a kernel, and
# explicit runs never need the tangent (a fresh install's first explicit run compiles only
# dissipative_forces).
@njit(parallel=True, cache=True)
def dissipative_forces(x, v, a4, ints, c_prev, gt_prev, was_active, was_stick, law, fr, m_eq, local_force,
                       stick_out, gt_out):  # fmt: skip
    """Damping + friction residual of every pair (no tangent)."""
    n = len(ints)
    for k in prange(PAIR_CHUNKS):
        xs, vs, out = np.zeros((6, 3)), np.zeros((6, 3)), np.zeros((6, 3))
        w0, D, wp, w, store = np.zeros(6), np.zeros((6, 2)), np.zeros(6), np.zeros(6), np.zeros(3)
        lo, hi = chunk_range(np.int64(k), PAIR_CHUNKS, n)  # np.int64: k is uint64 in the parallel body
        for c in range(lo, hi):
            _pair_force(c, x, v, a4, ints, c_prev, gt_prev, was_active, was_stick, law, fr, m_eq, local_force,
                        stick_out, gt_out, xs, vs, out, w0, D, wp, w, store)  # fmt: skip


@njit(parallel=True, cache=True)
def dissipative_terms(x, v, a4, ints, c_prev, gt_prev, was_active, was_stick, law, fr, m_eq, local_force,
                      local_tangent, stick_out, gt_out):  # fmt: skip
    """Damping + friction residual of every pair, and its analytic Jacobian (18 x 18) added to
    local_tangent (which holds the pairs' conservative tangent: one array, not two and their sum)."""
    n = len(ints)
    for k in prange(PAIR_CHUNKS):
        xs, vs, out = np.zeros((6, 3)), np.zeros((6, 3)), np.zeros((6, 3))
        w0, D, wp, w, store = np.zeros(6), np.zeros((6, 2)), np.zeros(6), np.zeros(6), np.zeros(3)
        J, vec = np.zeros((3, 2)), np.zeros((VECTORS, 3))
        lo, hi = chunk_range(np.int64(k), PAIR_CHUNKS, n)
        for c in range(lo, hi):
            _pair_force(c, x, v, a4, ints, c_prev, gt_prev, was_active, was_stick, law, fr, m_eq, local_force,
                        stick_out, gt_out, xs, vs, out, w0, D, wp, w, store)  # fmt: skip
            dissipative_tangent(ints[c, KIND], xs, vs, a4, c_prev[c], gt_prev[c], was_active[c], was_stick[c], law,
                                fr[c], m_eq[c], local_tangent[c], w0, D, wp, w, J, vec)  # fmt: skip


@njit(cache=True)
def _dot3(u, v):  # narrow._dot, inlined here by name for the reader of this kernel
    return u[0] * v[0] + u[1] * v[1] + u[2] * v[2]


@njit(cache=True)
def dissipative_tangent(kind, xs, vs, a4, c_prev, gt_prev, was_active, was_stick, law, fr, m_eq, out,
                        w0, D, wp, w, J, vec):  # fmt: skip
    """d(residual)/d(x) of `dissipative_force` at xs (velocities vs there, v = vs + a4 dx), added to
    out (18, 18): row 3 i + a the residual of node i's component a, column 3 p + b node p's
    coordinate b. Forward mode, one column per node coordinate (module docstring for dc).
    w0, D, wp, w, J (3, 2) and vec (VECTORS, 3) are the caller's scratch, every 3-vector a row of
    vec: allocations were most of this kernel's time (the 515-grain lid jam, one thread: 64 -> 23 ms
    for 7,356 pairs when the column loop's vector temporaries were hoisted; with none left here and in
    dissipative_force, `dissipative_terms` on 7,683 pairs 22.4 -> 14.4 ms, docs/results.md)."""
    nn = N_NODES[kind]
    m = N_COORDS[kind]
    n3 = 3 * nn
    c0, c1 = _lcp_coords(kind, xs)
    pair_weights_into(kind, c0, c1, w0, D, w)
    g, vrel, n, a_vec, gt, vt = vec[0], vec[1], vec[2], vec[3], vec[4], vec[5]
    f_try, u, force_on_a = vec[6], vec[7], vec[8]
    dg, dv, da, dn, dgt, dvt, df_try, dft = vec[9], vec[10], vec[11], vec[12], vec[13], vec[14], vec[15], vec[16]
    # the unperturbed state, as dissipative_force computes it
    for a in range(3):
        g[a] = 0.0
        vrel[a] = 0.0
        J[a, 0] = 0.0
        J[a, 1] = 0.0
        a_vec[a] = 0.0
        gt[a] = 0.0
        dgt[a] = 0.0  # stays 0 for a pair without history
    for i in range(nn):
        for a in range(3):
            g[a] += w[i] * xs[i, a]
            vrel[a] += w[i] * vs[i, a]
            J[a, 0] += D[i, 0] * xs[i, a]
            J[a, 1] += D[i, 1] * xs[i, a]
    d = np.sqrt(_dot3(g, g))
    for a in range(3):
        n[a] = g[a] / d
    fn, k = normal_force(d, law)
    dk_dd = normal_stiffness_slope(d, law)
    gn_dot = _dot3(n, vrel)
    c_n = 2.0 * fr[ZETA] * np.sqrt(k * m_eq)
    f_damp = -c_n * gn_dot
    clamped = fn + f_damp < 0.0
    if clamped:
        f_damp = -fn
    f_normal = fn + f_damp
    for i in range(6):
        wp[i] = 0.0
    if was_active:
        # the weights of c_prev; w0 and D are those of the kind, whatever the coordinates
        pair_weights_into(kind, c_prev[0], c_prev[1], w0, D, wp)
        for i in range(nn):
            for a in range(3):
                a_vec[a] += wp[i] * xs[i, a]
        for a in range(3):
            a_vec[a] += gt_prev[a]
        s = _dot3(n, a_vec)
        for a in range(3):
            gt[a] = a_vec[a] - s * n[a]
    for a in range(3):
        vt[a] = vrel[a] - gn_dot * n[a]
    for a in range(3):
        f_try[a] = fr[EPS_T] * gt[a] + fr[C_T] * vt[a]
    mu = fr[MU_S] if was_stick else fr[MU_D]
    f_try_norm = np.sqrt(_dot3(f_try, f_try))
    stick = f_try_norm <= mu * f_normal
    for a in range(3):
        u[a] = f_try[a] / f_try_norm if f_try_norm > 0.0 else 0.0
        force_on_a[a] = f_damp * n[a]
        if stick:
            force_on_a[a] -= f_try[a]
        else:
            force_on_a[a] -= fr[MU_D] * f_normal * u[a]
    # (J^T J)^-1 for dc (m = 0: the vertex-vertex pair has no coordinates)
    H00 = _dot3(J[:, 0], J[:, 0])
    H01 = _dot3(J[:, 0], J[:, 1])
    H11 = _dot3(J[:, 1], J[:, 1])
    det = H00 * H11 - H01 * H01
    n_a = _dot3(n, a_vec)
    for col in range(n3):
        p = col // 3
        b = col % 3
        r0 = D[p, 0] * g[b] + w[p] * J[b, 0]
        r1 = D[p, 1] * g[b] + w[p] * J[b, 1]
        if m == 2:
            dc0 = -(H11 * r0 - H01 * r1) / det
            dc1 = -(H00 * r1 - H01 * r0) / det
        elif m == 1:
            dc0 = -r0 / H00
            dc1 = 0.0
        else:
            dc0 = 0.0
            dc1 = 0.0
        for a in range(3):
            dg[a] = J[a, 0] * dc0 + J[a, 1] * dc1
            dv[a] = 0.0
        dg[b] += w[p]
        dv[b] += a4 * w[p]
        for i in range(nn):
            dwi = D[i, 0] * dc0 + D[i, 1] * dc1
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
        for i in range(nn):
            dwi = D[i, 0] * dc0 + D[i, 1] * dc1
            for a in range(3):
                dFa = df_damp * n[a] + f_damp * dn[a] - dft[a]
                out[3 * i + a, col] -= dwi * force_on_a[a] + w[i] * dFa


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
        w0, D, wp, store = np.zeros(6), np.zeros((6, 2)), np.zeros(6), np.zeros(3)
        w = np.zeros(6, dtype=np.complex128)
        for j in range(3 * nn):
            for i in range(nn):
                for a in range(3):
                    xc[i, a] = xs[i, a]
            xc[j // 3, j % 3] += 1j * h
            dissipative_force(kind, xc, vs, xs, a4, c_prev[c], gt_prev[c], was_active[c], was_stick[c],
                              law, fr[c], m_eq[c], outc, w0, D, wp, w, store)  # fmt: skip
            for r in range(3 * nn):
                local_tangent[c, r, j] = outc[r // 3, r % 3].imag / h
