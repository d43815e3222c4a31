"""benchmarks/jam_state.py writes a lid run's state where `bench_newton.py --state` rebuilds the run's
scene: the lid where it stood, the run's contact law and friction history (the lid jam's
Newton iteration measured by a benchmark anyone can rerun, from benchmarks/data/lid515_jam.npz)."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

from vemdem.driver import loop as loop_mod
from vemdem.io.results import wall_force_record
from vemdem.io.state import load_state
from vemdem.scenarios.registry import checked_config

ROOT = Path(__file__).resolve().parents[1]
PACK = ROOT / "tests" / "data" / "pack30_mu015.npz"
JAM = ROOT / "benchmarks" / "data" / "lid515_jam.npz"
# the 30-grain pack reaches 4.93 mm: the lid presses it from its second frame on
CONFIG = {"scenario": "lid_compression", "initial_state": str(PACK), "output": {"vtk": False},
          "lid": {"start": 4.95e-3, "end": 4.88e-3, "speed": 0.02, "frames": 4},
          "contact": {"mu_s": 0.15, "mu_d": 0.15, "damping_ratio": 0.05},
          "solver": {"integrator": "implicit", "mass_scaling": 1.0}}  # fmt: skip
STOP_AT = 4  # checkpoints: the start, then frames 1-3 of the loading


def _module(name):
    sys.path.insert(0, str(ROOT / "benchmarks"))  # bench_newton imports bench_dynamics
    try:
        spec = importlib.util.spec_from_file_location(name, ROOT / "benchmarks" / f"{name}.py")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        return module
    finally:
        sys.path.remove(str(ROOT / "benchmarks"))


@pytest.fixture(scope="module")
def interrupted(tmp_path_factory):
    """A lid run stopped at its third frame, the lid in the pack."""
    out = tmp_path_factory.mktemp("lid")
    cfg, module = checked_config(CONFIG)
    original, written = loop_mod.save_checkpoint, []

    def stopping(path, *args, **kwargs):
        original(path, *args, **kwargs)
        written.append(path)
        if len(written) == STOP_AT:
            raise KeyboardInterrupt

    loop_mod.save_checkpoint = stopping
    try:
        with pytest.raises(KeyboardInterrupt):
            module.run(cfg, out)
    finally:
        loop_mod.save_checkpoint = original
    return cfg, out


def test_the_bench_scene_is_the_runs_scene_at_the_checkpoint(interrupted, tmp_path):
    cfg, out = interrupted
    jam, bench = _module("jam_state"), _module("bench_newton")
    meta = jam.jam_state(out / "checkpoint.npz", PACK, cfg, tmp_path / "jam.npz")
    with np.load(out / "checkpoint.npz") as d:
        t, x = float(d["t"]), d["x"]
    assert meta["lid"]["start"] == pytest.approx(4.95e-3 - 0.02 * t, rel=1e-12)
    assert meta["contact"]["damping_ratio"] == 0.05 and meta["contact"]["mu_s"] == 0.15
    name, scene, state = bench.state_case(tmp_path / "jam.npz")
    assert name == "lid 30" and len(scene.contact.planes) == 6
    lid = scene.contact.planes[-1]
    assert lid.point_at(0.0)[2] == pytest.approx(meta["lid"]["start"], rel=1e-12)
    assert lid.point_at(1e-4)[2] == pytest.approx(meta["lid"]["start"] - 0.02 * 1e-4, rel=1e-9)  # on its way down
    np.testing.assert_array_equal(state.x, x)
    assert state.history is not None and len(state.history.keys) > 0
    # the lid's force on the grains at the checkpoint, as the run wrote it for that frame
    cand = scene.contact.search(state.x, 0.0)
    force = scene.contact.evaluate(state.x, 0.0, cand, state.history, v=state.v).wall_reactions[-1][2]
    times, lid_fz = wall_force_record(out / "walls.csv", "lid")
    assert times[-1] == pytest.approx(t, rel=1e-12)
    written = lid_fz[-1]
    assert abs(written) > 1e-4  # the lid is in the pack
    assert force == pytest.approx(written, rel=1e-6)


@pytest.mark.skipif(not JAM.is_file(), reason="benchmarks/data/lid515_jam.npz not in this checkout")
def test_the_shipped_jam_state_is_the_515_grain_lid_in_its_jam():
    s = load_state(JAM)
    assert len(s.grains) == 515 and s.meta["scenario"] == "lid_compression"
    assert 5.0e-3 < s.meta["lid"]["start"] < 5.4e-3 and s.meta["contact"]["mu_s"] == 0.15
    assert np.all(np.isfinite(s.x)) and len(s.friction["keys"]) > 5 * 515


def test_the_jam_bench_steps_the_rebuilt_lid_run_with_the_settings_it_is_given(interrupted, tmp_path):
    cfg, out = interrupted
    jam, bench = _module("jam_state"), _module("bench_jam")
    jam.jam_state(out / "checkpoint.npz", PACK, cfg, tmp_path / "jam.npz")
    newton = bench.newton_settings(["freeze_cycles=false", "stall_share=0.25", "ccd_fraction=0.5"])
    assert newton == {"freeze_cycles": False, "stall_share": 0.25, "ccd_fraction": 0.5}
    integrator, state = bench.jam_integrator(tmp_path / "jam.npz", {"solver.max_iterations": 30}, newton)
    params = integrator.params
    assert params.max_iterations == 30 and not params.freeze_cycles and params.stall_share == 0.25
    assert params.ccd_fraction == 0.5
    assert params.gamma == 0.6 and params.linear is not None  # the rest is the example's
    result = bench.run_jam(integrator, state, 1e-6, seconds=600.0, steps=3)
    assert result["accepted"] == 3 and 3e-6 <= result["simulated_s"] < 1e-3
    _, lid_fz = wall_force_record(out / "walls.csv", "lid")
    # three steps of at most a few microseconds: the lid has hardly moved, nor has its force
    assert result["lid_force_first"] == pytest.approx(lid_fz[-1], rel=0.2)
    for bad in (["nope=1"], ["freeze_cycles=yes"], ["max_iterations=many"], ["linear=direct"]):
        with pytest.raises(ValueError, match="--newton"):
            bench.newton_settings(bad)
