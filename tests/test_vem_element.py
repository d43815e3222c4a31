"""The virtual element of one grain (paper section 2.1, eq. 2-8): no energy in a rigid motion, a
homogeneous deformation reproduced, the force the gradient of the energy and the tangent the
derivative of the force, a tetrahedral grain the linear tetrahedron."""

import numpy as np
import pytest
from reference import neo_hooke_piola, neo_hooke_psi, random_rotation, surface_nodal_forces

from vemdem.geometry import cube, l_prism, sand_grain, tetrahedron, u_prism
from vemdem.vem.element import (
    InvertedElementError,
    VemOptions,
    build_elements,
    evaluate,
    projected_deformation_gradients,
    tangent_matrix,
)
from vemdem.vem.mass import build_mass
from vemdem.vem.material import Material

MAT = Material(E=90e9, nu=0.16, density=2200.0)
BETAS = [0.0, 0.1, 0.25, 0.5, 1.0]


def grains():
    return [
        sand_grain(seed=1, n_vertices=24),
        sand_grain(seed=5, n_vertices=38, elongation=0.6, flatness=0.7),
        cube(1.45e-3),
        l_prism(1e-3, 0.4e-3),  # kernel fan
        u_prism(1e-3, 0.4e-3),  # TetGen constrained, Steiner point slaved to u_Pi
    ]


def elements_for(grain, beta):
    return build_elements([grain], MAT, VemOptions(beta_internal=beta))


@pytest.mark.parametrize("beta", BETAS)
@pytest.mark.parametrize("grain", grains(), ids=lambda g: g.name)
def test_rigid_motion_has_no_energy_and_no_force(grain, beta, rng):
    el = elements_for(grain, beta)
    X = el.reference
    R90 = np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])  # 90 degrees about z
    for R, t in [(np.eye(3), rng.normal(size=3) * 1e-3), (R90, np.zeros(3)), (random_rotation(rng), np.ones(3))]:
        ev = evaluate(el, X @ R.T + t)
        scale = MAT.E * grain.volume ** (2 / 3)
        assert abs(ev.total_energy) <= 1e-12 * MAT.E * grain.volume
        assert np.abs(ev.force).max() <= 1e-10 * scale


@pytest.mark.parametrize("beta", BETAS)
@pytest.mark.parametrize("grain", grains(), ids=lambda g: g.name)
def test_homogeneous_deformation_is_reproduced(grain, beta, rng):
    """Patch test: F_Pi = F_t = F0, W = V psi(F0), force = surface traction P(F0) N."""
    el = elements_for(grain, beta)
    F0 = np.eye(3) + 0.25 * rng.normal(size=(3, 3))
    assert np.linalg.det(F0) > 0.2
    x = el.reference @ F0.T + rng.normal(size=3) * 1e-4
    ev = evaluate(el, x)
    np.testing.assert_allclose(projected_deformation_gradients(el, x)[0], F0, rtol=0, atol=1e-12)
    expected_W = grain.volume * neo_hooke_psi(F0, MAT.mu, MAT.kappa)
    assert ev.total_energy == pytest.approx(expected_W, rel=1e-10)
    f_ref = surface_nodal_forces(grain.vertices, grain.faces, neo_hooke_piola(F0, MAT.mu, MAT.kappa))
    np.testing.assert_allclose(ev.force, f_ref, rtol=0, atol=1e-9 * np.abs(f_ref).max())


def test_sub_tetrahedra_see_the_homogeneous_field(rng):
    """Every sub-tetrahedron, virtual apex included, has F_t = F0 under a linear field."""
    from vemdem.vem.element import tet_gradients
    from vemdem.geometry.submesh import augmented_points

    for grain in grains():
        el = elements_for(grain, 1.0)
        mesh = el.submeshes[0]
        F0 = np.eye(3) + 0.2 * rng.normal(size=(3, 3))
        n = grain.n_vertices
        T = el.virtual_weights.reshape(-1, n)
        x = grain.vertices @ F0.T
        xa = np.vstack([x, T @ x])
        _, dN = tet_gradients(augmented_points(grain, mesh), mesh.tets)
        Ft = np.einsum("tai,taj->tij", xa[mesh.tets], dN)
        np.testing.assert_allclose(Ft, np.broadcast_to(F0, Ft.shape), atol=1e-10)


def _large_random_state(el, rng, amplitude=0.25, noise=0.03):
    X = el.reference
    size = np.ptp(X, axis=0).max()
    for _ in range(100):
        F0 = random_rotation(rng) @ (np.eye(3) + amplitude * rng.normal(size=(3, 3)))
        x = X @ F0.T + noise * size * rng.normal(size=X.shape)
        try:
            evaluate(el, x)
            return x
        except InvertedElementError:
            continue
    raise AssertionError("no admissible random state found")


