"""The spring-back split (analysis.spring_back) against motions whose parts are known in closed form.

Four unit cubes: one at the origin and one beyond each of its +x, +y and +z faces, a gap of half
the activation gap between them, so that the branch vectors span 3-D.
"""

import warnings
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from vemdem.analysis.spring_back import branch_strain_split, rigid_fits
from vemdem.config.build import MassScalingWarning
from vemdem.contact.defaults import default_contact_laws
from vemdem.contact.forces import pair_points
from vemdem.contact.pairs import GAP, GRAIN_A, GRAIN_B
from vemdem.contact.walls import PlaneWall
from vemdem.geometry import cube
from vemdem.model.scene import Scene
from vemdem.scenarios.lid_compression import warn_if_grains_spring_back
from vemdem.vem.material import Material

EDGE = 1e-3


@pytest.fixture(scope="module")
def scene():
    law, friction = default_contact_laws(EDGE, 1e9, 2000.0)
    step = EDGE + 0.5 * law.activation_gap
    grains = [cube(EDGE, (0.0, 0.0, 0.0))] + [cube(EDGE, step * np.eye(3)[k]) for k in range(3)]
    floor = PlaneWall((0.0, 0.0, -0.5 * EDGE - 0.5 * law.activation_gap), (0.0, 0.0, 1.0))
    return Scene.build(grains, Material(E=1e9, nu=0.3, density=2000.0), law, friction, planes=[floor])


def records(scene, x, walls=False):
    """Every record at x, or the grain-to-grain ones (with walls=False) as contiguous arrays."""
    _, ints, floats = scene.contact.pairs(x, 0.0, scene.contact.search(x, 0.0))
    if walls:
        return ints, floats
    mine = (ints[:, GRAIN_A] < 4) & (ints[:, GRAIN_B] < 4)
    return np.ascontiguousarray(ints[mine]), np.ascontiguousarray(floats[mine])


def split(scene, x1):
    x0 = scene.bodies.reference.copy()
    return branch_strain_split(scene.bodies.reference, scene.bodies.vertex_ptr, x0, x1,
                               *scene.contact.grain_contacts(x0, 0.0))  # fmt: skip


def per_grain(scene, values):
    return np.repeat(values, np.diff(scene.bodies.vertex_ptr), axis=0)


def test_the_scene_has_grain_and_wall_records(scene):
    ints, _ = records(scene, scene.bodies.reference, walls=True)
    grains = (ints[:, GRAIN_A] < 4) & (ints[:, GRAIN_B] < 4)
    assert grains.sum() >= 3 and (~grains).sum() >= 1  # the floor's records are left out by the split
    a, b, gap_vectors = scene.contact.grain_contacts(scene.bodies.reference, 0.0)
    np.testing.assert_array_equal(a, ints[grains, GRAIN_A])
    np.testing.assert_array_equal(b, ints[grains, GRAIN_B])
    # every gap vector is as long as its record's gap
    _, floats = records(scene, scene.bodies.reference)
    np.testing.assert_allclose(np.linalg.norm(gap_vectors(scene.bodies.reference), axis=1), floats[:, GAP], rtol=1e-12)


def test_rigid_fits_recover_rigid_motions(scene):
    rng = np.random.default_rng(1)
    X, ptr = scene.bodies.reference, scene.bodies.vertex_ptr
    R = Rotation.random(4, random_state=rng).as_matrix()
    shift = rng.normal(size=(4, 3)) * EDGE
    centre = np.add.reduceat(X, ptr[:-1]) / np.diff(ptr)[:, None]
    x = np.einsum("vij,vj->vi", per_grain(scene, R), X - per_grain(scene, centre)) + per_grain(scene, centre + shift)
    t, R_fit, u = rigid_fits(X, x, ptr)
    np.testing.assert_allclose(t, centre + shift, atol=1e-15)
    np.testing.assert_allclose(R_fit, R, atol=1e-12)
    assert np.abs(u).max() < 1e-15


def test_the_parts_are_the_branch_vectors_exact_split(scene):
    """Random rigid motions and deformations: the rotation part, which the split takes as what the
    other three leave of the total, equals the one computed here from the fitted rotations at the
    records' material points, so the four are the total's exact split."""
    rng = np.random.default_rng(2)
    X, ptr = scene.bodies.reference, scene.bodies.vertex_ptr
    x0 = X.copy()
    R = Rotation.from_rotvec(rng.normal(scale=0.02, size=(4, 3))).as_matrix()
    x1 = np.einsum("vij,vj->vi", per_grain(scene, R), X) + per_grain(scene, rng.normal(size=(4, 3)) * 1e-5)
    x1 += rng.normal(size=x1.shape) * 1e-6
    parts = branch_strain_split(X, ptr, x0, x1, *scene.contact.grain_contacts(x0, 0.0))
    ints, floats = records(scene, x0)
    a, b = ints[:, GRAIN_A], ints[:, GRAIN_B]
    rotated = []
    for x in (x0, x1):
        t, R_fit, _ = rigid_fits(X, x, ptr)
        centre = np.add.reduceat(X, ptr[:-1]) / np.diff(ptr)[:, None]
        material = pair_points(np.ascontiguousarray(X), ints, floats)  # the records' points, in the reference
        arm_a = np.einsum("cij,cj->ci", R_fit[a], material[:, 0] - centre[a])
        arm_b = np.einsum("cij,cj->ci", R_fit[b], material[:, 1] - centre[b])
        rotated.append(arm_a - arm_b)
    t0 = rigid_fits(X, x0, ptr)[0]
    l0 = t0[b] - t0[a]
    expected_rotation = ((rotated[1] - rotated[0]).T @ l0) @ np.linalg.inv(l0.T @ l0)
    np.testing.assert_allclose(parts["rotation"], expected_rotation, atol=1e-12 * np.abs(parts["total"]).max())


