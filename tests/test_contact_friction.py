"""Coulomb friction with static and dynamic coefficients, damping, walls and history,
driven through the scene-level ContactModel."""

import numpy as np
import pytest

from vemdem.contact.friction import FrictionLaw
from vemdem.contact.law import InterfaceLaw, normal_force
from vemdem.contact.model import ContactHistory, ContactModel, PenetrationError, pair_keys
from vemdem.contact.walls import MeshWall, Motion, PlaneWall
from vemdem.io.surfaces import load_mesh_wall
from vemdem.geometry import cube, rotation_matrix

LAW = InterfaceLaw(activation_gap=2e-5, penalty=1e9)
GAP = 1.2e-5  # working gap: in the penalty band
EPS_T = 1e6
FRICTION = FrictionLaw(mu_s=0.5, mu_d=0.4, tangential_penalty=EPS_T)


def cube_on_floor(friction=FRICTION, **kw):
    c = cube(1e-3).translated((0, 0, 0.5e-3 + GAP))
    floor = PlaneWall(np.zeros(3), np.array([0.0, 0, 1]), name="floor", **kw)
    model = ContactModel(c.vertices, [c.faces], np.array([0, 8]), np.array([1.0]), LAW, friction, planes=[floor])
    return c, model


def tangential_force(model, x, history):
    res = model.evaluate(x, 0.0, model.search(x, 0.0), history)
    return -res.force.sum(axis=0), res  # physical force on the cube


def test_stick_below_mu_s_then_slip_at_mu_d_and_back():
    c, model = cube_on_floor()
    fn_pair = normal_force(GAP, LAW.packed())[0]
    FN = 4 * fn_pair  # four bottom vertices on the floor
    history = ContactHistory.empty()
    step = 0.5 * fn_pair / EPS_T / 10.5  # the static limit lies between steps 10 and 11
    x0 = c.vertices.copy()
    forces, states = [], []
    for k in range(0, 16):  # k = 0 starts the pairs: a new pair has no friction yet
        x = x0 + [k * step, 0, 0]
        F, res = tangential_force(model, x, history)
        history = res.trial_history  # commit: quasi-static, every state converged
        forces.append(F[0])
        states.append(bool(res.trial_history.stick.all()))
        assert F[2] == pytest.approx(FN, rel=1e-9)
    assert forces.pop(0) == 0.0 and states.pop(0)
    forces = np.array(forces)
    # stick: elastic tangential spring, f_t = eps_t * displacement per pair (opposing the motion)
    stick_steps = np.arange(1, 11)
    np.testing.assert_allclose(forces[:10], -4 * EPS_T * stick_steps * step, rtol=1e-9)
    assert all(states[:10])
    # beyond mu_s: slip, at mu_d (sliding force always uses mu_d)
    np.testing.assert_allclose(forces[10:], -0.4 * FN, rtol=1e-9)
    assert not any(states[10:])
    # reverse: slip-to-stick, the tangential spring unloads from the slip value
    x_back = x0 + [14 * step, 0, 0]
    F, res = tangential_force(model, x_back, history)
    assert res.trial_history.stick.all()
    assert F[0] == pytest.approx(-0.4 * FN + 4 * EPS_T * step, rel=1e-9)
    # after slip, the stick test uses mu_d: pushing on past 0.4 FN slips again at once
    F, res = tangential_force(model, x0 + [15 * step + 0.2 * step, 0, 0], history)
    assert not res.trial_history.stick.any() and F[0] == pytest.approx(-0.4 * FN, rel=1e-9)


def test_slipping_pairs_are_judged_by_mu_d():
    """`slipping` (Newton's broken stick-slip cycles, solver.newmark.NewmarkParameters.break_stick_cycles):
    a sticking pair whose trial force lies between mu_d and mu_s F_N sticks when judged by mu_s and
    slides at mu_d F_N when listed; pairs not listed are judged as before."""
    c, model = cube_on_floor()
    fn_pair = normal_force(GAP, LAW.packed())[0]
    FN = 4 * fn_pair
    step = 0.45 * fn_pair / EPS_T  # each pair's trial force 0.45 F_N: between mu_d (0.4) and mu_s (0.5)
    x0 = c.vertices.copy()
    _, res = tangential_force(model, x0, ContactHistory.empty())  # the pairs start, sticking
    history = res.trial_history
    x = x0 + [step, 0, 0]
    F, res = tangential_force(model, x, history)
    assert res.trial_history.stick.all() and F[0] == pytest.approx(-0.45 * FN, rel=1e-9)
    listed = history.keys[:2]  # two of the four pairs
    res = model.evaluate(x, 0.0, model.search(x, 0.0), history, slipping=listed)
    stick = dict(zip(res.trial_history.keys.tolist(), res.trial_history.stick.tolist()))
    assert [stick[k] for k in history.keys.tolist()] == [False, False, True, True]
    F = -res.force.sum(axis=0)
    assert F[0] == pytest.approx(-(2 * 0.4 + 2 * 0.45) * fn_pair, rel=1e-9)


