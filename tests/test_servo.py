"""Stress-controlled walls (lab/servo.py, contact.walls.ServoMotion) and load paths whose stages
end on a condition (lab/path.py).

The control law is checked against its closed form on a spring behind a contact layer, then the
whole loop on a grain pressed between the floor and a servo lid, with flexible grains
(implicit) and rigid ones (both integrators): each stage ends at its target within 1 %, at rest,
overshooting by at most 5 %, and the contacts' Love-Weber stress agrees with the lid's."""

import json

import numpy as np
import pytest

from vemdem.analysis.microstructure import love_weber_stress
from vemdem.config import ConfigError
from vemdem.contact.defaults import default_contact_laws
from vemdem.contact.walls import PlaneWall, ServoMotion
from vemdem.geometry import cube
from vemdem.model.scene import Scene
from vemdem.lab.path import LoadPath, Stage
from vemdem.lab.servo import RAMP, SEATING, STIFFNESS_RANGE, Servo
from vemdem.scenarios.registry import checked_config
from vemdem.solver.api import SolverOptions, make_integrator
from vemdem.solver.state import RunStats
from vemdem.vem.material import Material

SIZE = 1e-3


# ---------------------------------------------------------------- the steered path
def test_a_steered_path_is_continuous_and_remembers_its_last_segment():
    m = ServoMotion((0.0, 0.0, -2.0))
    assert np.allclose(m.axis, [0, 0, -1])
    m.steer(0.0, 1e-3)
    m.steer(0.5, -2e-3)  # 0.5 mm down by now, then back up at 2 mm/s
    assert np.allclose(m.displacement(0.5), [0, 0, -5e-4], rtol=0, atol=1e-18)
    assert np.allclose(m.displacement(0.75), [0, 0, -5e-4 + 5e-4], atol=1e-18)
    assert np.allclose(m.displacement(0.25), [0, 0, -2.5e-4], atol=1e-18)  # the segment before the steering
    assert np.allclose(m.velocity(0.25), [0, 0, -1e-3])
    assert np.allclose(m.velocity(0.6), [0, 0, 2e-3])
    h = 1e-7
    assert np.allclose((m.displacement(0.6 + h) - m.displacement(0.6 - h)) / (2 * h), m.velocity(0.6))


def test_a_steered_path_goes_through_a_checkpoint_to_the_bit():
    m = ServoMotion((0.0, 0.0, -1.0))
    for k, s in enumerate(np.random.default_rng(3).normal(size=20)):
        m.steer(0.1 * k + 1e-3 * s**2, 1e-3 * s)
    copy = ServoMotion((0.0, 0.0, -1.0))
    copy.carry_on(json.loads(json.dumps(m.carried())))
    for t in (1.7, 1.95, 2.3):
        assert np.array_equal(copy.displacement(t), m.displacement(t))
    assert copy.version == m.version


def test_a_steered_path_refuses_a_non_finite_speed():
    with pytest.raises(ValueError, match="non-finite speed"):
        ServoMotion((0.0, 0.0, 1.0)).steer(0.0, float("nan"))


# ---------------------------------------------------------------- the control law
class SpringBehindLayer:
    """A wall on a contact layer of stiffness K in series with a sample of stiffness k_s: N =
    k_eff travel, k_eff = K k_s / (K + k_s); the servo sees the layer's K (ContactModel.wall_stiffness)."""

    wall_names = ["lid"]

    def __init__(self, K, k_s):
        self.K, self.k_eff = K, K * k_s / (K + k_s)

    def wall_stiffness(self, ints, floats):
        return np.array([self.K])


