"""The tetrahedral FE reference (verification/fem_reference.py) and the VEM-vs-FE comparison of
single-grain compression (stabilisation beta_i in {0.1, 0.25, 0.5} at 5, 10 and 20 % strain).

Full numbers, finer meshes and several seeds: benchmarks/fem_comparison.py, docs/fem_comparison.md.
"""

import numpy as np
import pytest

from vemdem.verification import fem_reference as fr
from vemdem.analysis.homogeneous import nominal_axial_stress
from vemdem.config import apply_schema
from vemdem.geometry import cube, sand_grain
from vemdem.geometry.polyhedron import face_area_vectors
from vemdem.scenarios import grain_compression
from vemdem.vem.element import InvertedElementError, tet_gradients
from vemdem.vem.material import Material, neo_hooke_energy

MAT = Material(90e9, 0.16, 2200.0)
STRAINS = np.array([0.05, 0.10, 0.15, 0.20])
REPORTED = [0, 1, 3]  # 5, 10, 20 %
BETAS = (0.1, 0.25, 0.5)


@pytest.fixture(scope="module")
def grain():
    return sand_grain(size=1.45e-3, n_vertices=30, seed=0, truncate=0.7)


def boundary_nodes(tets):
    faces = np.concatenate([tets[:, [1, 2, 3]], tets[:, [0, 3, 2]], tets[:, [0, 1, 3]], tets[:, [0, 2, 1]]])
    key, counts = np.unique(np.sort(faces, axis=1), axis=0, return_counts=True)
    return np.unique(key[counts == 1])


# ----------------------------------------------------------------------------- mesh


@pytest.mark.parametrize("graded", [False, True])
def test_mesh_fills_the_grain_and_keeps_its_vertices_first(grain, graded):
    max_volume = 1e-3 * grain.volume
    nodes, tets = fr.reference_mesh(grain, max_volume, graded)
    n = grain.n_vertices
    assert np.array_equal(nodes[:n], grain.vertices)
    vol, _ = tet_gradients(nodes, tets)
    assert vol.min() > 0
    assert vol.sum() == pytest.approx(grain.volume, rel=1e-12)
    assert vol.max() < 1.5 * max_volume  # TetGen bounds the volume while refining; its final smoothing may exceed it a little
    assert np.array_equal(np.unique(tets), np.arange(len(nodes)))
    # the surface is refined (boundary triangles split), and it stays the grain's surface
    surface = boundary_nodes(tets)
    assert len(surface) > 3 * n
    an = face_area_vectors(grain.vertices, grain.faces)
    normals = an / np.linalg.norm(an, axis=1, keepdims=True)
    offsets = np.einsum("ij,ij->i", normals, grain.vertices[grain.faces[:, 0]])
    dist = np.abs(nodes[surface] @ normals.T - offsets).min(axis=1)  # convex grain: distance to nearest face plane
    assert dist.max() < 1e-9 * np.ptp(grain.vertices)


def test_graded_mesh_is_finer_at_the_cap_rims(grain):
    nodes, tets = fr.reference_mesh(grain, 1e-3 * grain.volume, graded=True)
    rims = fr.cap_rims(grain)
    assert len(rims) >= 6  # two caps, each a polygon of >= 3 rim edges
    edge = np.linalg.norm(nodes[tets[:, 1]] - nodes[tets[:, 0]], axis=1)
    d = fr.distance_to_segments(nodes[tets].mean(axis=1), grain.vertices[rims[:, 0]], grain.vertices[rims[:, 1]])
    h = np.ptp(grain.vertices[:, 2])
    assert np.median(edge[d < 0.03 * h]) < 0.4 * np.median(edge[d > 0.4 * h])


# ----------------------------------------------------------------------------- element


def test_homogeneous_deformation_of_the_refined_mesh(grain):
    """x = F0 X: energy V psi(F0) exactly, no force on interior nodes, forces in equilibrium."""
    nodes, tets = fr.reference_mesh(grain, 1e-3 * grain.volume)
    model = fr.build_tet_model(nodes, tets, MAT)
    F0 = np.array([[1.05, 0.02, -0.03], [0.01, 0.93, 0.04], [-0.02, 0.03, 0.97]])
    energy, f, K = model.evaluate((nodes @ F0.T).ravel(), tangent=True)
    assert energy == pytest.approx(grain.volume * neo_hooke_energy(F0, MAT.mu, MAT.kappa), rel=1e-12)
    f = f.reshape(-1, 3)
    interior = np.setdiff1d(np.arange(len(nodes)), boundary_nodes(tets))
    assert len(interior) > 50
    scale = np.abs(f).max()
    assert np.abs(f[interior]).max() < 1e-9 * scale
    assert np.abs(f.sum(axis=0)).max() < 1e-9 * scale
    # rigid translations are in the tangent's null space
    t = np.tile([0.3, -0.2, 0.5], len(nodes))
    assert np.abs(K @ t).max() < 1e-9 * np.abs(K).max() * np.abs(t).max()


def test_forces_and_tangent_match_finite_differences(grain, rng):
    nodes, tets = fr.mesh_grain(grain, 2e-2 * grain.volume)
    model = fr.build_tet_model(nodes, tets, MAT)
    L = np.ptp(nodes)
    # a smooth finite deformation plus nodal noise: every tet strained differently
    X = nodes / L
    x = L * (X + 0.05 * np.sin(3 * X[:, [1, 2, 0]]) + 0.02 * X[:, [2, 0, 1]] ** 2) + 1e-3 * L * rng.normal(size=X.shape)
    x = x.ravel()
    energy, f, K = model.evaluate(x, tangent=True)
    assert abs(K - K.T).max() < 1e-12 * abs(K).max()
    d = 1e-6 * L * rng.normal(size=x.size)
    e_p, f_p, _ = model.evaluate(x + d)
    e_m, f_m, _ = model.evaluate(x - d)
    assert (e_p - e_m) / 2 == pytest.approx(f @ d, rel=1e-6)
    np.testing.assert_allclose((f_p - f_m) / 2, K @ d, rtol=0, atol=1e-6 * np.abs(K @ d).max())


