"""Mass matrix and gravity load of the blended element: rigid-body inertia, symmetry and rank,
the weight at the centroid, the lumped mass."""

import numpy as np
import pytest

from vemdem.geometry import cube, l_prism, sand_grain, tetrahedron, u_prism
from vemdem.vem.element import VemOptions, build_elements
from vemdem.vem.mass import build_mass
from vemdem.vem.material import Material

RHO = 2200.0
GRAINS = [sand_grain(seed=3), sand_grain(seed=8, n_vertices=21, elongation=0.5), cube(1e-3), l_prism(1e-3), u_prism(1e-3)]


def mass_for(grain, beta_d, beta_e=None):
    opts = VemOptions(beta_mass=beta_d, beta_load=beta_d if beta_e is None else beta_e)
    el = build_elements([grain], Material(90e9, 0.16, RHO), opts)
    return build_mass([grain], el, RHO)


@pytest.mark.parametrize("beta_d", [0.0, 0.5, 1.0])
@pytest.mark.parametrize("grain", GRAINS, ids=lambda g: g.name)
def test_mass_matrix_reproduces_rigid_body_inertia(grain, beta_d):
    M = mass_for(grain, beta_d).matrix().toarray()
    X = grain.vertices - grain.centroid
    n = grain.n_vertices
    # translation: total mass rho V in each direction
    for i in range(3):
        t = np.zeros((n, 3))
        t[:, i] = 1.0
        assert t.ravel() @ M @ t.ravel() == pytest.approx(RHO * grain.volume, rel=1e-12)
    # rotation about the centroid: v = omega x X  ->  v^T M v = omega^T J omega
    J = np.empty((3, 3))
    for a in range(3):
        for b in range(3):
            va = np.cross(np.eye(3)[a], X).ravel()
            vb = np.cross(np.eye(3)[b], X).ravel()
            J[a, b] = va @ M @ vb
    np.testing.assert_allclose(J, RHO * grain.mass.inertia, rtol=0, atol=1e-12 * np.abs(RHO * grain.mass.inertia).max())
    # no coupling between translation and rotation about the centroid
    for i in range(3):
        t = np.zeros((n, 3))
        t[:, i] = 1.0
        for a in range(3):
            assert abs(t.ravel() @ M @ np.cross(np.eye(3)[a], X).ravel()) <= 1e-12 * RHO * grain.volume * 1e-3


@pytest.mark.parametrize("grain", GRAINS, ids=lambda g: g.name)
def test_mass_is_symmetric_positive_definite_with_submesh(grain):
    M = mass_for(grain, 1.0).matrix().toarray()
    np.testing.assert_allclose(M, M.T, atol=0)
    assert np.linalg.eigvalsh(M).min() > 0


def test_projection_mass_has_rank_twelve():
    """M_Pi sees only the linear part of the motion: rank 12 (docs/vem.md)."""
    grain = sand_grain(seed=4, n_vertices=30)
    M = mass_for(grain, 0.0).matrix().toarray()
    s = np.linalg.svd(M, compute_uv=False)
    assert np.sum(s > 1e-10 * s[0]) == 12


@pytest.mark.parametrize("beta", [0.0, 1.0])
def test_gravity_load_is_the_weight_applied_at_the_centroid(beta):
    grain = sand_grain(seed=2)
    m = mass_for(grain, 1.0, beta_e=beta)
    g = np.array([0.0, 0.0, -9.81])
    f = m.load[:, None] * g
    np.testing.assert_allclose(f.sum(axis=0), RHO * grain.volume * g, rtol=1e-12)
    moment = np.cross(grain.vertices - grain.centroid, f).sum(axis=0)
    assert np.abs(moment).max() <= 1e-12 * RHO * grain.volume * 9.81 * 1e-3


def test_lumped_mass_keeps_total_mass_and_centre():
    grain = sand_grain(seed=6)
    m = mass_for(grain, 1.0)
    assert (m.lumped > 0).all()
    assert m.lumped.sum() == pytest.approx(RHO * grain.volume, rel=1e-12)
    np.testing.assert_allclose(m.lumped @ grain.vertices / m.lumped.sum(), grain.centroid, atol=1e-15)


def test_tetrahedron_consistent_mass_is_the_fe_mass():
    X = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    grain = tetrahedron(X)
    fe = RHO * grain.volume / 20 * (np.ones((4, 4)) + np.eye(4))
    for beta_d in (0.0, 1.0):
        np.testing.assert_allclose(mass_for(grain, beta_d).block(0), fe, atol=1e-14 * RHO)


def test_mass_matrix_is_the_block_diagonal_of_the_grain_blocks_times_identity(rng):
    """The vectorised assembly against scipy's kron and block_diag, on grains of different sizes."""
    import scipy.sparse as sp

    grains = [GRAINS[0], GRAINS[1], GRAINS[2]]  # 30, 21 and 8 vertices
    el = build_elements(grains, Material(90e9, 0.16, RHO), VemOptions())
    mass = build_mass(grains, el, RHO)
    reference = sp.block_diag([sp.kron(mass.block(g), sp.identity(3)) for g in range(3)], format="csr")
    M = mass.matrix()
    assert M.shape == reference.shape and M.nnz == reference.nnz
    assert abs(M - reference).max() == 0.0
    assert mass.matrix() is M  # built once
    v = rng.normal(size=M.shape[0])
    assert np.array_equal(M @ v, reference @ v)  # same structure, same order: same bits
