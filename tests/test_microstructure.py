"""Microstructure measures (analysis.microstructure) against answers worked out by hand: hand-built
record arrays first, then the real contact model on cube stacks, then fabric.csv from the frames."""

import csv
import tomllib
from types import SimpleNamespace

import numpy as np
import pytest

from vemdem.analysis import microstructure as ms
from vemdem.contact.defaults import default_contact_laws
from vemdem.contact.forces import pair_normals, pair_points
from vemdem.contact.law import normal_force
from vemdem.contact.model import ContactHistory
from vemdem.contact.narrow import EDGE_EDGE, PAIR_NAMES, VERTEX_EDGE, VERTEX_FACE, VERTEX_VERTEX
from vemdem.contact.pairs import FLOAT_COLS, INT_COLS, KIND, NODE0
from vemdem.contact.walls import PlaneWall
from vemdem.driver.frames import FABRIC_FIRST, FABRIC_ROSE, FRAME_CSVS, FrameWriter
from vemdem.geometry import cube, rotation_matrix
from vemdem.model.scene import Scene
from vemdem.solver.state import State
from vemdem.vem.material import Material

AXES = np.eye(3)
MAT = Material(E=1e9, nu=0.3, density=2000.0)
EDGE = 1e-3


def records(a, b, normal, force, kind=None, point=None):
    """Hand-built records: arrays as ContactRecords holds them."""
    a, b = np.asarray(a), np.asarray(b)
    m = len(a)
    return SimpleNamespace(a=a, b=b, kind=np.full(m, VERTEX_FACE) if kind is None else np.asarray(kind),
                           point=np.zeros((m, 3)) if point is None else np.asarray(point, float),
                           normal=np.asarray(normal, float).reshape(m, 3),
                           force=np.asarray(force, float).reshape(m, 3))  # fmt: skip


# ---------------------------------------------------------------------------------------------- by hand


def test_the_kinds_are_the_narrow_phases():
    assert ms.KINDS == PAIR_NAMES
    assert [VERTEX_FACE, EDGE_EDGE, VERTEX_EDGE, VERTEX_VERTEX] == [0, 1, 2, 3]


def test_six_normals_along_the_axes_are_isotropic():
    """Grain 0 touched by six grains, one beyond each face: F = I/3, no anisotropy. Each outer grain
    has one contact: Z = 2*6/7, and Z_m = (12 - 6) / (7 - 0 - 6) = 6 with six rattlers."""
    directions = np.vstack([AXES, -AXES])
    rec = records(np.arange(1, 7), np.zeros(6, int), directions, 2.0 * directions)
    row = ms.fabric_row(0.5, rec, 7)
    F = np.array([[row["F_xx"], row["F_xy"], row["F_xz"]], [row["F_xy"], row["F_yy"], row["F_yz"]],
                  [row["F_xz"], row["F_yz"], row["F_zz"]]])  # fmt: skip
    np.testing.assert_allclose(F, np.eye(3) / 3.0, atol=1e-15)
    assert row["anisotropy"] == pytest.approx(0.0, abs=1e-14)
    assert row["n_pairs"] == 6 and row["coordination"] == pytest.approx(12 / 7)
    assert row["rattlers"] == 6 and row["mechanical_coordination"] == pytest.approx(6.0)
    assert row["fn_mean"] == pytest.approx(2.0) and row["strong_share"] == 0.0  # equal forces: none above the mean


def test_all_normals_along_z():
    """A column of four grains: F = diag(0, 0, 1), F' = diag(-1/3, -1/3, 2/3), a_ij = 15/2 F' =
    diag(-2.5, -2.5, 5), a = sqrt(3/2 (2.5^2 + 2.5^2 + 5^2)) = 7.5. Degrees 1, 2, 2, 1: Z = 6/4 and
    Z_m = (6 - 2) / (4 - 2) = 2."""
    z = np.tile(AXES[2], (3, 1))
    rec = records([1, 2, 3], [0, 1, 2], z, z)
    pairs = ms.pair_contacts(rec.a, rec.b, rec.normal, rec.force, 4)
    F = ms.fabric_tensor(pairs.normal)
    np.testing.assert_allclose(F, np.diag([0.0, 0.0, 1.0]), atol=1e-15)
    np.testing.assert_allclose(ms.fabric_deviator(F), np.diag([-1 / 3, -1 / 3, 2 / 3]), atol=1e-15)
    assert ms.anisotropy(F) == pytest.approx(7.5)
    net = ms.coordination(rec.a, rec.b, 4)
    assert net["coordination"] == pytest.approx(1.5) and net["mechanical_coordination"] == pytest.approx(2.0)
    assert (net["rattlers"], net["no_contact"], net["one_contact"]) == (2, 0, 2)


