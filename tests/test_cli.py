"""The command line: `vemdem run`, `vemdem example`, and config errors (exit status 2)."""

import json
import re
import subprocess
import sys
import tomllib

import pytest

from vemdem.scenarios.registry import EXAMPLES, example_text

GOOD = """
scenario = "grain_compression"
[material]
E = 90e9
nu = 0.16
density = 2200.0
[vem]
beta_internal = 0.5
[grain]
shape = "cube"
size = 1.45e-3
[loading]
mode = "uniaxial"
max_strain = 0.3
steps = 3
"""


def write(tmp_path, text):
    path = tmp_path / "job.toml"
    path.write_text(text)
    return path


def test_run_writes_results(tmp_path, cli):
    code, out, _ = cli("run", write(tmp_path, GOOD), "--out", tmp_path / "out", "--quiet")
    assert code == 0
    summary = json.loads((tmp_path / "out/summary.json").read_text())
    assert summary["scenario"] == "grain_compression" and summary["n_steps"] == 3
    assert (tmp_path / "out/force_strain.png").stat().st_size > 1000


@pytest.mark.parametrize(
    "edit,key,problem",
    [
        (("nu = 0.16", "nu = 0.5"), "material.nu", "must be in (-1, 0.5)"),
        (("E = 90e9", "E = -1.0"), "material.E", "must be in [1e3, 1e13] Pa"),
        (("E = 90e9", 'E = "stiff"'), "material.E", "expected a number"),
        (("max_strain = 0.3", "max_strain = 1.0"), "loading.max_strain", "must be in (0, 1)"),
        (("steps = 3", "steps = 2.5"), "loading.steps", "expected an integer"),
        (("mode = \"uniaxial\"", "mode = \"biaxial\""), "loading.mode", "is not one of"),
        (("size = 1.45e-3", "size = 1.45e-3\ncolour = 3"), "grain.colour", "unknown key"),
        (("E = 90e9\n", ""), "material.E", "required key is missing"),
        (('scenario = "grain_compression"', 'scenario = "avalanche"'), "scenario", "unknown scenario"),
        (("beta_internal = 0.5", "beta_internal = 0.0"), "vem.beta_internal", "must be in (0, 1]"),
        (("[loading]", "[loading\n"), "job.toml", "not valid TOML"),
    ],
)
def test_bad_config_stops_before_running_with_exit_2(tmp_path, cli, edit, key, problem):
    code, out, err = cli("run", write(tmp_path, GOOD.replace(*edit)), "--out", tmp_path / "out")
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert key in lines[0] and problem in lines[0]
    assert not (tmp_path / "out").exists()


def test_bad_grain_file_is_a_config_error(tmp_path, cli):
    text = GOOD.replace('shape = "cube"', 'file = "nowhere.stl"')
    code, _, err = cli("run", write(tmp_path, text), "--out", tmp_path / "out")
    assert code == 2 and "nowhere.stl" in err and "not found" in err


def test_missing_config_file(tmp_path, cli):
    code, _, err = cli("run", tmp_path / "none.toml", "--out", tmp_path / "out")
    assert code == 2 and "config file not found" in err


@pytest.mark.parametrize("name", list(EXAMPLES))
def test_examples_are_valid_configs(name, cli):
    code, out, _ = cli("example", name)
    assert code == 0 and out == example_text(name)
    from vemdem.scenarios.registry import checked_config

    cfg, _ = checked_config(tomllib.loads(out))
    assert cfg["scenario"]


