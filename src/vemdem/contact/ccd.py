"""Step bounds from contact (continuous collision detection): arrays in, numbers out.

Integrators ask here how far a step or a Newton update may go before two surfaces could meet
inside the activation layer unseen, and whether a step missed a pair. Nothing here knows a scene
or a state (they live in model/ and solver/), so contact never points back up at them.

- conservative advancement (docs/contact.md): surfaces with active pairs are at least their
  smallest active gap apart, any other two at least the activation gap gbar; an update moving
  surface s by at most d_s keeps every pair apart when alpha (d_a + d_b) < gap;
- missed pairs: a pair found only by the end-of-step search and already inside gbar;
- contact-impact step (docs/dynamics.md): an approaching pair closes at most a share f of gbar
  inside the layer per step, an active one resolves half its oscillation pi sqrt(m_eq / k) in
  N_impact steps;
- explicit approach bounds: per-grain centre speed and spin radius, lowest vertex over a plane.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .forces import pair_inverse_masses
from .law import normal_stiffness
from .narrow import (
    EDGE_EDGE,
    N_NODES,
    VERTEX_EDGE,
    VERTEX_FACE,
    edge_edge_closest,
    pair_weights,
    point_triangle_closest,
    vertex_edge_lcp,
)
from .pairs import C0, C1, GAP, GRAIN_A, GRAIN_B, KIND, NODE0, find_contacts


def surface_displacements(dx: np.ndarray, vertex_ptr: np.ndarray, n_surfaces: int) -> np.ndarray:
    """Largest vertex displacement of every grain, then 0 for each wall (walls move between steps)."""
    step = np.linalg.norm(dx, axis=1)
    grain_step = np.maximum.reduceat(step, vertex_ptr[:-1]) if len(step) else np.zeros(0)
    return np.concatenate([grain_step, np.zeros(n_surfaces - len(grain_step))])


# An update moves every point of surface s by trans[s] plus at most spread[s] (trans: the common
# translation of a grain, spread: what its rotation and deformation add); two surfaces then come
# closer by at most |trans_a - trans_b| + spread_a + spread_b, so grains that travel together
# (a falling or sliding cluster) do not shorten each other's updates. A plain displacement bound
# d_s is trans = 0, spread = d_s.
@njit(cache=True)
def _approach(trans, spread, a, b):
    d0, d1, d2 = trans[a, 0] - trans[b, 0], trans[a, 1] - trans[b, 1], trans[a, 2] - trans[b, 2]
    return np.sqrt(d0 * d0 + d1 * d1 + d2 * d2) + spread[a] + spread[b]


@njit(cache=True)
def _node_approach(ints, c, node_disp, node_extra, extra_factor=1.0):
    """How much closer the pair's own features can come: the distance from a point to a triangle
    (or between segments) falls by at most the largest relative displacement of a node of one
    side and a node of the other, max |u_p - u_q| <= |dx_p - dx_q| + e_p + e_q (e: what the
    update's path adds to alpha dx, per vertex; nodes past node_disp are walls: fixed)."""
    kind = ints[c, KIND]
    n_a = 2 if kind == EDGE_EDGE else 1
    n_vertices = len(node_disp)
    move = 0.0
    for i in range(n_a):
        p = ints[c, NODE0 + i]
        for j in range(n_a, N_NODES[kind]):
            q = ints[c, NODE0 + j]
            d2 = 0.0
            e = 0.0
            for k in range(3):
                up = node_disp[p, k] if p < n_vertices else 0.0
                uq = node_disp[q, k] if q < n_vertices else 0.0
                d2 += (up - uq) ** 2
            if p < n_vertices:
                e += node_extra[p]
            if q < n_vertices:
                e += node_extra[q]
            move = max(move, np.sqrt(d2) + extra_factor * e)
    return move


@njit(cache=True)
def _active_ratio(trans, spread, ints, floats, node_disp, node_extra):
    """min over feature pairs within the layer of gap / approach, the approach the smaller of the
    surfaces' bound and the pair's own nodes' (a grain pivoting on a vertex barely moves it)."""
    ratio = np.inf
    for c in range(len(ints)):
        move = _approach(trans, spread, ints[c, GRAIN_A], ints[c, GRAIN_B])
        if len(node_disp):
            move = min(move, _node_approach(ints, c, node_disp, node_extra))
        if move > 0.0:
            ratio = min(ratio, floats[c, GAP] / move)
    return ratio


_NO_NODES = (np.zeros((0, 3)), np.zeros(0))


# ------------------------------------------------------------------ additive CCD of active pairs
# A bound from the start of the update alone (gap / approach) stops a pair whose features slide
# along each other at a small gap: the relative motion of its nodes is large, the distance barely
# changes. Additive CCD (Li et al. 2021, the IPC Toolkit's default) advances alpha by what the
# bound allows from the distance measured at the current alpha, and measures again.
@njit(cache=True)
def _path_point(i, alpha, x_all, n_vertices, dx, vertex_grain, c, t, phi, out):
    """Position of node i after alpha of the update: grain vertices on their grain's rigid path
    (model/motion.py; t = phi = 0 and c = 0 give x + alpha dx), wall nodes fixed."""
    if i >= n_vertices:
        for k in range(3):
            out[k] = x_all[i, k]
        return
    g = vertex_grain[i]
    p0, p1, p2 = alpha * phi[g, 0], alpha * phi[g, 1], alpha * phi[g, 2]
    r0, r1, r2 = x_all[i, 0] - c[g, 0], x_all[i, 1] - c[g, 1], x_all[i, 2] - c[g, 2]
    f0, f1, f2 = phi[g, 0], phi[g, 1], phi[g, 2]
    d0 = dx[i, 0] - t[g, 0] - (f1 * r2 - f2 * r1)
    d1 = dx[i, 1] - t[g, 1] - (f2 * r0 - f0 * r2)
    d2 = dx[i, 2] - t[g, 2] - (f0 * r1 - f1 * r0)
    q0, q1, q2 = r0 + alpha * d0, r1 + alpha * d1, r2 + alpha * d2
    th = np.sqrt(p0 * p0 + p1 * p1 + p2 * p2)
    if th > 1e-300:
        k0, k1, k2 = p0 / th, p1 / th, p2 / th
        co, si = np.cos(th), np.sin(th)
        kq = k0 * q0 + k1 * q1 + k2 * q2
        x0, x1, x2 = k1 * q2 - k2 * q1, k2 * q0 - k0 * q2, k0 * q1 - k1 * q0
        q0, q1, q2 = q0 * co + x0 * si + k0 * kq * (1 - co), q1 * co + x1 * si + k1 * kq * (1 - co), q2 * co + x2 * si + k2 * kq * (1 - co)
    out[0] = c[g, 0] + alpha * t[g, 0] + q0
    out[1] = c[g, 1] + alpha * t[g, 1] + q1
    out[2] = c[g, 2] + alpha * t[g, 2] + q2


@njit(cache=True)
def _pair_distance(kind, xs, plane):
    """Distance of the pair's features: point-triangle, segment-segment, point-segment,
    point-point; a wall plane's vertex-face pair: the distance to the plane."""
    if kind == VERTEX_FACE:
        if plane:
            n = np.cross(xs[2] - xs[1], xs[3] - xs[1])
            return abs(np.dot(xs[0] - xs[1], n)) / np.sqrt(np.dot(n, n))
        return point_triangle_closest(xs[0], xs[1], xs[2], xs[3])[1]
    if kind == EDGE_EDGE:
        return edge_edge_closest(xs[0], xs[1], xs[2], xs[3])[1]
    if kind == VERTEX_EDGE:
        best = min(np.sqrt(np.sum((xs[0] - xs[1]) ** 2)), np.sqrt(np.sum((xs[0] - xs[2]) ** 2)))
        ok, u = vertex_edge_lcp(xs[0], xs[1], xs[2])
        if ok:
            best = min(best, np.sqrt(np.sum((xs[0] - (1.0 - u) * xs[1] - u * xs[2]) ** 2)))
        return best
    return np.sqrt(np.sum((xs[0] - xs[1]) ** 2))


@njit(cache=True)
def accd_alpha(ints, x_all, n_vertices, plane_node0, dx, vertex_grain, c, t, phi, excess, keep, cap,
               max_rounds=256):  # fmt: skip
    """Largest alpha <= cap (found by additive CCD) such that every pair in ints stays at least
    keep times its distance at alpha = 0 apart along the update's path. Between measurements,
    the distance falls at most at the rate L = max over a node p of one side and q of the other
    of |dx_p - dx_q| + 2 (e_p + e_q) (e: model.motion.path_excess, which also bounds half the
    path's departure from its tangent in rate).

    A round advances by at most (1 - keep) d / L, so a pair that slides past its neighbour by n
    of its gaps without closing needs about n / (1 - keep) rounds: 64 rounds stopped such pairs
    short in 49 of 202 updates of the 515-grain lid jam (0.10 instead of 0.40, 0.17 instead of
    0.64), and Newton crawled behind them (docs/dynamics.md). A pair out of rounds keeps the
    alpha it reached, which is safe."""
    alpha_min = cap
    xs = np.empty((4, 3))
    for c_ in range(len(ints)):
        kind = ints[c_, KIND]
        nn = N_NODES[kind]
        plane = kind == VERTEX_FACE and ints[c_, NODE0 + 1] >= plane_node0
        rate = _node_approach(ints, c_, dx, excess, 2.0)
        if rate <= 0.0:
            continue
        for k in range(nn):
            for a in range(3):
                xs[k, a] = x_all[ints[c_, NODE0 + k], a]
        d0 = _pair_distance(kind, xs[:nn], plane)
        floor = keep * d0
        alpha, d = 0.0, d0
        for _ in range(max_rounds):
            step = (d - floor) / rate
            if alpha + step >= alpha_min:  # this pair does not bind below the current minimum
                alpha = alpha_min
                break
            alpha += step
            for k in range(nn):
                _path_point(ints[c_, NODE0 + k], alpha, x_all, n_vertices, dx, vertex_grain, c, t, phi, xs[k])
            d = _pair_distance(kind, xs[:nn], plane)
            if d - floor <= 1e-3 * (d0 - floor):  # closing in: alpha is where it reaches the floor
                break
        alpha_min = min(alpha_min, alpha)
    return alpha_min


def _top2(values: np.ndarray) -> float:
    return float(np.sort(values)[-2:].sum()) if len(values) > 1 else 0.0


def _reach(trans: np.ndarray, spread: np.ndarray) -> np.ndarray:
    """r_s = |trans_s - m| + spread_s with m the centre of the translations' bounding box: any two
    surfaces approach by at most r_a + r_b (triangle inequality through m), so top2(r) bounds
    every pair at once, and a cluster travelling together does not count its common motion."""
    if not len(trans):
        return spread
    m = 0.5 * (trans.min(axis=0) + trans.max(axis=0))
    return np.linalg.norm(trans - m, axis=1) + spread


def update_reach(trans: np.ndarray, spread: np.ndarray) -> float:
    """The most any two surfaces can approach along an update: top2 of _reach."""
    return _top2(_reach(trans, spread))


def free_distance_ratio(trans: np.ndarray, spread: np.ndarray, ints: np.ndarray, floats: np.ndarray,
                        gbar: float, nodes=_NO_NODES) -> float:  # fmt: skip
    """Largest alpha such that the update scaled by alpha cannot bring two surfaces into contact
    (conservative advancement): active pairs keep apart when alpha approach < gap, every other
    pair is at least gbar apart, and no two surfaces approach faster than the two fastest move.
    nodes: (dx, e) of every grain vertex, for the pairs' own bound (_node_approach)."""
    ratio = _active_ratio(trans, spread, ints, floats, *nodes) if len(ints) else np.inf
    top2 = _top2(_reach(trans, spread))
    if top2 > 0:
        ratio = min(ratio, gbar / top2)
    return ratio


def missed_pairs(contact, x: np.ndarray, t: float, candidates: np.ndarray) -> int:
    """Pairs that appear only in a search at the end of a step and are already inside the
    activation gap: the step passed them by (docs/contact.md). `contact` is the ContactModel."""
    fresh = contact.search(x, t)
    if len(fresh) == 0:
        return 0
    width = int(max(fresh.max(), candidates.max() if len(candidates) else 0)) + 1
    new = fresh[~np.isin(fresh[:, 0] * width + fresh[:, 1], candidates[:, 0] * width + candidates[:, 1])]
    if len(new) == 0:
        return 0
    ints, _ = find_contacts(contact.all_positions(x, t), new, contact.topology, contact.law.activation_gap)
    return len(ints)


def impact_step_limit(gap: np.ndarray, rate: np.ndarray, m_eq: np.ndarray, law_params: np.ndarray, gbar: float,
                      entry_fraction: float, impact_steps: float) -> float:  # fmt: skip
    """Contact-impact step control (docs/dynamics.md) from the pairs' gaps, gap rates and masses:
    - an approaching pair (rate -dg/dt) may close at most f gbar inside the layer in one step:
      dt <= (max(g - gbar, 0) + f gbar) / (-dg/dt);
    - an active pair resolves half its contact oscillation in N steps: dt <= pi sqrt(m_eq / k(g)) / N.
    Without it a step may jump deep into the layer, where the trapezoidal rule's energy error at a
    stiff nonlinear spring is largest (docs/dynamics.md)."""
    limit = np.inf
    closing = rate < 0
    if closing.any():
        depth = np.maximum(gap[closing] - gbar, 0.0) + entry_fraction * gbar
        limit = float(np.min(depth / -rate[closing]))
    k = normal_stiffness(np.ascontiguousarray(gap), law_params)
    loaded = k > 0
    if loaded.any():
        limit = min(limit, np.pi * np.sqrt(np.min(m_eq[loaded] / k[loaded])) / impact_steps)
    return limit


def damped_contact_step(inv_mass_all: np.ndarray, ints: np.ndarray, floats: np.ndarray, law_params,
                        m_eq: np.ndarray, zeta: float, rigid_inverse: np.ndarray | None = None,
                        lam: float = 0.0) -> float:  # fmt: skip
    """The central-difference stability limit of every active pair as the explicit integrator sees
    it, its damping included:

        omega^2 = k(g) sum_i w_i^2 / m_i          the pair's spring on its nodes' lumped masses
        c       = 2 zeta sqrt(k(g) m_eq)          the normal damping friction.py applies (grain masses)
        zeta_p  = c / (2 sqrt(k / sum_i w_i^2 / m_i)) = zeta sqrt(m_eq sum_i w_i^2 / m_i)
        dt     <= (2 / omega) (sqrt(1 + zeta_p^2) - zeta_p)

    The damping acts on vertex masses 15-30 times lighter than the grain masses it is scaled
    with, so zeta_p is 2-4 for zeta = 0.5: a step from zeta alone was 1.5-2.3 times too long and
    impacts gained energy. With selective mass scaling lam the pairs' inverse masses are
    `scaled_pair_inverse_masses`, given the pairs' rigid inverse masses. inf without pairs."""
    if len(ints) == 0:
        return np.inf
    inverse = scaled_pair_inverse_masses(inv_mass_all, ints, floats, rigid_inverse, lam)
    return damped_pair_step(inverse, floats, law_params, m_eq, zeta)


def scaled_pair_inverse_masses(inv_mass_all: np.ndarray, ints: np.ndarray, floats: np.ndarray,
                               rigid_inverse: np.ndarray | None, lam: float) -> np.ndarray:  # fmt: skip
    """1/m_eff of every pair along its normal on flexible grains whose deformation modes carry
    (1 + lam) times their inertia (selective mass scaling, vem/selective_mass.py): the pair's
    point p = sum_i w_i x_i meets (sum_i w_i^2 / m_i + lam rigid) / (1 + lam), exactly, with
    `rigid` the pair's inverse mass as rigid grains of the lumped masses (`rigid_pair_inverse_masses`
    with each grain's current centroid and inertia): M_s^-1's rigid part acting on a point force
    is the grain's rigid response at that point, not the nodes' shares of it."""
    inv = pair_inverse_masses(inv_mass_all, ints, floats)
    if lam == 0.0 or len(ints) == 0:
        return inv
    return (inv + lam * rigid_inverse) / (1.0 + lam)


def pair_gaps(floats: np.ndarray) -> np.ndarray:
    """The gap of every pair (the column layout stays inside contact/)."""
    return floats[:, GAP]


@njit(cache=True)
def grain_speeds(v, mass, vptr):
    """Mass-weighted centre velocity c of each grain and r, its vertices' largest speed about c."""
    G = len(vptr) - 1
    c = np.zeros((G, 3))
    r = np.zeros(G)
    for g in range(G):
        m = 0.0
        for i in range(vptr[g], vptr[g + 1]):
            m += mass[i]
            for a in range(3):
                c[g, a] += mass[i] * v[i, a]
        for a in range(3):
            c[g, a] /= m
        for i in range(vptr[g], vptr[g + 1]):
            s = (v[i, 0] - c[g, 0]) ** 2 + (v[i, 1] - c[g, 1]) ** 2 + (v[i, 2] - c[g, 2]) ** 2
            r[g] = max(r[g], np.sqrt(s))
    return c, r


@njit(cache=True)
def max_displacement(x, x0):
    """Largest |x_i - x0_i| (the Verlet list's test: one pass instead of four array operations)."""
    most = 0.0
    for i in range(len(x)):
        d = (x[i, 0] - x0[i, 0]) ** 2 + (x[i, 1] - x0[i, 1]) ** 2 + (x[i, 2] - x0[i, 2]) ** 2
        most = max(most, d)
    return np.sqrt(most)


@njit(cache=True)
def plane_distances(x, vptr, point, normal):
    """Signed distance of each grain's lowest vertex over the plane (point, normal)."""
    G = len(vptr) - 1
    out = np.full(G, np.inf)
    for g in range(G):
        for i in range(vptr[g], vptr[g + 1]):
            d = (x[i, 0] - point[0]) * normal[0] + (x[i, 1] - point[1]) * normal[1] + (x[i, 2] - point[2]) * normal[2]
            out[g] = min(out[g], d)
    return out


@njit(cache=True)
def plane_closing_time(dist, approach, r, gbar, f):
    """Smallest (max(d - gbar, 0) + f min(d, gbar)) / s over the grains that approach a plane:
    d = max(dist, gbar), dist the grain's lowest vertex over it (plane_distances), s =
    max(approach, 0) + r (approach: the grain's centre speed towards the plane, r: its vertices'
    largest speed about the centre). One compiled pass instead of five array operations."""
    best = np.inf
    for g in range(len(dist)):
        speed = max(approach[g], 0.0) + r[g]
        if speed > 0.0:
            d = max(dist[g], gbar)
            best = min(best, (max(d - gbar, 0.0) + f * min(d, gbar)) / speed)
    return best


@njit(cache=True)
def max_pair_speed(c, r, pairs, n_grains, wall_velocity):
    """Bound on the approach speed of every candidate pair (grain, grain or mesh wall): the
    relative centre speed plus each grain side's largest vertex speed about its centre."""
    best = 0.0
    for k in range(len(pairs)):
        a, o = pairs[k, 0], pairs[k, 1]
        if o >= n_grains:
            w = o - n_grains
            d0, d1, d2 = c[a, 0] - wall_velocity[w, 0], c[a, 1] - wall_velocity[w, 1], c[a, 2] - wall_velocity[w, 2]
            other = 0.0
        else:
            d0, d1, d2 = c[a, 0] - c[o, 0], c[a, 1] - c[o, 1], c[a, 2] - c[o, 2]
            other = r[o]
        best = max(best, np.sqrt(d0 * d0 + d1 * d1 + d2 * d2) + r[a] + other)
    return best


@njit(cache=True)
def rigid_pair_inverse_masses(x_all, ints, floats, centre, rotation, mass, moments):
    """1/m_eff of every pair along its normal n = sum_i w_i x_i / |.|: sum over its grain sides
    of 1/m + (r x n) . I^-1 (r x n), r from the grain's centroid to the contact point, I^-1 =
    R diag(1/I_k) R^T (a wall side adds nothing): rigid grains (model/rigid.py), given as arrays."""
    G = len(mass)
    out = np.zeros(len(ints))
    w0 = np.empty(6)
    D = np.empty((6, 2))
    d = np.empty(3)
    p = np.empty(3)
    for c in range(len(ints)):
        kind = ints[c, KIND]
        w = pair_weights(kind, floats[c, C0], floats[c, C1], w0, D)
        d[:] = 0.0
        p[:] = 0.0
        n_a = 2 if kind == EDGE_EDGE else 1
        for i in range(N_NODES[kind]):
            node = ints[c, NODE0 + i]
            for a in range(3):
                d[a] += w[i] * x_all[node, a]
                if i >= n_a:  # side B's point (by role: a wall plane's weights take any sign)
                    p[a] -= w[i] * x_all[node, a]
        norm = np.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
        n0, n1, n2 = d[0] / norm, d[1] / norm, d[2] / norm
        for side in (GRAIN_A, GRAIN_B):
            g = ints[c, side]
            if g >= G:
                continue
            # r x n and R^T (r x n) written out: numba's np.cross and 3x3 products cost more to
            # compile and to call than the pair itself
            r0, r1, r2 = p[0] - centre[g, 0], p[1] - centre[g, 1], p[2] - centre[g, 2]
            q0, q1, q2 = r1 * n2 - r2 * n1, r2 * n0 - r0 * n2, r0 * n1 - r1 * n0
            inv = 1.0 / mass[g]
            for k in range(3):
                b = rotation[g, 0, k] * q0 + rotation[g, 1, k] * q1 + rotation[g, 2, k] * q2  # (R^T (r x n))_k
                inv += b * b / moments[g, k]
            out[c] += inv
    return out


def damped_pair_step(inv_mass: np.ndarray, floats: np.ndarray, law_params, m_eq: np.ndarray, zeta: float) -> float:
    """The central-difference limit of every pair given its inverse mass along the normal
    (omega^2 = k(g) / m_eff) and the damping ratio its normal damping has there,
    zeta_p = zeta sqrt(m_eq / m_eff): min of 2/omega (sqrt(1 + zeta_p^2) - zeta_p)."""
    k = normal_stiffness(np.ascontiguousarray(floats[:, GAP]), law_params)
    loaded = k * inv_mass > 0
    if not loaded.any():
        return np.inf
    omega = np.sqrt(k[loaded] * inv_mass[loaded])
    zp = zeta * np.sqrt(m_eq[loaded] * inv_mass[loaded])
    return float(np.min(2.0 / omega * (np.sqrt(1.0 + zp**2) - zp)))