@pytest.mark.parametrize("beta", [0.0, 0.3, 1.0])
@pytest.mark.parametrize("grain", grains(), ids=lambda g: g.name)
def test_force_is_the_gradient_of_the_energy(grain, beta, rng):
    el = elements_for(grain, beta)
    x = _large_random_state(el, rng)
    ev = evaluate(el, x)
    h = 1e-7 * np.ptp(x)
    fd = np.zeros(x.size)
    for k in range(x.size):
        xp, xm = x.ravel().copy(), x.ravel().copy()
        xp[k] += h
        xm[k] -= h
        fd[k] = (evaluate(el, xp.reshape(-1, 3), force=False).total_energy
                 - evaluate(el, xm.reshape(-1, 3), force=False).total_energy) / (2 * h)  # fmt: skip
    np.testing.assert_allclose(ev.force.ravel(), fd, rtol=0, atol=1e-6 * np.abs(fd).max())


@pytest.mark.parametrize("beta", [0.0, 0.3, 1.0])
@pytest.mark.parametrize("grain", grains(), ids=lambda g: g.name)
def test_tangent_is_the_derivative_of_the_force(grain, beta, rng):
    el = elements_for(grain, beta)
    x = _large_random_state(el, rng)
    K = tangent_matrix(el, evaluate(el, x, tangent=True).blocks).toarray()
    h = 1e-7 * np.ptp(x)
    fd = np.zeros_like(K)
    for k in range(x.size):
        xp, xm = x.ravel().copy(), x.ravel().copy()
        xp[k] += h
        xm[k] -= h
        fd[:, k] = (evaluate(el, xp.reshape(-1, 3)).force.ravel() - evaluate(el, xm.reshape(-1, 3)).force.ravel()) / (2 * h)
    np.testing.assert_allclose(K, fd, rtol=0, atol=1e-6 * np.abs(K).max())
    np.testing.assert_allclose(K, K.T, rtol=0, atol=1e-12 * np.abs(K).max())


@pytest.mark.parametrize("beta", BETAS)
def test_tetrahedral_grain_is_the_linear_tetrahedron(beta, rng):
    X = np.array([[0.0, 0, 0], [1.2, 0.1, 0], [0.2, 0.9, 0.1], [0.3, 0.2, 1.1]]) * 1e-3
    grain = tetrahedron(X)
    el = elements_for(grain, beta)
    Dinv = np.linalg.inv(np.column_stack([X[1] - X[0], X[2] - X[0], X[3] - X[0]]))
    dN = np.vstack([-Dinv.sum(axis=0), Dinv])  # rows: grad N_a
    V = abs(np.linalg.det(np.column_stack([X[1] - X[0], X[2] - X[0], X[3] - X[0]]))) / 6
    for _ in range(3):
        x = X @ (np.eye(3) + 0.3 * rng.normal(size=(3, 3))).T
        F = x.T @ dN
        if np.linalg.det(F) <= 0.1:
            continue
        ev = evaluate(el, x, tangent=True)
        assert ev.total_energy == pytest.approx(V * neo_hooke_psi(F, MAT.mu, MAT.kappa), rel=1e-11)
        f_fe = V * dN @ neo_hooke_piola(F, MAT.mu, MAT.kappa).T  # f_a = V P grad N_a
        np.testing.assert_allclose(ev.force, f_fe, atol=1e-10 * np.abs(f_fe).max())
        # FE tangent by finite differences of the independent FE force
        K = tangent_matrix(el, ev.blocks).toarray()
        h = 1e-9
        for k in range(12):
            xp, xm = x.ravel().copy(), x.ravel().copy()
            xp[k] += h
            xm[k] -= h
            fp = V * dN @ neo_hooke_piola(xp.reshape(4, 3).T @ dN, MAT.mu, MAT.kappa).T
            fm = V * dN @ neo_hooke_piola(xm.reshape(4, 3).T @ dN, MAT.mu, MAT.kappa).T
            np.testing.assert_allclose(K[:, k], (fp - fm).ravel() / (2 * h), atol=1e-6 * np.abs(K).max())


def test_batched_grains_equal_single_grains(rng):
    gs = grains()
    el = build_elements(gs, MAT, VemOptions(beta_internal=0.3))
    x = np.vstack([_large_random_state(elements_for(g, 0.3), rng, 0.1, 0.01) for g in gs])
    ev = evaluate(el, x, tangent=True)
    K = tangent_matrix(el, ev.blocks)
    for k, g in enumerate(gs):
        sl = slice(el.vertex_ptr[k], el.vertex_ptr[k + 1])
        single = evaluate(elements_for(g, 0.3), x[sl], tangent=True)
        assert ev.energy[k] == single.energy[0]
        np.testing.assert_array_equal(ev.force[sl], single.force)
        d = slice(3 * el.vertex_ptr[k], 3 * el.vertex_ptr[k + 1])
        np.testing.assert_array_equal(K[d, d].toarray(), tangent_matrix(elements_for(g, 0.3), single.blocks).toarray())


