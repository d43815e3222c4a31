"""The direct shear test (docs/direct-shear.md): its measures on closed-form curves, and a 20-grain
rigid sample in a split box: the lid's servo brings it to the normal stress at rest and holds it
while the lower half moves at its constant speed, and the forces on the box balance (the lower
half's push along x is carried by the upper half and the lid: momentum, read from other walls)."""

import json

import numpy as np
import pytest

from vemdem.analysis.direct_shear import (
    HEADER,
    coulomb_fit,
    dilation_angle,
    peak,
    peak_stresses,
    residual,
    residual_stresses,
    shear_figures,
)
from vemdem.scenarios.registry import checked_config

SIGMA_N = 20e3
CONFIG = {
    "scenario": "direct_shear",
    "pack": {"n_grains": 20, "seed": 3, "mu_s": 0.0, "mu_d": 0.0, "grains": {"size": 1.0e-3, "vertices": 8},
             "box": {"width": 3.6e-3, "depth": 2.6e-3}},
    "normal": {"stress": SIGMA_N, "max_time": 0.05},
    "shear": {"max_displacement": 0.1, "inertia_number": 2e-3},
    "servo": {"inertia_number": 2e-3},
    "model": {"grains": "rigid"},
    "solver": {"integrator": "explicit"},
    "contact": {"mu_s": 0.3, "mu_d": 0.3, "reference_force": 2 * SIGMA_N * 1.0e-3**2},  # the per-stress law at
    "output": {"every": 1e-3, "vtk": False},  # 2 sigma d^2: this file's subject is not the law (docs/contact.md)
}  # fmt: skip


# ------------------------------------------------------------------ measures in closed form
def test_peak_residual_and_dilation_of_a_known_curve():
    # tau / sigma_n rises to 0.8 at 1 mm, decays to 0.5; the lid rises at slope 0.2 until 1 mm, then stays
    x = np.linspace(0.0, 5e-3, 501)
    ratio = np.where(x < 1e-3, 0.8 * x / 1e-3, 0.5 + 0.3 * np.exp(-(x - 1e-3) / 0.3e-3))
    y = np.where(x < 1e-3, 0.2 * x, 0.2e-3)
    p = peak(x, ratio)
    assert p["phi_peak_deg"] == pytest.approx(np.degrees(np.arctan(0.8)))
    assert p["shear_displacement_at_peak"] == pytest.approx(1e-3)
    r = residual(x, ratio)  # the last 20 %: 4-5 mm, where the decay is 3e-5 of its start
    assert r["phi_residual_deg"] == pytest.approx(np.degrees(np.arctan(0.5)), abs=1e-3)
    assert r["phi_residual_spread_deg"] < 1e-3
    assert dilation_angle(x, y)["dilation_angle_deg"] == pytest.approx(np.degrees(np.arctan(0.2)))
    # a contracting sample: a negative angle
    assert dilation_angle(x, -0.1 * x)["dilation_angle_deg"] == pytest.approx(-np.degrees(np.arctan(0.1)))


def test_failure_states_are_the_stresses_at_the_peak_and_over_the_residual_window():
    # the lid's stress swings around 50 kPa; tau follows the known ratio of the curve above
    x = np.linspace(0.0, 5e-3, 501)
    ratio = np.where(x < 1e-3, 0.8 * x / 1e-3, 0.5 + 0.3 * np.exp(-(x - 1e-3) / 0.3e-3))
    sigma_n = 50e3 * (1.0 + 0.05 * np.sin(x / 1e-4))
    tau = ratio * sigma_n
    p = peak_stresses(ratio, sigma_n, tau)
    at = np.argmin(np.abs(x - 1e-3))
    assert p == {"sigma_n_peak_Pa": pytest.approx(sigma_n[at]), "tau_peak_Pa": pytest.approx(0.8 * sigma_n[at])}
    r = residual_stresses(x, ratio, sigma_n, tau)
    last = x >= 4e-3 - 1e-15
    assert r["sigma_n_residual_Pa"] == pytest.approx(sigma_n[last].mean())
    assert r["tau_residual_Pa"] == pytest.approx(0.5 * sigma_n[last].mean(), rel=1e-4)


def test_coulomb_fit_recovers_a_known_line_and_refuses_what_has_none():
    sigma = np.array([25e3, 50e3, 100e3])
    fit = coulomb_fit(sigma, 3e3 + sigma * np.tan(np.radians(35.0)))
    assert fit["phi_deg"] == pytest.approx(35.0) and fit["cohesion_Pa"] == pytest.approx(3e3)
    assert fit["r2"] == pytest.approx(1.0) and fit["n"] == 3
    # scattered states: the least-squares line (numpy's polyfit as the reference)
    tau = np.array([20e3, 41e3, 79e3])
    slope, intercept = np.polyfit(sigma, tau, 1)
    fit = coulomb_fit(sigma, tau)
    assert np.tan(np.radians(fit["phi_deg"])) == pytest.approx(slope) and fit["cohesion_Pa"] == pytest.approx(intercept)
    assert 0.99 < fit["r2"] < 1.0
    one = coulomb_fit([50e3], [40e3])  # one test: its cohesionless angle
    assert one["phi_deg"] == pytest.approx(np.degrees(np.arctan(0.8))) and one["cohesion_Pa"] == 0.0
    with pytest.raises(ValueError, match="same normal stress"):
        coulomb_fit([50e3, 50e3], [30e3, 40e3])
    with pytest.raises(ValueError, match="falls with sigma_n"):
        coulomb_fit([25e3, 50e3], [30e3, 20e3])
    with pytest.raises(ValueError, match="finite and positive"):
        coulomb_fit([25e3, np.nan], [30e3, 20e3])


