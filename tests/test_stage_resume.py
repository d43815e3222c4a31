"""Every stage of a two-stage scenario resumes to the same bits (docs/errors.md): pile_collapse and
lid_compression settle their [pack] first, into DIR/pack; a run killed in either stage and
continued with resume=True ends with the files of a run that was never interrupted."""

import json

import numpy as np
import pytest

from vemdem.config import ConfigError
from vemdem.driver import loop as loop_mod
from vemdem.driver.checkpoint import ResumeChangeWarning
from vemdem.scenarios.registry import checked_config

BOX = 3.2e-3
PACK = {"n_grains": 4, "seed": 5, "grains": {"vertices": 8, "size": 1.2e-3}, "box": {"width": BOX, "depth": BOX}}
CONFIGS = {
    "pile_collapse": {"scenario": "pile_collapse", "pack": PACK, "settle": {"max_time": 0.02, "min_time": 0.02, "kinetic_threshold": 1e-2},
                      "output": {"every": 5e-3, "vtk": False}},
    "lid_compression": {"scenario": "lid_compression", "pack": PACK, "output": {"vtk": False},
                        "settle": {"kinetic_threshold": 1e-2},
                        "lid": {"start": 4.0e-3, "end": 3.2e-3, "speed": 0.08, "frames": 4}},
    # a load path cut inside a stage, with the lid on the grains: the servo's path and the stage
    # records go through the checkpoint
    # (a box the four grains jam in: in a wider one the lid's first touches tip the top grain over)
    "oedometer": {"scenario": "oedometer", "pack": {**PACK, "seed": 1, "box": {"width": 2.6e-3, "depth": 2.6e-3}},
                  "settle": {"min_time": 0.04},
                  "output": {"every": 2e-3, "vtk": False}, "lid": {"gap": 0.01}, "servo": {"inertia_number": 1e-2},
                  "stages": [{"stress": 200.0, "max_time": 0.03}, {"stress": 400.0, "max_time": 0.01},
                             {"stress": 200.0, "max_time": 0.01}],
                  "contact": {"reference_force": 2 * 400.0 * 1.2e-3**2}},
    # cut in the shear, the platen pressing the sample and the lateral servos holding it
    "triaxial": {"scenario": "triaxial", "pack": {"n_grains": 12, "seed": 3, "mu_s": 0.0, "mu_d": 0.0,
                                                  "grains": {"size": 1.0e-3, "vertices": 8},
                                                  "box": {"width": 2.6e-3, "depth": 2.6e-3}},
                 "model": {"grains": "rigid"}, "solver": {"integrator": "explicit"},
                 "settle": {"kinetic_threshold": 1e-2},
                 "contact": {"reference_force": 2 * 20e3 * 1.0e-3**2},
                 "consolidation": {"stress": 20e3, "max_time": 0.05}, "shear": {"max_strain": 0.04,
                 "inertia_number": 2e-3}, "servo": {"inertia_number": 2e-3}, "output": {"every": 1e-3, "vtk": False}},
    "direct_shear": {"scenario": "direct_shear", "pack": {"n_grains": 20, "seed": 3, "mu_s": 0.0, "mu_d": 0.0,
                                                          "grains": {"size": 1.0e-3, "vertices": 8},
                                                          "box": {"width": 3.6e-3, "depth": 2.6e-3}},
                     "model": {"grains": "rigid"}, "solver": {"integrator": "explicit"},
                     "settle": {"kinetic_threshold": 1e-2},
                     "contact": {"reference_force": 2 * 20e3 * 1.0e-3**2},
                     "normal": {"stress": 20e3, "max_time": 0.03}, "shear": {"max_displacement": 0.02,
                     "inertia_number": 2e-3}, "servo": {"inertia_number": 2e-3}, "output": {"every": 1e-3, "vtk": False}},
}  # fmt: skip
# the lab tests above keep the per-stress law (their `reference_force`, 2 sigma d^2): the subject here is the resume
LOADED = {"oedometer": ("oedometer.csv", "lid_force"), "triaxial": ("triaxial.csv", "sigma_1"),
          "direct_shear": ("shear.csv", "sigma_n")}
STAGE_FILES = ["history.csv", "grains.csv", "walls.csv", "fabric.csv"]


def _run(raw, out, resume=False):
    cfg, module = checked_config(raw)
    return module.run(cfg, out, resume=resume)


