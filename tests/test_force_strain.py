"""Lid compression cycle: work, hysteresis and residual strain against closed-form cycles.

Loading F = K e^2 up to E_MAX; unloading F = K2 (e - E_R)^2 for e > E_R and 0 below, with K2
chosen so that the curves meet at the turning point. With u = e H0:
    W_load = K H0 E_MAX^3 / 3,  W_unload = K2 H0 (E_MAX - E_R)^3 / 3 = K H0 E_MAX^2 (E_MAX - E_R) / 3,
    hysteresis = K H0 E_MAX^2 E_R / 3.
"""

import math

import numpy as np
import pytest

from vemdem.analysis.force_strain import (
    ZERO_FRACTION,
    _figures_text,
    cycle_figures,
    plot_force_strain,
    read_force_strain_csv,
    write_force_strain_csv,
)

K = 2.0e4  # N per unit strain^2
H0 = 12e-3  # initial pile height (m)
E_MAX = 0.1
E_R = 0.04
K2 = K * E_MAX**2 / (E_MAX - E_R) ** 2
N = 2001  # rows per branch


def cycle(unload_force, unload_to=0.0):
    """Rows of a loading branch 0 -> E_MAX and an unloading branch back to unload_to; the
    unloading rows start one step after the turning point, which is not repeated."""
    load_e = np.linspace(0.0, E_MAX, N)
    unload_e = np.linspace(E_MAX, unload_to, N)[1:]
    phase = np.r_[np.full(N, "load"), np.full(N - 1, "unload")]
    return phase, np.r_[load_e, unload_e], np.r_[K * load_e**2, unload_force(unload_e)]


def quadratic_unloading(e):
    return K2 * np.clip(e - E_R, 0.0, None) ** 2


def test_hysteresis_matches_the_closed_form():
    figures = cycle_figures(*cycle(quadratic_unloading), H0)
    assert figures["peak_force"] == pytest.approx(K * E_MAX**2)
    assert figures["loading_work"] == pytest.approx(K * H0 * E_MAX**3 / 3, rel=1e-4)
    assert figures["unloading_work"] == pytest.approx(K * H0 * E_MAX**2 * (E_MAX - E_R) / 3, rel=1e-4)
    assert figures["hysteresis_energy"] == pytest.approx(K * H0 * E_MAX**2 * E_R / 3, rel=1e-4)


def test_elastic_cycle_has_no_hysteresis():
    """Unloading retraces loading (on other rows): nothing is dissipated, nothing is left."""
    phase, strain, force = cycle(lambda e: K * e**2)
    figures = cycle_figures(phase, strain, force, H0)
    assert abs(figures["hysteresis_energy"]) < 1e-6 * figures["loading_work"]
    assert figures["residual_strain"] == pytest.approx(math.sqrt(ZERO_FRACTION) * E_MAX, abs=E_MAX / N)


def test_residual_strain_is_where_the_force_vanishes():
    figures = cycle_figures(*cycle(quadratic_unloading), H0, zero_fraction=0.0)
    assert figures["residual_strain"] == pytest.approx(E_R, abs=1e-12)


def test_residual_strain_threshold_lateness_is_as_documented():
    """zero_fraction of the peak is reached zero_fraction^(1/n) of the unloading range late for
    F ~ (e - E_R)^n: exactly for a linear unloading, to a row for the quadratic one."""
    peak = K * E_MAX**2
    k_linear = peak / (E_MAX - E_R)
    linear = cycle_figures(*cycle(lambda e: k_linear * np.clip(e - E_R, 0.0, None)), H0)
    assert linear["residual_strain"] == pytest.approx(E_R + ZERO_FRACTION * (E_MAX - E_R), rel=1e-9)
    quadratic = cycle_figures(*cycle(quadratic_unloading), H0)
    late = math.sqrt(ZERO_FRACTION) * (E_MAX - E_R)
    assert quadratic["residual_strain"] == pytest.approx(E_R + late, abs=E_MAX / N)