def test_the_coulomb_line_through_the_origin_is_the_least_squares_one_without_an_intercept():
    sigma = np.array([25e3, 50e3, 100e3])
    exact = coulomb_fit(sigma, sigma * np.tan(np.radians(31.0)), through_origin=True)
    assert exact["phi_deg"] == pytest.approx(31.0) and exact["cohesion_Pa"] == 0.0 and exact["r2"] == pytest.approx(1.0)
    tau = np.array([20e3, 41e3, 79e3])
    (slope,), *_ = np.linalg.lstsq(sigma[:, None], tau, rcond=None)  # one column: no intercept
    fit = coulomb_fit(sigma, tau, through_origin=True)
    assert np.tan(np.radians(fit["phi_deg"])) == pytest.approx(slope) and fit["cohesion_Pa"] == 0.0
    # two tests at one normal stress still give a line through the origin
    same = coulomb_fit([50e3, 50e3], [30e3, 40e3], through_origin=True)
    assert np.tan(np.radians(same["phi_deg"])) == pytest.approx(0.7)


def test_measures_refuse_runs_too_short_and_figures_say_why():
    with pytest.raises(ValueError, match="residual state needs 3"):
        residual(np.array([0.0, 1e-3]), np.array([0.3, 0.4]))
    with pytest.raises(ValueError, match="needs 4"):
        dilation_angle(np.zeros(3), np.zeros(3))
    rows = np.zeros((3, len(HEADER)))
    rows[:, HEADER.index("stage")] = [0, 1, 1]
    out = shear_figures(rows)
    assert out["shear_rows"] == 2 and "residual_error" in out and "dilation_error" in out


# ------------------------------------------------------------------ the scenario
@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("direct_shear")
    cfg, module = checked_config(CONFIG)
    summary = module.run(cfg, out)
    rows = np.genfromtxt(out / "shear.csv", delimiter=",", names=True)
    return out, summary, rows


def test_the_lid_holds_the_normal_stress_while_the_lower_half_moves_at_its_speed(run):
    _, summary, rows = run
    consolidation, shear = summary["stages"]
    assert consolidation["end_reason"] == "reached" and consolidation["unbalanced"] <= 0.01
    assert consolidation["end_stress"] == pytest.approx(SIGMA_N, rel=0.01)
    assert shear["end_reason"] == "max_displacement"
    moving = rows[(rows["stage"] == 1) & (rows["shear_displacement"] < 0.1 * 3.6e-3)]
    speed = np.polyfit(moving["time"], moving["shear_displacement"], 1)[0]
    assert speed == pytest.approx(summary["shear_speed"], rel=1e-6)
    # the lid follows the sample's compaction at the shear's start with a lag: over three runs of
    # this 20-grain sample perturbed at round-off its mean stress here was 18.8, 19.0 and 20.3 kPa
    assert np.mean(moving["sigma_n"]) == pytest.approx(SIGMA_N, rel=0.1)
    assert summary["phi_peak_deg"] > 10.0 and np.all(np.isfinite(moving["tau_over_sigma_n"]))
    # the summary's held stress is the shear frames' own
    sheared = rows["sigma_n"][rows["stage"] == 1]
    assert summary["sigma_n_error_mean"] == pytest.approx(np.mean(sheared / SIGMA_N - 1.0), rel=1e-9, abs=1e-12)
    assert summary["sigma_n_error_max"] == pytest.approx(np.max(np.abs(sheared / SIGMA_N - 1.0)), rel=1e-9)


def test_the_box_is_in_balance_along_the_shear(run):
    out, summary, rows = run
    walls = np.genfromtxt(out / "walls.csv", delimiter=",", names=True, dtype=None, encoding="utf-8")
    shear_times = rows["time"][rows["stage"] == 1][2:]
    pushes, carried = [], []
    for t in shear_times:
        at = walls[np.isclose(walls["time"], t)]
        lower = sum(float(w["fx"]) for w in at if w["name"] in ("floor", "lower -x", "lower +x", "lower -x plate"))
        upper = sum(float(w["fx"]) for w in at
                    if w["name"] in ("upper -x", "upper +x", "upper +x plate", "lid", "wall -y", "wall +y"))
        pushes.append(-lower)
        carried.append(upper)
    # the grains' momentum hardly changes in a quasi-static shear: what the lower half pushes,
    # the upper half and the lid hold back, within a few % of the push
    pushes, carried = np.array(pushes), np.array(carried)
    assert np.median(np.abs(pushes - carried) / np.abs(pushes)) < 0.05
    assert np.mean(pushes) > 0


