"""`vemdem sweep`: --set parsing, the case list, and whole sweeps of grain_compression on Dask."""

import csv
import json
import tomllib
import os
from pathlib import Path

import numpy as np
import pytest

from vemdem.scenarios.registry import checked_config

from vemdem.config import ConfigError
from vemdem.sweep import (
    case_grid,
    case_name,
    default_plot_y,
    flatten,
    parse_set,
    parse_sets,
    plan_cases,
    run_case,
    with_values,
)

# A cube squeezed by 5 % in two steps: well under a second per case. Newton gets 5 iterations,
# so a case squeezed by 95 % fails the run (the schema accepts it).
CUBE = """
scenario = "grain_compression"
[material]
E = 1e6
nu = 0.3
[grain]
shape = "cube"
size = 1e-3
[loading]
max_strain = 0.05
steps = 2
[solver]
max_iterations = 5
[output]
vtk = false
plot = false
"""
BASE = {"scenario": "grain_compression", "material": {"E": 1e6, "nu": 0.3}, "grain": {"shape": "cube"}}


def write_config(tmp_path) -> Path:
    path = tmp_path / "cube.toml"
    path.write_text(CUBE)
    return path


def read_table(path: Path) -> list[dict]:
    with path.open(newline="") as fh:
        return list(csv.DictReader(fh))


def test_set_values_are_toml_scalars():
    key, values = parse_set('grain.shape=0.9,-1e6,3,true,"a,b",cube,sub/g.stl')
    assert key == "grain.shape"
    assert values == [0.9, -1e6, 3, True, "a,b", "cube", "sub/g.stl"]
    assert [type(v) for v in values] == [float, float, int, bool, str, str, str]


@pytest.mark.parametrize(
    "text,problem",
    [
        ("material.E", "expected KEY=V1,V2,..."),
        ("material.E=", "no values given"),
        ("material.E=1,,2", "empty value"),
        ("material.E=1,", "empty value"),
        ("=1,2", "not a dotted key"),
        ("material..E=1", "not a dotted key"),
        ('grain.shape="cube', "unbalanced quote"),
        ("grain.shape=big cube", "not a TOML value"),
        ("material.E=[1,2]", "not a TOML value"),
        ("material.E=2024-01-01", "not a number, string or boolean"),
    ],
)
def test_malformed_set_is_a_config_error(text, problem):
    with pytest.raises(ConfigError, match=problem):
        parse_set(text)


def test_a_key_set_twice_is_a_config_error():
    with pytest.raises(ConfigError, match="material.E: given twice"):
        parse_sets(["material.E=1", "material.E=2"])


def test_product_varies_the_last_key_fastest():
    grid = case_grid({"a": [1, 2], "b": [3, 4, 5]}, zipped=False)
    assert [tuple(p.values()) for p in grid] == [(1, 3), (1, 4), (1, 5), (2, 3), (2, 4), (2, 5)]
    assert list(grid[0]) == ["a", "b"]


def test_zip_pairs_the_lists_and_needs_equal_lengths():
    grid = case_grid({"a": [1, 2, 3], "b": [4, 5, 6]}, zipped=True)
    assert [tuple(p.values()) for p in grid] == [(1, 4), (2, 5), (3, 6)]
    with pytest.raises(ConfigError, match=r"a: 3, b: 2"):
        case_grid({"a": [1, 2, 3], "b": [4, 5]}, zipped=True)


def test_with_values_sets_nested_keys_on_a_copy():
    base = {"material": {"E": 1.0}, "grains": [{"size": 1.0}, {"size": 2.0}]}
    raw = with_values(base, {"material.E": 2.0, "contact.mu_s": 0.5, "grains.1.size": 3.0})
    assert raw == {"material": {"E": 2.0}, "contact": {"mu_s": 0.5}, "grains": [{"size": 1.0}, {"size": 3.0}]}
    assert base["material"]["E"] == 1.0 and base["grains"][1]["size"] == 2.0
    with pytest.raises(ConfigError, match="below a value"):
        with_values(base, {"material.E.x": 1.0})
    with pytest.raises(ConfigError, match="not an index of the 2 tables"):
        with_values(base, {"grains.2.size": 1.0})