def _servo_steps(K, k_s, gain, target_force, steps, h=1e-4, cap_share=0.08, drift=None, keep_secant=False):
    """The forces after each step. The speed cap moves the force by cap_share of the target per
    step: 0.08 seats the wall in two steps and never binds the law after (gain RAMP < 0.08).
    drift(n): the force added by step n from elsewhere (a platen's shear on a lateral wall)."""
    contact = SpringBehindLayer(K, k_s)
    lid = PlaneWall(np.zeros(3), np.array([0.0, 0.0, -1.0]), ServoMotion((0.0, 0.0, -1.0)), "lid")
    cap = cap_share * target_force / (contact.k_eff * h)
    servo = Servo(contact, lid, 1.0, gain=gain, target=target_force, max_speed=cap)
    servo.keep_secant = keep_secant
    forces = []
    for n in range(1, steps + 1):
        t = n * h
        force = contact.k_eff * servo.travel_at(t) + (0.0 if drift is None else drift(n))
        servo.measure(np.array([[0.0, 0.0, force]]), None, None, t)
        lid.motion.steer(t, servo.speed(h))
        forces.append(force)
    return np.array(forces)


@pytest.mark.parametrize("ratio", [1.0, 0.05, 1e-3])
def test_the_force_error_shrinks_by_one_minus_gain_per_step_on_a_linear_sample(ratio):
    """Closed form: with N = k_eff d and the wall moved by gain e / k per step, k the last step's
    secant dN/dd = k_eff (the layer's K where the secant is below K / STIFFNESS_RANGE), the error
    e_n = target - N_n obeys e_(n+1) = (1 - gain k_eff / k) e_n once it is below RAMP N_n (above,
    the force grows by gain RAMP of itself per step, and below SEATING of the target by the speed
    cap's step): never past the target."""
    K, gain, target = 1e6, 0.3, 2.0
    k_eff = K * ratio
    k_s = k_eff * K / (K - k_eff) if ratio < 1 else 1e30
    forces = _servo_steps(K, k_s, gain, target, 400)
    err = target - forces
    q = 1 - gain
    linear = (err[1:-1] < RAMP * forces[1:-1]) & (err[1:-1] > 1e-9 * target)  # from the second step (a secant)
    assert linear.sum() >= 10
    assert np.allclose((err[2:] / err[1:-1])[linear], q, rtol=1e-6)
    ramp = (err[1:-1] > RAMP * forces[1:-1]) & (forces[1:-1] >= SEATING * target)
    if ramp.any():
        assert np.allclose((forces[2:] / forces[1:-1])[ramp], 1 + gain * RAMP, rtol=1e-6)
    assert forces.max() <= target


@pytest.mark.parametrize("ratio", [0.05, 1e-3])
def test_a_wall_backs_off_a_force_raised_from_elsewhere_with_a_lag_of_its_rise_over_gain(ratio):
    """Once at its target the wall's force is raised by r per step from elsewhere (a lateral wall
    while the platen shears the sample): the wall backs off, its secant falls outside the range
    (the force rises while it retreats) and a holding wall keeps its last one inside it, so the
    error obeys e_(n+1) = (1 - gain) e_n - r and settles at -r / gain. On the layer's K the lag
    is r K / (gain k_sample), 20 times that here, or more than RAMP of the force."""
    K, gain, target, r = 1e6, 0.3, 2.0, 2e-3
    k_eff = K * ratio
    k_s = k_eff * K / (K - k_eff)
    held = 200  # steps to reach the target first
    drift = lambda n: r * max(n - held, 0)  # noqa: E731

    forces = _servo_steps(K, k_s, gain, target, held + 300, drift=drift, keep_secant=True)
    assert abs(forces[held - 1] - target) < 1e-9 * target
    lag = forces[held:] - target
    assert np.all(lag <= r / gain * (1 + 1e-9))
    assert lag[-1] == pytest.approx(r / gain, rel=1e-6)
    on_layer = _servo_steps(K, k_s, gain, target, held + 300, drift=drift)
    assert on_layer[-1] - target > min(0.9 * r * K / (gain * k_eff), RAMP * target)


