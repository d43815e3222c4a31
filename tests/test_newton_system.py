"""The Newton matrix assembled straight into grain blocks + one coupling matrix (docs/linear-solvers.md) is the
matrix a1 M + K_int + K_contact assembled the long way (sparse sums of the global matrices)."""

import numpy as np

from vemdem.contact.defaults import default_contact_laws
from vemdem.contact.walls import box_walls
from vemdem.geometry import cube, rotation_matrix
from vemdem.model.scene import Scene
from vemdem.solver.newmark import newton_blocks
from vemdem.vem.material import Material

MAT = Material(90e9, 0.16, 2200.0)


def touching_scene():
    """Three cubes stacked on a floor, the middle one turned about z (its edges cross the others':
    vertex-face and edge-edge pairs), each half an activation gap above the one below, with
    friction and normal damping active."""
    size = 1e-3
    law, friction = default_contact_laws(size, MAT.E, MAT.density, mu_s=0.6, mu_d=0.5)
    grains, z = [], 0.5 * law.activation_gap
    for k, angle in enumerate((0.0, 0.5, 0.1)):
        g = cube(size * (1.0 - 0.1 * k))
        g = g.translated(-g.centroid).rotated(rotation_matrix([0.0, 0.0, angle]))
        g = g.translated((0.0, 0.0, z - g.vertices[:, 2].min()))
        grains.append(g)
        z = g.vertices[:, 2].max() + 0.5 * law.activation_gap
    return Scene.build(grains, MAT, law, friction, planes=box_walls(4e-3, 4e-3))


def test_blocks_plus_coupling_equal_the_sparse_sum():
    scene = touching_scene()
    rng = np.random.default_rng(0)
    gbar = scene.contact.law.activation_gap
    # squeeze the stack a little and give every vertex a velocity, so that damping and friction act
    x = scene.bodies.reference * np.array([1.0, 1.0, 1.0 - 0.1 * gbar / 3e-3])
    v = rng.normal(scale=1e-3, size=x.shape)
    cand = scene.contact.search(x, 0.0)
    cr = scene.contact.evaluate(x, 0.0, cand, v=v, a4=2e3, tangent=True)
    assert (cr.ints[:, 1] < scene.n_grains).any() and cr.n_contacts > 6  # grain-grain pairs among them
    shift = 1.7e7
    k_int = scene.bodies.tangent_matrix(scene.bodies.evaluate(x, tangent=True).blocks)
    reference = shift * scene.mass_matrix() + k_int + cr.tangent
    blocks, coupling = newton_blocks(scene, scene.bodies.evaluate(x, tangent=True, mass_shift=shift), cr)
    assembled = scene.bodies.tangent_matrix(blocks) + coupling
    scale = abs(reference).max()
    assert abs(assembled - reference).max() <= 1e-13 * scale
    # the coupling holds only entries between different grains
    rows, cols = coupling.nonzero()
    grain_of_dof = np.repeat(scene.contact.topology.vertex_grain[: scene.n_vertices], 3)
    assert len(rows) > 0 and np.all(grain_of_dof[rows] != grain_of_dof[cols])


def test_the_coupling_triplets_become_scipys_csr_matrix():
    """csr_from_block_triplets with 1 x 1 blocks against SciPy's COO -> CSR: duplicates summed
    (many per entry, as pairs sharing nodes give), empty rows, explicit zeros, sorted columns."""
    import scipy.sparse as sp

    from vemdem.contact.forces import csr_from_block_triplets

    def csr_from_triplets(rows, cols, vals, n):
        return csr_from_block_triplets(np.asarray(rows, np.int64), np.asarray(cols, np.int64),
                                       np.asarray(vals, float).reshape(-1, 1, 1), n)  # fmt: skip

    rng = np.random.default_rng(3)
    for m, n in ((0, 5), (1, 1), (40, 6), (3000, 90), (20000, 4000)):
        rows, cols = rng.integers(0, n, m), rng.integers(0, n, m)
        vals = rng.standard_normal(m)
        vals[::7] = 0.0
        indptr, indices, data = csr_from_triplets(rows, cols, vals, n)
        ours = sp.csr_matrix((data, indices, indptr), shape=(n, n))
        theirs = sp.csr_matrix((vals, (rows, cols)), shape=(n, n))
        assert ours.has_sorted_indices
        assert ours.nnz == theirs.nnz  # one entry per distinct (row, column), zeros kept
        np.testing.assert_allclose(ours.toarray(), theirs.toarray(), rtol=0, atol=1e-12)
    # one row, all duplicates: the sum, in input order
    rows, cols, vals = np.zeros(4, np.int64), np.array([2, 0, 2, 2]), np.array([1.0, 5.0, 2.0, 3.0])
    indptr, indices, data = csr_from_triplets(rows, cols, vals, 1)
    assert list(indptr) == [0, 2] and list(indices) == [0, 2] and list(data) == [5.0, 6.0]