def test_case_names_are_deterministic_and_safe():
    assert case_name(0, 3, {"contact.mu_s": 0.9, "contact.mu_d": 0.8}) == "case_000_mu_s=0.9_mu_d=0.8"
    assert case_name(7, 1001, {"grain.file": "my grains/a.stl", "x.flag": True}) == (
        "case_0007_file=my_grains_a.stl_flag=true"
    )
    assert case_name(1, 2, {"material.E": 2e6}) == "case_001_E=2e+06"


def test_every_case_is_checked_before_anything_runs():
    cases = plan_cases(BASE, ["material.E=1e6,2e6", "material.nu=0.1,0.2"], zipped=False)
    assert [c.name for c in cases] == [
        "case_000_E=1e+06_nu=0.1",
        "case_001_E=1e+06_nu=0.2",
        "case_002_E=2e+06_nu=0.1",
        "case_003_E=2e+06_nu=0.2",
    ]
    assert cases[2].raw["material"] == {"E": 2e6, "nu": 0.1}
    with pytest.raises(ConfigError, match=r"case_001_E=-1: material.E: must be in \[1e3, 1e13\] Pa"):
        plan_cases(BASE, ["material.E=1e6,-1"], zipped=False)


def test_run_case_reports_errors_instead_of_raising(tmp_path):
    result = run_case({"scenario": "avalanche"}, str(tmp_path / "c"), str(tmp_path))
    assert result["status"] == "failed"
    assert result["error"].startswith("ConfigError: scenario: unknown scenario 'avalanche'")


def test_flatten_keeps_scalars_and_names_nested_fields():
    summary = {"a": np.int64(3), "b": {"c": np.float64(0.5), "d": "x"}, "e": [1, 2], "f": True}
    flat = flatten(summary)
    assert flat == {"a": 3, "b.c": 0.5, "b.d": "x", "f": True}
    assert type(flat["a"]) is int


def test_default_plot_y():
    ok = [{"n": 1, "force": 1.0, "wall_seconds": 0.1}, {"n": 2, "force": 2.0, "wall_seconds": 0.2}]
    assert default_plot_y("grain_compression", ok) == "force"  # measured floats before counts
    assert default_plot_y("grain_compression", [{**r, "force": 1.0} for r in ok]) == "n"
    piles = [{"angle_of_repose_deg": 30.0, "force": 1.0}, {"angle_of_repose_deg": 30.0, "force": 2.0}]
    assert default_plot_y("pile_collapse", piles) == "angle_of_repose_deg"
    assert default_plot_y("grain_compression", []) is None


def test_sweep_runs_cases_on_a_local_cluster(tmp_path, cli):
    out = tmp_path / "sweep"
    code, stdout, err = cli(
        "sweep", write_config(tmp_path), "--zip", "--workers", 2, "--out", out,
        "--set", "material.E=1e6,2e6,2e6", "--set", "loading.max_strain=0.05,0.05,0.95",
    )  # fmt: skip
    assert code == 0, err
    assert "1 of 3 cases failed" in err and "sweep.csv" in err
    assert "max_force against loading.max_strain" in stdout

    rows = read_table(out / "sweep.csv")
    assert list(rows[0])[:5] == ["case", "material.E", "loading.max_strain", "status", "error"]
    names = ["case_000_E=1e+06_max_strain=0.05", "case_001_E=2e+06_max_strain=0.05", "case_002_E=2e+06_max_strain=0.95"]
    assert [r["case"] for r in rows] == names
    assert [r["status"] for r in rows] == ["ok", "ok", "failed"]
    assert rows[2]["error"].startswith("NewtonDivergedError: Newton did not converge")
    assert rows[2]["max_force"] == "" and rows[0]["error"] == ""

    for name, row in zip(names, rows):
        # each case's config is TOML that `vemdem run` accepts as it is
        config = tomllib.loads((out / name / "config.toml").read_text())
        assert config["material"]["E"] == float(row["material.E"])
        checked_config(config)
    for name, row in zip(names[:2], rows[:2]):
        summary = json.loads((out / name / "summary.json").read_text())
        assert summary["max_force"] == float(row["max_force"])
    assert not (out / names[2] / "summary.json").exists()
    # Twice as stiff, twice the force at the same strain (the model is linear in E at fixed nu).
    soft, stiff = (float(r["max_force"]) for r in rows[:2])
    assert stiff > soft > 0
    assert stiff / soft == pytest.approx(2.0, rel=1e-6)
    assert (out / "sweep.png").stat().st_size > 1000