def test_rattlers_and_walls():
    """A triangle 0-1-2, grain 3 on grain 0 alone, grain 4 on the floor (body 5) alone, by three
    records: C = 4 pairs, Z = 8/5; N0 = 1 (grain 4: wall contacts do not count), N1 = 1 (grain 3),
    Z_m = (8 - 1) / (5 - 1 - 1) = 7/3; one wall contact."""
    up = AXES[2]
    rec = records([1, 2, 2, 3, 4, 4, 4], [0, 0, 1, 0, 5, 5, 5], np.tile(up, (7, 1)), np.tile(up, (7, 1)))
    row = ms.fabric_row(0.0, rec, 5)
    assert row["n_pairs"] == 4 and row["n_records"] == 4 and row["wall_contacts"] == 1
    assert row["coordination"] == pytest.approx(8 / 5)
    assert row["mechanical_coordination"] == pytest.approx(7 / 3) and row["rattlers"] == 2
    assert ms.wall_contacts([0, 5, 0], [5, 0, 6], 5) == 2  # grain 0 with wall 5 either side round, and wall 6


def test_several_records_of_one_pair_are_one_contact():
    """Grains 0 and 1 by three records, one of them with its sides swapped; 1 and 2 by one. The pair
    (0, 1): force on 0 from 1 = (0, 0, 3) + (0, 0, 2) + (0, 1, 0) = (0, 1, 5), f_n = 3 + 2 + 1 = 6, and
    its normal the records' normals oriented towards grain 0, weighted by their f_n:
    3 (0,0,1) + 2 (0,0,1) + 1 (0,1,0) = (0, 1, 5), over sqrt(26)."""
    rec = records(a=[0, 0, 1, 2], b=[1, 1, 0, 1],
                  normal=[[0, 0, 1], [0, 0, 1], [0, -1, 0], [1, 0, 0]],
                  force=[[0, 0, 3], [0, 0, 2], [0, -1, 0], [4, 0, 0]],
                  kind=[VERTEX_VERTEX, VERTEX_VERTEX, EDGE_EDGE, VERTEX_FACE])  # fmt: skip
    pairs = ms.pair_contacts(rec.a, rec.b, rec.normal, rec.force, 3)
    assert list(pairs.lo) == [0, 1] and list(pairs.hi) == [1, 2] and list(pairs.n_records) == [3, 1]
    np.testing.assert_allclose(pairs.force, [[0, 1, 5], [-4, 0, 0]])
    np.testing.assert_allclose(pairs.fn, [6.0, 4.0])
    np.testing.assert_allclose(pairs.normal, [[0, 1 / np.sqrt(26), 5 / np.sqrt(26)], [-1, 0, 0]])
    row = ms.fabric_row(0.0, rec, 3)
    assert (row["n_records"], row["n_pairs"]) == (4, 2)
    assert (row["vertex_face"], row["edge_edge"], row["vertex_edge"], row["vertex_vertex"]) == (1, 1, 0, 2)
    assert row["coordination"] == pytest.approx(4 / 3)


def test_strong_and_weak_network():
    """Four pairs along x with f_n = 1, 1, 1, 5: <f_n> = 2, one strong contact of four. Branch
    lengths 1, 1, 1, 2 (centroids): f . l = 1, 1, 1, 10, so the strong one carries 10/13 of p."""
    centroids = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0], [5, 0, 0]])
    x = AXES[0]
    rec = records([1, 2, 3, 4], [0, 1, 2, 3], np.tile(x, (4, 1)), np.outer([1, 1, 1, 5], x))
    row = ms.fabric_row(0.0, rec, 5, centroids)
    assert row["strong_share"] == pytest.approx(0.25) and row["strong_stress_share"] == pytest.approx(10 / 13)
    assert row["fn_mean"] == pytest.approx(2.0) and row["fn_max_over_mean"] == pytest.approx(2.5)
    assert ms.strong_network(np.array([1.0, 1, 1, 5]))["strong_stress_share"] is None  # no branches