def test_node_block_triplets_give_the_scalar_triplets_matrix_to_the_bit():
    """csr_from_block_triplets (the contact coupling as 3 x 3 node blocks) against SciPy's BSR -> CSR
    and against the scalar triplets of the same blocks in the same order: the same pattern and,
    duplicates summed in input order either way, the same values to the bit."""
    import scipy.sparse as sp

    from vemdem.contact.forces import csr_from_block_triplets

    rng = np.random.default_rng(5)
    for m, n in ((0, 4), (1, 1), (50, 7), (4000, 300)):
        rows, cols = rng.integers(0, n, m), rng.integers(0, n, m)
        vals = rng.standard_normal((m, 3, 3))
        indptr, indices, data = csr_from_block_triplets(rows, cols, vals, n)
        ours = sp.csr_matrix((data, indices, indptr), shape=(3 * n, 3 * n))
        assert ours.has_sorted_indices
        dense = np.zeros((3 * n, 3 * n))
        for k in range(m):
            dense[3 * rows[k] : 3 * rows[k] + 3, 3 * cols[k] : 3 * cols[k] + 3] += vals[k]
        np.testing.assert_allclose(ours.toarray(), dense, rtol=0, atol=1e-12)
        a, b = np.meshgrid(np.arange(3), np.arange(3), indexing="ij")
        scalar = csr_from_block_triplets((3 * rows[:, None, None] + a).ravel(), (3 * cols[:, None, None] + b).ravel(),
                                         vals.reshape(-1, 1, 1), 3 * n)  # fmt: skip
        for ours_part, scalar_part in zip((indptr, indices, data), scalar):
            assert np.array_equal(ours_part, scalar_part)


def test_the_rotated_tangent_leaves_the_motion_and_the_newton_iterations(monkeypatch):
    """`rotated_tangent`: Newton's grain blocks from the reference tangent rotated (vem.element) change
    the matrix by O(strain) and the residual not at all, so the stack settles as with the exact
    tangent, in the same steps and about the same Newton iterations."""
    from vemdem.model.bodies import VemBodies
    from vemdem.solver.newmark import NewmarkParameters, advance, initial_state
    from vemdem.solver.state import StepControl

    scene = touching_scene()
    used = []
    evaluate = VemBodies.evaluate

    def spy(self, *args, **kwargs):
        ev = evaluate(self, *args, **kwargs)
        if ev.rotated is not None:
            used.append(int(ev.rotated.sum()))
        return ev

    monkeypatch.setattr(VemBodies, "evaluate", spy)
    runs = {}
    for strain in (0.0, 1e-4):
        used.clear()
        params = NewmarkParameters(0.3025, 0.6, rotated_tangent=strain)
        state, stats = advance(scene, initial_state(scene), 3e-3, StepControl(dt=1e-5, dt_max=1e-4), params)
        runs[strain] = (state, stats, sum(used))
    (x0, s0, r0), (x1, s1, r1) = ((s.x, st, r) for s, st, r in runs.values())
    assert r0 == 0 and r1 >= 3 * s1.newton_iterations  # all three grains rotated at every iterate
    assert s1.accepted == s0.accepted
    assert abs(s1.newton_iterations - s0.newton_iterations) <= 0.05 * s0.newton_iterations
    moved = np.abs(x0 - scene.bodies.reference).max()
    assert moved > 1e-7
    assert np.abs(x1 - x0).max() <= 1e-6 * moved


def test_the_summary_counts_the_rotated_and_the_exact_blocks(tmp_path):
    """summary.json names the approximation: Newton's grain blocks, and those of the exact tangent."""
    import json
    import tomllib

    from vemdem.scenarios import scene as scene_mod
    from vemdem.scenarios.registry import checked_config, example_text

    for strain, folder in ((1e-4, "rotated"), (0.0, "exact")):
        raw = tomllib.loads(example_text("drop"))
        raw["duration"] = 0.002
        raw["output"] = {"every": 1e-3, "vtk": False}
        raw["solver"]["rotated_tangent"] = strain
        cfg, _ = checked_config(raw)
        scene_mod.run(cfg, tmp_path / folder)
    rotated, exact = (json.loads((tmp_path / f / "summary.json").read_text()) for f in ("rotated", "exact"))
    for run in (rotated, exact):
        assert run["n_tangent_blocks"] == 2 * run["n_newton_iterations"] > 0  # two grains in each Newton matrix
    assert rotated["n_exact_tangent_blocks"] == 0  # a falling grain at E = 90 GPa strains far less than 1e-4
    assert exact["n_exact_tangent_blocks"] == exact["n_tangent_blocks"]
