"""Grain-grain contact pairs: the hierarchy on flat contacts, action = reaction,
residual and tangent against finite differences of the potential, broad phase against brute force."""

from collections import Counter, namedtuple

import ipctk
import numpy as np
import pytest
from numba import njit

from vemdem.contact.broad import brute_force_pairs, candidate_pairs
from vemdem.contact.forces import evaluate_contacts, pair_inverse_masses
from vemdem.contact.law import InterfaceLaw
from vemdem.contact.narrow import (
    EDGE_EDGE,
    N_NODES,
    PAIR_NAMES,
    VERTEX_EDGE,
    VERTEX_FACE,
    VERTEX_VERTEX,
    edge_edge_closest,
    pair_weights,
    point_triangle_closest,
)
from vemdem.contact.pairs import (
    C0,
    C1,
    GAP,
    NODE0,
    _ee_gap,
    _ve_gap,
    _vertex_edge_survives,
    _vertex_vertex_survives,
    _vf_gap,
    find_contacts,
)
from vemdem.contact.topology import CONCAVE, CONVEX, FLAT, build_topology
from vemdem.geometry import Polyhedron, cube, l_prism, rotation_matrix, sand_grain

GBAR = 0.05


def scene(grains):
    vptr = np.cumsum([0] + [g.n_vertices for g in grains])
    X = np.vstack([g.vertices for g in grains])
    return X, build_topology(X, [g.faces for g in grains], vptr)


def pairs_of(grains, x=None):
    X, topo = scene(grains)
    x = X if x is None else x
    ints, floats = find_contacts(x, candidate_pairs(x, topo.grain_vertex_ptr, GBAR), topo, GBAR)
    return Counter(PAIR_NAMES[k] for k in ints[:, 0]), ints, floats, topo


def test_edge_types():
    _, topo = scene([cube(1.0), l_prism(1.0, 0.5)])
    t = topo.edge_type
    assert np.sum(t[topo.edge_grain == 0] == CONVEX) == 12 and np.sum(t[topo.edge_grain == 0] == FLAT) == 6
    assert np.sum(t[topo.edge_grain == 1] == CONCAVE) == 1  # the vertical edge at the reflex corner


def test_cube_on_smaller_offset_cube_gives_the_overlap_corners():
    """Upper cube shifted by (0.3, 0.2): the overlap rectangle's corners are one vertex of each cube
    over the other's face and two crossings of convex edges, gap 0.01 everywhere."""
    counts, ints, floats, _ = pairs_of([cube(1.0), cube(1.0, center=(0.3, 0.2, 1.01))])
    assert counts == Counter({"vertex-face": 2, "edge-edge": 2})
    np.testing.assert_allclose(floats[:, 2], 0.01, rtol=1e-12)
    points = np.array(sorted(tuple(np.round(p, 9)) for p in _contact_points(ints, floats, scene([cube(1.0), cube(1.0, center=(0.3, 0.2, 1.01))])[0])))
    expected = sorted([(-0.2, -0.3), (0.5, 0.5), (-0.2, 0.5), (0.5, -0.3)])
    np.testing.assert_allclose(points[:, :2], expected, atol=1e-9)


def _contact_points(ints, floats, x):
    """Point on side B of each pair (for the pictures in the tests)."""
    from vemdem.contact.narrow import pair_weights

    out = []
    for row, fl in zip(ints, floats):
        w = pair_weights(row[0], fl[0], fl[1], np.empty(6), np.empty((6, 2)))
        nodes = row[5:11]
        pB = sum(-w[i] * x[nodes[i]] for i in range(6) if nodes[i] >= 0 and w[i] < 0)
        out.append(pB)
    return np.array(out)


def test_aligned_cubes_touch_at_four_vertex_pairs():
    counts, *_ = pairs_of([cube(1.0), cube(1.0, center=(0, 0, 1.01))])
    assert counts == Counter({"vertex-vertex": 4})


def test_rotated_cube_on_cube_gives_eight_edge_crossings():
    top = cube(1.0).rotated(rotation_matrix([0, 0, np.pi / 4])).translated((0, 0, 1.01))
    counts, *_ = pairs_of([cube(1.0), top])
    assert counts == Counter({"edge-edge": 8})