def test_force_distribution():
    """f_n = 0.5, 1, 1.5, 3, 4: <f_n> = 2, ratios 0.25, 0.5, 0.75, 1.5, 2."""
    dist = ms.force_distribution(np.array([0.5, 1.0, 1.5, 3.0, 4.0]), bins=4)
    assert dist["mean"] == 2.0 and dist["max_over_mean"] == 2.0
    assert dist["share_above_1"] == pytest.approx(2 / 5) and dist["share_above_2"] == 0.0
    assert dist["share_below_half"] == pytest.approx(1 / 5)
    np.testing.assert_allclose(dist["edges"], [0, 0.5, 1, 1.5, 2])
    assert list(dist["counts"]) == [1, 2, 0, 2]  # numpy's last bin is closed: 1.5 and 2 both in it
    assert np.sum(dist["density"] * np.diff(dist["edges"])) == pytest.approx(1.0)
    assert ms.force_distribution(np.zeros(0))["max_over_mean"] is None


def test_love_weber_of_a_grain_squeezed_between_two_plates():
    """One grain (w x d x h, centroid away from the origin) between a top plate (body 1) and a bottom
    one (body 2), each pushing with F spread over four corner records: sigma_zz = F / (w d) in the
    volume w d h, compression positive, nothing else. The bottom plate's records name the plate as
    side A (as a mesh wall's vertex on a grain's face would): the same stress."""
    w, d, h, F = 2.0, 3.0, 0.5, 12.0
    c = np.array([0.1, -0.2, 0.3])
    corners = np.array([[sx * w / 2, sy * d / 2] for sx in (-1, 1) for sy in (-1, 1)])
    top = np.column_stack([corners, np.full(4, h / 2)]) + c
    bottom = np.column_stack([corners, np.full(4, -h / 2)]) + c
    down = np.tile(-AXES[2], (4, 1))
    rec = records(a=[0] * 4 + [2] * 4, b=[1] * 4 + [0] * 4, normal=np.vstack([down, down]),
                  force=np.vstack([F / 4 * down, F / 4 * down]), point=np.vstack([top, bottom]))  # fmt: skip
    sigma = ms.love_weber_stress(rec.a, rec.b, rec.point, rec.force, c[None, :], w * d * h)
    np.testing.assert_allclose(sigma, np.diag([0.0, 0.0, F / (w * d)]), atol=1e-12)
    row = ms.fabric_row(0.0, rec, 1, c[None, :], w * d * h)
    assert row["sigma_zz"] == pytest.approx(F / (w * d)) and row["sigma_xz"] == pytest.approx(0.0, abs=1e-12)
    assert row["wall_contacts"] == 2 and row["n_pairs"] == 0 and row["coordination"] == 0.0
    assert row["F_zz"] is None and row["fn_mean"] is None and row["mechanical_coordination"] is None


def test_love_weber_between_two_grains_is_force_times_branch():
    """Grain 1 at height L above grain 0, pushed up by it with F: sigma = F L / V e_z (x) e_z, where
    the contact point is does not matter."""
    L, F, V = 2.0, 3.0, 10.0
    centroids = np.array([[0.0, 0, 0], [0.0, 0, L]])
    for point in ([0.0, 0, 1.0], [0.4, -0.3, 0.7]):
        sigma = ms.love_weber_stress([1], [0], [point], [[0.0, 0, F]], centroids, V)
        np.testing.assert_allclose(sigma, np.diag([0.0, 0.0, F * L / V]), atol=1e-15)


def test_an_empty_frame():
    row = ms.fabric_row(1.0, records([], [], np.zeros((0, 3)), np.zeros((0, 3))), 3, np.zeros((3, 3)), 1.0)
    assert list(row) == ms.FABRIC_HEADER
    assert (row["n_records"], row["n_pairs"], row["coordination"], row["rattlers"], row["wall_contacts"]) == (0, 0, 0.0,
                                                                                                              3, 0)
    assert row["anisotropy"] is None and row["strong_share"] is None and row["sigma_zz"] == 0.0


