"""The explicit step honours the contact damping the grains really have (docs/dynamics.md).

The normal damping c = 2 zeta sqrt(k m_eq) is scaled with the grains' masses, but the explicit
integrator moves lumped vertex masses, 15-30 times lighter: on them the damping ratio is
zeta_p = zeta sqrt(m_eq sum w_i^2 / m_i), 2-4 for zeta = 0.5. The stability limit of velocity
Verlet with the damping at the half-step velocity is (2 / omega)(sqrt(1 + zeta_p^2) - zeta_p)."""

import numpy as np
import pytest

from vemdem.contact.ccd import damped_contact_step
from vemdem.contact.defaults import default_contact_laws
from vemdem.contact.forces import pair_inverse_masses
from vemdem.contact.law import normal_stiffness
from vemdem.contact.walls import PlaneWall
from vemdem.geometry import cube
from vemdem.model.scene import Scene
from vemdem.solver.api import SolverOptions, make_integrator
from vemdem.solver.state import RunStats
from vemdem.vem.material import Material


def verlet_energy_grows(dt, zeta, k=1.0, m=1.0, steps=3000) -> bool:
    """The integrator's scheme on one damped spring: does the energy end above where it started?"""
    c = 2 * zeta * np.sqrt(k * m)
    x, v, a = 1.0, 0.0, -k / m
    with np.errstate(over="ignore", invalid="ignore"):
        for _ in range(steps):
            vh = v + 0.5 * dt * a
            x = x + dt * vh
            a = -(k * x + c * vh) / m
            v = vh + 0.5 * dt * a
        energy = 0.5 * k * x * x + 0.5 * m * v * v
    return not energy <= 0.5 * k


@pytest.mark.parametrize("zeta", [0.5, 2.0, 3.5])
def test_the_damped_limit_is_the_schemes_own(zeta):
    limit = 2.0 * (np.sqrt(1 + zeta * zeta) - zeta)
    assert not verlet_energy_grows(0.99 * limit, zeta)
    assert verlet_energy_grows(1.01 * limit, zeta)
    # the undamped limit 2/omega is far too long once zeta_p is large
    assert verlet_energy_grows(0.9 * 2.0, zeta) or zeta < 0.1


def resting_cube(mass_scaling=1e6):
    material = Material(90e9, 0.16, 2200.0 * mass_scaling)
    law, friction = default_contact_laws(1e-3, material.E, material.density)
    grain = cube(1e-3)
    grain = grain.translated((0.0, 0.0, 0.5 * law.activation_gap - grain.vertices[:, 2].min()))
    floor = PlaneWall(np.zeros(3), np.array([0.0, 0.0, 1.0]), name="floor")
    return Scene.build([grain], material, law, friction, planes=[floor], mass_scaling=mass_scaling)


def test_the_step_uses_the_pairs_real_damping_ratio():
    """Each bottom vertex of a cube resting on the floor is a damped spring on its lumped mass. Its
    stiffness k and damping c are measured here by central differences of the contact model's own
    residual in that vertex's height and vertical velocity, so the limit (2 / omega)(sqrt(1 +
    zeta_v^2) - zeta_v), omega^2 = k / m, zeta_v = c / (2 sqrt(k m)), whose scheme the test above
    checks, is the one of the damping friction.py really applies: damped_contact_step must give it."""
    scene = resting_cube()
    x = scene.bodies.reference
    contact = scene.contact
    candidates = contact.search(x, 0.0)
    cr = contact.evaluate(x, 0.0, candidates)
    ints, floats = cr.ints, cr.floats
    assert len(ints) == 4  # the four bottom vertices on the floor
    bottom = np.flatnonzero(np.isclose(x[:, 2], x[:, 2].min()))
    m = scene.bodies.lumped[bottom]

    def vertical_residual(i, dx=0.0, dv=0.0):
        xi, vi = x.copy(), np.zeros_like(x)
        xi[i, 2] += dx
        vi[i, 2] += dv
        return contact.evaluate(xi, 0.0, candidates, v=vi).force[i, 2]

    h = 1e-4 * contact.law.activation_gap
    u = 1e-6  # m/s: far below where the damping's no-adhesion clamp could act
    k = np.array([(vertical_residual(i, h) - vertical_residual(i, -h)) / (2 * h) for i in bottom])
    c = np.array([(vertical_residual(i, dv=u) - vertical_residual(i, dv=-u)) / (2 * u) for i in bottom])
    assert np.all(k > 0) and np.all(c > 0)  # a spring that pushes back, a damper that resists
    zeta_v = c / (2 * np.sqrt(k * m))
    zeta = contact.friction.damping_ratio
    assert np.all(zeta_v > 2 * zeta)  # vertex masses are much lighter than the grain the damping is scaled with
    expected = np.min(2 / np.sqrt(k / m) * (np.sqrt(1 + zeta_v**2) - zeta_v))
    inv_all = np.concatenate([1.0 / scene.bodies.lumped, np.zeros(3)])
    got = damped_contact_step(inv_all, ints, floats, contact.law_params, contact.masses_of_pairs(ints), zeta)
    assert got == pytest.approx(expected, rel=1e-5)
    # shorter than the step the damping ratio zeta alone gave
    assert got < 0.7 * np.min(2 / np.sqrt(k / m)) * (np.sqrt(1 + zeta**2) - zeta)


def test_a_cube_bouncing_on_a_damped_floor_never_gains_energy():
    """Dropped 0.2 mm at mass scaling 1e6 with the default damping (the paper runs' setting)."""
    scene = resting_cube()
    lifted = scene.bodies.reference + np.array([0.0, 0.0, 2e-4])
    integrator = make_integrator(SolverOptions(integrator="explicit", dt_max=1e-4), scene)
    state = integrator.initial_state(x0=lifted)
    start = scene.kinetic_energy(state.v, True) + scene.gravity_energy(state.x, True)
    totals = []

    def record(st, info, h):
        totals.append(scene.kinetic_energy(st.v, True) + scene.gravity_energy(st.x, True) + info.contact_energy
                      + info.strain_energy)  # fmt: skip

    integrator.advance(state, 0.03, record, RunStats())
    totals = np.array(totals)
    assert totals.max() <= start + 1e-6 * abs(start)
    assert totals[-1] < start  # the damping took something
