"""The oedometer's measures (analysis/oedometer.py) on hand-built stage records whose answers are
known: a linear-elastic sample with a stiffer unloading branch, and a load-unload cycle whose
work is a trapezoid."""

import numpy as np
import pytest

from vemdem.analysis.oedometer import (
    HEADER,
    hysteresis_energy,
    inertia_number,
    moduli,
    modulus_exponent,
    oedometer_figures,
    turning_points,
)


def record(stage, target, end_stress, end_strain, work=0.0, loading=True, sigma_h=None, contacts=None,
           reason="reached", start_stress=0.0, overshoot=0.0):  # fmt: skip
    r = {"stage": stage, "target": target, "end_stress": end_stress, "end_strain": end_strain, "work": work,
         "loading": loading, "end_reason": reason, "start_stress": start_stress, "overshoot": overshoot,
         "unbalanced": 0.001, "end_time": 0.1 * (stage + 1)}  # fmt: skip
    if sigma_h is not None:
        r["sigma_h_end"] = sigma_h
    if contacts is not None:
        r["sigma_v_contacts_end"] = contacts
    return r


# a sample with constrained modulus M_load = 10 MPa on first loading and M_un = 40 MPa unloading
# and reloading, K0 = 0.4: the path 25 -> 50 -> 100 kPa, unload to 25, reload to 100
M_LOAD, M_UN, K0 = 10e6, 40e6, 0.4


def elastic_path():
    eps = {25e3: 25e3 / M_LOAD, 50e3: 50e3 / M_LOAD, 100e3: 100e3 / M_LOAD}
    top = eps[100e3]
    back = top - 75e3 / M_UN
    return [record(0, 25e3, 25e3, eps[25e3], sigma_h=K0 * 25e3, contacts=25e3 * 1.02),
            record(1, 50e3, 50e3, eps[50e3], sigma_h=K0 * 50e3, contacts=50e3 * 0.97),
            record(2, 100e3, 100e3, top, sigma_h=K0 * 100e3, contacts=100e3 * 1.01),
            record(3, 25e3, 25e3, back, loading=False, sigma_h=0.7 * 25e3, contacts=25e3),
            record(4, 100e3, 100e3, top, sigma_h=K0 * 100e3, contacts=100e3)]  # fmt: skip


def test_k0_moduli_and_the_residual_strain_of_an_elastic_path():
    stages = elastic_path()
    out = oedometer_figures(stages, np.zeros((0, len(HEADER))))
    assert out["K0"] == pytest.approx(K0) and out["K0_by_stage"] == pytest.approx([K0] * 3)  # first loading only
    loading = [m["modulus_Pa"] for m in out["constrained_modulus_loading_Pa"]]
    assert loading == pytest.approx([M_LOAD, M_LOAD, M_UN])  # 25->50, 50->100, the reloading
    assert [m["kind"] for m in out["constrained_modulus_loading_Pa"]] == ["virgin", "virgin", "reloading"]
    assert [m["modulus_Pa"] for m in out["constrained_modulus_unloading_Pa"]] == pytest.approx([M_UN])
    assert out["residual_strain"] == pytest.approx(100e3 / M_LOAD - 75e3 / M_UN)
    assert out["love_weber_error_at_turns"] == pytest.approx(0.03)
    assert out["stress_error_at_turns"] == 0.0


def power_law_path(exponent: float, stresses, C: float = 3e3) -> list[dict]:
    """First loading of a sample whose tangent modulus is M = C sigma^m: eps = sigma^(1 - m) / (C (1 - m))."""
    return [record(k, s, s, s ** (1 - exponent) / (C * (1 - exponent))) for k, s in enumerate(stresses)]


