"""Local Contact Problems of paper eq. 9-11 in their degenerate forms, in closed form.

Every contact pair is a small element over at most 6 vertices (3 on each side). Its gap vector
is affine in the convective coordinates c (m <= 2 of them on each side, 0 to 4 in all):

    g(x, c) = sum_i w_i(c) x_i,   w(c) = w0 + D c   (w > 0 on side A, w < 0 on side B)

    vertex-face   A: p            B: (1-u-v) t0 + u t1 + v t2          c = (u, v)
    edge-edge     A: (1-s) a0 + s a1     B: (1-t) b0 + t b1            c = (s, t)
    vertex-edge   A: p            B: (1-t) e0 + t e1                   c = (t)
    vertex-vertex A: p            B: q                                 c = ()

The LCP (eq. 11) is stationarity of q = |g|^2 in c; for flat triangles and straight edges it is
linear, solved here in closed form. A pair is *in range* when c lies strictly inside its features
(open triangle, open edge); the pair's gap is then the distance between the two features.
"""

from __future__ import annotations

import numpy as np
from numba import njit

VERTEX_FACE, EDGE_EDGE, VERTEX_EDGE, VERTEX_VERTEX = 0, 1, 2, 3
PAIR_NAMES = ("vertex-face", "edge-edge", "vertex-edge", "vertex-vertex")
N_NODES = (4, 4, 3, 2)
N_COORDS = (2, 2, 1, 0)

# Edges closer to parallel than this (squared sine of their angle) have no isolated closest
# point pair; their contact is carried by the vertex-edge pairs at the ends of their overlap.
PARALLEL_SIN2 = 1e-10
# A coordinate counts as inside its feature when it is this far (relative) from the boundary;
# points closer to an edge or vertex belong to that lower-dimensional feature's pair.
RANGE_TOL = 1e-12


@njit(cache=True)
def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(cache=True)
def vertex_face_coords(p, t0, t1, t2):
    """(u, v, det): barycentric coordinates of the projection of p on the triangle's plane, for
    real or complex positions (the complex-step reference tangent of friction.py calls it too)."""
    # scalar components, the same operations in the same order as with e1 = t1 - t0 and _dot:
    # numba puts every 3-vector temporary on the heap (the friction tangent calls this per pair)
    e10, e11, e12 = t1[0] - t0[0], t1[1] - t0[1], t1[2] - t0[2]
    e20, e21, e22 = t2[0] - t0[0], t2[1] - t0[1], t2[2] - t0[2]
    r0, r1, r2 = p[0] - t0[0], p[1] - t0[1], p[2] - t0[2]
    a11 = e10 * e10 + e11 * e11 + e12 * e12
    a12 = e10 * e20 + e11 * e21 + e12 * e22
    a22 = e20 * e20 + e21 * e21 + e22 * e22
    b1 = r0 * e10 + r1 * e11 + r2 * e12
    b2 = r0 * e20 + r1 * e21 + r2 * e22
    det = a11 * a22 - a12 * a12
    return (b1 * a22 - b2 * a12) / det, (b2 * a11 - b1 * a12) / det, det


@njit(cache=True)
def vertex_edge_coord(p, e0, e1):
    """t of the projection of p on the line through the edge (real or complex)."""
    d0, d1, d2 = e1[0] - e0[0], e1[1] - e0[1], e1[2] - e0[2]
    r0, r1, r2 = p[0] - e0[0], p[1] - e0[1], p[2] - e0[2]
    return (r0 * d0 + r1 * d1 + r2 * d2) / (d0 * d0 + d1 * d1 + d2 * d2)


@njit(cache=True)
def edge_edge_coords(a0, a1, b0, b1):
    """(s, t, det, aa * bb): closest points of the two lines (real or complex)."""
    da0, da1, da2 = a1[0] - a0[0], a1[1] - a0[1], a1[2] - a0[2]
    db0, db1, db2 = b1[0] - b0[0], b1[1] - b0[1], b1[2] - b0[2]
    r0, r1, r2 = a0[0] - b0[0], a0[1] - b0[1], a0[2] - b0[2]
    aa = da0 * da0 + da1 * da1 + da2 * da2
    bb = db0 * db0 + db1 * db1 + db2 * db2
    ab = da0 * db0 + da1 * db1 + da2 * db2
    ra = r0 * da0 + r1 * da1 + r2 * da2
    rb = r0 * db0 + r1 * db1 + r2 * db2
    det = aa * bb - ab * ab
    return (ab * rb - bb * ra) / det, (aa * rb - ab * ra) / det, det, aa * bb


