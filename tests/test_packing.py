"""Initial sand-pack placement: separation, bounds, reproducibility, uniform rotations."""

from functools import cache

import numpy as np
import pytest
from scipy.spatial import ConvexHull

from vemdem.geometry import cube, rotation_matrix
from vemdem.geometry.packing import (
    column_packing,
    pack_height,
    packing_fraction,
    random_rotations,
)

SIZE = 1.45e-3
BOX = (8e-3, 6e-3)
CENTRE = (1e-3, -2e-3)
FLOOR = 5e-3
CLEARANCE = 0.1
SEEDS = (0, 1, 2)


@cache
def packing(seed: int):
    return column_packing(
        60, SIZE, box=BOX, centre=CENTRE, floor=FLOOR, clearance=CLEARANCE, seed=seed
    )


# ------------------------------------------------- independent separation check (SAT)
def _hull(points: np.ndarray) -> ConvexHull:
    hull = ConvexHull(points)
    # SAT is exact for convex bodies only: every vertex must be a hull vertex
    assert len(hull.vertices) == len(points)
    return hull


def _edge_directions(hull: ConvexHull) -> np.ndarray:
    s = hull.simplices
    edges = np.unique(
        np.sort(np.vstack([s[:, [0, 1]], s[:, [1, 2]], s[:, [2, 0]]])), axis=0
    )
    return hull.points[edges[:, 1]] - hull.points[edges[:, 0]]


def _gap(a: np.ndarray, b: np.ndarray, axes: np.ndarray) -> float:
    """Largest gap between the projections of a and b on the unit `axes`."""
    pa, pb = a @ axes.T, b @ axes.T
    gaps = np.maximum(pb.min(axis=0) - pa.max(axis=0), pa.min(axis=0) - pb.max(axis=0))
    return float(gaps.max())


def separation(a: np.ndarray, b: np.ndarray) -> float:
    """A gap between the hulls of two convex point sets along a SAT axis.

    Face normals of both hulls and cross products of their edges contain a separating
    axis whenever the hulls are disjoint, so the gap is > 0 exactly then, and it is a
    lower bound on their distance. Face normals go first: they usually separate, and
    the ~7000 edge crosses are then not needed.
    """
    ha, hb = _hull(a), _hull(b)
    gap = _gap(a, b, np.vstack([ha.equations[:, :3], hb.equations[:, :3]]))
    if gap > 0:
        return gap
    ea, eb = _edge_directions(ha), _edge_directions(hb)
    crosses = np.cross(ea[:, None, :], eb[None, :, :]).reshape(-1, 3)
    norms = np.linalg.norm(crosses, axis=1)
    keep = norms > 1e-9 * norms.max()  # parallel edges span no axis
    return max(gap, _gap(a, b, crosses[keep] / norms[keep, None]))


def test_separation_checker_sees_gaps_and_overlaps():
    a = cube(1.0).vertices
    assert separation(a, a + [1.5, 0, 0]) == pytest.approx(0.5)
    assert 0.3 <= separation(a, a + [1.2, 1.3, 0]) <= np.hypot(0.2, 0.3)
    # ridge along x under ridge along y, 0.1 apart: only their cross product separates
    ridge_x = a @ rotation_matrix([np.pi / 4, 0, 0]).T
    ridge_y = a @ rotation_matrix([0, np.pi / 4, 0]).T + [0, 0, np.sqrt(2) + 0.1]
    assert separation(ridge_x, ridge_y) == pytest.approx(0.1)
    assert separation(a, a + [0.9, 0.9, 0.9]) < 0
    assert separation(a, a @ rotation_matrix([0.3, 0.4, 0.5]).T + 0.9) < 0


def near_pairs(vertices: list[np.ndarray], reach: float) -> list[tuple[int, int]]:
    """Pairs whose bounding boxes come within `reach` of each other."""
    lo = np.array([v.min(axis=0) for v in vertices]) - 0.5 * reach
    hi = np.array([v.max(axis=0) for v in vertices]) + 0.5 * reach
    i, j = np.triu_indices(len(vertices), 1)
    near = np.all((lo[i] <= hi[j]) & (lo[j] <= hi[i]), axis=1)
    return list(zip(i[near], j[near]))


@pytest.mark.parametrize("seed", SEEDS)
def test_no_two_grains_overlap(seed):
    vertices = [g.vertices for g in packing(seed).grains]
    pairs = near_pairs(vertices, reach=SIZE)
    assert len(pairs) > len(vertices)  # neighbours in the layer and the next layers
    gaps = [separation(vertices[i], vertices[j]) for i, j in pairs]
    assert min(gaps) > 0


# ------------------------------------------------------------------ bounds, count, sizes
def circumscribed_diameter(grains) -> float:
    return 2 * max(
        np.linalg.norm(g.vertices - g.centroid, axis=1).max() for g in grains
    )


@pytest.mark.parametrize("seed", SEEDS)
def test_grains_inside_walls_and_above_floor(seed):
    p = packing(seed)
    v = np.vstack([g.vertices for g in p.grains])
    margin = CLEARANCE * circumscribed_diameter(p.grains) / 2  # documented wall gap
    assert margin > 0.05 * SIZE
    for axis in (0, 1):
        assert v[:, axis].min() >= CENTRE[axis] - BOX[axis] / 2 + margin
        assert v[:, axis].max() <= CENTRE[axis] + BOX[axis] / 2 - margin
    assert v[:, 2].min() == pytest.approx(FLOOR + CLEARANCE * SIZE, rel=1e-12)
    assert p.top == v[:, 2].max()
    assert p.column_height == pytest.approx(p.top - FLOOR, rel=1e-12)
    assert (p.box, p.centre, p.floor, p.seed) == (BOX, CENTRE, FLOOR, seed)


