"""A run's identity for --resume and pack reuse (config.choices): the keys a config does not take
from their defaults. A key added to the schema later must not orphan checkpoints of runs whose
config nobody touched; a changed key must still be refused, by name."""

import json
import tomllib

import numpy as np
import pytest

from vemdem.config import Field, apply_schema, choices, digest, tables
from vemdem.driver.checkpoint import CheckpointError
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
    default = scene_mod.SCHEMA["solver"]["max_iterations"].default
    cfg_b, _ = checked_config(drop_raw(max_iterations=default))
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
    changed, _ = checked_config(drop_raw(dt_max=3e-4))
    with pytest.raises(CheckpointError, match=r"different config \(solver\.dt_max: default then, 0\.0003 now\)"):
        scene_mod.run(changed, tmp_path, resume=True)


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
