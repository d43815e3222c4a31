"""Grain geometry: validation of a grain's surface (each defect refused with the grain's name), mass
properties, the seeded generator, import from surface files, the stabilisation sub-mesh."""

import meshio
import numpy as np
import pytest
from scipy.spatial import ConvexHull

from vemdem.io.surfaces import load_surface, save_surface
from vemdem.geometry import (
    DegenerateFaceError,
    DuplicateVerticesError,
    GeometryError,
    InconsistentOrientationError,
    InwardOrientationError,
    NonFiniteCoordinatesError,
    NonManifoldEdgeError,
    NonManifoldVertexError,
    NonPositiveVolumeError,
    OpenSurfaceError,
    Polyhedron,
    UnusedVertexError,
    build_submesh,
    cube,
    l_prism,
    sand_grain,
    tetrahedron,
    u_prism,
)
from vemdem.geometry.submesh import SubMeshError, signed_tet_volumes, augmented_points

CUBE = cube(2.0)


# ---------------------------------------------------------------- bad input, one error per defect
def test_non_finite_coordinates():
    v = CUBE.vertices.copy()
    v[3, 1] = np.nan
    with pytest.raises(NonFiniteCoordinatesError, match="non-finite coordinates at vertex \\[3\\]"):
        Polyhedron(v, CUBE.faces)


def test_duplicate_vertices():
    v = np.vstack([CUBE.vertices, CUBE.vertices[5]])
    f = CUBE.faces.copy()
    f[f == 5] = 8
    f[0] = [0, 2, 1]
    f = np.vstack([f, [[5, 6, 7]]])  # vertex 5 and 8 coincide
    with pytest.raises(DuplicateVerticesError, match="duplicate vertices"):
        Polyhedron(v, f)


def test_open_surface():
    with pytest.raises(OpenSurfaceError, match="open surface"):
        Polyhedron(CUBE.vertices, CUBE.faces[:-1])


def test_non_manifold_edge():
    # two tetrahedra sharing one edge: that edge has four faces
    t = tetrahedron()
    v = np.vstack([t.vertices, t.vertices[[2, 3]] * 0 + [[-1.0, 0.3, 0.2], [-0.2, -1.0, 0.4]]])
    f2 = np.array([[0, 1, 4], [0, 4, 5], [1, 5, 4], [0, 5, 1]])
    f = np.vstack([t.faces, f2])
    with pytest.raises(NonManifoldEdgeError, match="non-manifold edge \\[0, 1\\]"):
        Polyhedron(v, f)


def test_non_manifold_vertex():
    # two tetrahedra touching at one vertex
    t = tetrahedron()
    v = np.vstack([t.vertices, -t.vertices[1:]])
    f = np.vstack([t.faces, np.where(t.faces == 0, 0, t.faces + 3)[:, ::-1]])
    with pytest.raises(NonManifoldVertexError, match="non-manifold vertex 0"):
        Polyhedron(v, f)


def test_inconsistent_orientation():
    f = CUBE.faces.copy()
    f[3] = f[3][::-1]
    with pytest.raises(InconsistentOrientationError, match="inconsistent orientation"):
        Polyhedron(CUBE.vertices, f)


def test_inward_orientation():
    with pytest.raises(InwardOrientationError, match="inward orientation"):
        Polyhedron(CUBE.vertices, CUBE.faces[:, ::-1])


def test_zero_volume():
    # a closed, consistently oriented surface folded flat: a "pillow" of two coincident squares
    v = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, 0.0]])
    top = np.array([[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]])
    f = np.vstack([top, top[:, ::-1] + 0])
    with pytest.raises(GeometryError):
        Polyhedron(v, f)
    # the volume check itself, on a valid topology with collapsed geometry
    t = tetrahedron()
    flat = t.vertices.copy()
    flat[3] = [0.3, 0.3, 0.0]
    with pytest.raises((NonPositiveVolumeError, DegenerateFaceError)):
        Polyhedron(flat, t.faces)


def test_zero_volume_error_names_the_volume():
    v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0.2, 0.2, 1e-13]])
    t = tetrahedron()
    with pytest.raises(NonPositiveVolumeError, match="zero volume"):
        Polyhedron(v, t.faces)


def test_degenerate_face_and_unused_vertex():
    v = np.vstack([CUBE.vertices, [[5.0, 5, 5]]])
    with pytest.raises(UnusedVertexError, match="vertex \\[8\\] belongs to no face"):
        Polyhedron(v, CUBE.faces)
    f = CUBE.faces.copy()
    f[0] = [0, 0, 1]
    with pytest.raises(DegenerateFaceError, match="face \\[0\\]"):
        Polyhedron(CUBE.vertices, f)


def test_every_error_is_a_value_error_with_the_grain_name():
    with pytest.raises(ValueError, match="^my-grain: inward"):
        Polyhedron(CUBE.vertices, CUBE.faces[:, ::-1], name="my-grain")


