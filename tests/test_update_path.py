"""Newton updates of stiff grains (model/motion.py) and the conservative-advancement bound that
uses their rigid part (contact/ccd.py): a rigid update is recovered and applied without
stretch, the path agrees with x + alpha dx to first order, its displacement bound holds, two
grains moved along an update scaled by the bound never meet (distances from ipctk), and Newton on
a spinning grain converges faster than with the straight update, to the same state."""

import ipctk
import numpy as np
import pytest
from scipy.spatial import ConvexHull

from vemdem.contact.ccd import free_distance_ratio
from vemdem.contact.defaults import default_contact_laws
from vemdem.geometry import rotation_matrix, sand_grain
from vemdem.model.motion import RigidRetraction, rigid_split
from vemdem.model.scene import Scene
from vemdem.solver.linear import make_linear_solver
from vemdem.solver.newmark import NewmarkParameters, initial_state, newmark_step
from vemdem.vem.material import Material


def skew(w):
    return np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])


def grain_points(rng, n=14):
    return sand_grain(1e-3, n, seed=int(rng.integers(2**31))).vertices


def test_rigid_split_recovers_a_rigid_update(rng):
    x = grain_points(rng)
    t, phi = rng.normal(size=3) * 1e-5, rng.normal(size=3) * 1e-2
    weights = rng.uniform(0.5, 2.0, len(x))
    c = weights @ x / weights.sum()
    dx = t + np.cross(phi, x - c)
    cs, ts, phis, bound = rigid_split(x, dx, weights, np.array([0, len(x)]))
    assert np.allclose(cs[0], c, rtol=1e-12)
    assert np.allclose(ts[0], t, rtol=1e-10, atol=1e-18)
    assert np.allclose(phis[0], phi, rtol=1e-10)
    r = np.linalg.norm(x - c, axis=1).max()
    assert bound[0] == pytest.approx(np.linalg.norm(t) + np.linalg.norm(phi) * r, rel=1e-10)


def test_rotation_is_applied_without_stretch(rng):
    x = grain_points(rng)
    c = x.mean(axis=0)
    phi = np.array([0.02, -0.05, 0.1])
    dx = np.cross(phi, x - c)
    moved = RigidRetraction(x, dx, np.ones(len(x)), np.array([0, len(x)])).at(1.0)
    pairs = np.triu_indices(len(x), 1)

    def lengths(y):
        return np.linalg.norm(y[pairs[0]] - y[pairs[1]], axis=1)

    assert np.allclose(lengths(moved), lengths(x), rtol=1e-12)
    stretch = np.abs(lengths(x + dx) / lengths(x) - 1).max()
    assert stretch > 1e-3  # the straight update stretches by about |phi|^2 / 2
    R = rotation_matrix(phi)
    assert np.allclose(moved, c + (x - c) @ R.T, rtol=0, atol=1e-15)


def test_path_agrees_with_the_straight_update_to_first_order(rng):
    x = grain_points(rng)
    dx = 1e-5 * rng.normal(size=x.shape) + np.cross([0.3, 0.1, -0.2], x - x.mean(axis=0))
    move = RigidRetraction(x, dx, np.ones(len(x)), np.array([0, len(x)]))
    errors = [np.abs(move.at(a) - (x + a * dx)).max() for a in (1e-1, 1e-2, 1e-3)]
    assert errors[1] / errors[0] == pytest.approx(1e-2, rel=0.1)  # O(alpha^2)
    assert errors[2] / errors[1] == pytest.approx(1e-2, rel=0.1)


def test_displacement_bound_holds_along_the_path(rng):
    xa, xb = grain_points(rng), grain_points(rng) + 3e-3
    x = np.vstack([xa, xb])
    vptr = np.array([0, len(xa), len(x)])
    for _ in range(20):
        dx = rng.normal(size=x.shape) * 1e-6 + np.repeat(rng.normal(size=(2, 3)) * 1e-4, np.diff(vptr), axis=0)
        for g in range(2):
            sl = slice(vptr[g], vptr[g + 1])
            dx[sl] += np.cross(rng.normal(size=3) * 0.3, x[sl] - x[sl].mean(axis=0))
        move = RigidRetraction(x, dx, rng.uniform(0.5, 2, len(x)), vptr)
        for a in np.linspace(0.05, 1.0, 20):
            disp = np.linalg.norm(move.at(a) - x, axis=1)
            for g in range(2):
                assert disp[vptr[g] : vptr[g + 1]].max() <= a * move.bounds[g] * (1 + 1e-12)


