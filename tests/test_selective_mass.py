"""Selective mass scaling (vem/selective_mass.py, docs/selective-mass-scaling.md): the operator
against the dense scaled mass matrix, the deformation periods against a generalised eigenproblem,
the rigid motions' inertia kept, a spinning grain's stretch, collisions, and the config key."""

import json
import tomllib

import numpy as np
import pytest
import scipy.linalg
import tomli_w

from vemdem.contact.defaults import default_contact_laws, material_contact_laws
from vemdem.geometry import sand_grain
from vemdem.model.scene import Scene
from vemdem.scenarios.registry import example_text
from vemdem.solver.api import SolverOptions, make_integrator
from vemdem.solver.state import RunStats
from vemdem.vem.element import evaluate
from vemdem.vem.material import Material
from vemdem.vem.selective_mass import rigid_point_mobility, selective_accelerations
from vemdem.verification.impact import head_on


def one_grain(E=90e9, density=2200.0, size=0.9e-3, n_vertices=20, seed=3):
    material = Material(E, 0.16, density)
    law, friction = default_contact_laws(size, E, density, 9.81)
    return Scene.build([sand_grain(size, n_vertices, seed=seed)], material, law, friction, gravity=(0, 0, 0))


def rigid_modes(x, m):
    """(3n, 6) translations and rotations about the lumped-mass centroid, dof 3 v + k."""
    r = x - m @ x / m.sum()
    phi = np.zeros((3 * len(x), 6))
    for k in range(3):
        phi[k::3, k] = 1.0
        e = np.zeros(3)
        e[k] = 1.0
        phi[:, 3 + k] = np.cross(e, r).ravel()
    return phi


def dense_scaled_mass(x, m, lam):
    """M_s = M + lam (M - M Phi (Phi^T M Phi)^-1 Phi^T M), Olovsson et al. (2005)."""
    M = np.diag(np.repeat(m, 3))
    phi = rigid_modes(x, m)
    return M + lam * (M - M @ phi @ np.linalg.solve(phi.T @ M @ phi, phi.T @ M))


@pytest.fixture(scope="module")
def grain():
    return one_grain()


def test_operator_is_the_inverse_of_the_dense_scaled_mass(grain, rng):
    b = grain.bodies
    x = b.reference + 1e-6 * rng.standard_normal(b.reference.shape)  # a deformed placement
    f = rng.standard_normal(x.shape)
    for lam in (0.0, 3.0, 1e4):
        a = selective_accelerations(f, x, np.zeros_like(x), b.lumped, b.vertex_ptr, lam)
        expected = np.linalg.solve(dense_scaled_mass(x, b.lumped, lam), f.ravel()).reshape(-1, 3)
        assert np.allclose(a, expected, rtol=1e-9, atol=1e-9 * np.abs(expected).max())


def test_translations_and_rotations_keep_their_real_inertia(grain, rng):
    """Net force and torque about the centroid give the real momenta' rates at every lambda, spinning or not."""
    b = grain.bodies
    x, m = b.reference, b.lumped
    v = np.cross(rng.standard_normal(3), x - m @ x / m.sum()) + rng.standard_normal(3)
    f = rng.standard_normal(x.shape)
    c = m @ x / m.sum()
    for lam in (10.0, 1e6):
        a = selective_accelerations(f, x, v, m, b.vertex_ptr, lam)
        assert np.allclose(m @ a, f.sum(axis=0), rtol=1e-9)
        assert np.allclose(np.sum(m[:, None] * np.cross(x - c, a), axis=0), np.sum(np.cross(x - c, f), axis=0),
                           rtol=1e-7, atol=1e-9 * np.abs(f).sum())  # fmt: skip


