"""Coulomb friction with static and dynamic coefficients, damping, walls and history
(issue 3 tests 3 and 6), driven through the scene-level ContactModel."""

import numpy as np
import pytest

from vemdem.contact.friction import FrictionLaw
from vemdem.contact.law import InterfaceLaw, normal_force
from vemdem.contact.model import ContactHistory, ContactModel, PenetrationError
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