def test_inverted_tet_raises(grain):
    nodes, tets = fr.mesh_grain(grain, 2e-2 * grain.volume)
    model = fr.build_tet_model(nodes, tets, MAT)
    x = nodes.copy()
    x[:, 2] *= -1  # a mirror image: every tet inverted
    with pytest.raises(InvertedElementError):
        model.evaluate(x.ravel())


# ----------------------------------------------------------------------------- drivers


@pytest.mark.parametrize("mode", ["uniaxial", "confined"])
def test_fem_cube_compression_matches_closed_form(mode):
    """Linear tets represent the homogeneous solution exactly: any mesh, plates holding every
    cap node, must give the closed form (checks the plates, pins and force read-out)."""
    c = cube(1.45e-3)
    run = fr.run_fem(c, MAT, STRAINS, mode, 1e-2 * c.volume)
    assert run.n_nodes > 2 * c.n_vertices
    expected = 1.45e-3**2 * nominal_axial_stress(STRAINS, MAT.mu, MAT.kappa, mode)
    np.testing.assert_allclose(run.forces, expected, rtol=1e-8)
    assert np.all(run.penetration == 0.0)


def test_vem_driver_is_the_scenario(tmp_path):
    raw = {
        "scenario": "grain_compression",
        "material": {"E": MAT.E, "nu": MAT.nu},
        "grain": {"shape": "random", "seed": 4},
        "vem": {"beta_internal": 0.25},
        "loading": {"mode": "uniaxial", "max_strain": 0.2, "steps": 4},
        "output": {"vtk": False, "plot": False},
    }
    cfg = apply_schema(raw, grain_compression.SCHEMA)
    grain_compression.run(cfg, tmp_path)
    data = np.loadtxt(tmp_path / "force_strain.csv", delimiter=",", skiprows=1)
    g = sand_grain(size=1.45e-3, n_vertices=30, seed=4, truncate=0.7)
    forces = fr.compress_vem(g, MAT, 0.25, data[1:, 0], "uniaxial")
    np.testing.assert_array_equal(forces, data[1:, 1])


# ----------------------------------------------------------------------------- VEM vs FE


@pytest.fixture(scope="module")
def comparison(grain):
    """FE on three graded meshes (max_volume V/100, V/333, V/1000) and the VEM for each beta."""
    fem = [fr.run_fem(grain, MAT, STRAINS, "uniaxial", f * grain.volume) for f in (1e-2, 3e-3, 1e-3)]
    vem = {b: fr.run_vem(grain, MAT, b, STRAINS, "uniaxial") for b in BETAS}
    return fem, vem


def test_fem_force_converges_under_refinement(comparison):
    """A conforming displacement FE is too stiff and converges from above: the force falls
    monotonically with refinement and the changes contract (the cap rims, where the plates'
    stress is singular, make the rate slow: measured contraction about 2 per level,
    docs/fem_comparison.md)."""
    fem, _ = comparison
    assert fem[0].n_nodes < fem[1].n_nodes < fem[2].n_nodes
    F = np.array([run.forces for run in fem])
    assert np.all(F > 0) and np.all(np.diff(F, axis=1) > 0)  # force grows with strain
    assert np.all(np.diff(F, axis=0) < 0)  # and falls with refinement
    limit, rho = fr.richardson(*F)
    assert np.all(rho > 1.3), rho
    # the last refinement changed the force by less than 30 %, the extrapolation by less than 25 %
    assert np.all(F[1] / F[2] - 1 < 0.30)
    assert np.all(np.abs(limit / F[2] - 1) < 0.25)


def test_vem_versus_fem(comparison):
    """The one-element VEM against the FE force extrapolated from the three meshes.

    Measured with finer meshes (up to ~8000 nodes, docs/fem_comparison.md, seed 0, uniaxial):
    beta_i = 0.1 is 32-39 % too soft, 0.25 is 35-50 % too stiff, 0.5 is 105-170 % too stiff at
    5-20 % strain; the stiffness grows with beta_i and the FE lies between beta_i = 0.1 and 0.25.
    On this test's coarse meshes the extrapolated FE force is 8-18 % above the fine-mesh one; the
    bounds leave room for that and fail if either model's stiffness were off by ~1.5x.
    """
    fem, vem = comparison
    F = np.array([run.forces for run in fem])
    reference, _ = fr.richardson(*F)
    err = {b: vem[b].forces[REPORTED] / reference[REPORTED] - 1 for b in BETAS}
    assert np.all(vem[0.1].forces < vem[0.25].forces) and np.all(vem[0.25].forces < vem[0.5].forces)
    assert np.all((-0.6 < err[0.1]) & (err[0.1] < -0.15)), err[0.1]
    assert np.all((0.1 < err[0.25]) & (err[0.25] < 0.7)), err[0.25]
    assert np.all((0.6 < err[0.5]) & (err[0.5] < 2.0)), err[0.5]
    # at 5 % strain, beta_i = 0.1 and 0.25 are within 50 % of the FE force
    assert abs(err[0.1][0]) < 0.5 and abs(err[0.25][0]) < 0.5
