"""A pack of the user's own grains: `[pack.grains] shape = "file"` with surface files and their
number shares, for the pack scenario and every laboratory test's pack stage."""

import math

import numpy as np
import pytest
from scipy.spatial import ConvexHull
from test_packing import near_pairs, separation

from vemdem.config import ConfigError
from vemdem.geometry import angular_grain, sand_grain
from vemdem.geometry.packing import SurfaceShapes, column_packing
from vemdem.io.surfaces import save_surface
from vemdem.scenarios.pack import grain_files_resolved, pack_config, place
from vemdem.scenarios.registry import checked_config, example_text

SIZE = 0.9e-3


@pytest.fixture(scope="module")
def surfaces(tmp_path_factory):
    """Two shapes written as STL files of their own (arbitrary) size, in a folder of their own."""
    folder = tmp_path_factory.mktemp("shapes")
    rounded, angular = sand_grain(size=2.0, n_vertices=20, seed=3), angular_grain(size=5.0, seed=4)
    save_surface(rounded, folder / "rounded.stl")
    save_surface(angular, folder / "angular.stl")
    return folder, rounded, angular


def test_each_grain_is_one_surface_at_its_drawn_size_in_the_shares_asked(surfaces):
    _, rounded, angular = surfaces
    make = SurfaceShapes([rounded, angular], [3.0, 1.0])
    picks = []
    for seed in range(400):
        size = SIZE * (1.0 + 0.1 * math.sin(seed))
        grain = make(size=size, seed=seed, n_vertices=99)  # a built-in shape's key: ignored
        # the volume of the scaled grain (scipy's hull, convex shapes) is the drawn size's sphere's
        assert ConvexHull(grain.vertices).volume == pytest.approx(math.pi * size**3 / 6.0, rel=1e-9)
        picks.append(len(grain.vertices) == len(rounded.vertices))
        assert np.allclose(grain.centroid, 0.0, atol=1e-12 * size)
    # a binomial share of 3/4 over 400 draws: its standard deviation is 0.022
    assert abs(np.mean(picks) - 0.75) < 4 * math.sqrt(0.75 * 0.25 / 400)
    assert make(size=SIZE, seed=7).vertices.tobytes() == make(size=SIZE, seed=7).vertices.tobytes()


def test_shares_must_match_the_surfaces():
    with pytest.raises(ValueError, match="one positive share per surface"):
        SurfaceShapes([sand_grain(size=1.0, seed=1)], [0.5, 0.5])
    with pytest.raises(ValueError, match="no surface"):
        SurfaceShapes([])


def pack_raw(files, **grains):
    return {"scenario": "pack", "n_grains": 24, "seed": 2, "box": {"width": 6e-3, "depth": 6e-3},
            "grains": {"size": SIZE, "shape": "file", "files": files, **grains}}  # fmt: skip


def test_a_pack_of_two_stl_shapes_places_them_apart_and_the_same_from_its_seed(surfaces):
    folder, rounded, angular = surfaces
    cfg, _ = checked_config(pack_raw(["rounded.stl", "angular.stl"], fractions=[1, 1]))
    packing = place(cfg, base_dir=folder)
    counts = {len(rounded.vertices): 0, len(angular.vertices): 0}
    for grain in packing.grains:
        counts[len(grain.vertices)] += 1
    assert all(n > 0 for n in counts.values()) and sum(counts.values()) == 24
    vertices = [g.vertices for g in packing.grains]
    assert min(separation(vertices[i], vertices[j]) for i, j in near_pairs(vertices, SIZE)) > 0
    again = place(cfg, base_dir=folder)
    assert all(a.vertices.tobytes() == b.vertices.tobytes() for a, b in zip(packing.grains, again.grains))
    # the same placement column_packing gives the maker directly
    direct = column_packing(24, SIZE, box=(6e-3, 6e-3), clearance=cfg["grains"]["clearance"], seed=2,
                            shape=SurfaceShapes([rounded, angular]))  # fmt: skip
    # (the files' vertices come in the order the STL writer left them: compare them as sets)
    for a, b in zip(direct.grains, packing.grains):
        assert np.allclose(np.sort(a.vertices, axis=0), np.sort(b.vertices, axis=0), rtol=0, atol=1e-12)


@pytest.mark.parametrize(("grains", "message"), [
    ({"files": []}, "pack.grains.files: required when pack.grains.shape = 'file'"),
    ({"shape": "sand", "files": ["a.stl"]}, "pack.grains.files: given with pack.grains.shape = 'sand'"),
    ({"files": ["a.stl", "b.stl"], "fractions": [1.0]}, "pack.grains.fractions: one per file"),
    ({"files": ["a.stl"], "fractions": [-1.0]}, "pack.grains.fractions: must be a list of positive numbers"),
])  # fmt: skip
def test_a_lab_tests_grain_files_are_checked_before_anything_runs(grains, message):
    raw = {"scenario": "oedometer", "stages": [{"stress": 25e3}],
           "pack": {"n_grains": 20, "grains": {"size": SIZE, "shape": "file", **grains}}}  # fmt: skip
    with pytest.raises(ConfigError, match=message.replace("(", r"\(").replace(")", r"\)")):
        checked_config(raw)


def test_a_missing_or_open_surface_is_one_error_naming_the_file(tmp_path, surfaces):
    cfg, _ = checked_config(pack_raw(["nowhere.stl"]))
    with pytest.raises(ConfigError, match="grains.files: .*nowhere.stl"):
        place(cfg, base_dir=tmp_path)
    folder, rounded, _ = surfaces
    open_grain = tmp_path / "open.stl"
    import meshio

    meshio.write(open_grain, meshio.Mesh(rounded.vertices, [("triangle", rounded.faces[:-2])]))
    cfg, _ = checked_config(pack_raw([str(open_grain)]))
    with pytest.raises(ConfigError, match="grains.files: .*open.stl"):
        place(cfg)


def test_a_lab_tests_pack_stage_names_its_files_absolutely(surfaces):
    folder, _, _ = surfaces
    raw = {"scenario": "triaxial", "consolidation": {"stress": 50e3}, "pack": {"n_grains": 40, "grains": {"size": SIZE, "shape": "file",
                                                                        "files": ["rounded.stl", "angular.stl"]}}}
    cfg, _ = checked_config(raw)
    resolved = grain_files_resolved(pack_config(cfg), folder)
    assert resolved["grains"]["files"] == [str(folder.resolve() / "rounded.stl"), str(folder.resolve() / "angular.stl")]
    assert place(resolved).grains  # settles from any folder: the files found where the config named them


def test_the_built_in_shapes_are_unchanged_by_the_file_keys():
    # the example packs keep their bits: the sand maker is reached as before
    cfg, _ = checked_config({"scenario": "pack", "n_grains": 6, "seed": 1, "grains": {"size": SIZE}})
    direct = column_packing(6, SIZE, box=(8e-3, 8e-3), clearance=cfg["grains"]["clearance"], seed=1,
                            shape_params={"n_vertices": 30, "elongation": 0.8, "flatness": 0.8, "roughness": 0.15})
    assert all(a.vertices.tobytes() == b.vertices.tobytes() for a, b in zip(place(cfg).grains, direct.grains))
    assert "files" not in example_text("triaxial")