def test_a_wall_seats_at_its_speed_cap_until_it_carries_a_tenth_of_its_target():
    """Below SEATING of the target force the sample does not resist yet (a loose pack under a
    lid): the wall closes at its cap, then the force law takes over and never passes the target."""
    K, h, target = 1e6, 1e-4, 2.0
    forces = _servo_steps(K, 1e30, 0.3, target, 200, h, cap_share=0.01)
    steps = np.diff(np.concatenate([[0.0], forces]))
    n = int(np.argmax(forces >= SEATING * target))  # the first step that ends at or above SEATING of the target
    assert forces[0] == 0.0  # the first measurement, before any travel
    assert n >= 9 and np.allclose(steps[1 : n + 1], 0.01 * target, rtol=1e-9)
    assert forces.max() <= target and target - forces[-1] < 1e-6 * target


def test_a_sample_softer_than_the_range_is_driven_by_the_layers_law_and_never_overshoots():
    """A secant below K / STIFFNESS_RANGE is taken for the sample's own motion: the wall then moves
    by gain e / K per step, so the force grows monotonically and stays below the target."""
    forces = _servo_steps(1e6, 1e6 * 1e-6, 0.3, 2.0, 200)
    assert np.all(np.diff(forces[1:]) > 0) and forces.max() < 2.0


def test_without_contact_the_wall_moves_at_its_speed_cap_towards_the_grains():
    lid = PlaneWall(np.zeros(3), np.array([0.0, 0.0, -1.0]), ServoMotion((0.0, 0.0, -1.0)), "lid")
    servo = Servo(SpringBehindLayer(0.0, 1.0), lid, 1.0, max_speed=3e-3, target=100.0)
    servo.measure(np.zeros((1, 3)), None, None, 0.0)
    assert servo.speed(1e-4) == 3e-3
    servo.target = 0.0
    servo.force = 5.0  # pressed where it should let go: back off at the cap
    assert servo.speed(1e-4) == -3e-3


def test_a_servo_needs_a_steered_wall_and_a_sane_gain():
    fixed = PlaneWall(np.zeros(3), np.array([0.0, 0.0, -1.0]), name="lid")
    with pytest.raises(ValueError, match="prescribed motion"):
        Servo(SpringBehindLayer(1.0, 1.0), fixed, 1.0)
    steered = PlaneWall(np.zeros(3), np.array([0.0, 0.0, -1.0]), ServoMotion((0.0, 0.0, -1.0)), "lid")
    with pytest.raises(ValueError, match="gain"):
        Servo(SpringBehindLayer(1.0, 1.0), steered, 1.0, gain=1.5)


# ---------------------------------------------------------------- the loop on a grain
def pressed_cube(grain_model: str, mass_scaling: float):
    material = Material(90e9, 0.16, 2200.0 * mass_scaling)
    law, friction = default_contact_laws(SIZE, material.E, material.density, 9.81, 0.3, 0.3)
    grain = cube(SIZE).translated((0.0, 0.0, 0.5 * law.activation_gap + 0.5 * SIZE))
    floor = PlaneWall(np.zeros(3), np.array([0.0, 0.0, 1.0]), name="floor")
    lid_z = float(grain.vertices[:, 2].max()) + 0.5 * law.activation_gap
    lid = PlaneWall(np.array([0.0, 0.0, lid_z]), np.array([0.0, 0.0, -1.0]), ServoMotion((0.0, 0.0, -1.0)), "lid")
    scene = Scene.build([grain], material, law, friction, planes=[floor, lid], gravity=(0.0, 0.0, -9.81),
                        mass_scaling=mass_scaling, grain_model=grain_model)  # fmt: skip
    return scene, lid, lid_z