@pytest.mark.parametrize("exponent", [1.0 / 3.0, 0.5, 0.8])
def test_the_modulus_exponent_of_a_power_law(exponent):
    """Stages a constant ratio apart: the secant moduli are C' sigma_mean^m exactly (the exponent to
    round-off); unevenly spaced, the fit is within a few hundredths."""
    stresses = [10e3, 30e3, 90e3, 270e3, 810e3]
    out = oedometer_figures(power_law_path(exponent, stresses), np.zeros((0, len(HEADER))))
    assert out["modulus_exponent"] == pytest.approx(exponent, rel=1e-9)
    uneven = oedometer_figures(power_law_path(exponent, [10e3, 30e3, 100e3, 300e3, 1e6]), np.zeros((0, len(HEADER))))
    assert uneven["modulus_exponent"] == pytest.approx(exponent, abs=0.02)


def test_the_modulus_exponent_takes_first_loading_only_and_needs_two_intervals():
    stages = elastic_path()  # 25 -> 50 -> 100 kPa at one modulus, then unloading and reloading
    assert oedometer_figures(stages, np.zeros((0, len(HEADER))))["modulus_exponent"] == pytest.approx(0.0, abs=1e-12)
    loading, _ = moduli(turning_points(stages[:2]))
    assert modulus_exponent(loading) is None  # one interval: no slope
    assert oedometer_figures(stages[:2], np.zeros((0, len(HEADER))))["modulus_exponent"] is None


def test_the_hysteresis_of_a_cycle_is_the_net_work_of_its_unloading_and_reloading():
    # unloading gives back 3 mJ, reloading takes 5 mJ: 2 mJ stay in the sample
    stages = elastic_path()
    stages[3]["work"], stages[4]["work"] = -3e-3, 5e-3
    assert hysteresis_energy(turning_points(stages)) == pytest.approx(2e-3)
    # a load-unload cycle without a reloading: the net work of the whole path
    cycle = [record(0, 100e3, 100e3, 0.01, work=4e-3), record(1, 1e3, 1e3, 0.006, work=-1.5e-3, loading=False)]
    assert hysteresis_energy(turning_points(cycle)) == pytest.approx(2.5e-3)
    assert hysteresis_energy(turning_points(cycle[:1])) is None


def test_a_stage_that_did_not_end_is_no_turning_point_and_moduli_skip_a_zero_strain_step():
    stages = elastic_path()
    stages[4]["end_reason"] = ""
    assert [p["stage"] for p in turning_points(stages)] == [0, 1, 2, 3]
    loading, unloading = moduli(turning_points([record(0, 1e3, 1e3, 0.01), record(1, 2e3, 2e3, 0.01)]))
    assert loading == [] and unloading == []


def test_inertia_number_follows_its_definition():
    # I = (v / H) d / sqrt(sigma / rho)
    assert inertia_number(1e-3, 4e-3, 1e-3, 1e5, 2500.0) == pytest.approx(0.25e-3 / np.sqrt(40.0))
    assert inertia_number(-1e-3, 4e-3, 1e-3, 1e5, 2500.0) == inertia_number(1e-3, 4e-3, 1e-3, 1e5, 2500.0)
    assert inertia_number(1e-3, 4e-3, 1e-3, 0.0, 2500.0) == np.inf


def test_each_grains_largest_strain_over_the_frames_and_the_validated_range(tmp_path):
    from vemdem.analysis.oedometer import VALIDATED_STRAIN, grain_strain_maxima, grain_strain_summary

    path = tmp_path / "grains.csv"
    rows = ["time,grain,x,y,z,vx,vy,vz,strain"]
    for t, strains in ((0.0, (0.01, 0.02, 0.0)), (0.1, (0.05, 0.25, 0.01)), (0.2, (0.04, 0.21, 0.3))):
        rows += [f"{t},{g},0,0,0,0,0,0,{e}" for g, e in enumerate(strains)]
    path.write_text("\n".join(rows) + "\n")
    strains = grain_strain_maxima(path)
    assert strains.tolist() == [0.05, 0.25, 0.3]
    summary = grain_strain_summary(strains)
    assert summary["max"] == 0.3 and summary["grain"] == 2 and summary["validated_range"] == VALIDATED_STRAIN
    assert summary["grains_past_validated_range"] == 2


