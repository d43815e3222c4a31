"""A run's identity for --resume and pack reuse (config.choices): the keys a config does not take
from their defaults. A key added to the schema later must not orphan checkpoints of runs whose
config nobody touched; a changed key must still be refused, by name."""

import json
import tomllib
import warnings

import numpy as np
import pytest

from vemdem.config import Field, apply_schema, choices, digest, tables
from vemdem.driver import loop as loop_mod
from vemdem.driver.checkpoint import CheckpointError, ResumeChangeWarning
from vemdem.scenarios import scene as scene_mod
from vemdem.scenarios.identity import run_identity
from vemdem.scenarios.registry import checked_config, example_text


def drop_raw(**solver):
    raw = tomllib.loads(example_text("drop"))
    raw["duration"] = 0.002
    raw["output"] = {"every": 1e-3, "vtk": False}
    raw["solver"].update(solver)
    return raw


def grown(schema: dict) -> dict:
    """The schema with a key a later version might add, whose default keeps today's behaviour."""
    return {**schema, "solver": {**schema["solver"], "future_option": Field(bool, False)}}


def test_choices_keep_only_what_differs_from_the_defaults():
    cfg, _ = checked_config(drop_raw(dt_max=2e-4))
    picked = choices(cfg, scene_mod.SCHEMA)
    assert picked["solver"]["dt_max"] == 2e-4
    defaults = {k: f.default for k, f in scene_mod.SCHEMA["solver"].items() if isinstance(f, Field)}
    assert all(defaults[k] != v for k, v in picked["solver"].items())
    assert len(picked["grains"]) == len(cfg["grains"])  # the number of [[grains]] tables is a choice


def test_writing_a_default_out_does_not_change_the_identity():
    cfg_a, _ = checked_config(drop_raw())
    default = scene_mod.SCHEMA["solver"]["easy_iterations"].default
    cfg_b, _ = checked_config(drop_raw(easy_iterations=default))
    assert run_identity(cfg_a, scene_mod.SCHEMA).fingerprint == run_identity(cfg_b, scene_mod.SCHEMA).fingerprint


def test_a_key_added_to_the_schema_keeps_the_identity():
    raw = drop_raw(dt_max=2e-4)
    schema = scene_mod.SCHEMA
    before = apply_schema(raw, schema)
    after = apply_schema(raw, grown(schema))
    assert digest(before) != digest(after)  # the whole-config digest (the old rule) changes
    assert run_identity(before, schema).fingerprint == run_identity(after, grown(schema)).fingerprint


def test_resume_after_the_schema_grew(tmp_path, monkeypatch):
    cfg, _ = checked_config(drop_raw())
    scene_mod.run(cfg, tmp_path)
    monkeypatch.setattr(scene_mod, "SCHEMA", grown(tables.SCENE))
    later = apply_schema(drop_raw(), scene_mod.SCHEMA)
    scene_mod.run(later, tmp_path, resume=True)  # accepted: nothing the user chose changed


def test_a_changed_key_is_refused_by_name(tmp_path):
    cfg, _ = checked_config(drop_raw())
    scene_mod.run(cfg, tmp_path)
    changed, _ = checked_config(drop_raw(gamma=0.7))
    with pytest.raises(CheckpointError, match=r"different config \(solver\.gamma: default then, 0\.7 now\); "
                                              r"--resume may change only solver\.dt, solver\.dt_min"):
        scene_mod.run(changed, tmp_path, resume=True)


def test_a_step_control_change_beside_a_model_change_is_refused_naming_the_model_key(tmp_path):
    cfg, _ = checked_config(drop_raw())
    scene_mod.run(cfg, tmp_path)
    changed, _ = checked_config(drop_raw(gamma=0.7, max_iterations=30))
    with pytest.raises(CheckpointError, match=r"\(solver\.gamma: default then, 0\.7 now\);"):
        scene_mod.run(changed, tmp_path, resume=True)