@pytest.mark.parametrize("tangent", [False, True])
def test_undamped_pairs_carry_the_forces_of_a_law_without_damping(tangent):
    """`undamped` (Newton's cycles on the damping's no-adhesion clamp, NewmarkParameters.hold_damping_cycles):
    the listed pairs of a cube pressed onto the floor while approaching it carry the force and tangent of
    the same law with damping_ratio 0, the others those of the damped law."""
    damped = FrictionLaw(mu_s=0.5, mu_d=0.4, tangential_penalty=EPS_T, damping_ratio=0.5)
    c, model = cube_on_floor(damped)
    _, plain = cube_on_floor(FrictionLaw(mu_s=0.5, mu_d=0.4, tangential_penalty=EPS_T, damping_ratio=0.0))
    x = c.vertices.copy()
    v = np.tile([2e-4, 0.0, -1e-3], (len(x), 1))  # approaching and sliding
    history = model.evaluate(x, 0.0, model.search(x, 0.0)).trial_history  # the pairs start, sticking
    x1 = x + 1e-9 * np.array([1.0, 0.0, -1.0])
    args = (x1, 0.0, model.search(x1, 0.0), history)
    listed = history.keys[:2]
    res = model.evaluate(*args, v=v, a4=1e4, tangent=tangent, undamped=listed)
    with_damping = model.evaluate(*args, v=v, a4=1e4, tangent=tangent)
    without = plain.evaluate(*args, v=v, a4=1e4, tangent=tangent)
    rows = pair_keys(res.ints)
    is_listed = np.isin(rows, listed)
    assert is_listed.sum() == 2 and len(rows) == 4
    for reference, chosen in ((without, is_listed), (with_damping, ~is_listed)):
        np.testing.assert_array_equal(pair_keys(reference.ints), rows)  # same state, same search: same order
        np.testing.assert_allclose(res.local_forces[1][chosen], reference.local_forces[1][chosen], rtol=1e-12, atol=0)
        if tangent:
            np.testing.assert_allclose(res.pair_tangent[chosen], reference.pair_tangent[chosen], rtol=1e-12, atol=0)
    # the damping is there to take away: the damped law pushes harder on the approaching cube
    assert -with_damping.force.sum(axis=0)[2] > -res.force.sum(axis=0)[2] > -without.force.sum(axis=0)[2]


def test_history_is_reset_when_the_pair_ends():
    c, model = cube_on_floor()
    x0 = c.vertices.copy()
    step = 1e-8
    _, res = tangential_force(model, x0 + [step, 0, 0], ContactHistory.empty())
    _, res = tangential_force(model, x0 + [2 * step, 0, 0], res.trial_history)
    assert np.abs(res.trial_history.gt).max() > 0
    lifted = x0 + [2 * step, 0, 3 * LAW.activation_gap]
    F, res = tangential_force(model, lifted, res.trial_history)
    assert res.n_contacts == 0 and np.all(F == 0)
    # back in contact: a new pair starts with no stored slip, so no friction in its first state
    F, res = tangential_force(model, x0 + [5 * step, 0, 0], res.trial_history)
    assert res.n_contacts == 4 and F[0] == pytest.approx(0.0, abs=1e-12)


def test_wall_reaction_balances_the_contact_forces():
    c, model = cube_on_floor()
    x = c.vertices + [3e-9, -2e-9, 0]
    _, res = tangential_force(model, x, ContactHistory.empty())
    _, res = tangential_force(model, x + [1e-8, 0, 0], res.trial_history)
    np.testing.assert_allclose(res.wall_reactions[0], res.force.sum(axis=0), rtol=1e-12)
    assert res.wall_reactions[0][2] < 0  # the cube pushes the floor down