def test_a_contact_point_meets_the_rigid_response_of_the_grain_where_it_stands(grain, rng):
    """The scaled pair inverse mass's rigid part, 1/M + (r x n) . J^-1 (r x n) at the contact point
    with the inertia of the current placement (grain_frames, as the explicit step takes it), is the
    dense projector Phi (Phi^T M Phi)^-1 Phi^T seen by a point force spread on three vertices."""
    from vemdem.vem.selective_mass import grain_frames  # noqa: PLC0415

    b = grain.bodies
    m = b.lumped
    x = b.reference + 1e-5 * rng.standard_normal(b.reference.shape)  # not the reference placement
    phi = rigid_modes(x, m)
    M = np.diag(np.repeat(m, 3))
    projector = phi @ np.linalg.solve(phi.T @ M @ phi, phi.T)
    _, centre, axes, moments = grain_frames(x, m, b.vertex_ptr)
    J_inv = axes[0] @ np.diag(1.0 / moments[0]) @ axes[0].T
    for _ in range(5):
        nodes = rng.choice(len(m), 3, replace=False)
        w = rng.dirichlet(np.ones(3))
        n = rng.standard_normal(3)
        n /= np.linalg.norm(n)
        force = np.zeros((len(m), 3))
        force[nodes] = w[:, None] * n
        dense = force.ravel() @ projector @ force.ravel()
        q = np.cross(w @ x[nodes] - centre[0], n)
        assert 1.0 / m.sum() + q @ J_inv @ q == pytest.approx(dense, rel=1e-9)


def test_free_fall_and_rest_are_exact(grain):
    b = grain.bodies
    g = np.array([0.0, 0.0, -9.81])
    b.scale_deformation_inertia(1e5)
    try:
        fall = b.accelerations(b.lumped[:, None] * g, b.reference, np.zeros_like(b.reference))
        rest = b.accelerations(np.zeros_like(b.reference), b.reference, np.zeros_like(b.reference))
    finally:
        b.scale_deformation_inertia(0.0)
    assert np.allclose(fall, g, rtol=1e-12, atol=1e-12)
    assert not rest.any()  # a grain at rest without forces stays at rest, to the bit


def test_deformation_periods_grow_by_the_square_root_of_one_plus_lambda(grain):
    """The critical step and the slowest vibration period from the generalised eigenproblem K u =
    w^2 M_s u (scipy), against the body model's closed form."""
    b = grain.bodies
    el = b.elements
    K = evaluate(el, el.reference, force=False, tangent=True).blocks.reshape(3 * b.n_vertices, -1)
    K = 0.5 * (K + K.T)
    lam = 250.0
    w2 = scipy.linalg.eigh(K, dense_scaled_mass(b.reference, b.lumped, lam), eigvals_only=True)
    b.scale_deformation_inertia(lam)
    try:
        step, period = b.critical_steps()[0], b.vibration_periods()[0]
    finally:
        b.scale_deformation_inertia(0.0)
    assert step == pytest.approx(2.0 / np.sqrt(w2[-1]), rel=1e-6)
    assert period == pytest.approx(2.0 * np.pi / np.sqrt(w2[6]), rel=1e-6)
    assert step == pytest.approx(np.sqrt(1 + lam) * b.critical_steps()[0], rel=1e-12)


def test_rigid_point_mobility_bounds_every_vertex_direction(grain, rng):
    """1/M + rho^2/I_min bounds n . (Phi (Phi^T M Phi)^-1 Phi^T)_ii n over vertices and directions."""
    b = grain.bodies
    phi = rigid_modes(b.reference, b.lumped)
    P = phi @ np.linalg.solve(phi.T @ np.diag(np.repeat(b.lumped, 3)) @ phi, phi.T)
    n = rng.standard_normal((200, 3))
    n /= np.linalg.norm(n, axis=1)[:, None]
    worst = max(float(d @ P[3 * i:3 * i + 3, 3 * i:3 * i + 3] @ d) for i in range(b.n_vertices) for d in n)
    bound = rigid_point_mobility(b.reference, b.lumped, b.vertex_ptr)[0]
    assert worst <= bound * (1 + 1e-12)
    assert worst > 0.5 * bound  # and not loose