def surface_distance(xa, fa, xb, fb) -> float:
    """Smallest distance between two triangle surfaces: all vertex-triangle and edge-edge
    distances, from ipctk (the independent oracle)."""
    best = np.inf
    for (xp, fp), (xq, fq) in (((xa, fa), (xb, fb)), ((xb, fb), (xa, fa))):
        for p in xp:
            for f in fq:
                best = min(best, ipctk.point_triangle_distance(p, *xq[f]))
    ea = {tuple(sorted(e)) for f in fa for e in ((f[0], f[1]), (f[1], f[2]), (f[2], f[0]))}
    eb = {tuple(sorted(e)) for f in fb for e in ((f[0], f[1]), (f[1], f[2]), (f[2], f[0]))}
    for i, j in ea:
        for k, m in eb:
            best = min(best, ipctk.edge_edge_distance(xa[i], xa[j], xb[k], xb[m]))
    return float(np.sqrt(best))


def test_bounded_update_never_brings_two_grains_into_contact(rng):
    """Two grains a small gap apart, carried by a large common translation plus rotations and
    deformation: the scene-wide bound (one activation gap, no active pair) and the pair bound
    (the pair active at its gap) keep them apart along the whole scaled path."""
    a = ConvexHull(grain_points(rng))
    b = ConvexHull(grain_points(rng))
    xa, xb = a.points.copy(), b.points.copy()
    xb[:, 0] += xa[:, 0].max() - xb[:, 0].min()  # touching along x at most ...
    xb[:, 0] += 1e-5  # ... then 10 um apart at least
    gap = surface_distance(xa, a.simplices, xb, b.simplices)
    x = np.vstack([xa, xb])
    vptr = np.array([0, len(xa), len(x)])
    ints = np.zeros((1, 11), np.int64)
    ints[0, 1:3] = (0, 1)
    floats = np.array([[0.0, 0.0, gap]])
    for trial in range(10):
        common = rng.normal(size=3) * 1e-3  # far larger than the gap
        dx = np.tile(common, (len(x), 1)) + rng.normal(size=x.shape) * 2e-6
        for g in range(2):
            sl = slice(vptr[g], vptr[g + 1])
            dx[sl] += np.cross(rng.normal(size=3) * 5e-3, x[sl] - x[sl].mean(axis=0))
        move = RigidRetraction(x, dx, np.ones(len(x)), vptr)
        spread = move.bounds - np.linalg.norm(move.t, axis=1)
        ratio = free_distance_ratio(move.t, spread, ints, floats, gbar=gap)
        plain = free_distance_ratio(np.zeros((2, 3)), move.bounds, ints, floats, gbar=gap)
        assert ratio > 3 * plain  # the common translation no longer counts
        for alpha in np.linspace(0, min(ratio, 1.0), 12)[1:]:
            y = move.at(alpha)
            d = surface_distance(y[: len(xa)], a.simplices, y[len(xa) :], b.simplices)
            approach = np.linalg.norm(move.t[0] - move.t[1]) + spread.sum()
            assert d >= gap - alpha * approach - 1e-12
            assert d > 0


def spinning_grain(rate):
    grain = sand_grain(1e-3, 16, seed=3)
    material = Material(90e9, 0.16, 2200.0)
    law, friction = default_contact_laws(1e-3, material.E, material.density)
    scene = Scene.build([grain], material, law, friction, planes=[], gravity=(0, 0, -9.81))
    x = scene.bodies.reference
    v = np.cross([0.0, rate, rate], x - x.mean(axis=0))
    return scene, initial_state(scene, x, v)


def test_newton_on_a_spinning_grain_converges_in_few_iterations_with_either_tangent():
    """Each grain's update along its rigid rotation: a grain spinning 0.14 rad per step of 1e-3 s
    converges in at most 10 iterations (the straight update x + alpha dx took 13, design notes),
    with the exact element tangent (quadratically) and with the rotated one (the default, to
    Newton's tolerance), on the same root."""
    scene, state = spinning_grain(100.0)
    exact = NewmarkParameters(0.3025, 0.6, linear=make_linear_solver("direct"), stall_share=1.0, rotated_tangent=0.0)
    x_exact, info = newmark_step(scene, state, 1e-3, exact)
    assert info.iterations <= 10
    rotated = NewmarkParameters(0.3025, 0.6, linear=make_linear_solver("direct"), stall_share=1.0)
    new, info = newmark_step(scene, state, 1e-3, rotated)
    assert info.iterations <= 10
    assert np.abs(new.x - x_exact.x).max() < rotated.xtol * np.abs(x_exact.x - state.x).max()