def test_absolute_residual_strain_is_where_the_force_falls_to_it():
    """F = K2 (e - E_R)^2 falls to F0 at e = E_R + sqrt(F0 / K2), whatever the peak; to a row's
    linear interpolation of the quadratic."""
    for f0 in (0.0, 1.0, 25.0):
        figures = cycle_figures(*cycle(quadratic_unloading), H0, zero_force=f0)
        assert figures["residual_strain_absolute"] == pytest.approx(E_R + math.sqrt(f0 / K2), abs=E_MAX / N)
    assert "residual_strain_absolute" not in cycle_figures(*cycle(quadratic_unloading), H0)
    with pytest.raises(ValueError, match="zero_force"):
        cycle_figures(*cycle(quadratic_unloading), H0, zero_force=-1.0)


def test_partial_unloading_keeps_the_stored_energy():
    """Stopping at 0.07 before the force is back to zero: the last strain is the residual one,
    and the hysteresis holds the elastic energy still stored there."""
    figures = cycle_figures(*cycle(quadratic_unloading, unload_to=0.07), H0)
    assert figures["residual_strain"] == pytest.approx(0.07)
    returned = K2 * H0 * ((E_MAX - E_R) ** 3 - (0.07 - E_R) ** 3) / 3
    assert figures["hysteresis_energy"] == pytest.approx(K * H0 * E_MAX**3 / 3 - returned, rel=1e-4)


def test_csv_round_trip_is_exact(tmp_path):
    phase, strain, force = cycle(quadratic_unloading)
    strain = strain + 1e-17 * np.arange(len(strain))  # digits a short format would lose
    path = tmp_path / "force_strain.csv"
    write_force_strain_csv(path, phase, strain, force)
    assert path.read_text().splitlines()[0] == "phase,strain,force"
    read_phase, read_strain, read_force = read_force_strain_csv(path)
    assert read_phase.tolist() == phase.tolist()
    assert np.array_equal(read_strain, strain) and np.array_equal(read_force, force)


def test_csv_with_another_header_is_refused(tmp_path):
    path = tmp_path / "force_strain.csv"
    path.write_text("strain,force\n0.0,0.0\n")
    with pytest.raises(ValueError, match="header must be phase,strain,force"):
        read_force_strain_csv(path)


@pytest.mark.parametrize(
    "phase, problem",
    [
        (["load", "load", "unload", "load"], "one cycle expected"),
        (["load", "load", "unload", "relax"], "got 'relax'"),
        (["load", "load", "load", "load"], "1 'unload' row"),
    ],
)
def test_malformed_cycles_are_refused(phase, problem):
    with pytest.raises(ValueError, match=problem):
        cycle_figures(phase, [0.0, 0.1, 0.05, 0.0], [0.0, 1.0, 0.5, 0.0], H0)


def test_plot_is_written(tmp_path):
    phase, strain, force = cycle(quadratic_unloading)
    path = tmp_path / "force_strain.png"
    plot_force_strain(phase, strain, force, path, figures=cycle_figures(phase, strain, force, H0))
    assert path.stat().st_size > 1000


def test_the_plot_box_gives_the_spring_back_shares_where_there_are_some(tmp_path):
    figures = cycle_figures(*cycle(quadratic_unloading), H0)
    assert len(_figures_text(figures).splitlines()) == 5
    back = {"branch_strain": 0.04, "deformation": 0.012, "contact_gap": 0.012, "tangential": 0.02, "rotation": -0.004}
    text = _figures_text({**figures, "spring_back": back})
    assert "spring-back 4 %: grains 30%," in text and "contact gaps 30%, rearrangement 40%" in text
    for nothing in ({"error": "no turn"}, {**back, "branch_strain": -0.01}):
        assert len(_figures_text({**figures, "spring_back": nothing}).splitlines()) == 5
    plot_force_strain(*cycle(quadratic_unloading), tmp_path / "fs.png", {**figures, "spring_back": back})
    assert (tmp_path / "fs.png").stat().st_size > 10_000