def spin(lam, omega=1000.0, duration=4e-3):
    """A free soft grain spun about z from its unstretched shape: (largest strain over the run, its
    angular momentum at the start and the end, the scaled energy at the start and the end)."""
    scene = one_grain(E=1e6, density=2200.0)
    b = scene.bodies
    b.scale_deformation_inertia(lam)
    c = b.lumped @ b.reference / b.lumped.sum()
    v0 = np.cross([0.0, 0.0, omega], b.reference - c)
    run = make_integrator(SolverOptions(integrator="explicit", dt_max=1e-5), scene)
    state = run.initial_state(v0=v0)
    strains, energies = [], []

    def record(s, info, h):
        strains.append(float(scene.grain_strains(s.x).max()))
        energies.append(scene.kinetic_energy(s.v, True, s.x) + info.strain_energy)

    momentum = [np.sum(b.lumped[:, None] * np.cross(state.x - c, state.v), axis=0)]
    state, _ = run.advance(state, duration, record, RunStats())
    c1 = b.lumped @ state.x / b.lumped.sum()
    momentum.append(np.sum(b.lumped[:, None] * np.cross(state.x - c1, state.v), axis=0))
    return max(strains), momentum, (scene.kinetic_energy(v0, True, b.reference), energies)


def test_a_spinning_grain_stretches_as_a_real_one():
    """The modes turn with the grain, so the centripetal force is not asked of the scaled
    deformation inertia: fixed modes would stretch the grain (1 + lambda) times more."""
    real, _, _ = spin(0.0)
    scaled, momentum, (e0, energies) = spin(1e3)
    assert scaled == pytest.approx(real, rel=0.05)  # 4.70e-4 and 4.77e-4; fixed modes: 0.37
    # rho omega^2 R^2 / E, the order of a spinning ball's stretch: 4e-4 here
    assert 1e-5 < real < 2e-3
    assert np.allclose(momentum[1], momentum[0], rtol=1e-6)
    assert max(energies) <= e0 * (1 + 1e-3)  # the scaled energy never grows


def tumble(lam, omega=300.0, duration=0.05):
    """A free grain at 90 GPa tumbling about a skew axis while it drifts, each step the stable one
    at lambda: (the scaled energy's largest rise over the run, relative; the largest strain)."""
    scene = one_grain()
    b = scene.bodies
    b.scale_deformation_inertia(lam)
    c = b.lumped @ b.reference / b.lumped.sum()
    axis = np.array([1.0, 2.0, 3.0]) / np.sqrt(14.0)
    v0 = np.cross(omega * axis, b.reference - c) + np.array([0.01, 0.0, 0.0])
    run = make_integrator(SolverOptions(integrator="explicit", dt_max=1.0), scene)
    state = run.initial_state(v0=v0)
    energies = []
    state, _ = run.advance(state, duration, lambda s, info, h: energies.append(
        scene.kinetic_energy(s.v, True, s.x) + info.strain_energy), RunStats())  # fmt: skip
    return max(energies) / scene.kinetic_energy(v0, True, b.reference) - 1.0, float(scene.grain_strains(state.x).max())


def test_a_tumbling_grain_keeps_its_energy_at_large_lambda():
    """The drift turns each grain exactly (corotational_drift): a straight drift along the
    vertices' velocities stretched a tumbling grain by a chord's sagitta every step, which the heavy
    deformation modes kept: energy +3.6e-4 and strain 5e-8 at lambda 3e6 over 1,067 steps, against
    +1e-6 and 3e-10 now (and 7e-7, 4e-10 unscaled over 7,390 steps)."""
    rise, strain = tumble(3e6)
    assert rise < 1e-5
    assert strain < 3e-9