def test_a_uniform_affine_map_gives_its_strain(scene):
    """Every point mapped by I + H: every branch vector too, so the best fit is H (the displacement
    gradient, E_ij = d(dl_i) / d(l_j)) exactly."""
    H = np.array([[2.0, 0.5, 0.0], [0.1, -1.0, 0.3], [0.0, -0.4, -3.0]]) * 1e-3  # not symmetric: no transposes hide
    x1 = scene.bodies.reference @ (np.eye(3) + H).T
    np.testing.assert_allclose(split(scene, x1)["total"], H, atol=1e-15)


def test_grains_swelling_in_place_move_nothing_apart(scene):
    """Each cube scaled by 1 + s about its centre: the centres stay, so the total is zero; the
    deformation at each contact point is s (p - t) on each side, s (g0 + l0) per record, and the
    contact layer closes by as much (g = p_A - p_B grows by the same)."""
    s = 2e-3
    X, ptr = scene.bodies.reference, scene.bodies.vertex_ptr
    centre = per_grain(scene, np.add.reduceat(X, ptr[:-1]) / np.diff(ptr)[:, None])
    parts = split(scene, centre + (1 + s) * (X - centre))
    assert np.abs(parts["total"]).max() < 1e-15
    ints, floats = records(scene, X)
    t = np.add.reduceat(X, ptr[:-1]) / np.diff(ptr)[:, None]
    l0 = t[ints[:, GRAIN_B]] - t[ints[:, GRAIN_A]]
    p = pair_points(np.ascontiguousarray(X), ints, floats)
    expected = s * ((p[:, 0] - p[:, 1] + l0).T @ l0) @ np.linalg.inv(l0.T @ l0)
    np.testing.assert_allclose(parts["deformation"], expected, rtol=1e-9, atol=1e-15)
    assert parts["deformation"][2, 2] == pytest.approx(s, rel=0.02)  # the gaps are 0.5 % of the branches
    np.testing.assert_allclose(parts["contact_gap"] + parts["tangential"], -parts["deformation"], atol=1e-15)
    assert np.abs(parts["rotation"]).max() < 1e-12


def test_a_grain_lifted_straight_up_opens_only_the_contacts(scene):
    """The top cube moved up by delta: the branch vectors to it grow by delta along z, and all of
    that is the contacts' opening (along their normals, and across them where a record is
    diagonal: the side cubes' edges), nothing deforms or turns."""
    delta = 1e-6
    X, ptr = scene.bodies.reference, scene.bodies.vertex_ptr
    x1 = X.copy()
    x1[ptr[3] : ptr[4], 2] += delta
    parts = split(scene, x1)
    ints, _ = records(scene, X)
    t = np.add.reduceat(X, ptr[:-1]) / np.diff(ptr)[:, None]
    l0 = t[ints[:, GRAIN_B]] - t[ints[:, GRAIN_A]]
    dl = np.outer((ints[:, GRAIN_B] == 3).astype(float) - (ints[:, GRAIN_A] == 3), [0.0, 0.0, delta])
    expected = (dl.T @ l0) @ np.linalg.inv(l0.T @ l0)
    assert expected[2, 2] > 0
    np.testing.assert_allclose(parts["total"], expected, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(parts["contact_gap"] + parts["tangential"], expected, rtol=1e-9, atol=1e-15)
    assert parts["contact_gap"][2, 2] > 0.5 * expected[2, 2]  # the face-to-face records open along z
    for name in ("deformation", "rotation"):
        assert np.abs(parts[name]).max() < 1e-12 * delta / EDGE


def test_too_few_records_are_refused(scene):
    X = scene.bodies.reference
    a, b, gap_vectors = scene.contact.grain_contacts(X, 0.0)
    keep = np.flatnonzero((a == 0) & (b == 3))[:2]
    with pytest.raises(ValueError, match="do not span"):
        branch_strain_split(X, scene.bodies.vertex_ptr, X, X, a[keep], b[keep], lambda f: gap_vectors(f)[keep])


@pytest.mark.parametrize("scaling, back, warns", [
    (1e6, {"branch_strain": 0.04, "deformation": 0.012, "contact_gap": 0.012}, True),
    (1e6, {"branch_strain": 0.04, "deformation": 0.002, "contact_gap": 0.02}, False),  # 5 %: below GRAINS_SPRING_BACK
    (1.0, {"branch_strain": 0.04, "deformation": 0.012, "contact_gap": 0.012}, False),  # the real density: nothing scaled
    (1e6, {"branch_strain": -0.01, "deformation": 0.012, "contact_gap": 0.0}, False),  # the pack gave back nothing
    (1e6, {"error": "no turn"}, False),
])  # fmt: skip
def test_a_mass_scaled_lid_says_when_its_grains_gave_back_much(scaling, back, warns):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        warn_if_grains_spring_back(SimpleNamespace(mass_scaling=scaling), back)
    said = [w for w in caught if issubclass(w.category, MassScalingWarning)]
    assert len(said) == int(warns)
    if warns:
        assert "30%" in str(said[0].message) and "spring_back" in str(said[0].message)


def test_a_lid_folder_without_its_turn_says_so(tmp_path, scene):
    from vemdem.scenarios.lid_compression import spring_back

    back = spring_back(scene, tmp_path, SimpleNamespace(t=0.0, x=scene.bodies.reference))
    assert set(back) == {"error"} and "turn_state.npz" in back["error"]
