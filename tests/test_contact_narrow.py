"""Closest points and distances of the degenerate LCPs, checked against the IPC Toolkit (ipctk),
and the exact gap derivatives against finite differences."""

import ipctk
import numpy as np
import pytest

from vemdem.contact.narrow import (
    EDGE_EDGE,
    N_NODES,
    VERTEX_EDGE,
    VERTEX_FACE,
    VERTEX_VERTEX,
    edge_edge_closest,
    edge_edge_lcp,
    gap_derivatives,
    gap_gradient,
    point_triangle_closest,
    vertex_edge_lcp,
    vertex_face_lcp,
)


def random_point_triangles(rng, n):
    cases = [rng.normal(size=(4, 3)) for _ in range(n)]
    t = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    # degenerate: exactly over a vertex, over an edge, in the plane, on the plane at a vertex
    cases += [np.vstack([[0.0, 0, 0.3], t]), np.vstack([[0.5, 0, 0.2], t]), np.vstack([[0.5, 0.5, 0.1], t]),
              np.vstack([[0.2, 0.2, 0.0], t]), np.vstack([[2.0, 0.5, 0.0], t]), np.vstack([[1.0, 0, 0], t]),
              np.vstack([[-1.0, -1.0, 0.5], t])]  # fmt: skip
    return cases


def random_edge_pairs(rng, n):
    cases = [rng.normal(size=(4, 3)) for _ in range(n)]
    a0, a1 = np.array([0.0, 0, 0]), np.array([1.0, 0, 0])
    for shift in ([0, 0.3, 0], [0.5, 0.2, 0.1], [1.5, 0.1, 0], [-0.5, 0, 0.2], [1.0, 0, 0]):
        cases.append(np.array([a0, a1, a0 + shift, a1 + shift]))  # parallel and collinear
    cases.append(np.array([a0, a1, [0.5, -1, 0.2], [0.5, 1, 0.2]]))  # crossing, perpendicular
    cases.append(np.array([a0, a1, [0.0, -1, 0.0], [0.0, 1, 0.0]]))  # touching at a vertex
    cases.append(np.array([a0, a1, [1.0, 0, 0], [2.0, 1, 0.0]]))  # sharing an end point
    cases.append(np.array([a0, a1, [0.5, 0, 0], [0.5, 1, 0.0]]))  # T-junction, zero distance
    return cases


def test_point_triangle_against_ipctk(rng):
    for p, t0, t1, t2 in random_point_triangles(rng, 3000):
        kind, d = point_triangle_closest(p, t0, t1, t2)
        assert d == pytest.approx(np.sqrt(ipctk.point_triangle_distance(p, t0, t1, t2)), rel=1e-9, abs=1e-12)
        ipc_kind = int(ipctk.point_triangle_distance_type(p, t0, t1, t2))
        if kind != ipc_kind:  # only ties (equal distance to two features) may differ
            assert d < 1e-12 or _ties_pt(p, t0, t1, t2, d)


def _ties_pt(p, t0, t1, t2, d):
    ds = [np.linalg.norm(p - v) for v in (t0, t1, t2)]
    return min(ds) == pytest.approx(d, rel=1e-9)


def test_edge_edge_against_ipctk(rng):
    for a0, a1, b0, b1 in random_edge_pairs(rng, 3000):
        kind, d = edge_edge_closest(a0, a1, b0, b1)
        assert d == pytest.approx(np.sqrt(ipctk.edge_edge_distance(a0, a1, b0, b1)), rel=1e-9, abs=1e-12)
        ipc_kind = int(ipctk.edge_edge_distance_type(a0, a1, b0, b1))
        da = np.cross(a1 - a0, b1 - b0)
        parallel = np.dot(da, da) <= 1e-10 * np.dot(a1 - a0, a1 - a0) * np.dot(b1 - b0, b1 - b0)
        if kind != ipc_kind and not parallel:  # parallel edges: a segment of closest points
            assert d < 1e-12