def test_a_collision_keeps_its_restitution():
    """Head-on impact at 90 GPa: lambda leaves the rebound alone, far past the uniform scaling that
    changes it (test_mass_scaling.py), and no energy is gained."""
    reference = head_on(1.0, selective_mass_scaling=1e3)
    for lam in (1e5, 1e7):
        impact = head_on(1.0, selective_mass_scaling=lam)
        assert impact.restitution == pytest.approx(reference.restitution, rel=0.01)
        assert 0.0 < impact.energy_kept < 1.0
        assert impact.steps < reference.steps / 5  # what it is for


def drop_config(tmp_path, **solver):
    raw = tomllib.loads(example_text("drop"))
    raw["duration"] = 2e-3
    raw["output"] = {"every": 1e-3, "vtk": False}
    raw["solver"] = {"integrator": "explicit", **solver}
    config = tmp_path / "drop.toml"
    config.write_text(tomli_w.dumps(raw))
    return config


def test_auto_is_named_in_the_log_and_the_summary(tmp_path, cli):
    code, _, err = cli("run", drop_config(tmp_path, selective_mass_scaling="auto"), "--out", tmp_path / "out",
                       "--quiet")  # fmt: skip
    assert code == 0, err
    (line,) = [line for line in err.splitlines() if "selective mass scaling" in line]
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    lam = summary["selective_mass_scaling"]
    auto = summary["selective_mass_scaling_auto"]
    assert f"lambda = {lam:.3g}" in line and lam == auto["lambda"] > 1e3
    assert lam == min(auto["lambda_contact"], auto["lambda_period_cap"])
    # the scaled slowest period within the named share of a contact's duration
    assert auto["scaled_period_s"] <= auto["period_fraction"] * auto["loading_time_s"] * (1 + 1e-9)
    history = (tmp_path / "out" / "history.csv").read_text().splitlines()
    assert len(history) >= 3  # frames written: the run went through
    # the books close with the scaled kinetic energy: what the step keeps
    assert abs(summary["energy"]["balance_error"]) < 0.01, summary["energy"]


@pytest.mark.parametrize(("solver", "cause"), [
    ({"integrator": "implicit", "selective_mass_scaling": 10.0}, 'set solver.integrator = "explicit"'),
    ({"selective_mass_scaling": -1.0}, "must be in [0, 1e12]"),
    ({"selective_mass_scaling": "yes"}, 'expected "auto" or a number'),
])  # fmt: skip
def test_bad_values_are_refused_naming_the_key(tmp_path, cli, solver, cause):
    config = drop_config(tmp_path, **solver)
    code, _, err = cli("run", config, "--out", tmp_path / "out", "--quiet")
    assert code == 2 and "solver.selective_mass_scaling" in err and cause in err, err


def test_rigid_grains_take_auto_as_nothing_to_scale(tmp_path, cli):
    config = drop_config(tmp_path, selective_mass_scaling="auto")
    raw = tomllib.loads(config.read_text())
    raw["model"] = {"grains": "rigid"}
    config.write_text(tomli_w.dumps(raw))
    code, _, err = cli("run", config, "--out", tmp_path / "out", "--quiet")
    assert code == 0, err
    assert json.loads((tmp_path / "out" / "summary.json").read_text())["selective_mass_scaling"] == 0.0
    raw["solver"]["selective_mass_scaling"] = 5.0
    config.write_text(tomli_w.dumps(raw))
    code, _, err = cli("run", config, "--out", tmp_path / "out2", "--quiet")
    assert code == 2 and "rigid grains have no deformation modes" in err


