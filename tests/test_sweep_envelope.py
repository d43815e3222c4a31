"""A triaxial sweep over the confining stress gives Mohr-Coulomb envelopes (docs/triaxial.md):
one per setting of the other swept keys and per seed, in sweep.csv (with mean and spread over the
seeds) and drawn in envelope.png; a sweep that does not vary the confining stress has none. A
direct shear sweep over the normal stress gives Coulomb lines the same way (docs/direct-shear.md)."""

import csv
import math
import statistics

import pytest

from vemdem.sweep import Case, add_envelopes, write_table

STRESSES = (50e3, 100e3, 200e3)
# (interparticle friction, seed) -> (cohesion Pa, peak angle deg, critical-state angle deg) the
# synthetic tests fail on
ENVELOPES = {(0.3, 1): (0.0, 30.0, 25.0), (0.3, 2): (0.0, 32.0, 25.5), (0.6, 1): (2e3, 38.0, 29.0),
             (0.6, 2): (1e3, 40.0, 28.0)}  # fmt: skip


def sigma_1(c, phi_deg, sigma_3):
    """The major principal stress of a Mohr circle tangent to tau = c + sigma tan(phi)."""
    k = math.tan(math.radians(45.0 + phi_deg / 2.0))
    return sigma_3 * k**2 + 2.0 * c * k


def _sweep(failed=()):
    cases, results = [], []
    for (mu, seed), (c, phi_peak, phi_cs) in ENVELOPES.items():
        for stress in STRESSES:
            params = {"contact.mu_s": mu, "consolidation.stress": stress, "seed": seed}
            cases.append(Case(f"case_{len(cases):03d}", params, {"scenario": "triaxial"}))
            if (mu, seed, stress) in failed:
                results.append({"status": "failed", "error": "boom"})
                continue
            results.append({"status": "ok", "sigma_3_peak_Pa": stress, "sigma_1_peak_Pa": sigma_1(c, phi_peak, stress),
                            "sigma_3_cs_Pa": stress, "sigma_1_cs_Pa": sigma_1(0.0, phi_cs, stress)})  # fmt: skip
    return cases, results


