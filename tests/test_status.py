"""`vemdem status DIR`: where a run stands, read from its checkpoint and summary without its config.
Its figures are the run's own books: those summary.json writes at the end, those the checkpoint
carries before it."""

import json

import numpy as np
import pytest
import tomli_w
from test_run_identity import drop_raw, interrupted

from vemdem.scenarios import scene as scene_mod
from vemdem.scenarios.registry import checked_config


def test_a_finished_run_reports_its_summary_books(tmp_path, cli):
    cfg, _ = checked_config(drop_raw())
    summary = scene_mod.run(cfg, tmp_path / "run")
    code, out, err = cli("status", tmp_path / "run", "--json")
    assert code == 0 and err == ""
    (entry,) = json.loads(out)
    assert entry["finished"] and entry["scenario"] == "scene" and entry["folder"] == str(tmp_path / "run")
    for key in ("n_steps", "n_rejected_steps", "n_newton_iterations", "newton_iterations_per_step", "resume_changes"):
        assert entry[key] == summary[key], key
    assert entry["time"] == summary["simulated_time"]
    code, out, _ = cli("status", tmp_path)  # a folder of runs (a sweep's cases): each one
    assert out.startswith(f"{tmp_path / 'run'}: finished (scene, ") and f"{summary['n_steps']:,} steps" in out


def test_an_interrupted_run_reports_its_checkpoint_and_later_its_resume_changes(tmp_path, cli, monkeypatch):
    cfg, _ = checked_config(drop_raw())
    interrupted(cfg, tmp_path / "cut", monkeypatch, after=2)  # the initial state and the first frame
    with np.load(tmp_path / "cut/checkpoint.npz") as d:
        steps, t = int(d["accepted"]), float(d["t"])
    code, out, _ = cli("status", tmp_path / "cut")
    assert code == 0
    assert "not finished, checkpoint written " in out and " min of wall time so far" in out
    assert f"t = {t:.6g} s (frame 1)" in out and f"{steps:,} steps" in out
    (tmp_path / "job.toml").write_text(tomli_w.dumps(drop_raw(max_iterations=30)))
    assert cli("run", tmp_path / "job.toml", "--out", tmp_path / "cut", "--quiet", "--resume")[0] == 0
    code, out, _ = cli("status", tmp_path / "cut")
    assert out.splitlines()[1] == "  resumed at t = 0.001 s with solver.max_iterations 15 -> 30"


def test_a_folder_without_a_run_or_with_a_damaged_checkpoint_is_one_line(tmp_path, cli):
    code, out, err = cli("status", tmp_path)
    assert code == 2 and out == ""
    assert err.strip() == (f"vemdem: status: {tmp_path} holds no run (no checkpoint.npz or summary.json, nor in "
                           "its subfolders)")
    (tmp_path / "checkpoint.npz").write_bytes(b"PK\x03\x04" + b"\x00" * 40)
    code, _, err = cli("status", tmp_path)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "checkpoint.npz is not a readable checkpoint" in err


def test_the_wall_time_adds_up_over_the_parts_of_a_resumed_run(tmp_path, monkeypatch):
    cfg, _ = checked_config(drop_raw())
    whole = scene_mod.run(cfg, tmp_path / "whole")
    assert whole["wall_seconds_total"] == whole["wall_seconds"]
    interrupted(cfg, tmp_path / "cut", monkeypatch, after=2)
    with np.load(tmp_path / "cut/checkpoint.npz") as d:
        earlier = float(d["wall_seconds"])
    assert earlier > 0
    resumed = scene_mod.run(cfg, tmp_path / "cut", resume=True)
    assert resumed["wall_seconds_total"] == pytest.approx(earlier + resumed["wall_seconds"], rel=1e-12)
    # an early format-0 checkpoint kept no wall time: the total is unknown, not the last part's
    interrupted(cfg, tmp_path / "old", monkeypatch, after=2)
    with np.load(tmp_path / "old/checkpoint.npz") as d:
        entries = {k: d[k] for k in d.files if k != "wall_seconds"}
    np.savez(tmp_path / "old/checkpoint.npz", **entries)
    assert scene_mod.run(cfg, tmp_path / "old", resume=True)["wall_seconds_total"] is None