def interrupted(cfg, folder, monkeypatch, after: int):
    """The run stopped (KeyboardInterrupt) after its `after`-th checkpoint, the initial one counted."""
    original = loop_mod.save_checkpoint
    calls = {"n": 0}

    def interrupting(*args, **kwargs):
        original(*args, **kwargs)
        calls["n"] += 1
        if calls["n"] == after:
            raise KeyboardInterrupt

    monkeypatch.setattr(loop_mod, "save_checkpoint", interrupting)
    with pytest.raises(KeyboardInterrupt):
        scene_mod.run(cfg, folder)
    monkeypatch.setattr(loop_mod, "save_checkpoint", original)


def test_a_resume_may_change_the_step_control_and_says_so(tmp_path, monkeypatch):
    """A stalled run given another Newton budget or step bounds goes on (the 515-grain lid's forks were
    made by hand, docs/results.md): with a warning, the new values in force from the first resumed step
    (a lowered dt_max: the resumed second frame takes at least its 1e-3 s / 2e-5 s = 50 steps, where the
    uninterrupted run took 16) and the change kept in summary.json through later plain resumes."""
    cfg, _ = checked_config(drop_raw())
    full = scene_mod.run(cfg, tmp_path / "full")
    interrupted(cfg, tmp_path / "cut", monkeypatch, after=2)  # the initial state and the first frame
    with np.load(tmp_path / "cut/checkpoint.npz") as d:
        t_cut, steps_cut = float(d["t"]), int(d["accepted"])
    assert t_cut == pytest.approx(1e-3)
    changed, _ = checked_config(drop_raw(dt_max=2e-5, max_iterations=30))
    with pytest.warns(ResumeChangeWarning, match=r"t = 0\.001 s with solver\.dt_max 0\.0001 -> 2e-05; "
                                                 r"solver\.max_iterations 15 -> 30"):
        summary = scene_mod.run(changed, tmp_path / "cut", resume=True)
    assert summary["n_steps"] - steps_cut >= 50 > full["n_steps"] - steps_cut
    expected = [{"key": "solver.dt_max", "then": 1e-4, "now": 2e-5, "time": t_cut, "frame": 1},
                {"key": "solver.max_iterations", "then": 15, "now": 30, "time": t_cut, "frame": 1}]
    assert summary["resume_changes"] == expected and full["resume_changes"] == []
    assert json.loads((tmp_path / "cut/summary.json").read_text())["resume_changes"] == expected
    with warnings.catch_warnings():
        warnings.simplefilter("error", ResumeChangeWarning)  # the same config again: a plain resume
        again = scene_mod.run(changed, tmp_path / "cut", resume=True)
    assert again["resume_changes"] == expected
    with pytest.raises(CheckpointError, match=r"solver\.gamma"):
        scene_mod.run(checked_config(drop_raw(dt_max=2e-5, max_iterations=30, gamma=0.7))[0], tmp_path / "cut",
                      resume=True)  # fmt: skip


def test_a_checkpoint_with_the_old_whole_config_fingerprint_resumes(tmp_path):
    cfg, _ = checked_config(drop_raw())
    scene_mod.run(cfg, tmp_path)
    path = tmp_path / "checkpoint.npz"
    with np.load(path) as d:
        old = {k: d[k] for k in d.files if k != "choices"}
    old["fingerprint"] = np.array(digest(cfg))  # what checkpoints carried before config.choices
    np.savez(path, **old)
    scene_mod.run(cfg, tmp_path, resume=True)
    other, _ = checked_config(drop_raw(dt_max=3e-4))
    with pytest.raises(CheckpointError, match=r"different config$"):  # no choices stored: no key to name
        scene_mod.run(other, tmp_path, resume=True)


def test_the_summary_carries_the_identity(tmp_path):
    cfg, _ = checked_config(drop_raw(dt_max=2e-4))
    scene_mod.run(cfg, tmp_path)
    with np.load(tmp_path / "checkpoint.npz") as d:
        assert json.loads(str(d["choices"]))["solver"]["dt_max"] == 2e-4
        assert str(d["fingerprint"]) == run_identity(cfg, scene_mod.SCHEMA).fingerprint