def test_the_rose_of_an_isotropic_and_of_a_vertical_fabric(tmp_path):
    """rose_histograms, 12 bins: the elevation's six bands of 30 degrees. A vertical normal adds
    nothing to the azimuth, and the elevation's count (the normal and its opposite) lies half in the
    top band and half in the bottom one, each (1 - sin 60) / 2 of the sphere's area. Normals spread
    evenly in the xy plane, one per azimuth bin: density 1 in every azimuth bin."""
    rose = ms.rose_histograms(np.tile(AXES[2], (5, 1)), bins=12)
    assert not rose["azimuth_density"].any()
    band = (1.0 - np.sin(np.pi / 3)) / 2.0
    np.testing.assert_allclose(rose["elevation_density"][[0, -1]], 0.5 / band)
    assert not rose["elevation_density"][1:-1].any()
    angle = np.radians(15.0 + 30.0 * np.arange(6))  # bin centres; with their opposites, all twelve bins
    flat = ms.rose_histograms(np.column_stack([np.cos(angle), np.sin(angle), np.zeros(6)]), bins=12)
    np.testing.assert_allclose(flat["azimuth_density"], 1.0)
    ms.plot_fabric_rose(tmp_path / "rose.png", [("one", AXES, np.ones(3)), ("none", np.zeros((0, 3)), np.zeros(0))])
    assert (tmp_path / "rose.png").stat().st_size > 10_000


# ---------------------------------------------------------------------------------------------- normals


def _one_record(kind, x, nodes, c0=0.0, c1=0.0):
    ints = np.full((1, INT_COLS), -1, np.int64)
    ints[0, KIND] = kind
    ints[0, NODE0 : NODE0 + len(nodes)] = nodes
    floats = np.zeros((1, FLOAT_COLS))
    floats[0, :2] = c0, c1
    return np.ascontiguousarray(x, dtype=float), ints, floats


@pytest.mark.parametrize("flip", [False, True])
def test_normals_from_the_features_where_the_gap_is_round_off(flip):
    """A vertex 1e-12 above a triangle, and two crossing edges 1e-12 apart, turned and a kilometre
    from the origin: the gap vector p_A - p_B is a difference of positions whose round-off (1e-13)
    turns it by percents, while the face's normal and the edges' cross product are exact but for
    round-off of the edges (1e-16 relative). An edge-edge normal turns with the gap (flip: A below B)."""
    R = rotation_matrix([0.3, -0.7, 1.1])
    far, gap = np.array([1000.0, -700.0, 300.0]), 1e-12

    def placed(points):
        return np.asarray(points, float) @ R.T + far

    x, ints, floats = _one_record(VERTEX_FACE, placed([[0.3, 0.3, gap], [0, 0, 0], [1, 0, 0], [0, 1, 0]]),
                                  [0, 1, 2, 3], 0.3, 0.3)  # fmt: skip
    np.testing.assert_allclose(pair_normals(x, ints, floats), [R[:, 2]], atol=1e-12)
    sides = pair_points(x, ints, floats)[0]
    assert np.abs((sides[0] - sides[1]) / np.linalg.norm(sides[0] - sides[1]) - R[:, 2]).max() > 1e-3
    sign = -1.0 if flip else 1.0
    edges = placed([[-1, 0, sign * gap], [1, 0, sign * gap], [0, -1, 0], [0, 1, 0]])
    x, ints, floats = _one_record(EDGE_EDGE, edges, [0, 1, 2, 3], 0.5, 0.5)
    np.testing.assert_allclose(pair_normals(x, ints, floats), [sign * R[:, 2]], atol=1e-12)


def test_vertex_edge_and_vertex_vertex_normals_follow_the_gap():
    x, ints, floats = _one_record(VERTEX_EDGE, [[0.5, 2.0, 0.0], [0.0, 0, 0], [1.0, 0, 0]], [0, 1, 2], 0.5)
    np.testing.assert_allclose(pair_normals(x, ints, floats), [[0.0, 1.0, 0.0]], atol=1e-15)
    x, ints, floats = _one_record(VERTEX_VERTEX, [[0.0, 0, 0], [3.0, 4.0, 0]], [0, 1])
    np.testing.assert_allclose(pair_normals(x, ints, floats), [[-0.6, -0.8, 0.0]], atol=1e-15)