# ---------------------------------------------------------------- mass properties
def test_cube_mass_properties():
    c = cube(2.0, center=(1.0, -2.0, 3.0))
    assert c.volume == pytest.approx(8.0)
    np.testing.assert_allclose(c.centroid, [1, -2, 3], atol=1e-14)
    np.testing.assert_allclose(c.mass.inertia, np.eye(3) * 8 * (4 + 4) / 12, atol=1e-13)


def test_tetrahedron_mass_properties():
    """Reference: the closed form of a unit right tetrahedron (Tonon 2004)."""
    t = tetrahedron()
    assert t.volume == pytest.approx(1 / 6)
    np.testing.assert_allclose(t.centroid, [0.25] * 3)
    # about the origin: int x^2 dV = 1/60, int xy dV = 1/120
    second_origin = t.mass.second_moment + t.volume * np.outer(t.centroid, t.centroid)
    np.testing.assert_allclose(second_origin, (np.ones((3, 3)) + np.eye(3)) / 120, atol=1e-15)


def test_random_grain_mass_against_scipy_and_monte_carlo():
    g = sand_grain(seed=11, size=1.0)
    hull = ConvexHull(g.vertices)
    assert g.volume == pytest.approx(hull.volume, rel=1e-12)
    rng = np.random.default_rng(0)
    lo, hi = g.vertices.min(axis=0), g.vertices.max(axis=0)
    pts = rng.uniform(lo, hi, size=(400_000, 3))
    inside = np.all(pts @ hull.equations[:, :3].T + hull.equations[:, 3] <= 0, axis=1)
    p = pts[inside]
    np.testing.assert_allclose(p.mean(axis=0), g.centroid, atol=3e-3)
    y = p - g.centroid
    second = y.T @ y / len(p) * g.volume
    np.testing.assert_allclose(second, g.mass.second_moment, atol=2e-2 * np.abs(second).max())


def test_non_convex_volume():
    assert l_prism(1.0, 0.5).volume == pytest.approx(0.75 * 0.5)
    assert u_prism(1.0, 0.5).volume == pytest.approx(7 / 9 * 0.5)


# ---------------------------------------------------------------- sand-grain generator
def test_same_seed_same_grain_and_size():
    a, b = sand_grain(seed=42), sand_grain(seed=42)
    np.testing.assert_array_equal(a.vertices, b.vertices)
    np.testing.assert_array_equal(a.faces, b.faces)
    assert not np.array_equal(a.vertices, sand_grain(seed=43).vertices)
    assert a.volume == pytest.approx(np.pi * 1.45e-3**3 / 6, rel=1e-12)
    np.testing.assert_allclose(a.centroid, 0, atol=1e-15)


@pytest.mark.parametrize("n", [8, 20, 30, 40, 60])
def test_generator_gives_the_requested_vertex_count(n):
    for seed in range(5):
        assert sand_grain(seed=seed, n_vertices=n, roughness=0.3).n_vertices == n


def test_elongation_and_flatness_shape_the_grain():
    g = sand_grain(seed=0, elongation=0.5, flatness=0.5, roughness=0.0, n_vertices=200)
    evals = np.sort(np.linalg.eigvalsh(g.mass.second_moment))[::-1]
    axes = np.sqrt(evals / evals[0])  # second moments scale with the axis length squared
    np.testing.assert_allclose(axes, [1.0, 0.5, 0.25], rtol=0.08)


def test_truncated_grain_has_flat_ends():
    g = sand_grain(seed=1, truncate=0.6)
    z = g.vertices[:, 2]
    assert np.sum(np.isclose(z, z.min(), rtol=0, atol=1e-12)) >= 3
    assert np.sum(np.isclose(z, z.max(), rtol=0, atol=1e-12)) >= 3


@pytest.mark.parametrize("kwargs", [{"size": -1.0}, {"n_vertices": 3}, {"elongation": 0.0}, {"roughness": 0.7}])
def test_generator_rejects_bad_parameters(kwargs):
    with pytest.raises(ValueError):
        sand_grain(**kwargs)


# ---------------------------------------------------------------- import from surface files
@pytest.mark.parametrize("ext", ["stl", "obj", "ply"])
def test_import_merges_duplicated_vertices(tmp_path, ext):
    g = l_prism(1e-3, 0.5e-3)  # non-convex
    path = tmp_path / f"grain.{ext}"
    # STL-like "triangle soup": every triangle with its own three vertices
    soup = g.vertices[g.faces].reshape(-1, 3)
    meshio.write(path, meshio.Mesh(soup, [("triangle", np.arange(len(soup)).reshape(-1, 3))]))
    h = load_surface(path)
    assert h.n_vertices == g.n_vertices
    assert h.volume == pytest.approx(g.volume, rel=1e-6)