@njit(cache=True)
def vertex_face_lcp(p, t0, t1, t2):
    """(in_range, u, v): closest point of the plane of the triangle to p, barycentric u, v."""
    e1 = t1 - t0
    e2 = t2 - t0
    det = _dot(e1, e1) * _dot(e2, e2) - _dot(e1, e2) ** 2
    if det <= 0.0:
        return False, 0.0, 0.0
    u, v, _ = vertex_face_coords(p, t0, t1, t2)
    ok = u > RANGE_TOL and v > RANGE_TOL and u + v < 1.0 - RANGE_TOL
    return ok, u, v


@njit(cache=True)
def vertex_edge_lcp(p, e0, e1):
    """(in_range, t): closest point of the line through the edge to p."""
    d = e1 - e0
    if _dot(d, d) <= 0.0:
        return False, 0.0
    t = vertex_edge_coord(p, e0, e1)
    return RANGE_TOL < t < 1.0 - RANGE_TOL, t


@njit(cache=True)
def edge_edge_lcp(a0, a1, b0, b1):
    """(in_range, s, t): closest points of the two lines; never in range for (nearly) parallel edges."""
    da = a1 - a0
    db = b1 - b0
    aa = _dot(da, da)
    bb = _dot(db, db)
    if aa * bb - _dot(da, db) ** 2 <= PARALLEL_SIN2 * aa * bb:
        return False, 0.0, 0.0
    s, t, _, _ = edge_edge_coords(a0, a1, b0, b1)
    ok = RANGE_TOL < s < 1.0 - RANGE_TOL and RANGE_TOL < t < 1.0 - RANGE_TOL
    return ok, s, t


@njit(cache=True)
def pair_weights(kind, c0, c1, w0, D):
    """Fill w0 (6,) and D (6, 2) so that w(c) = w0 + D c for the pair kind; returns w(c)."""
    w = np.empty(6)
    pair_weights_into(kind, c0, c1, w0, D, w)
    return w


@njit(cache=True)
def pair_weights_into(kind, c0, c1, w0, D, w):
    """pair_weights with w(c) written into w (6,): no allocation in a kernel's per-pair loop."""
    w0[:] = 0.0
    D[:, :] = 0.0
    if kind == VERTEX_FACE:
        w0[0] = 1.0
        w0[1] = -1.0
        D[1, 0] = 1.0
        D[1, 1] = 1.0
        D[2, 0] = -1.0
        D[3, 1] = -1.0
    elif kind == EDGE_EDGE:
        w0[0] = 1.0
        w0[2] = -1.0
        D[0, 0] = -1.0
        D[1, 0] = 1.0
        D[2, 1] = 1.0
        D[3, 1] = -1.0
    elif kind == VERTEX_EDGE:
        w0[0] = 1.0
        w0[1] = -1.0
        D[1, 0] = 1.0
        D[2, 0] = -1.0
    else:
        w0[0] = 1.0
        w0[1] = -1.0
    for i in range(6):
        w[i] = w0[i] + D[i, 0] * c0 + D[i, 1] * c1


@njit(cache=True)
def _gap_and_gradient(kind, xs, c0, c1, w0, D, w, g, grad):
    """d = |g|: the pair's weights at (c0, c1) into w, its gap vector g = sum w_i x_i into g; grad
    d = n (x) w into grad (zeros when d = 0)."""
    nn = N_NODES[kind]
    pair_weights_into(kind, c0, c1, w0, D, w)
    for a in range(3):
        g[a] = 0.0
    for i in range(nn):
        for a in range(3):
            g[a] += w[i] * xs[i, a]
    d = np.sqrt(_dot(g, g))
    grad[:, :] = 0.0
    if not d <= 0.0:  # a NaN gap fills grad with NaN, as before: never a silent zero
        for i in range(nn):
            for a in range(3):
                grad[i, a] = w[i] * g[a] / d
    return d