def run_path(scene, lid, lid_z, options, stresses, max_time=0.1):
    area = SIZE * SIZE
    servo = Servo(scene.contact, lid, area)
    # the oedometer's cap: the speed that gives an inertia number of 5e-4 at the target
    density = scene.material.density
    stages = [Stage(s, max_time, 0.5, max_speed=5e-4 * lid_z * np.sqrt(s / density) / SIZE) for s in stresses]
    path = LoadPath([servo], stages, lambda t, start: servo.travel_at(t) / lid_z, scene.bodies.lumped,
                    scene.bodies.vertex_ptr)  # fmt: skip
    integrator = make_integrator(options, scene)
    state, stats = integrator.initial_state(), RunStats()
    ends = []

    def on_step(st, info, h):
        before = path.current
        path.after_step(st, info)
        if path.current > before:  # a stage just ended: the contacts' stress there
            records = info.contact.records(scene.contact.all_positions(st.x, st.t))
            volume = area * (lid_z - servo.travel_at(st.t))
            sigma = love_weber_stress(records.a, records.b, records.point, records.force,
                                      scene.grain_centroids(st.x), volume)  # fmt: skip
            ends.append(sigma[2, 2])

    t_end = 0.0
    while not path.done and t_end < len(stresses) * max_time:
        t_end += 0.01
        state, stats = integrator.advance(state, t_end, on_step, stats)
    return path.stage_records(), ends