def test_local_workers_run_numba_single_threaded(monkeypatch):
    from vemdem.sweep import dask_client

    monkeypatch.setenv("NUMBA_NUM_THREADS", "7")  # what the workers would otherwise inherit
    with dask_client(None, 1) as client:
        assert client.submit(os.getenv, "NUMBA_NUM_THREADS").result() == "1"
        # the local scheduler and its dashboard listen on this machine only
        assert client.scheduler.address.startswith("tcp://127.0.0.1:")
        assert "127.0.0.1" in client.dashboard_link


@pytest.fixture(scope="module")
def scheduler():
    from dask.distributed import LocalCluster

    # In-process workers start in a blink: enough to stand for a cluster someone else runs.
    with LocalCluster(n_workers=1, threads_per_worker=2, processes=False, dashboard_address=None) as cluster:
        yield cluster.scheduler_address


def test_all_cases_failed_exits_1(tmp_path, cli, scheduler):
    out = tmp_path / "sweep"
    code, _, err = cli(
        "sweep", write_config(tmp_path), "--scheduler", scheduler, "--out", out, "--quiet",
        "--set", "loading.max_strain=0.9,0.95",
    )  # fmt: skip
    assert code == 1
    assert "2 of 2 cases failed" in err
    rows = read_table(out / "sweep.csv")
    assert [r["status"] for r in rows] == ["failed", "failed"]
    assert not (out / "sweep.png").exists()


@pytest.mark.parametrize(
    "setting,problem",
    [
        ("contact.mu_s=0.9,0.6", "contact: unknown key"),
        ("material.E=1e6,-1", "material.E: must be in [1e3, 1e13] Pa"),
        ("material.E", "expected KEY=V1,V2,..."),
    ],
)
def test_bad_set_exits_2_before_running(tmp_path, cli, setting, problem):
    out = tmp_path / "sweep"
    code, _, err = cli("sweep", write_config(tmp_path), "--set", setting, "--out", out)
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and problem in lines[0], err
    assert not out.exists()


def test_sweep_out_that_is_a_file_or_another_sweep_exits_2(tmp_path, cli):
    """A file as --out was a traceback, and a second sweep into a finished one's folder wrote over
    its cases and table without a word."""
    (tmp_path / "afile").write_text("")
    code, _, err = cli("sweep", write_config(tmp_path), "--set", "material.E=1e6,2e6", "--out", tmp_path / "afile")
    assert code == 2 and "is a file" in err and "Traceback" not in err
    done = tmp_path / "done"
    done.mkdir()
    (done / "sweep.csv").write_text("case\n")
    code, _, err = cli("sweep", write_config(tmp_path), "--set", "material.E=1e6,2e6", "--out", done)
    assert code == 2 and "another sweep" in err
    assert sorted(p.name for p in done.iterdir()) == ["sweep.csv"]