def _checkpoints(monkeypatch, stop_at=None):
    """Count the checkpoints written (by folder); raise KeyboardInterrupt after the stop_at-th."""
    original = loop_mod.save_checkpoint
    written = []

    def counting(path, *args, **kwargs):
        original(path, *args, **kwargs)
        written.append(path.parent.name)
        if stop_at is not None and len(written) == stop_at:
            raise KeyboardInterrupt

    monkeypatch.setattr(loop_mod, "save_checkpoint", counting)
    return written


def _same_results(a, b):
    for stage in (a / "pack", a):
        for name in STAGE_FILES:
            mine = b / stage.relative_to(a) / name
            assert mine.read_bytes() == (stage / name).read_bytes(), f"{stage.relative_to(a) / name} differs"
    for name in ("oedometer.csv", "triaxial.csv", "shear.csv"):
        if (a / name).is_file():
            assert (b / name).read_bytes() == (a / name).read_bytes(), f"{name} differs"
    s1, s2 = (json.loads((d / "summary.json").read_text()) for d in (a, b))
    for key in ("wall_seconds", "wall_seconds_total", "initial_state"):
        s1.pop(key), s2.pop(key)
    assert s1 == s2


@pytest.mark.parametrize("scenario", sorted(CONFIGS))
def test_a_run_killed_in_either_stage_resumes_to_the_same_bits(tmp_path, monkeypatch, scenario):
    raw = CONFIGS[scenario]
    written = _checkpoints(monkeypatch)
    _run(raw, tmp_path / "whole")
    in_pack = written.count("pack")
    in_main = len(written) - in_pack
    assert in_pack >= 3 and in_main >= 3, written  # both stages have frames to cut between
    # the lab tests are cut in their second stage, the lid or the platen pressing the grains
    late = scenario in LOADED
    if late:
        table, force = LOADED[scenario]
        rows = np.genfromtxt(tmp_path / "whole" / table, delimiter=",", names=True)
        # the last frame before the end with the sample loaded in the second stage or later
        loaded = np.flatnonzero((rows["stage"] >= 1) & (rows[force] > 0))
        loaded = loaded[loaded < in_main - 1]
        assert loaded.size, "the cut must find the sample loaded"
        cut = int(loaded[-1]) + 1
    for name, stop_at in (("cut-in-pack", in_pack // 2 + 1), ("cut-in-main", in_pack + (cut if late else 2))):
        _checkpoints(monkeypatch, stop_at)
        with pytest.raises(KeyboardInterrupt):
            _run(raw, tmp_path / name)
        assert not (tmp_path / name / "summary.json").exists()
        _checkpoints(monkeypatch)
        _run(raw, tmp_path / name, resume=True)
        _same_results(tmp_path / "whole", tmp_path / name)


def test_a_resume_that_changed_the_step_control_keeps_the_settled_pack(tmp_path, monkeypatch):
    """A run cut in its main stage and resumed with another Newton budget (driver.checkpoint.step_changes):
    the settled pack is kept as it was (its files and summary untouched, it never ran with the new keys)
    and the main stage records the change; a changed material is still refused, by the pack stage."""
    raw = CONFIGS["pile_collapse"]
    original = loop_mod.save_checkpoint
    main_stage = []

    def cut_in_main(path, *args, **kwargs):
        original(path, *args, **kwargs)
        main_stage.extend([path] if path.parent.name != "pack" else [])
        if len(main_stage) == 2:
            raise KeyboardInterrupt

    monkeypatch.setattr(loop_mod, "save_checkpoint", cut_in_main)
    with pytest.raises(KeyboardInterrupt):
        _run(raw, tmp_path)
    monkeypatch.setattr(loop_mod, "save_checkpoint", original)
    pack_files = {p.name: p.read_bytes() for p in (tmp_path / "pack").iterdir()}
    with pytest.raises(ConfigError, match="settled from a different"):
        _run({**raw, "material": {"E": 1.5e8}}, tmp_path, resume=True)
    with pytest.warns(ResumeChangeWarning, match=r"solver\.max_iterations 15 -> 30"):
        summary = _run({**raw, "solver": {"max_iterations": 30}}, tmp_path, resume=True)
    assert [c["key"] for c in summary["resume_changes"]] == ["solver.max_iterations"]
    assert {p.name: p.read_bytes() for p in (tmp_path / "pack").iterdir()} == pack_files
    assert json.loads(pack_files["summary.json"])["resume_changes"] == []