def test_example_dir_writes_the_config_with_the_files_it_names(cli, tmp_path):
    code, out, err = cli("example", "triaxial-two-shapes")
    assert code == 0 and "--dir" in err  # printed alone, the config says where its files come from
    code, out, _ = cli("example", "triaxial-two-shapes", "--dir", str(tmp_path / "job"))
    assert code == 0 and "vemdem run" in out
    written = sorted(p.name for p in (tmp_path / "job").iterdir())
    assert written == ["crushed.stl", "rounded.stl", "triaxial-two-shapes.toml"]
    raw = tomllib.loads((tmp_path / "job" / "triaxial-two-shapes.toml").read_text())
    assert sorted(raw["pack"]["grains"]["files"]) == ["crushed.stl", "rounded.stl"]
    from vemdem.scenarios.pack import pack_config, place
    from vemdem.scenarios.registry import checked_config

    cfg, _ = checked_config(raw)
    grains = place(pack_config(cfg), base_dir=tmp_path / "job").grains  # the files found beside the config
    assert len(grains) == raw["pack"]["n_grains"] and len({len(g.vertices) for g in grains}) == 2


def test_example_lists_names_and_rejects_unknown(cli):
    """`vemdem example` lists every example, one a line, each with what it runs."""
    code, out, _ = cli("example")
    rows = [line.split(None, 1) for line in out.splitlines()]
    assert code == 0 and [row[0] for row in rows] == list(EXAMPLES)
    assert all(len(row) == 2 and len(row[1]) > 20 for row in rows), out
    code, _, err = cli("example", "nope")
    assert code == 2 and "unknown example" in err


def test_console_script_is_installed(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "vemdem.cli", "example", "grain_compression"],
                          capture_output=True, text=True)  # fmt: skip
    assert proc.returncode == 0 and "grain_compression" in proc.stdout


def test_failed_run_exits_1_and_keeps_what_it_wrote(tmp_path, cli):
    text = GOOD.replace("max_strain = 0.3", "max_strain = 0.95").replace("steps = 3", "steps = 2")
    text = text.replace("[loading]", "[solver]\nmax_iterations = 5\n[loading]")
    code, _, err = cli("run", write(tmp_path, text), "--out", tmp_path / "out", "--quiet")
    assert code == 1
    assert "Newton did not converge" in err and str(tmp_path / "out") in err
    rows = (tmp_path / "out/force_strain.csv").read_text().splitlines()
    assert rows[0] == "strain,force" and len(rows) >= 2


def _compiling_run(monkeypatch, scenario="grain_compression"):
    """The scenario's run with a kernel numba has never seen compiled first: what a fresh install's
    first run does (a cached kernel raises no compile event; this one, not cached, does)."""
    import importlib

    import numba

    module = importlib.import_module(f"vemdem.scenarios.{scenario}")
    original = module.run

    def run(*args, **kwargs):
        numba.njit(lambda x: x + 1)(1)  # a new function: a real compile
        return original(*args, **kwargs)

    monkeypatch.setattr(module, "run", run)


def test_a_run_that_compiles_says_so_once(tmp_path, cli, monkeypatch):
    """A fresh install spends minutes compiling before the first output: say so, once, when numba
    really compiles; a cached run (the same command again) and a quiet one say nothing."""
    code, _, err = cli("run", write(tmp_path, GOOD), "--out", tmp_path / "cached")
    assert code == 0 and "compiling" not in err
    _compiling_run(monkeypatch)
    code, _, err = cli("run", write(tmp_path, GOOD), "--out", tmp_path / "out")
    assert code == 0 and err.count("compiling the numerical kernels") == 1
    code, _, err = cli("run", write(tmp_path, GOOD), "--out", tmp_path / "quiet", "--quiet")
    assert code == 0 and "compiling" not in err


def test_a_bad_config_on_a_cold_cache_is_its_one_line(tmp_path, cli, monkeypatch):
    """No compile notice ahead of a mistake: a config error, or a missing grain file that the run
    finds before its first kernel, is answered in the one line that names it, even where every
    kernel would have to be compiled (numba's disk cache made to miss)."""
    from numba.core import caching

    monkeypatch.setattr(caching.Cache, "load_overload", lambda *args, **kwargs: None)
    for i, text in enumerate((GOOD.replace("nu = 0.16", "nu = 0.7"), GOOD.replace('shape = "cube"', 'file = "x.stl"'))):
        code, _, err = cli("run", write(tmp_path, text), "--out", tmp_path / f"out{i}")
        lines = err.strip().splitlines()
        assert code == 2 and len(lines) == 1 and ("material.nu" in lines[0] or "x.stl" in lines[0]), err
        assert not (tmp_path / f"out{i}").exists()


