"""Shape descriptors against closed forms, and the angular grain option (docs/results.md, grain shapes)."""

import numpy as np
import pytest

from vemdem.geometry import angular_grain, cube, hull_polyhedron, sand_grain
from vemdem.geometry.descriptors import shape_descriptors
from vemdem.geometry.packing import column_packing


def test_descriptors_of_a_cube_and_a_tetrahedron():
    d = shape_descriptors(cube(2.0))
    assert (d["n_vertices"], d["faces"]) == (8, 6)
    assert d["sphericity"] == pytest.approx((np.pi / 6) ** (1 / 3), rel=1e-12)  # pi^(1/3) 6^(2/3) / 6
    assert d["edge_angle_deg"] == pytest.approx(90.0) and d["convexity"] == pytest.approx(1.0)
    assert d["elongation"] == pytest.approx(1.0) and d["flatness"] == pytest.approx(1.0)
    regular = hull_polyhedron(np.array([[1.0, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]]))
    t = shape_descriptors(regular)
    assert t["faces"] == 4
    assert t["sphericity"] == pytest.approx(0.6711, abs=1e-4)  # Wadell's value for the regular tetrahedron
    assert t["edge_angle_deg"] == pytest.approx(180.0 - np.degrees(np.arccos(1 / 3)))  # 109.47


def test_a_box_has_zingg_ratios_of_its_sides():
    corners = np.array([[x, y, z] for x in (0, 4.0) for y in (0, 2.0) for z in (0, 1.0)])
    d = shape_descriptors(hull_polyhedron(corners))
    assert d["elongation"] == pytest.approx(0.5) and d["flatness"] == pytest.approx(0.5)
    area, volume = 2 * (8 + 4 + 2), 8.0
    assert d["sphericity"] == pytest.approx(np.pi ** (1 / 3) * (6 * volume) ** (2 / 3) / area)


def test_a_fine_sphere_is_nearly_spherical_with_blunt_edges():
    rng = np.random.default_rng(0)
    points = rng.normal(size=(2000, 3))
    d = shape_descriptors(hull_polyhedron(points / np.linalg.norm(points, axis=1, keepdims=True)))
    assert d["sphericity"] > 0.99 and d["edge_angle_deg"] < 6.0


def test_angular_grains_have_flat_faces_and_sharp_edges():
    sand = [shape_descriptors(sand_grain(1e-3, 16, seed=s)) for s in range(10)]
    angular = [shape_descriptors(angular_grain(1e-3, 16, seed=s)) for s in range(10)]
    for s, a in zip(sand, angular):
        assert a["faces"] < 0.6 * s["faces"]
        assert a["edge_angle_deg"] > 1.5 * s["edge_angle_deg"]
        assert a["sphericity"] < s["sphericity"]
    assert np.mean([a["n_vertices"] for a in angular]) == pytest.approx(16, abs=2)
    g = angular_grain(1e-3, 16, seed=4)
    assert g.volume == pytest.approx(np.pi * 1e-9 / 6, rel=1e-12)
    assert np.array_equal(angular_grain(1e-3, 16, seed=4).vertices, g.vertices)  # same seed, same grain


def test_packings_take_the_shape():
    packing = column_packing(6, size=1e-3, box=(4e-3, 4e-3), seed=2, shape="angular",
                             shape_params={"n_vertices": 12})  # fmt: skip
    assert all(g.name.startswith("angular grain") for g in packing.grains)
    with pytest.raises(ValueError, match="shape must be one of"):
        column_packing(2, size=1e-3, box=(4e-3, 4e-3), shape="cubic")