@pytest.mark.parametrize("seed", SEEDS)
def test_count_and_sizes_within_spread(seed):
    p = packing(seed)
    assert len(p.grains) == len(p.sizes) == 60
    assert np.all((p.sizes >= 0.9 * SIZE) & (p.sizes <= 1.1 * SIZE))
    assert np.ptp(p.sizes) > 0.1 * SIZE  # sizes really vary
    volumes = np.array([g.volume for g in p.grains])
    np.testing.assert_allclose(volumes, np.pi * p.sizes**3 / 6, rtol=1e-9)


def test_same_seed_same_packing_other_seed_other_packing():
    again = column_packing(
        60, SIZE, box=BOX, centre=CENTRE, floor=FLOOR, clearance=CLEARANCE, seed=0
    )
    first = packing(0)
    assert np.array_equal(again.sizes, first.sizes)
    for a, b in zip(again.grains, first.grains):
        assert np.array_equal(a.vertices, b.vertices)
        assert np.array_equal(a.faces, b.faces)
    other = packing(1)
    assert not np.array_equal(other.sizes, first.sizes)
    assert not np.array_equal(other.grains[0].vertices, first.grains[0].vertices)


def test_shape_params_reach_the_grains():
    p = column_packing(5, SIZE, shape_params={"n_vertices": 12, "elongation": 1.0})
    assert all(g.n_vertices == 12 for g in p.grains)


# -------------------------------------------------------------------------- rotations
def test_rotations_are_proper_and_uniform():
    n = 2000
    r = random_rotations(np.random.default_rng(7), n)
    np.testing.assert_allclose(
        r @ r.transpose(0, 2, 1), np.broadcast_to(np.eye(3), r.shape), atol=1e-12
    )
    np.testing.assert_allclose(np.linalg.det(r), 1.0, rtol=1e-12)
    # Haar measure: every entry has mean 0 and variance 1/3, so R e_z averages to 0 ...
    assert np.abs(r.mean(axis=0)).max() < 4 * np.sqrt(1 / 3 / n)
    # ... and its second moment is I/3 (uniform Euler angles would give 1/2 for zz)
    ez = r[:, :, 2]
    np.testing.assert_allclose(
        ez.T @ ez / n, np.eye(3) / 3, atol=4 * np.sqrt(4 / 45 / n)
    )


# ---------------------------------------------------------- pack height and fraction
def stacked_cubes(edge: float, nx: int, ny: int, nz: int, floor: float = 0.0):
    return [
        cube(edge, ((i + 0.5) * edge, (j + 0.5) * edge, floor + (k + 0.5) * edge))
        for i in range(nx)
        for j in range(ny)
        for k in range(nz)
    ]


def test_exactly_stacked_cubes_fill_the_box():
    a, floor = 1e-3, -2e-3
    grains = stacked_cubes(a, 2, 2, 3, floor)
    height = pack_height(grains, floor)
    assert height == pytest.approx(3 * a, rel=1e-12)
    assert packing_fraction(grains, (2 * a, 2 * a), height) == pytest.approx(
        1.0, rel=1e-12
    )
    assert packing_fraction(grains[:6], (2 * a, 2 * a), height) == pytest.approx(
        0.5, rel=1e-12
    )


def test_pack_height_of_a_layer_with_one_grain_on_top():
    a = 1e-3
    layer = stacked_cubes(a, 4, 4, 1)
    assert pack_height(layer) == pytest.approx(a, rel=1e-12)
    # centre of volume (16 a/2 + 3a/2) / 17: one stray grain moves the height by a/17
    # (the highest vertex would double it) and the fraction stays near the layer's 1
    grains = layer + [cube(a, (0.5 * a, 0.5 * a, 1.5 * a))]
    height = pack_height(grains)
    assert height == pytest.approx(19 * a / 17, rel=1e-12)
    assert packing_fraction(grains, (4 * a, 4 * a), height) == pytest.approx(289 / 304)


def test_pack_height_and_fraction_reject_empty_or_flat():
    with pytest.raises(ValueError, match="grains"):
        pack_height([])
    with pytest.raises(ValueError, match="height"):
        packing_fraction([cube(1.0)], (1.0, 1.0), 0.0)


# ------------------------------------------------------------------------- validation
@pytest.mark.parametrize(
    "kwargs, name",
    [
        ({"n": 0}, "n"),
        ({"n": 2.5}, "n"),
        ({"size": 0.0}, "size"),
        ({"size": float("nan")}, "size"),
        ({"size_spread": 1.0}, "size_spread"),
        ({"size_spread": -0.1}, "size_spread"),
        ({"box": (0.0, 8e-3)}, "box"),
        ({"box": (8e-3,)}, "box"),
        ({"clearance": -0.1}, "clearance"),
        ({"shape_params": {"seed": 3}}, "shape_params"),
        ({"n": 1, "box": (2e-3, 2e-3)}, "sizes"),
    ],
)
def test_bad_arguments_name_the_argument(kwargs, name):
    with pytest.raises(ValueError, match=f"^{name}[ :]"):
        column_packing(**({"n": 3} | kwargs))
