"""Implicit Newmark stepping (issue 4, first part): exact free fall, resting on a floor, no tunnelling."""

import numpy as np
import pytest

from vemdem.contact.defaults import default_contact_laws
from vemdem.contact.friction import FrictionLaw
from vemdem.contact.walls import PlaneWall
from vemdem.geometry import cube, sand_grain
from vemdem.scene import Scene
from vemdem.solver.newmark import NewmarkParameters, StepControl, advance, initial_state
from vemdem.vem.material import Material

MAT = Material(90e9, 0.16, 2200.0)


def drop_scene(height, grain=None):
    grain = grain or cube(1e-3)
    grain = grain.translated((0, 0, height - grain.vertices[:, 2].min()))
    law, _ = default_contact_laws(1e-3, MAT.E, MAT.density)
    floor = PlaneWall(np.zeros(3), np.array([0.0, 0, 1]), name="floor")
    return Scene.build([grain], MAT, law, FrictionLaw(), planes=[floor])


@pytest.mark.parametrize("beta,gamma", [(0.25, 0.5), (0.3, 0.5), (0.3, 0.6)])
def test_free_fall_is_exact(beta, gamma):
    """Constant acceleration: every Newmark member integrates it exactly."""
    scene = drop_scene(5e-3, sand_grain(seed=3, size=1e-3))
    v0 = np.array([0.01, -0.02, 0.05])
    state = initial_state(scene, v0=np.tile(v0, (scene.n_vertices, 1)))
    np.testing.assert_allclose(state.a, np.tile([0, 0, -9.81], (scene.n_vertices, 1)), atol=1e-9)
    c0 = scene.grain_centroids(state.x)[0]
    state, stats = advance(scene, state, 0.01, StepControl(dt=1e-3, dt_max=1e-3), NewmarkParameters(beta, gamma))
    t = state.t
    expected = c0 + v0 * t + 0.5 * np.array([0, 0, -9.81]) * t**2
    np.testing.assert_allclose(scene.grain_centroids(state.x)[0], expected, rtol=0, atol=1e-12)
    np.testing.assert_allclose(state.v, np.tile(v0 + [0, 0, -9.81 * t], (scene.n_vertices, 1)), atol=1e-10)
    assert stats.rejected == 0


def test_grain_dropped_on_floor_never_penetrates_and_bounces_back():
    scene = drop_scene(0.1e-3)
    state = initial_state(scene)
    gbar = scene.contact.law.activation_gap
    lowest = []
    advance(scene, state, 0.006, StepControl(dt=1e-5, dt_max=2e-5), NewmarkParameters(0.25, 0.5),
            on_step=lambda s, info, h: lowest.append((s.t, s.x[:, 2].min(), s.v[:, 2].mean())))  # fmt: skip
    t, z, vz = np.array(lowest).T
    assert z.min() > 0 and z.min() < gbar  # it reached the contact layer, never the floor
    assert vz[-1] > 0.5 * np.sqrt(2 * 9.81 * 0.1e-3)  # undamped: it comes back up