def test_penetrating_a_wall_is_an_error():
    c, model = cube_on_floor()
    with pytest.raises(PenetrationError, match="behind wall 'floor'"):
        model.evaluate(c.vertices - [0, 0, 2 * GAP], 0.0, np.zeros((0, 2), np.int64))


def test_a_gap_within_round_off_is_a_penetration_not_a_division_by_zero():
    """A lid closed on a vertex to 1e-18 m in the 515-grain jam, and the friction kernel divided by
    the exact 0 its closest points' difference rounded to (ZeroDivisionError inside numba, a crash
    instead of a rejected step). Gaps at or below TOUCHING_GAP switch gaps are a penetration."""
    from vemdem.contact.model import TOUCHING_GAP

    c, model = cube_on_floor()
    x = c.vertices - [0, 0, GAP - 1e-19]  # bottom face 1e-19 m above the floor
    history = model.evaluate(c.vertices, 0.0, model.search(c.vertices, 0.0)).trial_history
    with pytest.raises(PenetrationError, match="within round-off"):
        model.evaluate(x, 0.0, model.search(x, 0.0), history, v=np.zeros_like(x), a4=1e6, tangent=True)
    # just above the floor the law still answers: a finite force
    x = c.vertices - [0, 0, GAP - 10 * TOUCHING_GAP * LAW.switch_gap]
    res = model.evaluate(x, 0.0, model.search(x, 0.0), history, v=np.zeros_like(x), a4=1e6, tangent=True)
    assert np.all(np.isfinite(res.force)) and np.all(np.isfinite(res.pair_tangent))
    # two grains face to face: the same rule
    a = cube(1e-3)
    b = cube(1e-3).translated((1e-3 + 1e-19, 0, 0))
    pair = ContactModel(np.vstack([a.vertices, b.vertices]), [a.faces, b.faces], np.array([0, 8, 16]),
                        np.array([1.0, 1.0]), LAW, FRICTION)  # fmt: skip
    x = np.vstack([a.vertices, b.vertices])
    with pytest.raises(PenetrationError, match="grains 0 and 1 touch"):
        pair.evaluate(x, 0.0, pair.search(x, 0.0))


def test_removed_and_moving_walls():
    c, model = cube_on_floor(motion=Motion(times=(0.0, 1.0), displacements=((0, 0, 0), (0, 0, -1e-3)), removed_at=2.0))
    x = c.vertices
    assert model.evaluate(x, 0.0, model.search(x, 0.0)).n_contacts == 4
    assert model.evaluate(x, 1.0, model.search(x, 1.0)).n_contacts == 0  # the floor moved away
    assert model.evaluate(x - [0, 0, 1e-3], 1.0, model.search(x, 1.0)).n_contacts == 4
    assert model.evaluate(x - [0, 0, 1e-3], 2.5, model.search(x, 2.5)).n_contacts == 0  # removed


def test_triangulated_lid_touches_like_a_grain():
    c = cube(1e-3)
    lid_v = np.array([[-2, -2, 0], [2, -2, 0], [2, 2, 0], [-2, 2, 0]]) * 1e-3 + [0, 0, 0.5e-3 + GAP]
    lid = MeshWall(lid_v, np.array([[0, 2, 1], [0, 3, 2]]), name="lid")  # normals point down
    model = ContactModel(c.vertices, [c.faces], np.array([0, 8]), np.array([1.0]), LAW, FRICTION, meshes=[lid])
    res = model.evaluate(c.vertices, 0.0, model.search(c.vertices, 0.0))
    assert res.n_contacts == 4
    fn = normal_force(GAP, LAW.packed())[0]
    np.testing.assert_allclose(res.wall_reactions[0], [0, 0, 4 * fn], rtol=1e-9, atol=1e-12 * fn)