def test_each_seed_and_setting_gets_its_own_envelope(tmp_path):
    cases, results = _sweep()
    note = add_envelopes(cases, results, tmp_path / "envelope.png")
    assert "consolidation.stress" in note and "2 panels" in note
    for case, result in zip(cases, results):
        c, phi_peak, phi_cs = ENVELOPES[case.params["contact.mu_s"], case.params["seed"]]
        # the free line finds the cohesion the peaks were made with; the default goes through the origin
        assert result["envelope_phi_peak_free_deg"] == pytest.approx(phi_peak, abs=1e-9)
        assert result["envelope_cohesion_peak_free_Pa"] == pytest.approx(c, abs=1e-6)
        assert result["envelope_cohesion_peak_Pa"] == 0.0
        assert (result["envelope_phi_peak_deg"] > phi_peak) == (c > 0)  # the cohesion taken up by the angle
        # a cohesionless critical state: both lines are the one it was made with
        for tail in ("", "_free"):
            assert result[f"envelope_phi_cs{tail}_deg"] == pytest.approx(phi_cs, abs=1e-9)
            assert result[f"envelope_cohesion_cs{tail}_Pa"] == pytest.approx(0.0, abs=1e-6)
        assert result["envelope_tests_peak"] == 3
    assert (tmp_path / "envelope.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    # the spread over seeds: sweep.csv's mean and std rows of the envelopes
    write_table(tmp_path / "sweep.csv", cases, results)
    rows = list(csv.DictReader((tmp_path / "sweep.csv").open()))
    means = {float(r["contact.mu_s"]): r for r in rows if r["case"] == "mean"}
    stds = {float(r["contact.mu_s"]): r for r in rows if r["case"] == "std"}
    for mu in (0.3, 0.6):
        angles = [ENVELOPES[mu, seed][1] for seed in (1, 2)]
        # the mean row averages over the confining stresses as well: every case of a seed carries its envelope
        assert float(means[mu]["envelope_phi_peak_free_deg"]) == pytest.approx(statistics.mean(angles))
        assert float(stds[mu]["envelope_phi_peak_free_deg"]) > 0.5


def test_a_failed_test_leaves_its_envelope_to_the_others(tmp_path):
    cases, results = _sweep(failed={(0.3, 1, 100e3)})
    add_envelopes(cases, results, tmp_path / "envelope.png")
    first = results[0]
    assert first["envelope_tests_peak"] == 2
    assert first["envelope_phi_peak_deg"] == pytest.approx(30.0, abs=1e-9)
    assert "envelope_phi_peak_deg" not in results[1]  # the failed case has no result to carry one
    # one test alone: the cohesionless angle of its own ratio
    cases, results = _sweep(failed={(0.3, 1, 100e3), (0.3, 1, 200e3)})
    add_envelopes(cases, results, tmp_path / "envelope.png")
    assert results[0]["envelope_tests_peak"] == 1 and results[0]["envelope_cohesion_peak_Pa"] == 0.0


def test_no_envelope_without_a_sweep_over_the_confining_stress(tmp_path):
    cases = [Case(f"case_{i}", {"contact.mu_s": mu}, {"scenario": "triaxial"}) for i, mu in enumerate((0.3, 0.6))]
    results = [{"status": "ok", "sigma_3_peak_Pa": 50e3, "sigma_1_peak_Pa": 150e3} for _ in cases]
    assert add_envelopes(cases, results, tmp_path / "envelope.png") is None
    assert not (tmp_path / "envelope.png").exists()
    assert all("envelope_phi_peak_deg" not in r for r in results)
    pile = [Case("case_0", {"consolidation.stress": 1.0}, {"scenario": "pile_collapse"})]
    assert add_envelopes(pile, [{"status": "ok"}], tmp_path / "envelope.png") is None


def test_tests_failing_at_one_mean_stress_give_no_free_line_but_the_one_through_the_origin(tmp_path):
    cases, results = _sweep()
    for r in results:  # every test failed at the same s: no slope to fit
        r["sigma_3_peak_Pa"], r["sigma_1_peak_Pa"] = 100e3, 300e3
    add_envelopes(cases, results, tmp_path / "envelope.png")
    assert "same mean stress" in results[0]["envelope_peak_free_error"]
    # through the origin one stress ratio still gives its angle: R = 3 is 30 deg
    assert results[0]["envelope_phi_peak_deg"] == pytest.approx(30.0)


def test_a_direct_shear_sweep_over_the_normal_stress_gives_coulomb_lines(tmp_path):
    # (seed) -> (cohesion Pa, peak angle, residual angle) the synthetic boxes fail on
    lines = {1: (2e3, 45.0, 38.0), 2: (0.0, 47.0, 37.0)}
    cases, results = [], []
    for seed, (c, phi_peak, phi_res) in lines.items():
        for stress in STRESSES:
            cases.append(Case(f"case_{len(cases):03d}", {"normal.stress": stress, "seed": seed},
                              {"scenario": "direct_shear"}))  # fmt: skip
            # the lid's measured stress is not the target: the fit uses what was measured
            s_peak, s_res = 1.02 * stress, 0.99 * stress
            results.append({"status": "ok", "sigma_n_peak_Pa": s_peak,
                            "tau_peak_Pa": c + s_peak * math.tan(math.radians(phi_peak)),
                            "sigma_n_residual_Pa": s_res, "tau_residual_Pa": s_res * math.tan(math.radians(phi_res))})
    note = add_envelopes(cases, results, tmp_path / "envelope.png")
    assert "normal.stress" in note
    for case, result in zip(cases, results):
        c, phi_peak, phi_res = lines[case.params["seed"]]
        assert result["envelope_phi_peak_free_deg"] == pytest.approx(phi_peak)
        assert result["envelope_cohesion_peak_free_Pa"] == pytest.approx(c, abs=1e-6)
        if c == 0.0:  # a cohesionless line: the default envelope through the origin is that line
            assert result["envelope_phi_peak_deg"] == pytest.approx(phi_peak)
        assert result["envelope_phi_residual_deg"] == pytest.approx(phi_res)
        assert result["envelope_tests_residual"] == 3
    assert (tmp_path / "envelope.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