def ipctk_pair_distance(kind, xs, plane_face=False):
    """The pair's feature distance from ipctk (the oracle of accd_alpha's own distances)."""
    if kind == 0:
        return np.sqrt(ipctk.point_triangle_distance(*xs[:4]))
    if kind == 1:
        return np.sqrt(ipctk.edge_edge_distance(*xs[:4]))
    if kind == 2:
        return np.sqrt(ipctk.point_edge_distance(*xs[:3]))
    return float(np.linalg.norm(xs[0] - xs[1]))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_additive_ccd_keeps_every_active_pair_apart_and_lets_sliding_pass(seed):
    """Two sand grains a third of an activation gap apart; the upper one slides sideways and
    spins (an update far larger than the gap, nearly parallel to the contact): additive CCD lets
    most of it through where the bound from the start alone allowed a sliver, and every active
    pair keeps at least 1 - 0.8 of its distance along the whole path (ipctk distances)."""
    from vemdem.contact.ccd import accd_alpha
    from vemdem.contact.narrow import N_NODES
    from vemdem.contact.pairs import GAP, KIND, NODE0

    rng = np.random.default_rng(seed)
    material = Material(90e9, 0.16, 2200.0)
    law, friction = default_contact_laws(1e-3, material.E, material.density)
    a = sand_grain(1e-3, 18, seed=10 + seed)
    b = sand_grain(1e-3, 18, seed=20 + seed)
    b = b.translated((0.0, 0.0, a.vertices[:, 2].max() - b.vertices[:, 2].min() + 1e-3))
    scene = Scene.build([a, b], material, law, friction, planes=[], gravity=(0, 0, -9.81))
    contact, x = scene.contact, scene.bodies.reference.copy()
    # lower b until its closest pair is a third of the activation gap away
    for _ in range(40):
        _, ints, floats = contact.pairs(x, 0.0, contact.search(x, 0.0, margin=2e-3), reach=2e-3)
        x[scene.bodies.vertex_ptr[1] :, 2] -= floats[:, GAP].min() - law.activation_gap / 3
    _, ints, floats = contact.pairs(x, 0.0, contact.search(x, 0.0))
    assert len(ints) >= 1
    nb = scene.bodies.vertex_ptr[1]
    dx = np.zeros_like(x)
    dx[nb:, :2] = rng.normal(size=2) * 5e-5  # ~15 activation gaps sideways
    dx[nb:] += np.cross(np.array([0.0, 0.0, 0.02]), x[nb:] - x[nb:].mean(axis=0))
    move = RigidRetraction(x, dx, scene.bodies.lumped, scene.bodies.vertex_ptr)
    x_all = contact.all_positions(x, 0.0)
    alpha = accd_alpha(ints, x_all, len(x), contact.plane_node0, dx, contact.topology.vertex_grain,
                       move.c, move.t, move.phi, move.excess(), 0.2, 1.0)  # fmt: skip
    spread = move.bounds - np.linalg.norm(move.t, axis=1)
    start_only = 0.8 * free_distance_ratio(move.t, spread, ints, floats, law.activation_gap)
    assert alpha > 5 * start_only
    d0 = [ipctk_pair_distance(k, x_all[ints[c, NODE0 : NODE0 + N_NODES[k]]]) for c, k in enumerate(ints[:, KIND])]
    for s in np.linspace(0.0, alpha, 25)[1:]:
        y = move.at(s)
        for c, k in enumerate(ints[:, KIND]):
            d = ipctk_pair_distance(k, y[ints[c, NODE0 : NODE0 + N_NODES[k]]])
            assert d >= 0.2 * d0[c] * (1 - 1e-9)


def test_additive_ccd_lets_a_long_slide_at_a_constant_gap_through():
    """A small cube resting flat on a large one, a fifth of an activation gap above it, slides
    0.2 mm sideways (about 100 of its gaps) without coming closer: additive CCD must let the whole
    update through. Its rounds advance by 0.8 d / |dx| each (about 125 here); a cap of 64 rounds
    stopped it at half the update, and Newton then crawled behind such pairs in the 515-grain lid
    jam (docs/dynamics.md)."""
    from vemdem.contact.ccd import accd_alpha
    from vemdem.contact.pairs import GAP
    from vemdem.geometry import cube

    material = Material(90e9, 0.16, 2200.0)
    law, friction = default_contact_laws(1e-3, material.E, material.density)
    gap = law.activation_gap / 5
    big = cube(1e-3)
    small = cube(0.5e-3)
    small = small.translated((0.0, 0.0, big.vertices[:, 2].max() - small.vertices[:, 2].min() + gap))
    scene = Scene.build([big, small], material, law, friction, planes=[], gravity=(0, 0, -9.81))
    contact, x = scene.contact, scene.bodies.reference.copy()
    _, ints, floats = contact.pairs(x, 0.0, contact.search(x, 0.0))
    assert len(ints) >= 4 and np.allclose(floats[:, GAP], gap, rtol=1e-6)
    dx = np.zeros_like(x)
    dx[scene.bodies.vertex_ptr[1] :, 0] = 2e-4
    move = RigidRetraction(x, dx, scene.bodies.lumped, scene.bodies.vertex_ptr)
    x_all = contact.all_positions(x, 0.0)
    args = (ints, x_all, len(x), contact.plane_node0, dx, contact.topology.vertex_grain, move.c, move.t, move.phi,
            move.excess(), 0.2, 1.0)  # fmt: skip
    assert accd_alpha(*args) == 1.0
    assert accd_alpha(*args, max_rounds=64) < 0.7  # the old cap