def test_inverted_grain_is_reported_not_nan():
    grain = cube(1.0)
    el = elements_for(grain, 0.5)
    x = el.reference.copy()
    x[:, 2] *= -1  # mirror: J < 0
    with pytest.raises(InvertedElementError, match="grain \\[0\\]"):
        evaluate(el, x)
    ev = evaluate(el, x, raise_on_inversion=False)
    assert ev.energy[0] == np.inf
    # its tangent block is zeros, not the uninitialised memory the blocks are allocated with (here
    # most likely the freed blocks of the evaluation before, which hold a tangent)
    for _ in range(3):
        assert np.abs(evaluate(el, el.reference, tangent=True).blocks).max() > 0.0
        assert np.all(evaluate(el, x, tangent=True, raise_on_inversion=False).blocks == 0.0)


def test_material_constants():
    m = Material(90e9, 0.16, 2200)
    assert m.mu == pytest.approx(90e9 / 2.32)
    assert m.kappa == pytest.approx(90e9 / (3 * 0.68))
    with pytest.raises(ValueError, match="nu"):
        Material(1.0, 0.5, 1.0)
    with pytest.raises(ValueError, match="E"):
        Material(-1.0, 0.3, 1.0)


def _rigidly_moved(el, rng, strain=0.0):
    """Every grain rotated at random and shifted, after an affine strain of this size about its centroid."""
    x = np.empty_like(el.reference)
    for g in range(el.n_grains):
        sl = slice(el.vertex_ptr[g], el.vertex_ptr[g + 1])
        c = el.reference[sl].mean(axis=0)
        stretch = np.eye(3) + strain * rng.uniform(-1.0, 1.0, size=(3, 3))
        x[sl] = c + (el.reference[sl] - c) @ stretch.T @ random_rotation(rng).T + rng.normal(size=3) * 1e-3
    return x


@pytest.mark.parametrize("beta", [0.0, 0.5, 1.0])
def test_rotated_tangent_is_exact_for_rigid_motions(beta, rng):
    """`rotated_strain`: K(R X + t) = (I (x) R) K(X) (I (x) R)^T, since P(R U) = R P(U) and P(I) = 0."""
    el = build_elements(grains(), MAT, VemOptions(beta_internal=beta))
    x = _rigidly_moved(el, rng)
    exact = evaluate(el, x, tangent=True)
    rotated = evaluate(el, x, tangent=True, rotated_strain=1e-4)
    assert rotated.rotated.all() and not exact.rotated.any()
    np.testing.assert_allclose(rotated.blocks, exact.blocks, rtol=0, atol=1e-9 * np.abs(exact.blocks).max())
    np.testing.assert_array_equal(rotated.force, exact.force)  # the residual is never approximated
    np.testing.assert_array_equal(rotated.energy, exact.energy)


@pytest.mark.parametrize("strain", [1e-7, 1e-6, 1e-5])
def test_rotated_tangent_is_off_by_the_order_of_the_strain(strain, rng):
    """Below the bound the block is the rotated reference one, its error O(strain) against the exact
    tangent (itself checked against finite differences above); above it the exact block, bit for bit."""
    el = build_elements(grains(), MAT, VemOptions(beta_internal=0.5))
    x = _rigidly_moved(el, rng, strain)
    exact = evaluate(el, x, tangent=True)
    rotated = evaluate(el, x, tangent=True, rotated_strain=100 * strain)
    assert rotated.rotated.all()
    error = np.abs(rotated.blocks - exact.blocks).max() / np.abs(exact.blocks).max()
    assert 1e-3 * strain < error < 10 * strain
    strict = evaluate(el, x, tangent=True, rotated_strain=0.01 * strain)
    assert not strict.rotated.any()
    np.testing.assert_array_equal(strict.blocks, exact.blocks)
    np.testing.assert_array_equal(strict.force, exact.force)  # from the deviation check's pass
    np.testing.assert_array_equal(strict.energy, exact.energy)


def test_rotated_tangent_keeps_the_mass_shift_and_inversion(rng):
    el = build_elements(grains(), MAT, VemOptions(beta_internal=0.5))
    mass = build_mass(grains(), el, MAT.density)
    x = _rigidly_moved(el, rng)
    shifted = evaluate(el, x, tangent=True, mass=mass, mass_shift=3e8, rotated_strain=1e-4)
    plain = evaluate(el, x, tangent=True, mass=mass, mass_shift=3e8)
    np.testing.assert_allclose(shifted.blocks, plain.blocks, rtol=0, atol=1e-9 * np.abs(plain.blocks).max())
    x[el.vertex_ptr[2] : el.vertex_ptr[3], 2] *= -1  # the cube mirrored: J < 0
    ev = evaluate(el, x, tangent=True, rotated_strain=1e-4, raise_on_inversion=False)
    assert ev.energy[2] == np.inf and not ev.rotated[2]
    assert np.all(ev.blocks[el.block_ptr[2] : el.block_ptr[3]] == 0.0)
