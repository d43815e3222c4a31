"""benchmarks/bench_paper.py builds its runs from the examples: the mass-scaled ones by default, the
real-density implicit ones with --implicit (every 515-grain real-density run's wall time
from a benchmark anyone can rerun)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_paper.py"


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location("bench_paper", BENCH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("implicit", [False, True])
def test_each_run_is_its_example_in_the_chosen_integrator(bench, tmp_path, implicit):
    pack = tmp_path / "elsewhere" / "state.npz"
    for name in bench.RUNS:
        cfg, module = bench.config_for(name, tmp_path, None, implicit=implicit, pack_state=pack, vtk=False)
        solver = cfg["solver"]
        assert solver["integrator"] == ("implicit" if implicit else "explicit"), name
        assert (solver["mass_scaling"] == 1.0) == implicit, name
        assert cfg["output"]["vtk"] is False, name
        if name in ("high", "mid", "low", "compression-pack"):
            assert Path(cfg["initial_state"]) == pack.resolve(), name
        else:
            assert not cfg.get("initial_state"), name


def test_the_collapses_start_from_the_runs_own_pack_by_default(bench, tmp_path):
    cfg, _ = bench.config_for("mid", tmp_path, None, implicit=True)
    assert Path(cfg["initial_state"]) == tmp_path / "pack" / "state.npz"
    assert cfg["output"]["vtk"] is True  # the example's own choice unless --no-vtk


def test_a_missing_pack_state_is_refused_in_one_line(bench, tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_:
        bench.main(["--implicit", "--only", "mid", "--pack-state", str(tmp_path / "none.npz"), "--out", str(tmp_path)])
    assert exit_.value.code == 2
    assert "--pack-state: no file" in capsys.readouterr().err


def test_lid_turn_moves_only_the_lids_turning_point(bench, tmp_path):
    for name in bench.RUNS:
        plain, _ = bench.config_for(name, tmp_path, None, implicit=True)
        turned, _ = bench.config_for(name, tmp_path, None, implicit=True, lid_turn=0.22)
        if "lid" in plain:
            assert turned["lid"]["end"] == pytest.approx(plain["lid"]["start"] * 0.78), name
            assert turned["lid"]["end"] != plain["lid"]["end"], name
            turned["lid"]["end"] = plain["lid"]["end"]
        assert turned == plain, name


@pytest.mark.parametrize("strain", ["0", "1.2", "-0.1"])
def test_a_lid_turn_outside_0_1_is_refused(bench, tmp_path, capsys, strain):
    with pytest.raises(SystemExit) as exit_:
        bench.main(["--only", "compression-pack", "--lid-turn", strain, "--out", str(tmp_path)])
    assert exit_.value.code == 2
    assert "--lid-turn: a strain between 0 and 1" in capsys.readouterr().err


def test_a_lid_row_gives_its_spring_back_shares(bench):
    s = {"wall_seconds": 100.0, "n_steps": 1000, "n_grains": 515, "simulated_time": 0.168, "peak_force": 2.0,
         "residual_strain_absolute": 0.2285}  # fmt: skip
    assert "spring-back" not in bench.row("compression-pack", s, 3600.0)
    s["spring_back"] = {"branch_strain": 0.04, "deformation": 0.012, "contact_gap": 0.012}
    line = bench.row("compression-pack", s, 3600.0)
    assert "residual_strain_absolute 0.2285" in line and "spring-back 0.04 (grains 30%, gaps 30%)" in line
    s["spring_back"] = {"error": "no turn_state.npz"}
    assert "spring-back" not in bench.row("compression-pack", s, 3600.0)


def test_set_changes_one_value_of_every_run_and_nothing_else(bench, tmp_path):
    overrides = {"solver.max_iterations": 30, "solver.easy_iterations": 16}
    for name in ("pack", "compression-pack"):
        plain, _ = bench.config_for(name, tmp_path, None, implicit=True)
        changed, _ = bench.config_for(name, tmp_path, None, implicit=True, overrides=overrides)
        assert (changed["solver"]["max_iterations"], changed["solver"]["easy_iterations"]) == (30, 16), name
        assert (plain["solver"]["max_iterations"], plain["solver"]["easy_iterations"]) != (30, 16), name
        changed["solver"]["max_iterations"] = plain["solver"]["max_iterations"]
        changed["solver"]["easy_iterations"] = plain["solver"]["easy_iterations"]
        assert changed == plain, name


@pytest.mark.parametrize("text, message", [("solver.max_iterations=30,40", "one value per key"),
                                           ("solver.max_iterations", "expected KEY=V1,V2"),
                                           ("solver.max_iterations=-3", "solver.max_iterations")])  # fmt: skip
def test_a_bad_set_is_refused_in_one_line(bench, tmp_path, capsys, text, message):
    with pytest.raises(SystemExit) as exit_:
        bench.main(["--implicit", "--only", "pack", "--set", text, "--out", str(tmp_path)])
    assert exit_.value.code == 2
    assert message in capsys.readouterr().err


def test_a_key_set_twice_is_refused_as_the_sweep_refuses_it(bench, tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_:
        bench.main(["--only", "pack", "--set", "solver.max_iterations=30", "--set", "solver.max_iterations=40",
                    "--out", str(tmp_path)])  # fmt: skip
    assert exit_.value.code == 2
    assert "--set solver.max_iterations: given twice" in capsys.readouterr().err