# A 4-grain pile collapse of rigid grains (seconds): two seeds, two collapse frictions.
PILE = """
scenario = "pile_collapse"
[model]
grains = "rigid"
[pack]
n_grains = 4
seed = 5
[pack.grains]
vertices = 8
size = 1.2e-3
[pack.box]
width = 3.2e-3
depth = 3.2e-3
[contact]
mu_s = 0.6
mu_d = 0.5
[settle]
max_time = 0.02
min_time = 0.02
kinetic_threshold = 1e-2
[output]
every = 5e-3
vtk = false
"""


def test_cases_that_settle_the_same_pack_share_it(tmp_path, cli, scheduler, monkeypatch):
    from vemdem.scenarios import pack

    config = tmp_path / "pile.toml"
    config.write_text(PILE)
    settled = []
    original = pack.run
    monkeypatch.setattr(pack, "run", lambda cfg, folder, **kw: (settled.append(cfg["seed"]), original(cfg, folder, **kw))[1])
    out = tmp_path / "sweep"
    code, _, err = cli("sweep", config, "--scheduler", scheduler, "--out", out, "--quiet",
                       "--set", "seed=1,2", "--set", "contact.mu_s=0.6,0.9")  # fmt: skip
    assert code == 0, err
    rows = read_table(out / "sweep.csv")[:4]
    assert [r["status"] for r in rows] == ["ok"] * 4
    # one pack per seed, not one per case
    assert sorted(settled) == [1, 2]
    names = [r["case"] for r in rows]
    packs = [(out / name / "pack" / "state.npz").read_bytes() for name in names]
    assert packs[0] == packs[1] != packs[2] == packs[3]
    # a case that started from a shared pack ends with the bits of the same case run alone
    code, _, err = cli("run", out / names[3] / "config.toml", "--out", tmp_path / "alone")
    assert code == 0, err
    assert sorted(settled) == [1, 2, 2]
    for name in ("history.csv", "grains.csv", "pack/state.npz"):
        assert (tmp_path / "alone" / name).read_bytes() == (out / names[3] / name).read_bytes(), name


def test_a_failed_shared_pack_fails_each_of_its_cases_with_its_reason(tmp_path):
    from vemdem.sweep import Case, run_case, shared_packs

    raw = tomllib.loads(PILE)
    cases = [Case(f"case_{i}", {}, with_values(raw, {"contact.mu_s": mu})) for i, mu in enumerate((0.6, 0.9))]
    (shared,) = shared_packs(cases, tmp_path)
    assert shared.cases == (0, 1) and shared.folder == tmp_path / "case_0" / "pack"
    result = run_case(cases[1].raw, str(tmp_path / "case_1"), str(tmp_path), {"status": "failed", "error": "X: y"},
                      str(shared.folder))  # fmt: skip
    assert result == {"status": "failed", "error": f"shared pack stage ({shared.folder}): X: y"}
    # a case that starts from initial_state has no pack stage to share
    alone = {k: v for k, v in with_values(raw, {"initial_state": "pack.npz"}).items() if k != "pack"}
    assert shared_packs([Case("a", {}, alone), Case("b", {}, alone)], tmp_path) == []


def test_a_settled_shared_pack_says_so_in_its_first_case_progress(tmp_path, monkeypatch):
    import vemdem.sweep as sweep_mod

    monkeypatch.setattr(sweep_mod, "settle_pack", lambda config, folder, progress: progress(3, 200, "t = 0.1 s"))
    assert sweep_mod.run_pack({}, str(tmp_path / "pack"), str(tmp_path)) == {"status": "ok"}
    assert (tmp_path / "progress.txt").read_text() == "pack settled, shared; the case waits for a worker"

    def broken(config, folder, progress):
        raise RuntimeError("no room")

    monkeypatch.setattr(sweep_mod, "settle_pack", broken)
    assert sweep_mod.run_pack({}, str(tmp_path / "pack"), str(tmp_path)) == {"status": "failed", "error": "RuntimeError: no room"}
