"""The edge-edge fade (`[contact] edge_fade`, off by default): edge-edge records weighed out near
their edges' ends (docs/contact.md, "twins", where the measurements say why it is off: it slows
Newton in jammed packs).

Near an edge's end an edge-edge record and its end vertex's records (vertex-face, vertex-edge)
carry the same touching spot, and the edge-edge record leaves when its closest point passes the
end (s = 1). Unweighted, force and potential jump there by one barrier term. Every edge-edge
record (normal law, damping and friction together) is therefore multiplied by

    w = psi(s L_a) psi((1 - s) L_a) psi(t L_b) psi((1 - t) L_b),

with L the edge lengths, s, t the closest points' coordinates and psi(l) the C2 smooth step
10 u^3 - 15 u^4 + 6 u^5 of u = l / r, 1 for l >= r. l is the distance of a closest point from an
edge end; the radius r is the activation gap gbar (law[FADE]; 0 turns the fade off). w is 1
wherever both closest points lie at least r from the ends, and falls to 0 at an end, where the
vertex records take over: the pair's potential w Phi(d) is continuous. Its derivatives:

    d(w Phi)/dx   = w dPhi/dx + Phi dw/dx
    d2(w Phi)/dx2 = w d2Phi/dx2 + dPhi/dx dw/dx^T + dw/dx dPhi/dx^T + Phi d2w/dx2
    damping + friction F:  w F,  tangent w dF/dx + F dw/dx^T

dw/dx is closed form (s and t are rational in the nodes, below). d2w/dx2 is the complex-step
derivative of that closed form (12 complex evaluations per pair, exact to round-off), and only
for the few records inside the fade zone.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .law import FADE
from .narrow import EDGE_EDGE

COMPLEX_STEP = 1e-30


@njit(cache=True)
def smooth_step(l, r):
    """(psi, dpsi/dl) of the C2 step from 0 at l = 0 to 1 at l = r (real or complex l)."""
    zero = 0.0 * l
    if l.real >= r:
        return zero + 1.0, zero
    if l.real <= 0.0:
        return zero, zero
    u = l / r
    return u * u * u * (10.0 - 15.0 * u + 6.0 * u * u), 30.0 * u * u * (1.0 - u) * (1.0 - u) / r


@njit(cache=True)
def _edge_scalars(xs):
    """da, db, r and aa, bb, ab, ra, rb of the edge pair a0 a1 | b0 b1 = xs[0:4] (edge_edge_coords)."""
    da = xs[1] - xs[0]
    db = xs[3] - xs[2]
    r = xs[0] - xs[2]
    return (da, db, r, np.sum(da * da), np.sum(db * db), np.sum(da * db), np.sum(r * da), np.sum(r * db))


@njit(cache=True)
def in_fade_zone(xs, r):
    """Whether an edge-edge pair's closest points lie within r of an end of their edges (w < 1)."""
    aa, bb, ab, ra, rb = 0.0, 0.0, 0.0, 0.0, 0.0
    for a in range(3):
        da, db, rv = xs[1, a] - xs[0, a], xs[3, a] - xs[2, a], xs[0, a] - xs[2, a]
        aa += da * da
        bb += db * db
        ab += da * db
        ra += rv * da
        rb += rv * db
    det = aa * bb - ab * ab
    s = (ab * rb - bb * ra) / det
    t = (aa * rb - ab * ra) / det
    la, lb = np.sqrt(aa), np.sqrt(bb)
    return min(s, 1.0 - s) * la < r or min(t, 1.0 - t) * lb < r


@njit(cache=True)
def fade_gradient(xs, r, grad):
    """w of an edge-edge pair and dw/dx into grad (4, 3) (real or complex xs).

    With q = (aa, bb, ab, ra, rb) the dot products of edge_edge_coords, s = (ab rb - bb ra) / det and
    t = (aa rb - ab ra) / det, det = aa bb - ab^2: every derivative is the chain rule through q."""
    da, db, rv, aa, bb, ab, ra, rb = _edge_scalars(xs)
    det = aa * bb - ab * ab
    s = (ab * rb - bb * ra) / det
    t = (aa * rb - ab * ra) / det
    la = np.sqrt(aa)
    lb = np.sqrt(bb)
    u = (s * la, (1.0 - s) * la, t * lb, (1.0 - t) * lb)
    p0, q0 = smooth_step(u[0], r)
    p1, q1 = smooth_step(u[1], r)
    p2, q2 = smooth_step(u[2], r)
    p3, q3 = smooth_step(u[3], r)
    w = p0 * p1 * p2 * p3
    # dw/du_k for the four distances from the ends
    w0, w1, w2, w3 = q0 * p1 * p2 * p3, p0 * q1 * p2 * p3, p0 * p1 * q2 * p3, p0 * p1 * p2 * q3
    # dw/ds, dw/dt, dw/dla, dw/dlb
    ws = (w0 - w1) * la
    wt = (w2 - w3) * lb
    wla = w0 * s + w1 * (1.0 - s)
    wlb = w2 * t + w3 * (1.0 - t)
    # dw/dq through s, t (quotient rule) and la = sqrt(aa), lb = sqrt(bb)
    ddet = (bb, aa, -2.0 * ab, 0.0 * ab, 0.0 * ab)  # d det / d(aa, bb, ab, ra, rb)
    ds_num = (0.0 * ab, -ra, rb, -bb, ab)  # d(ab rb - bb ra)
    dt_num = (rb, 0.0 * ab, -ra, -ab, aa)  # d(aa rb - ab ra)
    wq = np.zeros(5, dtype=xs.dtype)
    for k in range(5):
        wq[k] = ws * (ds_num[k] - s * ddet[k]) / det + wt * (dt_num[k] - t * ddet[k]) / det
    wq[0] += wla / (2.0 * la)
    wq[1] += wlb / (2.0 * lb)
    # dq/dx: aa = da.da, bb = db.db, ab = da.db, ra = r.da, rb = r.db with da = a1 - a0,
    # db = b1 - b0, r = a0 - b0
    for a in range(3):
        grad[0, a] = -2.0 * wq[0] * da[a] - wq[2] * db[a] + wq[3] * (da[a] - rv[a]) + wq[4] * db[a]
        grad[1, a] = 2.0 * wq[0] * da[a] + wq[2] * db[a] + wq[3] * rv[a]
        grad[2, a] = -2.0 * wq[1] * db[a] - wq[2] * da[a] - wq[3] * da[a] - wq[4] * (db[a] + rv[a])
        grad[3, a] = 2.0 * wq[1] * db[a] + wq[2] * da[a] + wq[4] * rv[a]
    return w