CASES = {
    "flexible-implicit": ("flexible", SolverOptions(integrator="implicit", dt_max=1e-3), 1.0),
    "rigid-implicit": ("rigid", SolverOptions(integrator="implicit", dt_max=1e-3), 1.0),
    "rigid-explicit": ("rigid", SolverOptions(integrator="explicit"), 1e4),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_each_stage_ends_at_its_target_at_rest_and_the_contacts_carry_the_lids_stress(case):
    model, options, scaling = CASES[case]
    scene, lid, lid_z = pressed_cube(model, scaling)
    # about 45 and 180 grain weights (times the scaling) on the lid, then back
    weight = float(scene.bodies.body_mass[0]) * 9.81
    stresses = [x * weight / SIZE**2 for x in (45.0, 180.0, 45.0)]
    records, love_weber = run_path(scene, lid, lid_z, options, stresses)
    assert [r["end_reason"] for r in records] == ["reached"] * 3, records
    for r, sigma_zz in zip(records, love_weber):
        assert abs(r["end_stress"] - r["target"]) <= 0.01 * r["target"]
        assert r["overshoot"] <= 0.05
        assert r["unbalanced"] <= 0.01
        # the floor carries the grain's weight too: half of it counts at the grain's centre
        assert sigma_zz == pytest.approx(r["end_stress"], rel=0.05)
    assert records[0]["loading"] and records[1]["loading"] and not records[2]["loading"]
    assert records[1]["end_strain"] > max(records[0]["end_strain"], records[2]["end_strain"])


def test_a_stage_begins_where_the_one_before_ended():
    """A frame written at the step that ends a stage belongs to the next stage, its strain measured
    from there: the next stage opens at that state, not a step later."""
    scene, lid, lid_z = pressed_cube("rigid", 1e4)
    weight = float(scene.bodies.body_mass[0]) * 9.81
    servo = Servo(scene.contact, lid, SIZE * SIZE)
    stages = [Stage(x * weight / SIZE**2, 0.1, 0.5, max_speed=1e-3) for x in (45.0, 180.0)]
    path = LoadPath([servo], stages, lambda t, start: servo.travel_at(t) - (start[1] if start else 0.0),
                    scene.bodies.lumped, scene.bodies.vertex_ptr, mark=lambda t: (t, servo.travel_at(t)))  # fmt: skip
    integrator = make_integrator(SolverOptions(integrator="explicit"), scene)
    seen = []

    def on_step(st, info, h):
        before = path.current
        path.after_step(st, info)
        if path.current > before and not path.done:  # what a frame at this state would read
            seen.append((path.current, path.stage_records()[-1]["stage"], path.start[0] == st.t,
                         path.strain(st.t, path.start)))  # fmt: skip

    state, t_end = integrator.initial_state(), 0.0
    while not path.done and t_end < 0.2:
        t_end += 0.01
        state, _ = integrator.advance(state, t_end, on_step, RunStats())
    assert seen == [(1, 1, True, 0.0)]


# ---------------------------------------------------------------- a servo wall in a scene config
def servo_scene(tmp_path, servo: dict, lid: dict | None = None) -> dict:
    """A cube on the floor under a plane lid with a `[walls.servo]` table (scene scenario)."""
    return {"scenario": "scene", "duration": 0.08,
            "material": {"E": 90e9, "nu": 0.16, "density": 2200.0},
            "solver": {"integrator": "implicit", "dt_max": 1e-3},
            "grains": [{"shape": "cube", "size": SIZE, "position": [0.0, 0.0, 0.5 * SIZE + 2e-6]}],
            "walls": [{"type": "plane", "name": "floor"},
                      {"type": "plane", "name": "lid", "point": [0.0, 0.0, SIZE + 4e-6], "normal": [0.0, 0.0, -1.0],
                       **(lid or {}), "servo": servo}],
            "output": {"every": 0.02, "vtk": False}}  # fmt: skip


# a square mesh lid 4 mm wide at the plane lid's height, its normals facing down at the grain
MESH_LID = (b"v -0.002 -0.002 0.001004\nv 0.002 -0.002 0.001004\nv 0.002 0.002 0.001004\n"
            b"v -0.002 0.002 0.001004\nf 1 3 2\nf 1 4 3\n")


@pytest.mark.parametrize("kind", ["plane", "mesh"])
def test_a_scene_wall_with_a_servo_table_follows_its_target_stress(tmp_path, kind):
    """The scene's lid, a plane or a mesh, holds 45 grain weights, then twice that from t = 0.04 s
    on (a ramp over 0.01 s): the walls.csv force at the frames after each is the target stress x
    area within 1 %."""
    weight = 2200.0 * SIZE**3 * 9.81
    s1 = 45 * weight / SIZE**2
    servo = {"stress": [s1, s1, 2 * s1], "times": [0.0, 0.04, 0.05], "area": SIZE**2, "max_speed": 2e-3}
    lid = None
    if kind == "mesh":
        (tmp_path / "lid.obj").write_bytes(MESH_LID)
        lid = {"type": "mesh", "file": str(tmp_path / "lid.obj")}
    cfg, module = checked_config(servo_scene(tmp_path, servo, lid))
    module.run(cfg, tmp_path / "run")
    rows = np.genfromtxt(tmp_path / "run" / "walls.csv", delimiter=",", names=True, dtype=None, encoding=None)
    lid = rows[rows["name"] == "lid"]
    force = {round(float(t), 3): f for t, f in zip(lid["time"], lid["fz"])}  # the grains push the lid up
    assert force[0.04] == pytest.approx(s1 * SIZE**2, rel=0.01)
    assert force[0.08] == pytest.approx(2 * s1 * SIZE**2, rel=0.01)


@pytest.mark.parametrize("servo, lid, message", [
    ({"stress": [1e3], "max_speed": 1e-3}, None, "walls[1].servo.area: required for a servo wall"),
    ({"stress": [1e3], "area": 1e-6}, None, "walls[1].servo.max_speed: required for a servo wall"),
    ({"stress": [float("nan")], "area": 1e-6, "max_speed": 1e-3}, None, "walls[1].servo.stress: must be a list of finite numbers"),
    ({"stress": [-5.0], "area": 1e-6, "max_speed": 1e-3}, None, "cannot pull"),
    ({"stress": [1e3, 2e3], "area": 1e-6, "max_speed": 1e-3}, None, "one stress per servo.times"),
    ({"stress": [1e3], "area": 1e-6, "max_speed": 1e-3}, {"times": [0.0, 1.0], "displacements": [[0, 0, 0], [0, 0, -1e-4]]},
     "walls[1]: a servo wall's motion is steered"),
])  # fmt: skip
def test_a_servo_wall_with_bad_keys_is_refused_in_one_line(tmp_path, servo, lid, message):
    with pytest.raises(ConfigError) as err:
        cfg, module = checked_config(servo_scene(tmp_path, servo, lid))
        module.run(cfg, tmp_path / "run")
    assert message in str(err.value) and "\n" not in str(err.value)
