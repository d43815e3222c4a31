"""The narrow phase's feature list (contact/feature_list.py) finds the search's records, bit for
bit, in the same order: along moving, deforming, jumping and approaching grains, against a mesh
wall, and through whole explicit runs (the reference is pairs.find_contacts, the full search)."""

from pathlib import Path

import ipctk
import numpy as np
import pytest

from vemdem.config.build import scene_from, solver_options_from
from vemdem.contact.broad import candidate_pairs
from vemdem.contact.feature_list import FeatureList, _line_gap, _plane_gap, _segments_gap
from vemdem.contact.narrow import EDGE_EDGE, VERTEX_FACE
from vemdem.contact.pairs import find_contacts
from vemdem.contact.topology import build_topology
from vemdem.geometry import cube, rotation_matrix
from vemdem.io.state import load_state
from vemdem.scenarios.pile_collapse import standing_walls
from vemdem.scenarios.registry import checked_config
from vemdem.solver.api import make_integrator
from vemdem.solver.state import RunStats

PACK = Path(__file__).parent / "data" / "pack30_mu015.npz"
GBAR = 1.5e-5  # the law's activation gap for these 1.45 mm grains, about


def _same(a, b):
    return np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])


@pytest.fixture(scope="module")
def pack():
    s = load_state(PACK)
    vptr = np.cumsum([0] + [g.n_vertices for g in s.grains])
    topo = build_topology(s.x, [g.faces for g in s.grains], vptr)
    return s.x.copy(), topo, vptr


def _moved(x0, vptr, rng, scale):
    """x0 with every grain turned and shifted at random (rigid), its vertices jittered (a deformation)."""
    x = x0.copy()
    for g in range(len(vptr) - 1):
        sl = slice(vptr[g], vptr[g + 1])
        c = x0[sl].mean(axis=0)
        R = rotation_matrix(rng.normal(scale=scale / 7e-4, size=3))  # turns a vertex 7e-4 m out by about scale
        x[sl] = (x0[sl] - c) @ R.T + c + rng.normal(scale=scale, size=3)
    return x + rng.normal(scale=0.05 * scale, size=x.shape)


def test_the_list_finds_the_searchs_records_along_a_trajectory(pack):
    """300 calls, each grain moving 0.1-0.3 gbar per call (turn, shift, jitter): the same records every
    time, while most grain pairs' lists are kept and some are rebuilt."""
    x0, topo, vptr = pack
    rng = np.random.default_rng(5)
    fl = FeatureList(2 * GBAR)
    x = x0.copy()
    calls = kept_pairs = 0
    for k in range(300):
        if k % 10 == 0:
            candidates = candidate_pairs(x, vptr, 5 * GBAR)
        x = _moved(x, vptr, rng, GBAR * rng.uniform(0.05, 0.15))
        expected = find_contacts(x, candidates, topo, GBAR)
        assert len(expected[0]) > 20  # a pack in contact, not a vacuous comparison
        assert _same(fl.find(x, candidates, topo, GBAR), expected), f"call {k}"
        calls += len(candidates)
        kept_pairs = calls - fl.builds
    assert fl.builds > 2 * len(candidates)  # lists were rebuilt as the grains travelled
    assert kept_pairs > 0.5 * calls  # and most were kept


def test_a_pack_falling_as_one_keeps_its_lists(pack):
    """Translated as a whole by 50 gbar in 100 calls, each grain jittered by 1e-3 gbar: no list is
    rebuilt after the first (distances do not change under a common shift), the records stay the
    search's."""
    x0, topo, vptr = pack
    rng = np.random.default_rng(2)
    fl = FeatureList(2 * GBAR)
    candidates = candidate_pairs(x0, vptr, 5 * GBAR)
    fl.find(x0, candidates, topo, GBAR)
    first = fl.builds
    for k in range(1, 101):
        x = x0 + [0.0, 0.1 * k * GBAR, -0.5 * k * GBAR] + rng.normal(scale=1e-3 * GBAR, size=x0.shape)
        assert _same(fl.find(x, candidates, topo, GBAR), find_contacts(x, candidates, topo, GBAR)), f"call {k}"
    assert first == len(candidates) and fl.builds == first


def test_a_jump_rebuilds_every_list(pack):
    x0, topo, vptr = pack
    fl = FeatureList(2 * GBAR)
    candidates = candidate_pairs(x0, vptr, 5 * GBAR)
    fl.find(x0, candidates, topo, GBAR)
    x = _moved(x0, vptr, np.random.default_rng(1), 3 * GBAR)  # far beyond the skin in one call
    before = fl.builds
    assert _same(fl.find(x, candidates, topo, GBAR), find_contacts(x, candidates, topo, GBAR))
    assert fl.builds - before == len(candidates)


def test_approaching_cubes_meet_in_several_kinds():
    """Two cubes closing face to face from 4 gbar to 0.05 gbar, the upper one turned about the
    vertical and shifted, so that vertex-face (both ways) and edge-edge records appear: the same
    records at every step of the approach."""
    gbar = 0.05
    a = cube(1.0)
    R = rotation_matrix([0.0, 0.0, 0.1])
    b_ref = a.vertices @ R.T
    vptr = np.array([0, 8, 16])
    X = np.vstack([a.vertices, b_ref])
    topo = build_topology(X, [a.faces, a.faces], vptr)
    fl = FeatureList(0.5 * gbar)
    kinds = set()
    base = 0.5 - b_ref[:, 2].min()
    for gap in np.linspace(4 * gbar, 0.05 * gbar, 60):
        x = np.vstack([a.vertices, b_ref + [0.3, 0.2, base + gap]])
        candidates = candidate_pairs(x, vptr, 6 * gbar)
        expected = find_contacts(x, candidates, topo, gbar)
        assert _same(fl.find(x, candidates, topo, gbar), expected)
        kinds |= set(expected[0][:, 0].tolist())
    assert kinds >= {VERTEX_FACE, EDGE_EDGE}