def test_a_quasi_static_test_loads_its_grains_over_its_strain_rate_not_a_contact():
    """A lab test's loading time is the time its fastest drive (lab.servo.quasi_static_rate at the
    test's inertia number and stress) strains neighbouring grains by one activation gap over their
    size; "auto" then reaches the contact bound, which a collision's duration kept it below."""
    from vemdem.lab.servo import quasi_static_rate
    from vemdem.model.selective import auto_selective_scaling

    inertia, stress, d = 5e-4, 50e3, 0.9e-3  # the rate goes as 1/d and the strain to cross a gap as 1/d
    law, friction = default_contact_laws(d, 90e9, 2200.0, 9.81, reference_force=2.0 * stress * d**2)  # the lab's
    grain = Scene.build([sand_grain(d, 20, seed=3)], Material(90e9, 0.16, 2200.0), law, friction, gravity=(0, 0, 0))
    collision = auto_selective_scaling(grain)
    lab = auto_selective_scaling(grain, (inertia, stress))
    rate = quasi_static_rate(inertia, stress, grain.material.density, d)
    expected = grain.contact.law.activation_gap / d / rate
    assert lab["loading_time_s"] == pytest.approx(expected, rel=1e-12)
    assert lab["loading_time_from"] == "the test's strain rate"
    assert collision["loading_time_from"] == "a contact's duration"
    assert lab["loading_time_s"] > 100 * collision["loading_time_s"]
    assert collision["bound"] == "vibration period" and collision["lambda"] < collision["lambda_contact"]
    assert lab["bound"] == "contact step" and lab["lambda"] == lab["lambda_contact"]
    assert lab["scaled_period_s"] <= lab["period_fraction"] * lab["loading_time_s"]


def test_a_lab_tests_contact_bound_is_the_stiffness_at_a_grains_weight():
    """In a lab test "auto" matches the grains' step to the contact step where the law carries a
    grain's weight (its mass from the grains' lumped masses, at standard gravity where the scene has
    none), so a rigid run's soft seating contacts do not outstep it; a collision keeps the switch
    gap's stiffness."""
    from vemdem.contact.law import normal_force
    from vemdem.model.selective import auto_selective_scaling, stiffness_at_force

    d, stress = 0.9e-3, 50e3
    for law, friction in (default_contact_laws(d, 90e9, 2200.0, 9.81, reference_force=2.0 * stress * d**2),
                          material_contact_laws(d, 90e9, 0.16)):  # fmt: skip
        for gravity in ((0, 0, -3.0), (0, 0, 0)):
            scene = Scene.build([sand_grain(d, 20, seed=3)], Material(90e9, 0.16, 2200.0), law, friction,
                                gravity=gravity)  # fmt: skip
            weight = float(scene.bodies.lumped.sum()) * (3.0 if gravity[2] else 9.81)
            lab = auto_selective_scaling(scene, (5e-4, stress))
            assert lab["contact_stiffness_N_per_m"] == pytest.approx(stiffness_at_force(law, weight), rel=1e-9)
            k_switch = normal_force(law.switch_gap, law.packed())[1]
            assert lab["contact_stiffness_N_per_m"] < k_switch
            assert lab["lambda_contact"] > auto_selective_scaling(scene)["lambda_contact"]


@pytest.mark.parametrize("n1", [1.5, 2.0])
def test_the_contact_bound_takes_the_laws_stiffness_where_it_carries_the_force(n1):
    """stiffness_at_force against the law's own force and stiffness at the gap where it carries that
    force, found by bisection; above the switch force, the switch gap's stiffness."""
    from scipy.optimize import brentq

    from vemdem.contact.law import InterfaceLaw, normal_force
    from vemdem.model.selective import stiffness_at_force

    law = InterfaceLaw(9e-6, 1e9, n1, 0.3, -2.0)
    p = law.packed()
    for force in (1e-4, 1e-2, 0.5 * law.switch_force):
        gap = brentq(lambda g: normal_force(g, p)[0] - force, law.switch_gap, law.activation_gap, xtol=1e-18)
        assert stiffness_at_force(law, force) == pytest.approx(normal_force(gap, p)[1], rel=1e-8)
    assert stiffness_at_force(law, 3.0 * law.switch_force) == pytest.approx(normal_force(law.switch_gap, p)[1])
