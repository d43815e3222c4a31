"""The implicit integrator at the real density finishes the scenes that used to stop it (docs/dynamics.md):
twelve random sand grains (18 vertices, 1.2 mm, mu 0.6/0.5, E = 90 GPa, rho = 2200 kg/m^3)
dropped from a 2 x 2 x 3 grid into a 4.8 mm box, 0.03 s. Before the rigid update the run stopped
at t = 0.0299 s with TimeStepTooSmall after 15 minutes. Checked: it ends at 0.03 s, no accepted
step is below 1e-8 s, every grain stays in the box and above the floor, and no energy is made
(total energy at the end at most the initial one: the box is closed, contact damping and friction
dissipate)."""

import numpy as np
import pytest

from vemdem.contact.defaults import default_contact_laws
from vemdem.contact.walls import box_walls
from vemdem.geometry import sand_grain
from vemdem.model.scene import Scene
from vemdem.solver.api import SolverOptions, make_integrator
from vemdem.solver.state import RunStats
from vemdem.vem.material import Material

SIZE, BOX = 1.2e-3, 4.8e-3


def twelve_grain_drop(grain_model="flexible"):
    material = Material(90e9, 0.16, 2200.0)
    law, friction = default_contact_laws(SIZE, material.E, material.density, 9.81, 0.6, 0.5)
    grains = []
    spacing = 1.6 * SIZE
    for k, (i, j, level) in enumerate(np.ndindex(2, 2, 3)):
        g = sand_grain(SIZE, 18, seed=100 + k)
        target = np.array([(i - 0.5) * spacing, (j - 0.5) * spacing, 0.8 * SIZE + level * spacing])
        grains.append(g.translated(target - g.centroid))
    walls = box_walls(BOX, BOX, floor_z=0.0)
    return Scene.build(grains, material, law, friction, planes=walls, gravity=(0, 0, -9.81), grain_model=grain_model)


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


def test_lid_moving_past_its_gap_in_one_step_carries_the_grain():
    """A lid that moves further in one step than its gap to a grain (a lid pressing a pack at a
    large step) used to start Newton with the lid behind the grain's surface, and the step was
    rejected until the lid's travel per step fell below its gap. The walls now start where they
    can go and move on to the step's end between Newton iterations: the step converges, the
    grain ends in front of the lid and has been pushed at least as far as the lid went past the
    initial gap (checked against the lid's position, computed independently of the solver). The
    rigid predictor is bounded against the lid where it stands at the step's start (it used to be
    bounded against the lid at the step's end, already past the grain, and crashed)."""
    from vemdem.contact.walls import Motion, PlaneWall
    from vemdem.geometry.shapes import cube
    from vemdem.solver.newmark import NewmarkParameters, initial_state, newmark_step

    size, speed = 1e-3, 0.02
    material = Material(90e9, 0.16, 2200.0)
    law, friction = default_contact_laws(size, material.E, material.density, 9.81)
    grain = cube(size)
    gap = 0.5 * law.activation_gap
    top = float(grain.vertices[:, 2].max())
    lid = PlaneWall((0.0, 0.0, top + gap), (0.0, 0.0, -1.0), Motion((0.0, 1.0), ((0, 0, 0), (0, 0, -speed))), "lid")
    scene = Scene.build([grain], material, law, friction, planes=[lid], gravity=(0, 0, 0))
    dt = 4 * gap / speed  # the lid passes four gaps into where the grain stands
    state = initial_state(scene)
    new, _ = newmark_step(scene, state, dt, NewmarkParameters())
    lid_z = top + gap - speed * dt
    assert new.x[:, 2].max() < lid_z  # in front of the lid: pushed by at least its overshoot
    assert np.ptp(new.x[:, 2] - state.x[:, 2]) < 1e-3 * (top - lid_z)  # moved as a body, not crushed
    assert new.v[:, 2].mean() < 0  # momentum along the lid (the vertices also carry element vibration)


def test_rigid_twelve_grain_drop_makes_no_energy():
    """The same drop with rigid grains and the implicit rigid integrator (solver/rigid_implicit.py):
    the closed box's energy books (kinetic, gravity, contact, dissipated) never exceed their start,
    the grains stay in the box, and the step control keeps every gap open."""
    from vemdem.solver.rigid import rigid_kinetic_energy

    scene = twelve_grain_drop("rigid")
    integrator = make_integrator(SolverOptions(integrator="implicit"), scene)
    state = integrator.initial_state()
    books = []

    def on_step(s, info, dt):
        books.append(rigid_kinetic_energy(scene.bodies, s) + scene.gravity_energy(s.x) + info.contact_energy
                     + s.dissipated)  # fmt: skip

    e0 = scene.gravity_energy(state.x)
    state, _ = integrator.advance(state, 0.03, on_step, RunStats())
    assert abs(state.t - 0.03) < 1e-12
    assert state.x[:, 2].min() > 0.0 and np.all(np.abs(scene.grain_centroids(state.x)[:, :2]) < BOX / 2)
    drop = e0 - scene.gravity_energy(state.x)
    assert drop > 0  # the grains fell and
    assert max(books) <= e0 + 0.01 * drop  # made no energy (1 % of the released potential)
    assert state.dissipated > 0.3 * drop  # the impacts dissipated (measured: 0.96 of the drop, balance -2.7 %)


def test_wall_time_keeps_the_share_of_the_gap():
    """wall_time against the closed form: a plane approaching at speed v from distance d may go on
    for share d / v; a plane that stops (a corner in its motion) before using that share goes all
    the way to the step's end; a plane moving away never limits."""
    from vemdem.contact.walls import Motion, PlaneWall
    from vemdem.geometry.shapes import cube
    from vemdem.solver.newmark import wall_time

    size, v, d, share = 1e-3, 0.02, 2e-6, 0.8
    material = Material(90e9, 0.16, 2200.0)
    law, friction = default_contact_laws(size, material.E, material.density, 9.81)
    grain = cube(size)
    top = float(grain.vertices[:, 2].max())

    def scene_with(times, heights):
        motion = Motion(times, [(0.0, 0.0, -h) for h in heights])
        lid = PlaneWall((0.0, 0.0, top + d), (0.0, 0.0, -1.0), motion, "lid")
        return Scene.build([grain], material, law, friction, planes=[lid], gravity=(0, 0, 0))

    x = grain.vertices
    steady = scene_with((0.0, 1.0), (0.0, v))
    assert wall_time(steady, x, 0.0, 1e-3, share) == pytest.approx(share * d / v, rel=1e-9)
    assert wall_time(steady, x, 0.0, 0.5 * share * d / v, share) == 0.5 * share * d / v  # room to spare
    # stops after travelling half the gap (a corner in its motion): the step's end is reachable
    stopping = scene_with((0.0, 0.5 * d / v, 1.0), (0.0, 0.5 * d, 0.5 * d))
    assert wall_time(stopping, x, 0.0, 1e-3, share) == 1e-3
    # slow, then fast (a corner inside the step): never past the share of the gap
    speeding = scene_with((0.0, 5e-4, 1e-3), (0.0, 0.1 * d, 2 * d))
    t = wall_time(speeding, x, 0.0, 1e-3, share)
    assert 0 < t < 1e-3 and speeding.contact.planes[0].motion.displacement(t)[2] >= -share * d
    receding = scene_with((0.0, 1.0), (0.0, -v))
    assert wall_time(receding, x, 0.0, 1e-3, share) == 1e-3