# a 4-grain oedometer loaded to 400 Pa: enough to press the grains against the side walls
SMALL = {"scenario": "oedometer", "pack": {"n_grains": 4, "seed": 5, "grains": {"vertices": 8, "size": 1.2e-3},
                                           "box": {"width": 3.2e-3, "depth": 3.2e-3}},
         "settle": {"min_time": 0.04}, "output": {"every": 2e-3, "vtk": False}, "lid": {"gap": 0.01},
         "servo": {"inertia_number": 1e-2}, "stages": [{"stress": 400.0, "max_time": 0.03}],
         # the per-stress law at 2 x 400 Pa x d^2: these tests' subject is the ring and the pack, not the law
         "contact": {"reference_force": 2 * 400.0 * 1.2e-3**2}}  # fmt: skip


def _side_walls_vertical_force(tmp_path, ring_friction: bool):
    from vemdem.scenarios.registry import checked_config

    out = tmp_path / f"ring_{ring_friction}"
    cfg, module = checked_config({**SMALL, "ring": {"friction": ring_friction}})
    summary = module.run(cfg, out)
    rows = np.genfromtxt(out / "walls.csv", delimiter=",", names=True, dtype=None, encoding=None)
    sides = np.isin(rows["name"], ["wall -x", "wall +x", "wall -y", "wall +y"])
    return np.abs(rows["fz"][sides]), np.abs(rows["fx"][sides]) + np.abs(rows["fy"][sides]), summary


def test_a_lubricated_ring_carries_no_vertical_force_and_a_rough_one_does(tmp_path):
    """The ring's friction (`ring.friction`): smooth by default, so that the side walls press the
    sample only along their normals and the lid's stress is the sample's; rough, they carry some
    of the load by friction."""
    smooth_fz, smooth_normal, summary = _side_walls_vertical_force(tmp_path, False)
    rough_fz, rough_normal, _ = _side_walls_vertical_force(tmp_path, True)
    assert smooth_normal.max() > 0 and rough_normal.max() > 0  # the grains press the side walls in both
    assert smooth_fz.max() <= 1e-12 * smooth_normal.max()  # round-off of the normal force alone
    assert rough_fz.max() > 1e-3 * rough_normal.max()
    # the given law (the per-stress law at 2 x 400 Pa x d^2) is the one the test loads with
    d = SMALL["pack"]["grains"]["size"]
    assert summary["contact"]["reference_force"] == pytest.approx(2 * 400.0 * d**2)


def test_a_sweeps_shared_pack_is_the_one_the_oedometer_settles_and_may_be_rigid(tmp_path):
    """A sweep settles its cases' shared pack from registry.pack_stage, and the run then finds it
    in DIR/pack: for the oedometer that pack is settled under the test's law (the one its run
    settles; a pack under the weight's law would be refused there as another pack).
    `[pack] model = "rigid"` settles it with rigid grains and explicit steps for a flexible test."""
    import json

    from vemdem.scenarios.oedometer import pack_config_for
    from vemdem.scenarios.pack import initial_state_from
    from vemdem.scenarios.registry import checked_config, pack_stage, settle_pack

    raw = {**SMALL, "pack": {**SMALL["pack"], "model": "rigid"}}
    fingerprint, config = pack_stage(raw)
    d = SMALL["pack"]["grains"]["size"]
    assert config["contact"]["reference_force"] == pytest.approx(2 * 400.0 * d**2)
    assert config["model"]["grains"] == "rigid" and config["solver"]["integrator"] == "explicit"
    settle_pack(config, tmp_path / "pack")
    assert json.loads((tmp_path / "pack" / "summary.json").read_text())["config_fingerprint"] == fingerprint
    cfg, _ = checked_config(raw)
    assert cfg["model"]["grains"] == "flexible"
    state, path = initial_state_from(cfg, None, tmp_path, pack_cfg=pack_config_for(cfg))  # reused, not refused
    assert path == tmp_path / "pack" / "state.npz" and state.x.shape[0] > 0
    _, flexible = pack_stage(SMALL)
    assert flexible["model"]["grains"] == "flexible" and flexible["solver"]["integrator"] == "implicit"