@pytest.mark.parametrize("stuck", [True, False])
def test_tangent_with_friction_and_damping_matches_differences(stuck, rng):
    """For a fixed history, the residual's derivative (velocities follow x with a4) is the tangent."""
    friction = FrictionLaw(mu_s=0.5 if stuck else 0.05, mu_d=0.4 if stuck else 0.04, tangential_penalty=EPS_T,
                           tangential_viscosity=3.0, damping_ratio=0.4)  # fmt: skip
    R = rotation_matrix([2e-3, -1e-3, 0.3])
    c = cube(1e-3).rotated(R)
    c = c.translated((0, 0, GAP - c.vertices[:, 2].min() + 3e-6 * 0))
    other = cube(1e-3).rotated(rotation_matrix([1e-3, 3e-3, -0.2]))
    other = other.translated((0.2e-3, 0.1e-3, c.vertices[:, 2].max() + 0.7 * GAP - other.vertices[:, 2].min()))
    X = np.vstack([c.vertices, other.vertices])
    floor = PlaneWall(np.zeros(3), np.array([0.0, 0, 1]))
    model = ContactModel(X, [c.faces, other.faces], np.array([0, 8, 16]), np.array([2e-6, 2e-6]), LAW, friction,
                         planes=[floor])  # fmt: skip
    cand = model.search(X, 0.0)
    first = model.evaluate(X, 0.0, cand)
    moved = X + (2e-9 if stuck else 2e-7) * rng.normal(size=X.shape)
    history = first.trial_history
    v0 = 1e-3 * rng.normal(size=X.shape)
    a4 = 2e4
    res = model.evaluate(moved, 0.0, cand, history, v=v0, a4=a4, tangent=True)
    assert res.n_contacts >= 5
    stick = res.trial_history.stick
    assert stick.all() if stuck else not stick.all()
    K = res.tangent.toarray()
    h = 1e-12
    fd = np.zeros_like(K)
    for k in range(X.size):
        dx = np.zeros(X.size)
        dx[k] = h
        dx = dx.reshape(-1, 3)
        rp = model.evaluate(moved + dx, 0.0, cand, history, v=v0 + a4 * dx, a4=a4).force.ravel()
        rm = model.evaluate(moved - dx, 0.0, cand, history, v=v0 - a4 * dx, a4=a4).force.ravel()
        fd[:, k] = (rp - rm) / (2 * h)
    np.testing.assert_allclose(K, fd, atol=2e-5 * np.abs(K).max())


def test_damping_never_pulls():
    friction = FrictionLaw(damping_ratio=5.0)
    c, model = cube_on_floor(friction=friction)
    x = c.vertices
    separating = np.tile([0.0, 0, 10.0], (8, 1))  # fast separation: damping would pull
    res = model.evaluate(x, 0.0, model.search(x, 0.0), v=separating)
    assert res.wall_reactions[0][2] == pytest.approx(0.0, abs=1e-12)
    approaching = -separating
    res = model.evaluate(x, 0.0, model.search(x, 0.0), v=approaching)
    assert res.wall_reactions[0][2] < -4 * normal_force(GAP, LAW.packed())[0]
    assert res.dissipation_power > 0


def test_wall_from_an_stl_file(tmp_path):
    import meshio

    c = cube(1e-3)
    lid_v = np.array([[-2, -2, 0], [2, -2, 0], [2, 2, 0], [-2, 2, 0]]) * 1e-3 + [0, 0, 0.5e-3 + GAP]
    soup = lid_v[np.array([[0, 1, 2], [0, 2, 3]])].reshape(-1, 3)  # normals up: flip them
    meshio.write(tmp_path / "lid.stl", meshio.Mesh(soup, [("triangle", np.arange(6).reshape(2, 3))]))
    lid = load_mesh_wall(tmp_path / "lid.stl", flip=True)
    assert len(lid.vertices) == 4
    model = ContactModel(c.vertices, [c.faces], np.array([0, 8]), np.array([1.0]), LAW, FRICTION, meshes=[lid])
    res = model.evaluate(c.vertices, 0.0, model.search(c.vertices, 0.0))
    assert res.n_contacts == 4 and res.wall_reactions[0][2] > 0


def _pair_nodes(kind, d, rng):
    """Node positions of one pair of the given kind at gap d, the closest points inside the
    features, turned and moved at random (kinds and node order as in contact.narrow)."""
    from vemdem.contact.narrow import EDGE_EDGE, VERTEX_EDGE, VERTEX_FACE

    L = 1e-4
    j = rng.uniform(-0.2, 0.2, size=3) * L
    if kind == VERTEX_FACE:
        xs = [[0.1 * L, 0.05 * L, d], [-L, -L, 0], [L, -0.8 * L, 0], [0.1 * L, L, 0]]
    elif kind == EDGE_EDGE:
        xs = [[-L, j[0], d], [L, j[1], d], [j[2], -L, 0], [0.3 * j[0], L, 0]]
    elif kind == VERTEX_EDGE:
        xs = [[j[0], 0, d], [-L, 0, 0], [L, 0, 0]]
    else:
        xs = [[0, 0, d], [0, 0, 0]]
    xs = np.array(xs) @ rotation_matrix(rng.normal(size=3)).T + rng.normal(size=3) * 1e-3
    out = np.zeros((6, 3))
    out[: len(xs)] = xs
    return out


