"""The triaxial scenario (docs/triaxial.md) on a 12-grain rigid sample: consolidation brings all
five moving walls to the confining stress with the sample at rest, the shear compresses it at the
platen's constant strain rate while the lateral walls hold the confining stress, the walls' stresses
agree with the contacts' Love-Weber stress, and a given reference force is the law in use."""

import json

import numpy as np
import pytest

from vemdem.lab.path import unbalanced_force
from vemdem.scenarios.registry import checked_config
from vemdem.solver.state import State

SIGMA_C = 20e3
# the pack's mean equivalent diameter (summary.json's grain_size): the per-stress law 2 sigma_3 d^2 on it
GRAIN_SIZE = 0.0009771359919118823
CONFIG = {
    "scenario": "triaxial",
    "pack": {"n_grains": 12, "seed": 3, "mu_s": 0.0, "mu_d": 0.0, "grains": {"size": 1.0e-3, "vertices": 8},
             "box": {"width": 2.6e-3, "depth": 2.6e-3}},
    "consolidation": {"stress": SIGMA_C, "max_time": 0.05},
    "shear": {"max_strain": 0.06, "inertia_number": 2e-3},
    "servo": {"inertia_number": 2e-3},
    "model": {"grains": "rigid"},
    "solver": {"integrator": "explicit"},
    "contact": {"mu_s": 0.3, "mu_d": 0.3, "reference_force": 2 * SIGMA_C * GRAIN_SIZE**2},  # the per-stress law at
    "output": {"every": 1e-3, "vtk": False},  # 2 sigma d^2: this file's subject is not the law (docs/contact.md)
}  # fmt: skip


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("triaxial")
    cfg, module = checked_config(CONFIG)
    summary = module.run(cfg, out)
    rows = np.genfromtxt(out / "triaxial.csv", delimiter=",", names=True)
    return out, summary, rows


def test_consolidation_reaches_the_confining_stress_at_rest(run):
    _, summary, rows = run
    consolidation, shear = summary["stages"]
    assert consolidation["name"] == "consolidation" and consolidation["end_reason"] == "reached"
    # the top platen's stress where the stage ended, and the sample at rest
    assert consolidation["end_stress"] == pytest.approx(SIGMA_C, rel=0.01)
    assert consolidation["unbalanced"] <= 0.1  # the shear tests' servo.unbalanced_tolerance
    # the lateral walls at the first shear frame, a step after the stage ended
    first = rows[rows["stage"] == 1][0]
    assert first["sigma_3"] == pytest.approx(SIGMA_C, rel=0.02)
    assert shear["name"] == "shear" and shear["end_reason"] == "max_strain"


def test_shear_at_constant_strain_rate_under_the_confining_stress(run):
    _, summary, rows = run
    shear = rows[rows["stage"] == 1]
    # the platen's constant speed: axial strain linear in time, at the rate the inertia number sets
    rate = 2e-3 * np.sqrt(SIGMA_C / 2200.0) / summary["grain_size"]
    moving = shear[shear["axial_strain"] < 0.06]  # the frame after the stage's end finds the platen held
    fit = np.polyfit(moving["time"], moving["axial_strain"], 1)
    assert fit[0] == pytest.approx(rate, rel=1e-6) == pytest.approx(summary["axial_strain_rate"], rel=1e-12)
    assert shear["axial_strain"][-1] >= 0.06
    # the lateral servos hold the confining stress: on average within 1 %, every frame within 10 %
    assert np.mean(shear["sigma_3"]) == pytest.approx(SIGMA_C, rel=0.01)
    assert np.all(np.abs(shear["sigma_3"] / SIGMA_C - 1.0) < 0.10)
    # the sample carries a deviator: q rises above zero and the ratio gives an angle in a sand's range
    assert summary["q_peak"] > 0.5 * SIGMA_C
    assert 15.0 < summary["phi_peak_deg"] < 50.0
    assert summary["preparation"]["name"] == "dense"


def test_the_walls_stresses_are_the_contacts_love_weber_stress(run):
    _, _, rows = run
    loaded = rows[rows["stage"] == 1]
    # the walls measure force over area, the contacts the sample's mean stress: independent sums
    # over different records (wall records against all records' branch vectors)
    for wall, contacts in (("sigma_1", "sigma_1_contacts"), ("sigma_3", "sigma_3_contacts")):
        error = np.abs(loaded[contacts] / loaded[wall] - 1.0)
        assert np.median(error) < 0.05, (wall, error)


def test_a_given_reference_force_is_the_law_in_use(run):
    """`[contact] reference_force` sets the per-force law in place of the material's (here the
    per-stress law at 2 sigma_3 d^2); the friction springs stay within the contact layer under it."""
    _, summary, _ = run
    assert summary["contact"]["reference_force"] == pytest.approx(CONFIG["contact"]["reference_force"], rel=1e-9)
    assert summary["grain_size"] == pytest.approx(GRAIN_SIZE, rel=1e-12)  # the pack the law was pinned for
    assert summary["contact"]["penalty_exponent"] == 2.0
    assert summary["friction"]["beyond_contact_layer"] is False


def test_summary_is_strict_json_with_the_named_keys(run):
    out, summary, _ = run
    on_disk = json.loads((out / "summary.json").read_text(), parse_constant=lambda c: pytest.fail(c))
    for key in ("phi_peak_deg", "phi_cs_deg", "phi_cs_spread_deg", "dilatancy_angle_deg", "E50_Pa",
                "max_inertia_number", "sigma_3_peak_Pa", "sigma_1_peak_Pa", "sigma_3_cs_Pa", "sigma_1_cs_Pa",
                "sigma_3_error_mean", "sigma_3_error_abs_mean", "sigma_3_error_max"):
        assert isinstance(on_disk[key], float), key
    assert (out / "triaxial.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_unbalanced_force_of_rigid_and_flexible_grains():
    # two grains of two vertices each; grain 0 at rest, grain 1 pushed by a net 3 N; contact forces of 2 N
    lumped = np.array([1.0, 1.0, 2.0, 2.0])
    vertex_ptr = np.array([0, 2, 4])

    class Contact:
        n_contacts = 2
        pair_force = np.array([[0.0, 0.0, 2.0], [0.0, 2.0, 0.0]])

    a = np.array([[0, 0, 1.0], [0, 0, -1.0], [0, 0, 0.5], [0, 0, 1.0]])
    flexible = State(0.0, np.zeros((4, 3)), np.zeros((4, 3)), a)
    assert unbalanced_force(flexible, lumped, vertex_ptr, Contact) == pytest.approx((0.0 + 3.0) / 2 / 2.0)
    # rigid grains: the net force is the body's, the vertices' accelerations are not kept
    rigid = State(0.0, np.zeros((4, 3)), np.zeros((4, 3)), np.zeros((4, 3)),
                  bodies={"force": np.array([[4.0, 0.0, 0.0], [0.0, 0.0, 0.0]])})
    assert unbalanced_force(rigid, lumped, vertex_ptr, Contact) == pytest.approx(4.0 / 2 / 2.0)