# ---------------------------------------------------------------------------------------------- the contact model


def contact_records(scene, x=None):
    x = scene.bodies.reference if x is None else x
    cr = scene.contact.evaluate(x, 0.0, scene.contact.search(x, 0.0))
    x_all = scene.contact.all_positions(x, 0.0)
    return cr, cr.records(x_all), x_all


@pytest.fixture(scope="module")
def cube_stack():
    """A simple cubic 2 x 2 x 2 stack of unit cubes, faces 0.8 gbar apart: within the activation gap,
    while the cubes across an edge are 0.8 sqrt(2) gbar > gbar apart (no contact)."""
    law, friction = default_contact_laws(EDGE, MAT.E, MAT.density)
    step = EDGE + 0.8 * law.activation_gap
    grains = [cube(EDGE, step * np.array([i, j, k], float)) for i in range(2) for j in range(2) for k in range(2)]
    return Scene.build(grains, MAT, law, friction, gravity=(0.0, 0.0, 0.0)), step


def test_a_simple_cubic_stack_of_cubes(cube_stack):
    """Every cube touches three: Z = Z_m = 3, no rattlers, 12 pairs. Aligned faces meet corner to
    corner (a vertex's projection lands on the other face's corner, out of the face's and the edges'
    range; parallel edges have no edge-edge pair): four vertex-vertex records per face pair. F = I/3.
    Love-Weber in the stack's cube (2 step)^3: per axis 4 pairs of 4 records at f_n(0.8 gbar) over a
    branch of one step, sigma_ii = 16 f_n step / V."""
    scene, step = cube_stack
    _, rec, _ = contact_records(scene)
    centroids = scene.grain_centroids(scene.bodies.reference)
    V = (2 * step) ** 3
    row = ms.fabric_row(0.0, rec, 8, centroids, V)
    assert (row["n_pairs"], row["n_records"], row["rattlers"], row["wall_contacts"]) == (12, 48, 0, 0)
    assert row["coordination"] == 3.0 and row["mechanical_coordination"] == 3.0
    assert (row["vertex_face"], row["edge_edge"], row["vertex_edge"], row["vertex_vertex"]) == (0, 0, 0, 48)
    for name in ms.FABRIC_COLUMNS:
        assert row[name] == pytest.approx(1 / 3 if name[-2] == name[-1] else 0.0, abs=1e-12)
    assert row["anisotropy"] == pytest.approx(0.0, abs=1e-10)
    # the normals are the axes, from B to A, and the forces push A away from B
    assert np.allclose(np.abs(rec.normal).max(axis=1), 1.0)
    offset = centroids[rec.a] - centroids[rec.b]
    assert np.all(np.einsum("ri,ri->r", rec.normal, offset) == pytest.approx(step))
    f = normal_force(0.8 * scene.contact.law.activation_gap, scene.contact.law.packed())[0]
    np.testing.assert_allclose(np.einsum("ri,ri->r", rec.force, rec.normal), f, rtol=1e-6)
    assert row["fn_mean"] == pytest.approx(4 * f, rel=1e-6) and row["strong_share"] == 0.0
    for axis in ("xx", "yy", "zz"):
        assert row[f"sigma_{axis}"] == pytest.approx(16 * f * step / V, rel=1e-6)
    assert abs(row["sigma_xy"]) < 1e-9 * row["sigma_xx"]