def test_small_cube_on_large_cube():
    """Corners over the face interior are vertex-face pairs; corners exactly over the large cube's
    face diagonal (a flat edge) are vertex-edge pairs, found once, not twice."""
    counts, *_ = pairs_of([cube(2.0), cube(1.0, center=(0, 0, 1.51))])
    assert counts == Counter({"vertex-face": 2, "vertex-edge": 2})
    counts, *_ = pairs_of([cube(2.0), cube(1.0, center=(0.1, 0.05, 1.51))])
    assert counts == Counter({"vertex-face": 4})


def test_cube_in_the_concave_corner_of_an_l_prism():
    """A small cube resting in the L's inner corner touches both walls of the concave edge."""
    L = l_prism(2.0, 1.0)  # outline corner at the origin after centring: reflex corner at (1, 1) - centre
    reflex = L.vertices[3]  # bottom vertex at the reflex corner
    c = cube(0.4).translated(reflex + np.array([0.2 + 0.01, 0.2 + 0.01, 0.5]))
    counts, ints, floats, topo = pairs_of([L, c])
    # the cube sits in the quadrant x > reflex, y > reflex: it faces the two walls of the notch
    assert counts["vertex-face"] == 8  # four cube corners against each wall
    assert counts["vertex-edge"] == 0 and counts["vertex-vertex"] == 0
    np.testing.assert_allclose(floats[:, 2], 0.01, rtol=1e-9)


def test_no_duplicate_pairs_on_random_grains(rng):
    a = sand_grain(seed=1, size=1.0)
    for seed in range(10):
        R = rotation_matrix(rng.normal(size=3))
        b = sand_grain(seed=100 + seed, size=1.0).rotated(R)
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction)
        b = _place_at_gap(a, b, direction, 0.3 * GBAR)
        counts, ints, _, _ = pairs_of([a, b])
        keys = {tuple(r[:5]) for r in ints}
        assert len(keys) == len(ints)
        assert sum(counts.values()) >= 1


def test_recorded_gaps_are_the_ipctk_distances_of_their_primitives(rng):
    """Every pair found between random grains at a gap of 0.3 gbar carries the distance ipctk
    computes for its primitives (point-triangle, edge-edge, point-edge, point-point), and the
    closest one is the surfaces' distance."""
    a = sand_grain(seed=2, size=1.0)
    checked = 0
    for seed in range(6):
        b = sand_grain(seed=200 + seed, size=1.0).rotated(rotation_matrix(rng.normal(size=3)))
        direction = rng.normal(size=3)
        b = _place_at_gap(a, b, direction / np.linalg.norm(direction), 0.3 * GBAR)
        _, ints, floats, _ = pairs_of([a, b])
        x = np.vstack([a.vertices, b.vertices])
        for rec, gap in zip(ints, floats[:, GAP]):
            n = x[rec[NODE0 : NODE0 + 4].clip(0)]
            if rec[0] == VERTEX_FACE:
                d2 = ipctk.point_triangle_distance(n[0], n[1], n[2], n[3])
            elif rec[0] == EDGE_EDGE:
                d2 = ipctk.edge_edge_distance(n[0], n[1], n[2], n[3])
            elif rec[0] == VERTEX_EDGE:
                d2 = ipctk.point_edge_distance(n[0], n[1], n[2])
            else:
                d2 = ipctk.point_point_distance(n[0], n[1])
            assert gap == pytest.approx(np.sqrt(d2), rel=1e-9)
            checked += 1
        assert floats[:, GAP].min() == pytest.approx(0.3 * GBAR, rel=1e-6)
    assert checked >= 6