def test_import_round_trip_and_errors(tmp_path):
    g = sand_grain(seed=2)
    save_surface(g, tmp_path / "g.obj")
    h = load_surface(tmp_path / "g.obj")
    np.testing.assert_allclose(h.volume, g.volume, rtol=1e-12)
    with pytest.raises(GeometryError, match="not found"):
        load_surface(tmp_path / "missing.stl")
    open_cube = meshio.Mesh(CUBE.vertices, [("triangle", CUBE.faces[:-2])])
    meshio.write(tmp_path / "open.stl", open_cube)
    with pytest.raises(OpenSurfaceError):
        load_surface(tmp_path / "open.stl")


# ---------------------------------------------------------------- stabilisation sub-mesh
@pytest.mark.parametrize(
    "grain,expected",
    [
        (sand_grain(seed=3), "fan"),
        (cube(1.0), "fan"),
        (l_prism(1.0, 0.5), "kernel-fan"),  # vertex average is the reflex corner
        (u_prism(1.0, 0.5), "constrained"),  # not star-shaped
    ],
    ids=lambda x: getattr(x, "name", x),
)
def test_submesh_fills_the_grain(grain, expected):
    mesh = build_submesh(grain)
    assert mesh.method == expected
    vol = signed_tet_volumes(augmented_points(grain, mesh), mesh.tets)
    assert vol.min() > 0
    assert vol.sum() == pytest.approx(grain.volume, rel=1e-12)
    assert np.all(mesh.tets[:, :3] < grain.n_vertices + mesh.n_virtual)


def test_fan_is_refused_where_it_would_invert():
    with pytest.raises(SubMeshError, match="inverted or flat"):
        build_submesh(l_prism(1.0, 0.5), "fan")
    with pytest.raises(SubMeshError, match="not star-shaped"):
        build_submesh(u_prism(1.0, 0.5), "kernel-fan")


def test_constrained_submesh_of_a_schonhardt_polyhedron():
    """The twisted prism has no tetrahedralisation without a Steiner point; TetGen adds one,
    which becomes a virtual node (no new unknown)."""
    tri = np.array([[1.0, 0, 0], [np.cos(2 * np.pi / 3), np.sin(2 * np.pi / 3), 0],
                    [np.cos(4 * np.pi / 3), np.sin(4 * np.pi / 3), 0]])  # fmt: skip
    twist = np.array([[np.cos(0.5), -np.sin(0.5), 0], [np.sin(0.5), np.cos(0.5), 0], [0, 0, 1]])
    top = tri @ twist.T + [0, 0, 1.0]
    v = np.vstack([tri, top])
    # sides: each quad split along the diagonal that makes the prism non-convex
    f = [[0, 2, 1], [3, 4, 5]]
    for i in range(3):
        j = (i + 1) % 3
        f += [[i, j, 3 + j], [i, 3 + j, 3 + i]]
    g = Polyhedron(v, np.array(f), "schonhardt")
    mesh = build_submesh(g, "constrained")
    assert mesh.n_virtual >= 1
    vol = signed_tet_volumes(augmented_points(g, mesh), mesh.tets)
    assert vol.min() > 0 and vol.sum() == pytest.approx(g.volume, rel=1e-10)


def test_unknown_submesh_method():
    with pytest.raises(ValueError, match="unknown sub-mesh method"):
        build_submesh(cube(), "voronoi")


# ---------------------------------------------------------------- a grain's mean deformation
def _surfaces(grains):
    """Stacked vertices, faces (global indices) and face -> grain of some polyhedra."""
    X, faces, owner, start = [], [], [], 0
    for g, p in enumerate(grains):
        X.append(p.vertices)
        faces.append(p.faces + start)
        owner.append(np.full(len(p.faces), g))
        start += len(p.vertices)
    return np.vstack(X), np.vstack(faces), np.concatenate(owner)


def test_the_mean_deformation_gradient_of_an_affine_map_is_the_map_and_of_a_rotation_no_strain():
    """Divergence theorem on flat triangles: exact for x = A X + c (any A), whatever the shape; a
    rotation has stretches of 1, a uniaxial stretch lambda a largest strain |lambda - 1|."""
    from vemdem.geometry.mass import largest_strains, mean_deformation_gradients
    from vemdem.geometry.shapes import rotation_matrix, sand_grain

    grains = [sand_grain(size=1e-3, n_vertices=30, seed=s) for s in range(3)]
    X, faces, owner = _surfaces(grains)
    rng = np.random.default_rng(7)
    A = np.eye(3) + 0.3 * rng.normal(size=(3, 3))
    F = mean_deformation_gradients(X @ A.T + [1e-3, -2e-3, 5e-4], X, faces, owner, 3)
    assert np.allclose(F, A, rtol=0, atol=1e-12)
    R = rotation_matrix([0.3, -1.1, 0.7])
    assert np.allclose(largest_strains(mean_deformation_gradients(X @ R.T, X, faces, owner, 3)), 0.0, atol=1e-12)
    stretch = np.diag([1.0, 1.0, 0.75])  # a quarter shorter along z, then rotated
    strains = largest_strains(mean_deformation_gradients(X @ (R @ stretch).T, X, faces, owner, 3))
    assert np.allclose(strains, 0.25, rtol=1e-12)