def test_a_mesh_wall_is_a_body_of_the_list():
    """A cube sliding and sinking onto a triangulated floor (a mesh wall: one more body of the
    topology, paired with the grain)."""
    gbar = 0.05
    c = cube(1.0)
    floor = np.array([[-3, -3, 0], [3, -3, 0], [3, 3, 0], [-3, 3, 0], [0, 0, 0]], float)
    floor_faces = np.array([[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]])
    vptr = np.array([0, 8, 13])
    topo = build_topology(np.vstack([c.vertices, floor]), [c.faces, floor_faces], vptr)
    fl = FeatureList(gbar)
    pairs = np.array([[0, 1]])
    R = rotation_matrix(0.02 * np.array([0.2, 1.0, 0.1]))
    for k in range(80):
        lift = 0.5 + 2 * gbar - k * 0.024 * gbar
        x = np.vstack([c.vertices @ R.T + [0.01 * k, 0.0, lift], floor])
        assert _same(fl.find(x, pairs, topo, gbar), find_contacts(x, pairs, topo, gbar)), f"call {k}"


def test_new_positions_of_another_size_start_a_new_list(pack):
    x0, topo, vptr = pack
    fl = FeatureList(2 * GBAR)
    fl.find(x0, candidate_pairs(x0, vptr, 5 * GBAR), topo, GBAR)
    a = cube(1.0)
    small = build_topology(np.vstack([a.vertices, a.vertices + [0, 0, 1.02]]), [a.faces, a.faces], np.array([0, 8, 16]))
    x = np.vstack([a.vertices, a.vertices + [0, 0, 1.02]])
    assert _same(fl.find(x, np.array([[0, 1]]), small, 0.05), find_contacts(x, np.array([[0, 1]]), small, 0.05))


def test_the_builds_distances_are_ipctks():
    """The build's filters against ipctk: the segment distance equals its edge-edge distance (random
    and crossing pairs; near parallel a lower bound within 1e-5), the plane and line distances are its point-plane and
    point-line distances, at most the point-triangle and point-edge ones (lower bounds: no feature
    pair within reach is left out)."""
    rng = np.random.default_rng(3)
    edges = np.array([[0, 1], [2, 3]])
    faces = np.array([[0, 1, 2]])
    for k in range(400):
        x = rng.normal(size=(4, 3))
        if k % 4 == 1:  # near parallel
            x[3] = x[2] + (x[1] - x[0]) * rng.uniform(0.5, 2) + rng.normal(scale=1e-7, size=3)
        if k % 4 == 2:  # crossing, closest points inside both
            x[2:] = 0.5 * (x[0] + x[1]) + np.array([[-1.0], [1.0]]) * rng.normal(size=3) + [0, 0, 1e-3]
        expected = np.sqrt(ipctk.edge_edge_distance(x[0], x[1], x[2], x[3]))
        gap = _segments_gap(x, 0, 1, edges)
        if k % 4 == 1:  # a lower bound there, within 2 L sin of the angle (about 1e-6 here)
            assert expected - 1e-5 < gap <= expected * (1 + 1e-12)
        else:
            assert gap == pytest.approx(expected, rel=1e-9, abs=1e-12)
        p = np.vstack([x[:3], x[3:]])
        plane = _plane_gap(p, 3, 0, faces)
        assert plane == pytest.approx(np.sqrt(ipctk.point_plane_distance(p[3], p[0], p[1], p[2])), rel=1e-9)
        assert plane <= np.sqrt(ipctk.point_triangle_distance(p[3], p[0], p[1], p[2])) * (1 + 1e-12)
        line = _line_gap(x, 3, 0, edges)
        assert line == pytest.approx(np.sqrt(ipctk.point_line_distance(x[3], x[0], x[1])), rel=1e-9)
        assert line <= np.sqrt(ipctk.point_edge_distance(x[3], x[0], x[1])) * (1 + 1e-12)


def test_a_skin_must_be_positive():
    with pytest.raises(ValueError, match="skin must be > 0"):
        FeatureList(0.0)


@pytest.mark.parametrize("grains, integrator",
                         [("rigid", "explicit"), ("flexible", "explicit"), ("flexible", "implicit")])
def test_runs_are_the_same_with_and_without_the_list(grains, integrator):
    """The 30-grain pack's walls opened, 10 ms of steps (rigid grains at the real density, flexible
    ones explicit with mass scaling 1e6, implicit at the real density): the same state to the bit
    with the list as with the full search."""
    scaling = 1e6 if (grains, integrator) == ("flexible", "explicit") else 1.0
    cfg, _ = checked_config({"scenario": "pile_collapse", "initial_state": str(PACK), "model": {"grains": grains},
                             "solver": {"integrator": integrator, "mass_scaling": scaling}})  # fmt: skip
    s = load_state(PACK)
    ends = []
    for keep in (True, False):
        scene = scene_from(s.grains, cfg, standing_walls(s.meta, "corner"))
        runner = make_integrator(solver_options_from(cfg), scene)
        assert scene.contact.feature_list is not None  # every integrator keeps one
        if not keep:
            scene.contact.feature_list = None
        state = runner.initial_state(s.x, s.v)
        state, stats = runner.advance(state, 0.01, None, RunStats())
        ends.append((state, stats.accepted))
    (a, steps), (b, _) = ends
    assert steps > 50 and np.abs(a.x - s.x).max() > GBAR  # the grains moved
    assert np.array_equal(a.x, b.x) and np.array_equal(a.v, b.v)