@njit(cache=True)
def _min_distance(va, fa, ea, vb, fb, eb):
    """Brute-force distance between two surfaces from the closest-point kernels that
    test_contact_narrow.py checks against ipctk."""
    best = np.inf
    for f in range(len(fa)):
        for p in range(len(vb)):
            best = min(best, point_triangle_closest(vb[p], va[fa[f, 0]], va[fa[f, 1]], va[fa[f, 2]])[1])
    for f in range(len(fb)):
        for p in range(len(va)):
            best = min(best, point_triangle_closest(va[p], vb[fb[f, 0]], vb[fb[f, 1]], vb[fb[f, 2]])[1])
    for i in range(len(ea)):
        for j in range(len(eb)):
            best = min(best, edge_edge_closest(va[ea[i, 0]], va[ea[i, 1]], vb[eb[j, 0]], vb[eb[j, 1]])[1])
    return best


def _place_at_gap(a, b, direction, gap):
    """Move b along `direction` until its distance to a equals gap (bisection)."""
    ea, eb = a.edges(), b.edges()

    def dist(s):
        return _min_distance(a.vertices, a.faces, ea, b.vertices + s * direction, b.faces, eb)

    lo, hi = -3.0, 3.0  # b overlaps a at lo (distance 0) and is clear of it at hi
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        if dist(mid) < gap:
            lo = mid
        else:
            hi = mid
    return b.translated(hi * direction)


def _plank():
    c = cube(1.0)
    return Polyhedron(c.vertices * np.array([6.0, 1.0, 0.2]), c.faces)


def test_a_cube_off_the_plank_axis_keeps_its_four_corner_pairs():
    """The narrow phase's slab test runs along the line between the box centres: a cube lying on
    the end of a long plank is far off it (83 deg from the contact normal) and still rests on
    four vertex-face pairs at the gap it was put at."""
    top = cube(0.4, center=(2.5, 0.1, 0.1 + 0.2 + 0.01))
    counts, _, floats, _ = pairs_of([_plank(), top])
    assert counts == Counter({"vertex-face": 4})
    np.testing.assert_allclose(floats[:, GAP], 0.01, rtol=1e-9)


def _unculled_pairs(x, A, B, gbar, t):
    """grain_pair_contacts' loops over every feature pair of grains A and B, without its box and
    slab culling (the same gap kernels and hierarchy, in the same order): what the culling must
    leave unchanged. Returns (kind, grain A, grain B, feature A, feature B, gap) rows."""
    return _unculled(x, A, B, gbar, t.grain_vertex_ptr, t.grain_face_ptr, t.grain_edge_ptr,
                     _Topo(t.faces, t.edges, t.edge_faces, t.edge_type, t.vertex_face_ptr, t.vertex_faces,
                           t.vertex_edge_ptr, t.vertex_edges))  # fmt: skip


_Topo = namedtuple(
    "_Topo", "faces edges edge_faces edge_type vertex_face_ptr vertex_faces vertex_edge_ptr vertex_edges"
)


@njit(cache=True)
def _unculled(x, A, B, gbar, vptr, fptr, eptr, t):
    out = []
    for side in range(2):
        ga, gb = (A, B) if side == 0 else (B, A)
        for p in range(vptr[ga], vptr[ga + 1]):
            for f in range(fptr[gb], fptr[gb + 1]):
                d = _vf_gap(x, p, f, t.faces, gbar)[0]
                if d >= 0.0:
                    out.append((VERTEX_FACE, ga, gb, p, f, d))
    for ea in range(eptr[A], eptr[A + 1]):
        for eb in range(eptr[B], eptr[B + 1]):
            d = _ee_gap(x, ea, eb, t.edges, t.edge_type, gbar)[0]
            if d >= 0.0:
                out.append((EDGE_EDGE, A, B, ea, eb, d))
    for side in range(2):
        ga, gb = (A, B) if side == 0 else (B, A)
        for p in range(vptr[ga], vptr[ga + 1]):
            for e in range(eptr[gb], eptr[gb + 1]):
                d = _ve_gap(x, p, e, t.edges, gbar)[0]
                if d >= 0.0 and _vertex_edge_survives(x, p, e, t.faces, t.edge_faces, t.edge_type, gbar):
                    out.append((VERTEX_EDGE, ga, gb, p, e, d))
    for p in range(vptr[A], vptr[A + 1]):
        for q in range(vptr[B], vptr[B + 1]):
            d = np.sqrt((x[p, 0] - x[q, 0]) ** 2 + (x[p, 1] - x[q, 1]) ** 2 + (x[p, 2] - x[q, 2]) ** 2)
            if d <= gbar and _vertex_vertex_survives(x, p, q, t.faces, t.edges, t.vertex_face_ptr, t.vertex_faces,
                                                     t.vertex_edge_ptr, t.vertex_edges, gbar):  # fmt: skip
                out.append((VERTEX_VERTEX, A, B, p, q, d))
    return out