def test_analytic_friction_tangent_is_the_complex_step_derivative(rng):
    """The analytic tangent (forward mode, dc/dx by implicit differentiation of the LCP) against
    the complex-step derivative of the same residual, exact to round-off: every pair kind, the
    penalty and the barrier band, stick and slip, with and without the damping clamp, new and
    continuing pairs."""
    from vemdem.contact.friction import _lcp_coords, complex_step_tangent, dissipative_terms
    from vemdem.contact.pairs import INT_COLS, KIND, NODE0

    friction = FrictionLaw(mu_s=0.5, mu_d=0.4, tangential_penalty=EPS_T, tangential_viscosity=3.0,
                           damping_ratio=0.4)  # fmt: skip
    n_pairs = 400
    law, fr = LAW.packed(), np.tile(friction.packed(), (n_pairs, 1))
    x = np.zeros((6 * n_pairs, 3))
    ints = np.full((n_pairs, INT_COLS), -1, dtype=np.int64)
    for c in range(n_pairs):
        kind = c % 4
        d = rng.uniform(0.1, 0.95) * LAW.activation_gap  # both bands (switch at 0.3)
        x[6 * c : 6 * c + 6] = _pair_nodes(kind, d, rng)
        ints[c, KIND] = kind
        ints[c, NODE0 : NODE0 + 6] = np.arange(6 * c, 6 * c + 6)
    # a third of the pairs slowly moving and hardly shifted since the last step (they stick), the
    # rest fast (the damping clamp) or far from their previous contact point (slip)
    slow = rng.random(n_pairs) < 0.35
    v = rng.normal(size=(n_pairs, 6, 3)) * np.where(slow, 1e-5, rng.choice([1e-3, 1e-1], size=n_pairs))[:, None, None]
    v = v.reshape(-1, 3)
    c_now = np.array([_lcp_coords(ints[c, KIND], x[6 * c : 6 * c + 6]) for c in range(n_pairs)], dtype=float)
    c_prev = np.where(slow[:, None], c_now + 1e-6 * rng.normal(size=(n_pairs, 2)), rng.uniform(0.1, 0.4, (n_pairs, 2)))
    gt_prev = rng.normal(size=(n_pairs, 3)) * np.where(slow, 1e-10, 1e-5)[:, None]
    was_active = rng.random(n_pairs) < 0.8
    was_stick = rng.random(n_pairs) < 0.5
    m_eq = rng.uniform(1e-6, 3e-6, size=n_pairs)
    a4 = 2e4
    local_force = np.zeros((n_pairs, 6, 3))
    analytic = np.zeros((n_pairs, 18, 18))
    stick, gt = np.zeros(n_pairs, dtype=np.bool_), np.zeros((n_pairs, 3))
    dissipative_terms(x, v, a4, ints, c_prev, gt_prev, was_active, was_stick, law, fr, m_eq, local_force, analytic,
                      stick, gt)  # fmt: skip
    reference = np.zeros((n_pairs, 18, 18))
    complex_step_tangent(x, v, a4, ints, c_prev, gt_prev, was_active, was_stick, law, fr, m_eq, reference)
    assert 0.2 < stick.mean() < 0.8  # both branches
    assert (np.abs(local_force).max(axis=(1, 2)) > 0).all()  # every pair has a force to differentiate
    for c in range(n_pairs):
        scale = np.abs(reference[c]).max()
        assert scale > 0
        np.testing.assert_allclose(analytic[c], reference[c], rtol=0, atol=1e-9 * scale, err_msg=f"pair {c}")