@njit(cache=True)
def fade_hessian(xs, r, hess):
    """d2w/dx2 (12, 12) of an edge-edge pair: the complex-step derivative of fade_gradient."""
    scale = 0.0
    for i in range(4):
        for a in range(3):
            scale = max(scale, abs(xs[i, a]))
    h = COMPLEX_STEP * max(scale, 1e-300)
    xc = np.zeros((4, 3), dtype=np.complex128)
    gc = np.zeros((4, 3), dtype=np.complex128)
    for j in range(12):
        for i in range(4):
            for a in range(3):
                xc[i, a] = xs[i, a]
        xc[j // 3, j % 3] += 1j * h
        fade_gradient(xc, r, gc)
        for k in range(12):
            hess[k, j] = gc[k // 3, k % 3].imag / h


@njit(cache=True)
def is_faded(kind, xs, law):
    """Whether the pair (kind, node positions xs) is an edge-edge record inside the fade zone: the
    few records the fade touches."""
    return law[FADE] > 0.0 and kind == EDGE_EDGE and in_fade_zone(xs, law[FADE])


@njit(cache=True)
def real_fade_gradient(xs, r):
    """(w, dw/dx (4, 3)) at real node positions, through the complex version (one compilation of
    fade_gradient: its Hessian is the complex-step derivative anyway)."""
    xc = np.zeros((4, 3), dtype=np.complex128)
    for i in range(4):
        for a in range(3):
            xc[i, a] = xs[i, a]
    gc = np.zeros((4, 3), dtype=np.complex128)
    w = fade_gradient(xc, r, gc)
    return w.real, gc.real.copy()


@njit(cache=True)
def fade_conservative(xs, law, c, energy, local_force):
    """Weigh pair c's potential Phi and its gradient by w (module docstring); returns (w, dw/dx, Phi)."""
    w, gw = real_fade_gradient(xs, law[FADE])
    phi = energy[c]
    energy[c] = w * phi
    for i in range(4):
        for a in range(3):
            local_force[c, i, a] = w * local_force[c, i, a] + phi * gw[i, a]
    return w, gw, phi


@njit(cache=True)
def fade_conservative_tangent(xs, law, c, energy, local_force, local_tangent):
    """fade_conservative, and the pair's Hessian weighed too (a kernel of its own: explicit runs never
    compile the complex-step Hessian)."""
    hw = np.zeros((12, 12))
    fade_hessian(xs, law[FADE], hw)
    f = np.empty(12)  # dPhi/dx before weighing
    for i in range(12):
        f[i] = local_force[c, i // 3, i % 3]
    w, gw, phi = fade_conservative(xs, law, c, energy, local_force)
    for i in range(12):
        gi = gw[i // 3, i % 3]
        for j in range(12):
            local_tangent[c, i, j] = w * local_tangent[c, i, j] + f[i] * gw[j // 3, j % 3] + gi * f[j] + phi * hw[i, j]


@njit(cache=True)
def fade_dissipative(xs, law, c, local_force):
    """Weigh pair c's damping and friction residual F by w; returns (w, dw/dx)."""
    w, gw = real_fade_gradient(xs, law[FADE])
    for i in range(4):
        for a in range(3):
            local_force[c, i, a] *= w
    return w, gw


@njit(cache=True)
def fade_dissipative_tangent(xs, law, c, local_force, pair_tangent, local_tangent):
    """fade_dissipative, and pair_tangent (18, 18), that residual's own Jacobian, added to
    local_tangent[c] as w dF/dx + F dw/dx^T."""
    f = np.empty(12)  # F before weighing
    for i in range(12):
        f[i] = local_force[c, i // 3, i % 3]
    w, gw = fade_dissipative(xs, law, c, local_force)
    for i in range(12):
        for j in range(12):
            local_tangent[c, i, j] += w * pair_tangent[i, j] + f[i] * gw[j // 3, j % 3]