def test_culling_keeps_every_pair_of_the_unculled_loops(rng):
    """The narrow phase culls feature pairs by boxes and by a slab along the line between the
    grains' box centres (contact/pairs.py); the records must be those of the same loops over
    every feature pair, in the same order. Sand grains at 0.3 and 0.8 gbar on every side of a long
    plank (far off that line: up to 80 deg from the contact normal) and against each other;
    at 1.5 gbar, nothing."""
    plank = _plank()
    checked = 0
    for seed in range(8):
        b = sand_grain(seed=300 + seed, size=0.8).rotated(rotation_matrix(rng.normal(size=3)))
        a = plank if seed < 6 else sand_grain(seed=400 + seed, size=1.0)
        along = rng.uniform(-2.5, 2.5) if seed < 6 else 0.0
        b = b.translated(np.array([along, 0.0, 0.0]) - b.vertices.mean(axis=0))
        side = rng.normal(size=3) * np.array([0.2, 1.0, 1.0])
        direction = side / np.linalg.norm(side)
        for gap in (0.3 * GBAR, 0.8 * GBAR, 1.5 * GBAR):
            placed = _place_at_gap(a, b, direction, gap)
            x, t = scene([a, placed])
            found, ints, floats, _ = pairs_of([a, placed])
            reference = _unculled_pairs(x, 0, 1, GBAR, t)
            assert [tuple(r) for r in ints[:, :5]] == [r[:5] for r in reference]
            np.testing.assert_array_equal(floats[:, GAP], [r[5] for r in reference])
            checked += len(reference)
            if gap < GBAR:
                assert floats[:, GAP].min() == pytest.approx(gap, rel=1e-6)
    assert checked >= 8


def test_action_equals_reaction_and_no_net_moment(rng):
    law = InterfaceLaw(GBAR, 1e3).packed()
    a = sand_grain(seed=3, size=1.0)
    b = _place_at_gap(a, sand_grain(seed=4, size=1.0), np.array([0.3, 0.2, 1.0]) / np.linalg.norm([0.3, 0.2, 1.0]), 0.2 * GBAR)
    counts, ints, floats, topo = pairs_of([a, b])
    X = np.vstack([a.vertices, b.vertices])
    ev = evaluate_contacts(X, ints, floats, law, len(X))
    assert len(ints) > 0 and np.abs(ev.force).max() > 0
    scale = np.abs(ev.force).max()
    np.testing.assert_allclose(ev.force.sum(axis=0), 0, atol=1e-12 * scale)
    for origin in (np.zeros(3), rng.normal(size=3) * 10):
        np.testing.assert_allclose(np.cross(X - origin, ev.force).sum(axis=0), 0, atol=1e-11 * scale * 10)
    force_on_a = -ev.force[: a.n_vertices].sum(axis=0)  # ev.force is dPhi/dx
    assert force_on_a @ (b.centroid - a.centroid) < 0  # repulsive