def test_a_small_cube_on_a_large_one_on_the_floor():
    """A cube of 0.6 turned about z on a unit cube on the floor, each 0.5 gbar above what is below:
    the small cube's four bottom corners over the large one's top face (vertex-face, turned off the
    face's diagonal), the large one's four on the floor. One grain pair with normal +z (F = e_z e_z,
    a = 7.5), two grains with one contact each (no Z_m), one wall contact. Love-Weber in V, with
    f = f_n(g), g = gbar / 2, each contact point g / 2 below its vertex, h the half edges:
    sigma_zz = 4 f [(h_s + g/2) + (h_b + g/2) + (h_b + g/2)] / V (the small cube's, the large one's
    from above and from the floor)."""
    small = 0.6 * EDGE
    law, friction = default_contact_laws(EDGE, MAT.E, MAT.density)
    g = 0.5 * law.activation_gap
    big = cube(EDGE, (0.0, 0.0, 0.5 * EDGE + g))
    top = cube(small).rotated(rotation_matrix([0.0, 0.0, 0.3])).translated((0.0, 0.0, EDGE + 2 * g + 0.5 * small))
    scene = Scene.build([big, top], MAT, law, friction, planes=[PlaneWall((0.0, 0.0, 0.0), (0.0, 0.0, 1.0))],
                        gravity=(0.0, 0.0, 0.0))  # fmt: skip
    _, rec, _ = contact_records(scene)
    assert len(rec.a) == 8 and np.all(rec.kind == VERTEX_FACE)
    np.testing.assert_allclose(rec.normal, np.tile(AXES[2], (8, 1)), atol=1e-12)
    grain_pair = (rec.a < 2) & (rec.b < 2)
    assert set(rec.a[grain_pair]) == {1} and set(rec.b[~grain_pair]) == {2}  # the small cube's vertices; the floor
    V = 7e-9
    row = ms.fabric_row(0.0, rec, 2, scene.grain_centroids(scene.bodies.reference), V)
    assert (row["n_pairs"], row["n_records"], row["vertex_face"], row["wall_contacts"]) == (1, 4, 4, 1)
    assert row["coordination"] == 1.0 and row["mechanical_coordination"] is None and row["rattlers"] == 2
    assert row["F_zz"] == pytest.approx(1.0) and row["anisotropy"] == pytest.approx(7.5)
    f = normal_force(g, law.packed())[0]
    expected = 4 * f * ((0.5 * small + 0.5 * g) + (0.5 * EDGE + 0.5 * g) + (0.5 * EDGE + 0.5 * g)) / V
    assert row["sigma_zz"] == pytest.approx(expected, rel=1e-6)
    assert abs(row["sigma_xz"]) < 1e-9 * row["sigma_zz"] and abs(row["sigma_xx"]) < 1e-9 * row["sigma_zz"]


def test_every_normal_is_the_unit_gap_vector_where_the_gap_is_not_small():
    """Three cubes stacked on a floor, the middle one turned (vertex-face and edge-edge records): each
    record's normal is (p_A - p_B) / |p_A - p_B| of its closest points, and its force pushes A off B."""
    law, friction = default_contact_laws(EDGE, MAT.E, MAT.density, mu_s=0.6, mu_d=0.5)
    grains, z = [], 0.5 * law.activation_gap
    for k, angle in enumerate((0.0, 0.5, 0.1)):
        grain = cube(EDGE * (1.0 - 0.1 * k)).rotated(rotation_matrix([0.0, 0.0, angle]))
        grain = grain.translated((0.0, 0.0, z - grain.vertices[:, 2].min()))
        grains.append(grain)
        z = grain.vertices[:, 2].max() + 0.5 * law.activation_gap
    scene = Scene.build(grains, MAT, law, friction, planes=[PlaneWall((0.0, 0.0, 0.0), (0.0, 0.0, 1.0))])
    cr, rec, x_all = contact_records(scene)
    assert {VERTEX_FACE, EDGE_EDGE} <= set(rec.kind)
    sides = pair_points(x_all, cr.ints, cr.floats)
    gap = sides[:, 0] - sides[:, 1]
    np.testing.assert_allclose(rec.normal, gap / np.linalg.norm(gap, axis=1, keepdims=True), atol=1e-9)
    np.testing.assert_allclose(rec.point, 0.5 * (sides[:, 0] + sides[:, 1]))
    assert np.all(np.einsum("ri,ri->r", rec.force, rec.normal) > 0.0)
    np.testing.assert_array_equal(rec.a, cr.ints[:, 1])


# ---------------------------------------------------------------------------------------------- fabric.csv


def read_rows(path):
    with open(path) as fh:
        return list(csv.reader(fh))