@njit(cache=True)
def gap_gradient(kind, xs, c0, c1, grad):
    """gap_derivatives without the Hessian: explicit steps compile only this (no LCP Schur
    complement, no matrix inverse: seconds of a fresh install's first run)."""
    return gap_gradient_into(kind, xs, c0, c1, grad, np.empty(6), np.empty((6, 2)), np.empty(6), np.empty(3))


@njit(cache=True)
def gap_gradient_into(kind, xs, c0, c1, grad, w0, D, w, g):
    """gap_gradient with the caller's scratch (gap_derivatives_into)."""
    d = _gap_and_gradient(kind, xs, c0, c1, w0, D, w, g, grad)
    return 0.0 if d <= 0.0 else d


@njit(cache=True)
def gap_derivatives(kind, xs, c0, c1, want_hessian, grad, hess):
    """gap_derivatives_into with its own scratch (tests and single pairs)."""
    return gap_derivatives_into(kind, xs, c0, c1, want_hessian, grad, hess, np.empty(6), np.empty((6, 2)),
                                np.empty(6), np.empty(3), np.empty((3, 2)), np.empty((3, 18)))  # fmt: skip


@njit(cache=True)
def gap_derivatives_into(kind, xs, c0, c1, want_hessian, grad, hess, w0, D, w, g, J, B):
    """Gap d = |g| of an in-range pair and its exact derivatives in the pair's node positions.

    xs (6, 3): node positions in the pair's order. Because c solves the LCP, grad d = n (x) w
    (the change of c does not enter to first order). The Hessian includes it through the Schur
    complement of q = |g|^2 (docs/contact.md: dc/dx = -H_cc^-1 d2q/dc dx):

        d2q/dx2 = 2 (w w^T) (x) I,   H_cc = 2 J^T J,   d2q/dx_i dc_k = 2 (D_ik g + w_i J_k),
        hess q  = d2q/dx2 - B H_cc^-1 B^T,   hess d = hess q / (2 d) - grad q grad q^T / (4 d^3).

    w0 (6,), D (6, 2), w (6,), g (3,), J (3, 2) and B (3, 18) are the caller's scratch: a kernel's
    per-pair loop allocates nothing (numba puts every array on the heap)."""
    nn = N_NODES[kind]
    m = N_COORDS[kind]
    d = _gap_and_gradient(kind, xs, c0, c1, w0, D, w, g, grad)
    if d <= 0.0:
        return 0.0
    if not want_hessian:
        return d
    n3 = 3 * nn
    # H_cc^-1 and B H_cc^-1 B^T written out (m <= 2): np.linalg.inv and two BLAS products on 2 x 2
    # and 18 x 2 matrices cost more in calls and allocations than in flops (27 -> 9 ms for the 7,356
    # pairs of the 515-grain lid jam, one thread)
    for a in range(3):  # J = dg/dc
        J[a, 0] = 0.0
        J[a, 1] = 0.0
    for i in range(nn):
        for a in range(3):
            J[a, 0] += D[i, 0] * xs[i, a]
            J[a, 1] += D[i, 1] * xs[i, a]
    h00 = 2.0 * _dot(J[:, 0], J[:, 0])
    h01 = 2.0 * _dot(J[:, 0], J[:, 1])
    h11 = 2.0 * _dot(J[:, 1], J[:, 1])
    if m == 2:
        det = h00 * h11 - h01 * h01
        i00, i01, i11 = h11 / det, -h01 / det, h00 / det
    elif m == 1:
        i00, i01, i11 = 1.0 / h00, 0.0, 0.0
    else:
        i00, i01, i11 = 0.0, 0.0, 0.0
    b0, b1, gq = B[0], B[1], B[2]  # the columns of B = d2q/dx dc, and grad q
    for r in range(18):
        b0[r] = 0.0
        b1[r] = 0.0
        gq[r] = 0.0
    for i in range(nn):
        for a in range(3):
            b0[3 * i + a] = 2.0 * (D[i, 0] * g[a] + w[i] * J[a, 0])
            b1[3 * i + a] = 2.0 * (D[i, 1] * g[a] + w[i] * J[a, 1])
            gq[3 * i + a] = 2.0 * w[i] * g[a]
    for r in range(n3):
        # (B H^-1) row r
        e0 = b0[r] * i00 + b1[r] * i01
        e1 = b0[r] * i01 + b1[r] * i11
        wr = w[r // 3]
        ar = r % 3
        for s in range(n3):
            hq = 2.0 * wr * w[s // 3] if ar == s % 3 else 0.0
            hq -= e0 * b0[s] + e1 * b1[s]
            hess[r, s] = hq / (2.0 * d) - gq[r] * gq[s] / (4.0 * d * d * d)
    return d


# Closest feature pairs assembled from the degenerate LCPs. The feature codes follow the IPC
# Toolkit's distance types so that tests can compare with it directly.
PT_T0, PT_T1, PT_T2, PT_E0, PT_E1, PT_E2, PT_T = range(7)  # point-triangle
EE_A0B0, EE_A0B1, EE_A1B0, EE_A1B1, EE_A_B0, EE_A_B1, EE_A0_B, EE_A1_B, EE_A_B = range(9)


@njit(cache=True)
def _point_edge_candidate(p, e0, e1, code, best_type, best):
    ok, t = vertex_edge_lcp(p, e0, e1)
    if ok:
        d = _norm3(p - (1.0 - t) * e0 - t * e1)
        if d < best:
            return code, d
    return best_type, best


@njit(cache=True)
def _point_point_candidate(p, q, code, best_type, best):
    d = _norm3(p - q)
    if d < best:
        return code, d
    return best_type, best


@njit(cache=True)
def point_triangle_closest(p, t0, t1, t2):
    """(type, distance) of a point and a triangle: the face LCP if in range, else the best
    in-range edge LCP, else the nearest vertex."""
    ok, u, v = vertex_face_lcp(p, t0, t1, t2)
    if ok:
        return PT_T, _norm3(p - (1.0 - u - v) * t0 - u * t1 - v * t2)
    # np.int64: numba compiles a callee once per literal argument value (compile time: tests/test_compile_once.py)
    k, d = _point_point_candidate(p, t0, np.int64(PT_T0), np.int64(-1), np.inf)
    k, d = _point_point_candidate(p, t1, np.int64(PT_T1), k, d)
    k, d = _point_point_candidate(p, t2, np.int64(PT_T2), k, d)
    k, d = _point_edge_candidate(p, t0, t1, np.int64(PT_E0), k, d)
    k, d = _point_edge_candidate(p, t1, t2, np.int64(PT_E1), k, d)
    return _point_edge_candidate(p, t2, t0, np.int64(PT_E2), k, d)


@njit(cache=True)
def edge_edge_closest(a0, a1, b0, b1):
    """(type, distance) of two segments: the edge-edge LCP if in range, else the best vertex-edge
    LCP, else the nearest vertex pair (parallel edges end up in the latter two)."""
    ok, s, t = edge_edge_lcp(a0, a1, b0, b1)
    if ok:
        return EE_A_B, _norm3((1.0 - s) * a0 + s * a1 - (1.0 - t) * b0 - t * b1)
    k, d = _point_point_candidate(a0, b0, np.int64(EE_A0B0), np.int64(-1), np.inf)
    k, d = _point_point_candidate(a0, b1, np.int64(EE_A0B1), k, d)
    k, d = _point_point_candidate(a1, b0, np.int64(EE_A1B0), k, d)
    k, d = _point_point_candidate(a1, b1, np.int64(EE_A1B1), k, d)
    k, d = _point_edge_candidate(b0, a0, a1, np.int64(EE_A_B0), k, d)
    k, d = _point_edge_candidate(b1, a0, a1, np.int64(EE_A_B1), k, d)
    k, d = _point_edge_candidate(a0, b0, b1, np.int64(EE_A0_B), k, d)
    return _point_edge_candidate(a1, b0, b1, np.int64(EE_A1_B), k, d)


@njit(cache=True)
def _norm3(v):
    return np.sqrt(_dot(v, v))
