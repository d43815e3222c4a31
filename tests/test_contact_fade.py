"""The edge-edge fade (contact/fade.py, `[contact] edge_fade`): edge-edge records weighed out near
their edges' ends, so that the contact potential is continuous where an edge-edge record hands its
spot to the end vertex's records (docs/contact.md, "twins")."""

import numpy as np
import pytest

from vemdem.contact.fade import fade_hessian, in_fade_zone, real_fade_gradient, smooth_step
from vemdem.contact.friction import FrictionLaw
from vemdem.contact.law import InterfaceLaw
from vemdem.contact.model import ContactModel
from vemdem.contact.narrow import EDGE_EDGE, VERTEX_EDGE, VERTEX_FACE, edge_edge_lcp
from vemdem.contact.pairs import KIND, NODE0
from vemdem.geometry import cube

GBAR = 2e-5
LAW = InterfaceLaw(activation_gap=GBAR, penalty=1e9, edge_fade=True)
FRICTIONLESS = FrictionLaw()
FRICTION = FrictionLaw(mu_s=0.5, mu_d=0.4, tangential_penalty=1e6, tangential_viscosity=3.0, damping_ratio=0.4)


def edge_pairs_in_zone(rng, n, r):
    """n random skew edge pairs (unit size) whose closest points lie inside both open edges, within
    r of at least one end."""
    out = []
    while len(out) < n:
        xs = rng.normal(size=(4, 3))
        if in_fade_zone(xs, r) and edge_edge_lcp(*xs)[0]:
            out.append(xs)
    return out


def test_the_smooth_step_rises_from_0_to_1_with_continuous_slope_and_curvature():
    r = 0.3
    ls = np.linspace(-0.1, 0.4, 2001)
    psi = np.array([smooth_step(l, r)[0] for l in ls])
    dpsi = np.array([smooth_step(l, r)[1] for l in ls])
    assert psi[ls <= 0].max() == 0.0 and psi[ls >= r].min() == 1.0
    assert np.all(np.diff(psi) >= 0)
    h = ls[1] - ls[0]
    np.testing.assert_allclose(np.gradient(psi, h)[2:-2], dpsi[2:-2], atol=1e-4)
    assert smooth_step(1e-9, r)[1] < 1e-14 and smooth_step(r - 1e-9, r)[1] < 1e-14  # C1 at both ends
    curvature = np.diff(dpsi) / h  # C2: no jump of psi'' at the ends either
    peak = np.abs(curvature).max()
    assert np.abs(curvature[ls[1:] < 1e-3]).max() < 0.05 * peak
    assert np.abs(curvature[ls[1:] > r - 1e-3]).max() < 0.05 * peak


def test_the_weight_gradient_is_the_derivative_of_the_weight(rng):
    r = 0.4
    for xs in edge_pairs_in_zone(rng, 20, r):
        w, grad = real_fade_gradient(xs, r)
        assert 0.0 <= w < 1.0
        fd = np.zeros((4, 3))
        h = 1e-6
        for i in range(4):
            for a in range(3):
                xp, xm = xs.copy(), xs.copy()
                xp[i, a] += h
                xm[i, a] -= h
                fd[i, a] = (real_fade_gradient(xp, r)[0] - real_fade_gradient(xm, r)[0]) / (2 * h)
        np.testing.assert_allclose(grad, fd, atol=1e-7 * max(1.0, np.abs(grad).max()))