def test_a_heap_run_ends_with_its_angle(tmp_path, cli):
    """The main job's last lines: its headline (the angle of repose with its uncertainty, the
    heap's height), then the wall time and the folder."""
    from vemdem.analysis.repose import repose_headline

    summary = {"angle_of_repose_deg": 21.63, "angle_of_repose_uncertainty_deg": 3.21, "pile_height": 6.41e-3}
    assert repose_headline(summary) == "angle of repose 21.6 +- 3.2 deg; pile height 6.41 mm"
    flat = {"angle_of_repose_deg": None, "angle_of_repose_error": "too few surface grains", "pile_height": 1e-3}
    assert repose_headline(flat) == "no angle of repose (too few surface grains); pile height 1.00 mm"
    raw = tomllib.loads(example_text("pile"))
    raw["pack"].update(n_grains=4, grains={"size": 1.45e-3, "vertices": 8}, box={"width": 3.6e-3, "depth": 3.6e-3})
    raw["settle"] = {"min_time": 0.02, "max_time": 0.03}
    raw["output"] = {"every": 1e-2, "vtk": False}
    import tomli_w

    config = tmp_path / "pile.toml"
    config.write_text(tomli_w.dumps(raw))
    code, out, _ = cli("run", config, "--out", tmp_path / "out")
    summary = json.loads((tmp_path / "out/summary.json").read_text())
    last = out.strip().splitlines()[-2:]
    assert code == 0 and last[0] == f"pile_collapse: {repose_headline(summary)}", out
    assert last[1].startswith("pile_collapse: done in "), out


def test_long_frames_still_report_progress(tmp_path, monkeypatch):
    """Between frames (minutes apart in a jammed lid cycle) the loop reports the step it is on,
    at most every PROGRESS_EVERY_S of wall time; each frame still reports its own line."""
    from vemdem.driver import loop
    from vemdem.scenarios.registry import checked_config

    raw = tomllib.loads(example_text("drop"))
    raw["duration"], raw["output"] = 2e-3, {"every": 1e-3, "vtk": False}
    cfg, module = checked_config(raw)
    calls = []
    monkeypatch.setattr(loop, "PROGRESS_EVERY_S", 0.0)
    summary = module.run(cfg, tmp_path / "out", progress=lambda done, total, text="": calls.append((done, total, text)))
    inside = [c for c in calls if "inside frame" in c[2]]
    frames = [c for c in calls if "steps/s" in c[2]]
    assert [c[0] for c in frames] == [1, 2] and all(c[1] == 2 for c in calls)
    # an implicit frame's line says Newton's iterations per step: the run's mean lies between the frames'
    per_frame = [float(re.search(r", ([0-9.]+) Newton it\./step$", c[2]).group(1)) for c in frames]
    assert min(per_frame) - 0.05 <= summary["newton_iterations_per_step"] <= max(per_frame) + 0.05
    assert summary["newton_iterations_per_step"] >= 1
    assert inside and all(c[2].startswith("t = ") for c in inside)
    # a step line carries the frame done so far: the bar never runs ahead of the frames written
    assert [c[0] for c in inside] == sorted(c[0] for c in inside) and max(c[0] for c in inside) <= 1
    monkeypatch.setattr(loop, "PROGRESS_EVERY_S", 1e9)
    calls.clear()
    module.run(cfg, tmp_path / "again", progress=lambda done, total, text="": calls.append((done, total, text)))
    assert not [c for c in calls if "inside frame" in c[2]]