def test_the_frames_write_fabric_csv_and_the_rose(tmp_path, cube_stack):
    """FrameWriter: a row per frame; the stress only with a volume; the rose at close, of the first
    frame with contacts (kept in fabric_first.npz for a resumed run) and the last."""
    scene, step = cube_stack
    assert "fabric.csv" in FRAME_CSVS
    x = scene.bodies.reference
    apart = x * 1.5  # no contact
    V = (2 * step) ** 3
    writer = FrameWriter(scene, tmp_path, vtk=False, resume_frames=None, volume=lambda t, x: V)
    for t, xt in ((0.0, apart), (1.0, x), (2.0, x)):
        cr = scene.contact.evaluate(xt, t, scene.contact.search(xt, t))
        writer.write(State(t, xt, np.zeros_like(xt), np.zeros_like(xt), ContactHistory.empty()), 0.0, cr)
    writer.close()
    rows = read_rows(tmp_path / "fabric.csv")
    assert rows[0] == ms.FABRIC_HEADER and len(rows) == 4
    table = [dict(zip(rows[0], r)) for r in rows[1:]]
    assert table[0]["n_pairs"] == "0" and table[0]["anisotropy"] == "" and table[0]["sigma_zz"] == "0.0"
    assert [r["coordination"] for r in table[1:]] == ["3.0", "3.0"] and float(table[2]["sigma_zz"]) > 0.0
    assert (tmp_path / FABRIC_ROSE).stat().st_size > 10_000
    with np.load(tmp_path / FABRIC_FIRST) as first:
        assert float(first["t"]) == 1.0 and first["normals"].shape == (12, 3)
    # resumed after the frame at t = 1 (its checkpoint): the frame at 2 again, the first one kept
    writer = FrameWriter(scene, tmp_path, vtk=False, resume_frames=2)
    cr = scene.contact.evaluate(x, 2.0, scene.contact.search(x, 2.0))
    writer.write(State(2.0, x, np.zeros_like(x), np.zeros_like(x), ContactHistory.empty()), 0.0, cr)
    assert writer.first_rose.t == 1.0
    writer.close()
    assert read_rows(tmp_path / "fabric.csv")[-1][ms.FABRIC_HEADER.index("sigma_zz")] == ""  # no volume given
    # resumed before the frame at t = 1: the kept first frame is one the run redoes, so it goes (here
    # the redone frame has no contact)
    writer = FrameWriter(scene, tmp_path, vtk=False, resume_frames=1)
    assert writer.first_rose.t == 1.0
    cr = scene.contact.evaluate(apart, 1.0, scene.contact.search(apart, 1.0))
    writer.write(State(1.0, apart, np.zeros_like(x), np.zeros_like(x), ContactHistory.empty()), 0.0, cr)
    assert writer.first_rose is None
    writer.close()


def test_a_granular_run_writes_fabric_csv(tmp_path):
    """The `scene` scenario (over driver.loop.simulate): two cubes stacked on the floor, each half an
    activation gap above what is below, for two frames: one grain pair and one wall contact per row."""
    from vemdem.scenarios import scene as scene_mod
    from vemdem.scenarios.registry import checked_config, example_text

    raw = tomllib.loads(example_text("drop"))
    gbar = 0.01 * EDGE * (6 / np.pi) ** (1 / 3)  # default activation gap: 1 % of the equivalent diameter
    cubes = [{"shape": "cube", "size": EDGE, "position": [0.0, 0.0, (k + 0.5) * EDGE + (k + 0.5) * gbar],
              "rotation": [0.0, 0.0, 0.0]} for k in range(2)]  # fmt: skip
    raw.update({"grains": cubes, "duration": 0.002, "output": {"every": 1e-3, "vtk": False}})
    cfg, _ = checked_config(raw)
    scene_mod.run(cfg, tmp_path)
    rows = read_rows(tmp_path / "fabric.csv")
    assert rows[0] == ms.FABRIC_HEADER and len(rows) == 1 + 3
    for r in rows[1:]:
        row = dict(zip(rows[0], r))
        assert (row["n_pairs"], row["wall_contacts"], row["coordination"]) == ("1", "1", "1.0")
        assert float(row["F_zz"]) == pytest.approx(1.0) and row["sigma_zz"] == ""
    assert (tmp_path / FABRIC_ROSE).is_file()