def test_the_weight_hessian_is_the_derivative_of_its_gradient(rng):
    r = 0.4
    for xs in edge_pairs_in_zone(rng, 10, r):
        hess = np.zeros((12, 12))
        fade_hessian(xs, r, hess)
        np.testing.assert_allclose(hess, hess.T, atol=1e-9 * np.abs(hess).max())
        fd = np.zeros((12, 12))
        h = 1e-6
        for j in range(12):
            xp, xm = xs.copy(), xs.copy()
            xp[j // 3, j % 3] += h
            xm[j // 3, j % 3] -= h
            fd[:, j] = (real_fade_gradient(xp, r)[1] - real_fade_gradient(xm, r)[1]).ravel() / (2 * h)
        np.testing.assert_allclose(hess, fd, atol=1e-6 * max(1.0, np.abs(hess).max()))


def tetrahedron_on_cube(apex, others, friction=FRICTIONLESS):
    """A 1 mm cube (grain 0) and a tetrahedron (grain 1) with vertex `apex` and three more."""
    b = cube(1e-3)
    tet = np.vstack([apex, others])
    faces = []
    centre = tet.mean(axis=0)
    for f in ([0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]):
        n = np.cross(tet[f[1]] - tet[f[0]], tet[f[2]] - tet[f[0]])
        faces.append(f if n @ (tet[f].mean(axis=0) - centre) > 0 else [f[0], f[2], f[1]])
    x = np.vstack([b.vertices, tet])
    model = ContactModel(x, [b.faces, np.array(faces)], np.array([0, 8, 12]), np.array([1e-6, 1e-7]), LAW, friction)
    return model, x


def wedge_over_edge(x1, friction=FRICTIONLESS):
    """A tetrahedron whose lowest vertex a1 (at height 0.5 gbar) sits at x = x1 over the top face of a
    1 mm cube, near the cube's top edge at x = 0.5 mm, with an edge from a1 rising gently outward over
    that edge. For x1 a little below the edge, the edge-edge record of that edge with the cube's top
    edge and a1's vertex-face record with the top face carry the same spot (twins); the edge-edge
    record leaves where its closest point passes a1, and a1's vertex-edge record follows the
    vertex-face one past the edge."""
    L, slope, g = 4e-4, 0.05, 0.5 * GBAR
    a1 = np.array([x1, 0.0, 0.5e-3 + g])
    others = a1 + L * np.array([[1.0, 0.1, slope], [-0.3, -0.5, 0.8], [-0.3, 0.6, 0.8]])
    return tetrahedron_on_cube(a1, others, friction)


def test_the_contact_potential_is_continuous_where_an_edge_edge_record_meets_its_end():
    """Sliding the wedge across the cube's edge: the work of the contact force along the path equals the
    change of the potential. Unweighted, the edge-edge record's potential vanished at once where its
    closest point passed a1 (its vertex-face twin stayed): a jump of one barrier term, about half
    the potential, that the force never does work for."""
    edge = 0.5e-3
    xs = np.linspace(edge - 4 * GBAR, edge + GBAR, 801)
    energy, slope, kinds = [], [], set()
    for x1 in xs:
        model, x = wedge_over_edge(x1)
        cand = model.search(x, 0.0)
        res = model.evaluate(x, 0.0, cand)
        energy.append(res.energy)
        slope.append(res.force[8:, 0].sum())  # dE/dx1: the wedge's vertices moved together along x
        kinds |= set(res.ints[:, KIND].tolist())
    assert {EDGE_EDGE, VERTEX_FACE, VERTEX_EDGE} <= kinds  # the sweep crosses every hand-over
    energy, slope = np.array(energy), np.array(slope)
    work = np.sum(0.5 * (slope[1:] + slope[:-1]) * np.diff(xs))
    assert energy[-1] - energy[0] == pytest.approx(work, rel=1e-3, abs=1e-4 * energy.max())
    steps = np.abs(np.diff(energy))
    assert steps.max() < 5 * np.abs(slope).max() * (xs[1] - xs[0])  # no jump anywhere along the way


@pytest.mark.parametrize("friction", [FRICTIONLESS, FRICTION], ids=["frictionless", "friction"])
def test_a_faded_record_has_the_derivatives_of_its_weighted_potential(friction, rng):
    """Inside the fade zone, the residual is the derivative of the weighted potential (frictionless),
    and the tangent is the derivative of the residual (with damping and friction: for a fixed history)."""
    model, x = wedge_over_edge(0.5e-3 - 0.4 * GBAR, friction)
    cand = model.search(x, 0.0)
    res = model.evaluate(x, 0.0, cand, tangent=True)
    ee = np.flatnonzero(res.ints[:, KIND] == EDGE_EDGE)
    assert len(ee) == 1
    nodes = np.zeros((4, 3))
    for i in range(4):
        nodes[i] = x[res.ints[ee[0], NODE0 + i]]
    assert in_fade_zone(nodes, GBAR)
    w = real_fade_gradient(nodes, GBAR)[0]
    assert 0.05 < w < 0.95
    history = res.trial_history
    v0 = 1e-3 * rng.normal(size=x.shape)
    a4 = 2e4 if friction.active else 0.0
    moved = x + 1e-8 * rng.normal(size=x.shape)
    at = model.evaluate(moved, 0.0, cand, history, v=v0, a4=a4, tangent=True)
    K = at.tangent.toarray()
    fd, grad = np.zeros_like(K), np.zeros(x.size)
    h = 1e-11
    for k in range(x.size):
        dx = np.zeros(x.size)
        dx[k] = h
        dx = dx.reshape(-1, 3)
        plus = model.evaluate(moved + dx, 0.0, cand, history, v=v0 + a4 * dx, a4=a4)
        minus = model.evaluate(moved - dx, 0.0, cand, history, v=v0 - a4 * dx, a4=a4)
        fd[:, k] = (plus.force - minus.force).ravel() / (2 * h)
        grad[k] = (plus.energy - minus.energy) / (2 * h)
    if not friction.active:
        np.testing.assert_allclose(at.force.ravel(), grad, atol=1e-6 * np.abs(grad).max())
    np.testing.assert_allclose(K, fd, atol=2e-5 * np.abs(K).max())


def test_a_vertex_over_an_edge_keeps_its_vertex_edge_record_beside_fading_edge_edge_records():
    """A vertex just past the cube's top edge, two of its edges running back over that edge: both
    edge-edge records have their closest points a fraction of gbar from the vertex, where they fade.
    The vertex-edge record must carry the spot. The hierarchy used to drop a vertex-edge record that
    two edge-edge records linked, which with the fade would leave the spot nearly unsupported."""
    eps, g, L, slope = 0.2 * GBAR, 0.5 * GBAR, 4e-4, 0.05
    p = np.array([0.5e-3 + eps, 0.0, 0.5e-3 + g])
    others = p + L * np.array([[-1.0, 0.5, slope], [-1.0, -0.5, slope], [-0.5, 0.0, 0.8]])
    model, x = tetrahedron_on_cube(p, others)
    res = model.evaluate(x, 0.0, model.search(x, 0.0))
    kinds = res.ints[:, KIND]
    assert (kinds == EDGE_EDGE).sum() == 2
    assert (kinds == VERTEX_EDGE).sum() == 1
    d_ve = float(res.floats[kinds == VERTEX_EDGE, 2][0])
    assert d_ve == pytest.approx(np.hypot(eps, g), rel=1e-9)
    phi_ve = float(LAW.packed()[2] * (GBAR - d_ve) ** 3 / 3)  # the penalty branch's potential
    assert res.energy >= phi_ve
    assert res.energy < 1.5 * phi_ve  # the faded edge-edge records add little


def test_the_fade_is_off_by_default():
    """(The config key: test_contact_law.test_contact_switches_are_off_by_default_and_keys_turn_them_on.)"""
    assert InterfaceLaw(GBAR, 1e9).edge_fade is False
    model, x = wedge_over_edge(0.5e-3 - 0.4 * GBAR)
    faded = model.evaluate(x, 0.0, model.search(x, 0.0))
    model.law_params = InterfaceLaw(GBAR, 1e9).packed()  # the same scene without the fade
    unweighted = model.evaluate(x, 0.0, model.search(x, 0.0))
    assert unweighted.energy > 1.05 * faded.energy