def test_vertex_vertex_and_vertex_edge_against_ipctk(rng):
    for _ in range(1000):
        p, e0, e1 = rng.normal(size=(3, 3))
        ok, t = vertex_edge_lcp(p, e0, e1)
        if ok:
            d = np.linalg.norm(p - (1 - t) * e0 - t * e1)
            assert d == pytest.approx(np.sqrt(ipctk.point_edge_distance(p, e0, e1)), rel=1e-10)
            assert int(ipctk.point_edge_distance_type(p, e0, e1)) == 2  # P_E
        assert np.linalg.norm(p - e0) == pytest.approx(np.sqrt(ipctk.point_point_distance(p, e0)), rel=1e-12)


def test_parallel_edges_are_never_an_edge_edge_pair():
    a0, a1 = np.zeros(3), np.array([1.0, 0, 0])
    for eps in (0.0, 1e-9):
        ok, _, _ = edge_edge_lcp(a0, a1, np.array([0.2, 0.1, eps]), np.array([1.2, 0.1, 0.0]))
        assert not ok
    # their contact survives as vertex-edge pairs at the ends of the overlap
    assert vertex_edge_lcp(np.array([0.2, 0.1, 0.0]), a0, a1)[0]
    assert vertex_edge_lcp(a1, np.array([0.2, 0.1, 0.0]), np.array([1.2, 0.1, 0.0]))[0]


def _lcp(kind, xs):
    if kind == VERTEX_FACE:
        return vertex_face_lcp(*xs[:4])[1:]
    if kind == EDGE_EDGE:
        return edge_edge_lcp(*xs[:4])[1:]
    if kind == VERTEX_EDGE:
        return vertex_edge_lcp(*xs[:3])[1], 0.0
    return 0.0, 0.0


def _gap(kind, xs):
    return gap_derivatives(kind, xs, *_lcp(kind, xs), False, np.zeros((6, 3)), np.zeros((1, 1)))


@pytest.mark.parametrize("kind", [VERTEX_FACE, EDGE_EDGE, VERTEX_EDGE, VERTEX_VERTEX])
def test_gap_derivatives_include_the_moving_contact_point(kind, rng):
    nn = N_NODES[kind]
    for _ in range(20):
        xs = np.zeros((6, 3))
        xs[:nn] = rng.normal(size=(nn, 3))
        grad = np.zeros((6, 3))
        hess = np.zeros((3 * nn, 3 * nn))
        d = gap_derivatives(kind, xs, *_lcp(kind, xs), True, grad, hess)
        h = 1e-6
        fd_grad = np.zeros(3 * nn)
        fd_hess = np.zeros((3 * nn, 3 * nn))
        for k in range(3 * nn):
            xp, xm = xs.copy(), xs.copy()
            xp.reshape(-1)[k] += h
            xm.reshape(-1)[k] -= h
            fd_grad[k] = (_gap(kind, xp) - _gap(kind, xm)) / (2 * h)
            gp, gm = np.zeros((6, 3)), np.zeros((6, 3))
            gap_derivatives(kind, xp, *_lcp(kind, xp), False, gp, np.zeros((1, 1)))
            gap_derivatives(kind, xm, *_lcp(kind, xm), False, gm, np.zeros((1, 1)))
            fd_hess[:, k] = (gp[:nn] - gm[:nn]).ravel() / (2 * h)
        assert d > 0
        np.testing.assert_allclose(grad[:nn].ravel(), fd_grad, atol=1e-7)
        only = np.zeros((6, 3))  # the explicit steps' gradient-only kernel: the same numbers
        assert gap_gradient(kind, xs, *_lcp(kind, xs), only) == d
        np.testing.assert_array_equal(only, grad)
        np.testing.assert_allclose(hess, fd_hess, atol=1e-6 * max(1.0, np.abs(hess).max()))