def test_plane_pairs_match_ipctk_and_the_general_face_lcp():
    """Vertex-plane records (contact/model._plane_records, compiled): every vertex within the
    activation gap of each plane, no other, with the gap of ipctk's signed point-plane distance
    and the barycentric coordinates the general vertex-face LCP gives on the plane's triangle."""
    import ipctk

    from vemdem.contact.narrow import vertex_face_coords
    from vemdem.contact.pairs import FEATURE_A, GAP, GRAIN_B, NODE0

    R = rotation_matrix([0.3, -0.5, 0.8])
    c = cube(1e-3)
    x = c.vertices @ R.T
    gbar = 0.6e-3  # wide: several vertices per plane, at several gaps
    law = InterfaceLaw(activation_gap=gbar, penalty=1e3)
    normals = [np.array([0.2, 0.1, 1.0]), np.array([-1.0, 0.3, 0.2])]
    planes = [PlaneWall(-0.95e-3 * n / np.linalg.norm(n), n / np.linalg.norm(n), name=f"w{k}") for k, n in enumerate(normals)]
    model = ContactModel(c.vertices, [c.faces], np.array([0, 8]), np.array([1.0]), law, FRICTION, planes=planes)
    x_all, ints, floats = model.pairs(x, 0.0, model.search(x, 0.0))
    found = 0
    for w, plane in enumerate(planes):
        tri = x_all[model.plane_node0 + 3 * w : model.plane_node0 + 3 * w + 3]
        gaps = np.array([ipctk.point_plane_signed_distance(p, *tri) for p in x])
        rows = ints[:, GRAIN_B] == 1 + w
        np.testing.assert_array_equal(ints[rows, FEATURE_A], np.flatnonzero(gaps <= gbar))
        assert 0 < rows.sum() < 8  # the test sees both sides of the gap
        for r, f in zip(ints[rows], floats[rows]):
            u, v, _ = vertex_face_coords(x[r[FEATURE_A]], *tri)
            np.testing.assert_allclose(f[:2], [u, v], rtol=1e-12, atol=1e-12)
            np.testing.assert_allclose(f[GAP], gaps[r[FEATURE_A]], rtol=1e-12, atol=1e-18)
            np.testing.assert_array_equal(r[NODE0 + 1 : NODE0 + 4], model.plane_node0 + 3 * w + np.arange(3))
        found += rows.sum()
    assert found == len(ints)
    deeper = x - 0.3e-3 * planes[1].normal  # past the second wall only
    with pytest.raises(PenetrationError, match="behind wall 'w1'"):
        model.pairs(deeper, 0.0, model.search(deeper, 0.0))


def test_a_frictionless_wall_carries_no_tangential_force_and_the_same_normal_one():
    """A frictionless wall (a mirror plane): on the same sliding path as the stick/slip test its
    pairs carry the normal force of the frictional floor and no tangential force; a second cube
    resting on the first still feels the grains' friction."""
    from vemdem.contact.pairs import GRAIN_B

    c = cube(1e-3).translated((0, 0, 0.5e-3 + GAP))
    top = cube(1e-3).translated((0, 0, 1.5e-3 + 2 * GAP))
    vertices = np.vstack([c.vertices, top.vertices])

    def model_with(frictionless):
        floor = PlaneWall(np.zeros(3), np.array([0.0, 0, 1]), name="floor", frictionless=frictionless)
        return ContactModel(vertices, [c.faces, top.faces], np.array([0, 8, 16]), np.array([1.0, 1.0]), LAW, FRICTION,
                            planes=[floor])  # fmt: skip

    step = 1e-7  # far beyond the static limit on the floor: sliding
    results = {}
    for frictionless in (False, True):
        model = model_with(frictionless)
        history = ContactHistory.empty()
        for k in range(3):  # the bottom cube slides on the floor under the top one
            x = vertices + np.r_[np.full(8, k * step), np.zeros(8)][:, None] * [1, 0, 0]
            res = model.evaluate(x, 0.0, model.search(x, 0.0), history)
            history = res.trial_history
        results[frictionless] = res
    frictional, mirror = results[False], results[True]
    on_floor = frictional.ints[:, GRAIN_B] == 2
    assert on_floor.sum() == 4 and (mirror.ints[:, GRAIN_B] == 2).sum() == 4
    np.testing.assert_allclose(mirror.wall_reactions[0][2], frictional.wall_reactions[0][2], rtol=1e-12)
    assert abs(frictional.wall_reactions[0][0]) > 0.1 * abs(frictional.wall_reactions[0][2])  # mu_d 0.4 there
    assert mirror.wall_reactions[0][0] == 0.0 and mirror.wall_reactions[0][1] == 0.0
    # the grain-grain pairs keep their friction
    np.testing.assert_allclose(mirror.pair_force[~on_floor], frictional.pair_force[~on_floor], rtol=1e-12)
    assert np.abs(mirror.pair_force[~on_floor][:, 0]).max() > 0
