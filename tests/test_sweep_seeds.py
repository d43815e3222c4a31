"""Sweeps over seeds (docs/sweeps.md): seed is a product axis even with --zip, sweep.csv gains mean and
std rows per setting, sweep.png draws mean and spread; round-off is not a trend."""

import csv
import statistics

import pytest

from vemdem.analysis.seeds import seed_statistics, varies
from vemdem.sweep import (
    Case,
    _progress_file,
    case_grid,
    default_plot_y,
    plot_sweep,
    running_line,
    write_table,
)


def test_seed_is_never_zipped():
    grid = case_grid({"contact.mu_s": [0.9, 0.3], "contact.mu_d": [0.8, 0.2], "seed": [1, 2, 3]}, zipped=True)
    assert grid == [
        {"contact.mu_s": mu_s, "contact.mu_d": mu_d, "seed": seed}
        for mu_s, mu_d in [(0.9, 0.8), (0.3, 0.2)] for seed in (1, 2, 3)
    ]  # fmt: skip
    # the seed list may differ in length from the zipped lists
    assert len(case_grid({"a": [1, 2], "seed": [1, 2, 3, 4, 5]}, zipped=True)) == 10


ANGLES = {(0.9, 1): 31.0, (0.9, 2): 29.0, (0.9, 3): 33.5, (0.3, 1): 12.0, (0.3, 2): 14.0, (0.3, 3): 0.0}


def _seeded_sweep():
    cases, results = [], []
    for i, (mu, seed) in enumerate(ANGLES):
        cases.append(Case(f"case_{i:03d}", {"contact.mu_s": mu, "seed": seed}, {"scenario": "pile_collapse"}))
        failed = (mu, seed) == (0.3, 3)
        results.append({"status": "failed", "error": "boom"} if failed else
                       {"status": "ok", "angle_of_repose_deg": ANGLES[mu, seed], "n_steps": 10 * seed, "label": "x"})
    return cases, results


def test_mean_and_std_rows_match_the_statistics_module(tmp_path):
    cases, results = _seeded_sweep()
    write_table(tmp_path / "sweep.csv", cases, results)
    rows = list(csv.DictReader((tmp_path / "sweep.csv").open()))
    assert [r["case"] for r in rows[6:]] == ["mean", "std", "mean", "std"]
    high_mean, high_std, low_mean, low_std = rows[6:]
    assert float(high_mean["contact.mu_s"]) == 0.9 and high_mean["seed"] == ""
    assert float(high_mean["angle_of_repose_deg"]) == pytest.approx(statistics.mean([31.0, 29.0, 33.5]))
    assert float(high_std["angle_of_repose_deg"]) == pytest.approx(statistics.stdev([31.0, 29.0, 33.5]))
    # the failed seed is left out, and the count says so
    assert low_mean["n_seeds"] == "2" and high_mean["n_seeds"] == "3"
    assert float(low_mean["angle_of_repose_deg"]) == pytest.approx(13.0)
    assert float(low_std["angle_of_repose_deg"]) == pytest.approx(statistics.stdev([12.0, 14.0]))
    assert float(high_mean["n_steps"]) == pytest.approx(20.0)
    assert high_mean["label"] == "" and rows[0]["n_seeds"] == ""


def test_a_single_seed_has_unknown_spread():
    (group,) = seed_statistics([{"k": 1, "y": 2.0}], ["k"])
    assert group.n == 1 and group.mean["y"] == 2.0 and group.std["y"] != group.std["y"]  # NaN


def test_seed_plot_draws_means_against_the_other_key(tmp_path):
    cases, results = _seeded_sweep()
    note = plot_sweep(tmp_path / "sweep.png", cases, results, zipped=False)
    assert "angle_of_repose_deg against contact.mu_s, mean and spread over seeds" in note
    assert (tmp_path / "sweep.png").stat().st_size > 1000
    only_seeds = [Case(c.name, {"seed": c.params["seed"]}, c.raw) for c in cases[:3]]
    note = plot_sweep(tmp_path / "seeds.png", only_seeds, results[:3], zipped=False)
    assert "against seed" in note and (tmp_path / "seeds.png").stat().st_size > 1000


def test_round_off_is_not_a_trend():
    assert not varies([0.004999999999999994, 0.005])
    assert varies([0.0049, 0.005]) and varies([0.0, 1e-12]) is True
    ok = [{"dt": 0.004999999999999994, "force": 1.0, "n": 3}, {"dt": 0.005, "force": 1.0, "n": 4}]
    assert default_plot_y("grain_compression", ok) == "n"


def test_running_cases_report_progress(tmp_path):
    cases = [Case(f"case_00{i}_a={i}", {"a": i}, {}) for i in range(3)]
    for case in cases:
        (tmp_path / case.name).mkdir()
    _progress_file(tmp_path / cases[1].name)(12, 40, "t = 0.06 s")
    _progress_file(tmp_path / cases[2].name)(40, 40, "done")
    assert running_line(tmp_path, cases, done={2}) == "001: 12/40 t = 0.06 s"


def test_the_seed_of_a_scenario_with_a_pack_stage_is_the_packs():
    """`--set seed=...` on a config that settles a pack first (the README's pile) seeds its [pack];
    one that starts from a saved state has no pack to seed, and says so."""
    import tomllib

    from vemdem.config import ConfigError
    from vemdem.scenarios.registry import example_text
    from vemdem.sweep import plan_cases

    pile = tomllib.loads(example_text("pile"))
    cases = plan_cases(pile, ["seed=3,4"], zipped=False)
    assert [c.raw["pack"]["seed"] for c in cases] == [3, 4]
    assert "seed" not in cases[0].raw and [c.params["seed"] for c in cases] == [3, 4]
    pack = tomllib.loads(example_text("paper-pack"))  # its seed is at the top
    assert [c.raw["seed"] for c in plan_cases(pack, ["seed=5"], zipped=False)] == [5]
    with pytest.raises(ConfigError, match="initial_state"):
        plan_cases(tomllib.loads(example_text("paper-collapse-high")), ["seed=1,2"], zipped=False)