def test_residual_and_tangent_are_derivatives_of_the_potential(rng):
    law = InterfaceLaw(GBAR, 1e3).packed()
    top = cube(1.0).rotated(rotation_matrix([0.01, 0.02, 0.3])).translated((0.3, 0.2, 0.0))
    top = top.translated((0, 0, 0.5 + 0.4 * GBAR - top.vertices[:, 2].min()))
    X, topo = scene([cube(1.0), top])
    x = X + 1e-4 * rng.normal(size=X.shape)

    def total(xx):
        ints, floats = find_contacts(xx, np.array([[0, 1]]), topo, GBAR)
        return evaluate_contacts(xx, ints, floats, law, len(xx), tangent=True), ints

    ev, ints = total(x)
    assert len(ints) >= 3
    K = ev.tangent_matrix(len(x)).toarray()
    h = 1e-7
    fd_f = np.zeros(x.size)
    fd_K = np.zeros_like(K)
    for k in range(x.size):
        xp, xm = x.ravel().copy(), x.ravel().copy()
        xp[k] += h
        xm[k] -= h
        ep, _ = total(xp.reshape(-1, 3))
        em, _ = total(xm.reshape(-1, 3))
        fd_f[k] = (ep.total_energy - em.total_energy) / (2 * h)
        fd_K[:, k] = (ep.force.ravel() - em.force.ravel()) / (2 * h)
    np.testing.assert_allclose(ev.force.ravel(), fd_f, atol=1e-6 * np.abs(fd_f).max())
    np.testing.assert_allclose(K, fd_K, atol=1e-6 * np.abs(K).max())
    np.testing.assert_allclose(K, K.T, atol=1e-9 * np.abs(K).max())


@pytest.mark.parametrize("n_grains", [2, 50, 515])
def test_broad_phase_equals_brute_force(n_grains, rng):
    L = 1.3 * n_grains ** (1 / 3)
    centres = rng.uniform(0, L, size=(n_grains, 3))
    x = (centres[:, None, :] + rng.uniform(-0.5, 0.5, size=(n_grains, 12, 3))).reshape(-1, 3)
    vptr = np.arange(n_grains + 1) * 12
    pts = x.reshape(n_grains, 12, 3)
    for gap in (0.0, 0.05, 0.5):
        found = candidate_pairs(x, vptr, gap)
        np.testing.assert_array_equal(found, brute_force_pairs(x, vptr, gap))
        # the contract, from the vertices themselves and not through the package's grain_boxes:
        # exactly the pairs whose boxes, each grown by half the activation gap, overlap
        lo, hi = pts.min(axis=1) - 0.5 * gap, pts.max(axis=1) + 0.5 * gap
        overlap = np.all((hi[:, None] >= lo[None]) & (hi[None] >= lo[:, None]), axis=2)
        expected = np.column_stack(np.nonzero(np.triu(overlap, k=1)))
        np.testing.assert_array_equal(found, expected)
        # and so every pair of grains with two vertices closer than the gap is a candidate
        near = {(a, b) for a in range(n_grains) for b in range(a + 1, n_grains)
                if (np.linalg.norm(pts[a][:, None] - pts[b][None], axis=2) < gap).any()}  # fmt: skip
        assert near <= {tuple(p) for p in found.tolist()}


def test_pair_inverse_mass_is_the_eigenvalue_of_the_pair_spring(rng):
    """k sum_i w_i^2 / m_i (the explicit stable step's contact frequency) equals the largest
    eigenvalue of M^-1/2 K M^-1/2 for the spring K = k (w (x) n)(w (x) n)^T of each pair."""
    a = sand_grain(seed=3, size=1.0)
    b = sand_grain(seed=4, size=1.0).rotated(rotation_matrix(rng.normal(size=3)))
    direction = rng.normal(size=3)
    b = _place_at_gap(a, b, direction / np.linalg.norm(direction), 0.3 * GBAR)
    _, ints, floats, _ = pairs_of([a, b])
    x = np.vstack([a.vertices, b.vertices])
    mass = rng.uniform(0.5, 2.0, len(x))
    w0, D = np.empty(6), np.empty((6, 2))
    for rec, fl, inv_m in zip(ints, floats, pair_inverse_masses(1.0 / mass, ints, floats)):
        w = pair_weights(rec[0], fl[C0], fl[C1], w0, D)[: N_NODES[rec[0]]]
        nodes = rec[NODE0 : NODE0 + len(w)]
        g = w @ x[nodes]
        spring = np.zeros(3 * len(x))
        for wi, node in zip(w, nodes):
            spring[3 * node : 3 * node + 3] += wi * g / np.linalg.norm(g)
        s = spring / np.sqrt(np.repeat(mass, 3))
        assert np.linalg.eigvalsh(np.outer(s, s))[-1] == pytest.approx(inv_m, rel=1e-9)
