"""The implicit integrator at the real density finishes the scenes that used to stop it (issue 14):
twelve random sand grains (18 vertices, 1.2 mm, mu 0.6/0.5, E = 90 GPa, rho = 2200 kg/m^3)
dropped from a 2 x 2 x 3 grid into a 4.8 mm box, 0.03 s. Before the rigid update the run stopped
at t = 0.0299 s with TimeStepTooSmall after 15 minutes. Checked: it ends at 0.03 s, no accepted
step is below 1e-8 s, every grain stays in the box and above the floor, and no energy is made
(total energy at the end at most the initial one: the box is closed, contact damping and friction
dissipate)."""

import numpy as np

from vemdem.contact.defaults import default_contact_laws
from vemdem.contact.walls import box_walls
from vemdem.geometry import sand_grain
from vemdem.model.scene import Scene
from vemdem.solver.api import SolverOptions, make_integrator
from vemdem.solver.state import RunStats
from vemdem.vem.material import Material

SIZE, BOX = 1.2e-3, 4.8e-3


def twelve_grain_drop():
    material = Material(90e9, 0.16, 2200.0)
    law, friction = default_contact_laws(SIZE, material.E, material.density, 9.81, 0.6, 0.5)
    grains = []
    spacing = 1.6 * SIZE
    for k, (i, j, level) in enumerate(np.ndindex(2, 2, 3)):
        g = sand_grain(SIZE, 18, seed=100 + k)
        target = np.array([(i - 0.5) * spacing, (j - 0.5) * spacing, 0.8 * SIZE + level * spacing])
        grains.append(g.translated(target - g.centroid))
    walls = box_walls(BOX, BOX, floor_z=0.0)
    return Scene.build(grains, material, law, friction, planes=walls, gravity=(0, 0, -9.81))


def total_energy(scene, state, strain):
    return scene.kinetic_energy(state.v) + scene.gravity_energy(state.x) + strain


def test_twelve_grain_drop_finishes_at_the_real_density():
    scene = twelve_grain_drop()
    integrator = make_integrator(SolverOptions(integrator="implicit"), scene)
    state = integrator.initial_state()
    steps = []
    energy = []

    def on_step(s, info, dt):
        steps.append(dt)
        energy.append(total_energy(scene, s, info.strain_energy) + info.contact_energy + s.dissipated)

    e0 = total_energy(scene, state, 0.0)
    state, stats = integrator.advance(state, 0.03, on_step, RunStats())
    assert state.t == np.float64(state.t) and abs(state.t - 0.03) < 1e-12
    assert min(steps) > 1e-8
    centroids = scene.grain_centroids(state.x)
    assert np.all(np.abs(centroids[:, :2]) < BOX / 2)
    assert state.x[:, 2].min() > 0.0
    # energy balance: what is left plus what was dissipated never exceeds the start (1 % slack
    # for the trapezoidal rule's error on the barrier law, docs/dynamics.md)
    assert max(energy) <= e0 + 0.01 * abs(e0)
    assert stats.newton_iterations / stats.accepted < 10
