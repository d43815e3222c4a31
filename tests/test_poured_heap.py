"""The poured heap (docs/repose.md): a settled pack flows out from under its rising box onto a disc of
finite radius. With 16 grains the heap is too low for a flank fit, so friction is read from the
heap's shape: grains that roll further off and a lower, wider heap when friction falls."""

import numpy as np
import pytest

from vemdem.config import ConfigError
from vemdem.contact.walls import box_sides, disc_wall
from vemdem.io.state import load_state
from vemdem.scenarios.registry import checked_config

BOX = 5.5e-3
PACK = {"n_grains": 16, "seed": 3, "grains": {"vertices": 16}, "box": {"width": BOX, "depth": BOX}}


def test_walls_face_the_grains():
    disc = disc_wall(2e-3, z=0.5)
    for face in disc.faces:
        a, b, c = disc.vertices[face]
        assert np.cross(b - a, c - a)[2] > 0
    for side in box_sides(2.0, 4.0, 0.0, 1.0):
        v = side.vertices
        inward = -v.mean(axis=0)[:2]  # towards the box axis (centre at the origin)
        for face in side.faces:
            a, b, c = v[face]
            assert np.cross(b - a, c - a)[:2] @ inward > 0


@pytest.fixture(scope="module")
def pack(tmp_path_factory):
    out = tmp_path_factory.mktemp("pack")
    cfg, module = checked_config({"scenario": "pack", **PACK, "output": {"vtk": False}})
    module.run(cfg, out)
    return out / "state.npz"


def pour(out, pack, mu_s, mu_d):
    cfg, module = checked_config({"scenario": "poured_heap", "initial_state": str(pack), "source": {"lift_speed": 0.05},
                                  "disc": {"radius": 5e-3}, "contact": {"mu_s": mu_s, "mu_d": mu_d},
                                  "output": {"vtk": False, "every": 1e-2}})  # fmt: skip
    return module.run(cfg, out)


def test_a_poured_heap_stands_higher_with_more_friction(tmp_path, pack):
    heaps = {}
    for name, mu in (("rough", (0.9, 0.8)), ("smooth", (0.2, 0.1))):
        summary = pour(tmp_path / name, pack, *mu)
        assert summary["settled"] and summary["heap_grains"] + summary["lost_grains"] == 16
        assert (tmp_path / name / "heap.png").stat().st_size > 10_000
        assert (tmp_path / name / "heap_3d.png").stat().st_size > 10_000
        final = load_state(tmp_path / name / "state.npz")
        ptr = np.cumsum([0] + [g.n_vertices for g in final.grains])
        c = np.array([final.x[a:b].mean(axis=0) for a, b in zip(ptr[:-1], ptr[1:])])
        on = c[:, 2] > 0
        assert on.sum() == summary["heap_grains"]
        heaps[name] = (c[on, 2].mean(), summary["angle_fixed_base_deg"], summary["lost_grains"])
    assert heaps["smooth"][0] < heaps["rough"][0]  # the mean grain sits lower
    assert heaps["smooth"][1] <= heaps["rough"][1]  # and the heap's top too


def test_corner_walls_mirror_and_the_disc_is_centred_on_the_corner():
    from vemdem.scenarios.poured_heap import hopper_walls

    meta = {"box": [2e-3, 3e-3], "centre": [1.0, 2.0], "floor": 0.5}
    cfg, _ = checked_config({"scenario": "poured_heap", "source": {"open": "corner"}, "disc": {"radius": 4e-3}})
    planes, meshes, lift_time = hopper_walls(meta, 0.5 + 3e-3, cfg)
    catch, back, side = planes
    assert catch.point[2] == pytest.approx(0.5 - cfg["disc"]["catch_depth"]) and not catch.frictionless
    # the standing sides: the planes x = 0.999 (normal +x) and y = 1.9985 (normal +y), frictionless
    assert back.frictionless and side.frictionless
    assert back.point[0] == pytest.approx(0.999) and back.normal @ [1, 0, 0] == pytest.approx(1.0)
    assert side.point[1] == pytest.approx(1.9985) and side.normal @ [0, 1, 0] == pytest.approx(1.0)
    disc, *rising = meshes
    assert [m.name for m in rising] == ["side +x", "side +y"]
    rim = disc.vertices[:, :2] - [0.999, 1.9985]
    assert np.allclose(np.linalg.norm(rim, axis=1).max(), 4e-3)  # centred on the corner
    assert lift_time == pytest.approx(1.5 * 3e-3 / cfg["source"]["lift_speed"])
    # the disc must reach beyond the box's far corner, measured from the corner
    small, _ = checked_config({"scenario": "poured_heap", "source": {"open": "corner"}, "disc": {"radius": 3.5e-3}})
    with pytest.raises(ConfigError, match="from the corner"):
        hopper_walls(meta, 0.5 + 3e-3, small)


def test_a_corner_heap_stays_in_its_quadrant(tmp_path, pack):
    cfg, module = checked_config({"scenario": "poured_heap", "initial_state": str(pack),
                                  "source": {"lift_speed": 0.05, "open": "corner"}, "disc": {"radius": 9e-3},
                                  "model": {"grains": "rigid"}, "output": {"vtk": False, "every": 1e-2}})  # fmt: skip
    summary = module.run(cfg, tmp_path)
    assert summary["source_open"] == "corner" and summary["heap_grains"] + summary["lost_grains"] == 16
    final = load_state(tmp_path / "state.npz")
    corner = np.array(final.meta["centre"]) - 0.5 * np.array(final.meta["box"])
    # no vertex behind the mirror planes, and the heap spread away from the corner
    assert np.all(final.x[:, :2] > corner)
    start = load_state(pack)
    assert np.max(final.x[:, 0]) > np.max(start.x[:, 0]) + 1e-3
    assert (tmp_path / "heap.png").stat().st_size > 10_000