def test_summary_and_figure(run):
    out, _, _ = run
    on_disk = json.loads((out / "summary.json").read_text(), parse_constant=lambda c: pytest.fail(c))
    for key in ("phi_peak_deg", "phi_residual_deg", "dilation_angle_deg", "max_inertia_number", "sigma_n_peak_Pa",
                "tau_peak_Pa", "sigma_n_residual_Pa", "tau_residual_Pa"):  # fmt: skip
        assert isinstance(on_disk[key], float), key
    assert on_disk["tau_peak_Pa"] / on_disk["sigma_n_peak_Pa"] == pytest.approx(on_disk["ratio_peak"])
    assert (out / "shear.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def _normals(wall):
    v = wall.vertices[wall.faces]
    n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def test_the_frames_plates_close_the_box_past_the_travel():
    """The halves' ends no longer face each other once the lower half has moved: the lower half's
    -x plate at the split (facing up, moving with the half) and the upper half's +x plate at the
    split's top (facing down, held) reach a grain past the largest travel outwards."""
    from types import SimpleNamespace

    from vemdem.scenarios.direct_shear import shear_box

    size = 1e-3
    grains = [SimpleNamespace(volume=np.pi * size**3 / 6.0)] * 2
    initial = SimpleNamespace(meta={"box": (4e-3, 3e-3), "floor": 0.0, "centre": (0.0, 0.0)}, grains=grains,
                              x=np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 2e-3]]))  # fmt: skip
    cfg, _ = checked_config({**CONFIG, "shear": {"max_displacement": 0.4}, "sample": {"opening": 0.2}})
    cell = shear_box(cfg, initial)
    walls = {w.name: w for w in cell.meshes}
    split = cfg["sample"]["split"] * 2e-3
    lower, upper = walls["lower -x plate"], walls["upper +x plate"]
    assert np.allclose(_normals(lower), [0, 0, 1]) and np.allclose(_normals(upper), [0, 0, -1])
    assert np.allclose(lower.vertices[:, 2], split) and np.allclose(upper.vertices[:, 2], split + 0.2 * size)
    # the inner edges stand back from the sides' by twice the contact layer (0.01 d)
    reach, back = 0.4 * 4e-3 + size, 0.02 * size
    assert lower.vertices[:, 0].min() == pytest.approx(-2e-3 - reach)
    assert lower.vertices[:, 0].max() == pytest.approx(-2e-3 - back)
    assert upper.vertices[:, 0].min() == pytest.approx(2e-3 + back)
    assert upper.vertices[:, 0].max() == pytest.approx(2e-3 + reach)
    assert lower.motion is cell.drive and upper.motion is not cell.drive  # the upper frame is held
    # the plates span the box's depth, and the sides still face into the box
    assert np.ptp(lower.vertices[:, 1]) == pytest.approx(3e-3) and np.ptp(upper.vertices[:, 1]) == pytest.approx(3e-3)
    assert np.allclose(_normals(walls["lower -x"]), [1, 0, 0]) and np.allclose(_normals(walls["upper +x"]), [-1, 0, 0])


def test_the_upper_frame_rides_with_the_lids_rise_and_never_sinks():
    """The upper frame's speed rule (lab.shear_box.ShearBox.frame_speed), steered step by step along
    a lid that rises, sinks below where the shear began, and rises again: the frame follows the
    rise, stops at its start while the lid is below it, and moves again only once the lid is back
    above the frame."""
    from types import SimpleNamespace

    from vemdem.contact.walls import ServoMotion
    from vemdem.lab.shear_box import ShearBox

    cell = ShearBox.__new__(ShearBox)
    cell.lid, cell.drive = SimpleNamespace(motion=ServoMotion((0.0, 0.0, -1.0))), ServoMotion((1, 0, 0))
    cell.frame = ServoMotion((0.0, 0.0, 1.0))
    start = (0.0, 0.0, 0.0)
    dt, rise, lifted = 1e-4, [], []
    lid_up = [1e-3] * 10 + [-1e-3] * 20 + [1e-3] * 20  # m/s: up by 1 um, down to 1 um below, up to 1 um above
    for i, up in enumerate(lid_up):
        t = i * dt
        cell.lid.motion.steer(t, -up)
        cell.frame.steer(t, cell.frame_speed(start, t))
        rise.append(cell.displacements(start, t + dt)[1])
        lifted.append(cell.frame.travel(t + dt))
    rise, lifted = np.array(rise), np.array(lifted)
    np.testing.assert_allclose(lifted[:10], rise[:10], atol=1e-15)  # rides up with the lid
    assert lifted.min() >= -1e-15  # never below its start
    expected = np.maximum(rise, 0.0)
    assert np.max(np.abs(lifted - expected)) <= 1e-3 * dt + 1e-15  # within one step's travel of max(rise, 0)
    assert lifted[-1] == pytest.approx(rise[-1], abs=1e-3 * dt)
