"""The triaxial measures (analysis.triaxial) against curves and stress states whose answers are
known in closed form: a stress-ratio curve with a known peak and exponential tail, a volumetric
curve with a known steepest slope, a Duncan-Chang hyperbola and exact Mohr-Coulomb failure states.
"""

import math

import numpy as np
import pytest

from vemdem.analysis.triaxial import (
    HEADER,
    critical_state,
    dilatancy_angle,
    friction_angle,
    friction_angle_of_eta,
    mohr_coulomb_fit,
    peak,
    plot_envelope,
    plot_triaxial,
    secant_modulus_50,
    stress_ratio_from_angle,
    triaxial_figures,
    until_sheared,
)

SIGMA_3 = 100e3
# the synthetic stress-ratio curve: R rises as a hyperbola from 1 to its peak R = 4 at 3 % axial
# strain, then decays exponentially (length LAM) towards R = 3 by 25 %
E_PEAK, R_PEAK, R_CS, LAM, E_END = 0.03, 4.0, 3.0, 0.03, 0.25


def ratio_curve(e):
    rise = 1.0 + (R_PEAK - 1.0) * (e / E_PEAK) * 1.5 / (1.0 + 0.5 * e / E_PEAK)  # = R_PEAK at E_PEAK, rising
    tail = R_CS + (R_PEAK - R_CS) * np.exp(-(e - E_PEAK) / LAM)
    return np.where(e <= E_PEAK, rise, tail)


def test_friction_angle_of_known_ratios():
    assert friction_angle(3.0) == pytest.approx(30.0, abs=1e-12)  # sin(phi) = 2/4
    assert friction_angle(1.0) == 0.0
    # by hand: R = 4 gives sin(phi) = 3/5, the 3-4-5 triangle's angle atan(3/4) = 36.8699 deg
    assert friction_angle(4.0) == pytest.approx(36.86989764584402, abs=1e-12)
    phi = np.linspace(0.0, 60.0, 61)
    assert np.allclose(friction_angle(stress_ratio_from_angle(phi)), phi, atol=1e-10)
    # the inverse against the textbook passive coefficient tan^2(45 + phi/2)
    assert np.allclose(stress_ratio_from_angle(phi), np.tan(np.radians(45.0 + phi / 2.0)) ** 2, rtol=1e-12)
    assert isinstance(friction_angle(2.0), float) and friction_angle(np.array([2.0, 3.0])).shape == (2,)


def test_peak_and_critical_state_of_a_closed_form_curve():
    e = np.linspace(0.0, E_END, 2501)  # 0.01 % steps: E_PEAK is a row
    s3 = np.full_like(e, SIGMA_3)
    s1 = ratio_curve(e) * s3
    top = peak(e, s1, s3)
    assert top["ratio_peak"] == pytest.approx(R_PEAK, rel=1e-12)
    assert top["phi_peak_deg"] == pytest.approx(math.degrees(math.atan2(3.0, 4.0)), abs=1e-9)
    assert top["axial_strain_at_peak"] == pytest.approx(E_PEAK, abs=1e-12)
    assert top["q_peak"] == pytest.approx((R_PEAK - 1.0) * SIGMA_3, rel=1e-12)

    window = 0.05
    cs = critical_state(e, s1, s3, window=window)
    assert cs["window_rows"] == 501  # 0.20 to 0.25 in 0.01 % steps, both ends included
    # the tail's exact mean excess over R_CS on [E_END - window, E_END] (integral of the exponential)
    a, b = E_END - window - E_PEAK, E_END - E_PEAK
    excess = (R_PEAK - R_CS) * LAM / window * (math.exp(-a / LAM) - math.exp(-b / LAM))
    assert 0.0 < excess < 2e-3
    # the mean of 501 evenly spaced rows against the integral mean: within the trapezoid's ends term
    assert cs["phi_cs_deg"] == pytest.approx(friction_angle(R_CS + excess), abs=1e-5)
    assert cs["phi_cs_from_ratio_deg"] == pytest.approx(friction_angle(R_CS + excess), abs=1e-5)
    assert cs["critical_state_window"] == window
    assert 30.0 < cs["phi_cs_deg"] < friction_angle(R_CS + 2 * excess)
    assert cs["phi_cs_deg"] - 30.0 > 0.5 * (friction_angle(R_CS + excess) - 30.0)  # the tail is seen, not lost
    # eta = 3 (R - 1) / (R + 2) is 6/5 at R = 3; the tail lifts it by d eta / dR = 9 / (R + 2)^2
    # = 9/25 per unit of R (eta is all but straight over so small an excess)
    assert cs["q_over_p_cs"] == pytest.approx(1.2 + 9 / 25 * excess, abs=1e-6)
    assert cs["q_over_p_cs"] > 1.2
    assert 0.0 < cs["phi_cs_spread_deg"] < 0.05
    assert 0.0 < cs["q_over_p_cs_spread"] < 0.005


def test_the_angle_of_eta_is_the_angle_of_the_ratio_it_comes_from():
    r = np.linspace(1.0, 6.0, 51)
    eta = 3.0 * (r - 1.0) / (r + 2.0)  # q / p with sigma_2 = sigma_3
    assert np.allclose(friction_angle_of_eta(eta), friction_angle(r), atol=1e-12)
    assert isinstance(friction_angle_of_eta(1.2), float)


def test_the_critical_state_angle_comes_from_the_mean_q_over_p_not_the_mean_ratio():
    # a servo-held sigma_3 that swings 40-60 kPa under a steady sigma_1: the mean of R = s1/s3 reads
    # high (Jensen: 1/s3 is convex), the mean of eta = q/p much less
    e = np.linspace(0.0, 0.1, 101)
    s1 = np.full_like(e, 150e3)
    s3 = np.where(np.arange(len(e)) % 2 == 0, 40e3, 60e3)
    cs = critical_state(e, s1, s3, window=0.05)
    inside = e >= 0.05 - 1e-12
    eta = [(a - b) / ((a + 2 * b) / 3) for a, b in zip(s1[inside], s3[inside])]
    eta_mean = sum(eta) / len(eta)
    assert cs["q_over_p_cs"] == pytest.approx(eta_mean, rel=1e-12)
    assert cs["phi_cs_deg"] == pytest.approx(math.degrees(math.asin(3 * eta_mean / (6 + eta_mean))), abs=1e-9)
    ratio_mean = float(np.mean(s1[inside] / s3[inside]))
    assert cs["phi_cs_from_ratio_deg"] == pytest.approx(math.degrees(math.asin((ratio_mean - 1) / (ratio_mean + 1))))
    # the angle of the mean stresses (R = 3, 30 deg) lies below both; the ratio's mean is the further
    assert 30.0 < cs["phi_cs_deg"] < cs["phi_cs_from_ratio_deg"] - 0.4


def test_critical_state_refuses_short_runs():
    e = np.linspace(0.0, 0.03, 31)
    s3 = np.full_like(e, SIGMA_3)
    with pytest.raises(ValueError, match="less than the critical-state window"):
        critical_state(e, ratio_curve(e) * s3, s3, window=0.05)
    e = np.array([0.0, 0.01, 0.06, 0.1])
    s3 = np.full_like(e, SIGMA_3)
    with pytest.raises(ValueError, match="needs 3"):
        critical_state(e, 3.0 * s3, s3, window=0.05)


def volumetric_curve(e, slopes):
    """eps_v whose slope d eps_v / d eps_a is piecewise linear through `slopes` ((strain, slope)
    knots): the trapezoid rule integrates a linear slope exactly, knots being rows."""
    knots = np.array(slopes)
    s = np.interp(e, knots[:, 0], knots[:, 1])
    return np.concatenate([[0.0], np.cumsum(0.5 * (s[1:] + s[:-1]) * np.diff(e))])


def test_dilatancy_angle_from_the_steepest_dilation():
    e = np.linspace(0.0, 0.2, 2001)
    # contracts at slope 0.5, turns, dilates at slope -0.3 from 4 % to 10 %, then eases to the
    # critical state's zero slope: the steepest dilation is the -0.3 plateau, and a least-squares
    # slope over any window is a weighted mean of the slopes inside it, so never steeper
    ev = volumetric_curve(e, [(0.0, 0.5), (0.04, -0.3), (0.10, -0.3), (0.2, 0.0)])
    out = dilatancy_angle(e, ev, window=0.02)
    # by hand: sin(psi) = 0.3 / (2 + 0.3) = 0.1304348, psi = 7.49472 deg
    assert out["dilatancy_angle_deg"] == pytest.approx(7.49472, abs=1e-5)
    assert out["dilatancy_angle_deg"] == pytest.approx(math.degrees(math.asin(0.3 / 2.3)), abs=1e-9)
    assert 0.05 - 1e-9 <= out["axial_strain_at_max_dilatancy"] <= 0.09 + 1e-9  # windows inside the plateau
    # noise of a DEM frame's size does not make the maximum: the fitted window averages it out
    noisy = ev + np.random.default_rng(0).normal(0.0, 2e-5, len(e))
    assert dilatancy_angle(e, noisy)["dilatancy_angle_deg"] == pytest.approx(7.4947, abs=0.3)


def test_a_contracting_sample_has_a_negative_dilatancy_angle():
    e = np.linspace(0.0, 0.2, 2001)
    ev = 0.3 * e - 0.5 * e**2  # slope 0.3 - e: contracts throughout, least at the end
    out = dilatancy_angle(e, ev, window=0.02)
    # a line fitted to a parabola over a symmetric window has the parabola's slope at the centre;
    # the last full window is centred at 0.19: slope 0.11, sin(psi) = -0.11 / 1.89
    assert out["dilatancy_angle_deg"] < 0.0
    assert out["dilatancy_angle_deg"] == pytest.approx(math.degrees(math.asin(-0.11 / 1.89)), abs=1e-6)
    assert out["axial_strain_at_max_dilatancy"] == pytest.approx(0.19, abs=1e-9)
    with pytest.raises(ValueError, match="no window"):
        dilatancy_angle(e[:10], ev[:10], window=0.02)


def test_e50_of_a_duncan_chang_hyperbola():
    e_i, q_ult = 50e6, 300e3  # initial tangent modulus, asymptotic deviator
    a, b = 1.0 / e_i, 1.0 / q_ult
    e = np.linspace(0.0, 0.2, 20001)
    q = e / (a + b * e)
    # q's peak is its last row; half of it is reached at e50 = a q50 / (1 - b q50), so
    # E50 = q50 / e50 = (1 - b q50) / a
    q50 = 0.5 * (0.2 / (a + b * 0.2))
    expected = (1.0 - b * q50) / a
    assert expected == pytest.approx(25.75e6, rel=0.01)  # a touch over half the initial tangent
    assert secant_modulus_50(e, q) == pytest.approx(expected, rel=1e-6)
    # the same curve from a consolidated start: q0 = 50 kPa, the strain column offset
    assert secant_modulus_50(e + 0.01, q + 50e3) == pytest.approx(expected, rel=1e-6)
    # linear interpolation between coarse rows: an exact straight line gives its modulus exactly
    assert secant_modulus_50(np.array([0.0, 0.1, 0.3]), np.array([10.0, 20.0, 40.0])) == pytest.approx(100.0)
    with pytest.raises(ValueError, match="never rose"):
        secant_modulus_50(e, np.full_like(e, 5.0))


def failure_states(c, phi_deg, sigma_3):
    k = math.tan(math.radians(45.0 + phi_deg / 2.0))
    return sigma_3 * k**2 + 2.0 * c * k


def test_mohr_coulomb_fit_recovers_cohesion_and_angle():
    s3 = np.array([50e3, 100e3, 200e3])
    s1 = failure_states(10e3, 35.0, s3)
    fit = mohr_coulomb_fit(s3, s1)
    assert fit["phi_deg"] == pytest.approx(35.0, abs=1e-9)
    assert fit["cohesion_Pa"] == pytest.approx(10e3, abs=1e-9 * 10e3)
    assert fit["r2"] == pytest.approx(1.0, abs=1e-12)
    assert fit["n"] == 3
    noisy = s1 * np.array([1.03, 0.98, 1.01])
    fit = mohr_coulomb_fit(s3, noisy)
    assert fit["r2"] < 1.0 and 30.0 < fit["phi_deg"] < 40.0


def test_the_mohr_coulomb_envelope_through_the_origin_is_tangent_to_every_circle_of_a_cohesionless_material():
    s3 = np.array([25e3, 50e3, 100e3])
    k2 = math.tan(math.radians(45.0 + 34.0 / 2.0)) ** 2  # the passive coefficient of 34 deg
    fit = mohr_coulomb_fit(s3, k2 * s3, through_origin=True)
    assert fit["phi_deg"] == pytest.approx(34.0) and fit["cohesion_Pa"] == 0.0
    # scattered peaks: sin(phi) the s-t slope without an intercept, numpy's least squares the reference
    s1 = np.array([90e3, 170e3, 360e3])
    s, t = 0.5 * (s1 + s3), 0.5 * (s1 - s3)
    (slope,), *_ = np.linalg.lstsq(s[:, None], t, rcond=None)
    fit = mohr_coulomb_fit(s3, s1, through_origin=True)
    assert math.sin(math.radians(fit["phi_deg"])) == pytest.approx(slope)
    assert fit["r2"] < mohr_coulomb_fit(s3, s1)["r2"]  # the free line fits its own points better


def test_mohr_coulomb_fit_of_one_test_and_bad_input():
    one = mohr_coulomb_fit([100e3], [300e3])
    assert one["phi_deg"] == pytest.approx(30.0, abs=1e-12)
    assert one["cohesion_Pa"] == 0.0 and math.isnan(one["r2"]) and one["n"] == 1
    with pytest.raises(ValueError, match="sigma_3 must be finite and positive: test 1"):
        mohr_coulomb_fit([100e3, -50e3], [300e3, 200e3])
    with pytest.raises(ValueError, match="sigma_1 must be finite and positive"):
        mohr_coulomb_fit([100e3, 50e3], [300e3, np.nan])


def synthetic_rows():
    """A triaxial.csv table: 20 consolidation frames, then the closed-form shear from a
    consolidated start at axial strain 0.004 and volumetric strain 0.002 (the consolidation's)."""
    e = np.linspace(0.0, E_END, 1251)
    ratio = ratio_curve(e)
    ev = volumetric_curve(e, [(0.0, 0.5), (0.04, -0.3), (0.10, -0.3), (E_END, 0.0)])
    n_c, n = 20, len(e)
    rows = np.zeros((n_c + n, len(HEADER)))
    col = {name: k for k, name in enumerate(HEADER)}
    rows[:, col["time"]] = np.arange(n_c + n) * 1e-3
    rows[n_c:, col["stage"]] = 1
    rows[:n_c, col["axial_strain"]] = np.linspace(0.0, 0.004, n_c)
    rows[n_c:, col["axial_strain"]] = 0.004 + e
    rows[:n_c, col["volumetric_strain"]] = np.linspace(0.0, 0.002, n_c)
    rows[n_c:, col["volumetric_strain"]] = 0.002 + ev
    rows[:, col["sigma_3"]] = SIGMA_3
    rows[:n_c, col["sigma_1"]] = SIGMA_3
    rows[n_c:, col["sigma_1"]] = ratio * SIGMA_3
    rows[:, col["q"]] = rows[:, col["sigma_1"]] - rows[:, col["sigma_3"]]
    rows[:, col["p"]] = (rows[:, col["sigma_1"]] + 2 * rows[:, col["sigma_3"]]) / 3
    rows[:, col["inertia_number"]] = np.r_[np.full(n_c, 5e-2), np.full(n, 1e-4)]  # consolidation's left out
    rows[n_c + 7, col["inertia_number"]] = 3e-4
    rows[n_c + 8, col["inertia_number"]] = np.inf
    return rows


def test_triaxial_figures_measure_the_shear_from_its_start(tmp_path):
    rows = synthetic_rows()
    fig = triaxial_figures(rows)
    assert fig["shear_rows"] == 1251
    assert fig["phi_peak_deg"] == pytest.approx(math.degrees(math.atan2(3.0, 4.0)), abs=1e-9)
    assert fig["axial_strain_at_peak"] == pytest.approx(E_PEAK, abs=1e-12)  # from the start of shear, not 0.034
    assert 30.0 < fig["phi_cs_deg"] < 30.05
    assert fig["dilatancy_angle_deg"] == pytest.approx(math.degrees(math.asin(0.3 / 2.3)), abs=1e-9)
    e = np.linspace(0.0, E_END, 1251)
    assert fig["E50_Pa"] == pytest.approx(secant_modulus_50(e, (ratio_curve(e) - 1.0) * SIGMA_3), rel=1e-12)
    assert fig["max_inertia_number"] == pytest.approx(3e-4)
    assert "critical_state_error" not in fig

    short = rows[: 20 + 200]  # shear stopped at 4 %: no critical state, the rest still measured
    fig_short = triaxial_figures(short)
    assert "less than the critical-state window" in fig_short["critical_state_error"]
    assert "phi_cs_deg" not in fig_short and fig_short["phi_peak_deg"] == pytest.approx(fig["phi_peak_deg"])
    assert triaxial_figures(rows[:20])["shear_rows"] == 0

    # the held stress over the shear frames only: the consolidation's rows (here 10 % off) do not count
    rows = synthetic_rows()
    n_c = int(np.sum(rows[:, HEADER.index("stage")] == 0))
    rows[:n_c, HEADER.index("sigma_3")] = 1.1 * SIGMA_3
    rows[n_c::2, HEADER.index("sigma_3")] = 1.03 * SIGMA_3  # every other shear frame 3 % high, the rest on target
    held = triaxial_figures(rows, SIGMA_3)
    n_high = len(range(n_c, len(rows), 2))
    assert held["sigma_3_error_mean"] == pytest.approx(0.03 * n_high / (len(rows) - n_c), rel=1e-9)
    assert held["sigma_3_error_abs_mean"] == pytest.approx(held["sigma_3_error_mean"], rel=1e-9)
    assert held["sigma_3_error_max"] == pytest.approx(0.03, rel=1e-9)
    assert "sigma_3_error_mean" not in triaxial_figures(rows)  # no target given, nothing to hold it to

    # smoke checks: the figures are written
    plot_triaxial(rows, tmp_path / "triaxial.png", "synthetic", fig)
    plot_triaxial(short, tmp_path / "short.png", "synthetic, short", fig_short)
    s3 = np.array([50e3, 100e3, 200e3])
    s1 = failure_states(10e3, 35.0, s3)
    plot_envelope(s3, s1, mohr_coulomb_fit(s3, s1), tmp_path / "envelope.png", "synthetic envelope")
    for name in ("triaxial.png", "short.png", "envelope.png"):
        assert (tmp_path / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert (tmp_path / name).stat().st_size > 10_000


def test_frames_after_the_shear_ended_are_left_out():
    """The time loop stops at the frame after the shear stage ended: that frame's sample relaxed
    under a standing platen, and no measure may read it; consolidation rows and a shear that did
    not end stay."""
    rows = np.zeros((6, len(HEADER)))
    rows[:, HEADER.index("time")] = [0.0, 0.01, 0.02, 0.03, 0.04, 0.05]
    rows[:, HEADER.index("stage")] = [0, 0, 1, 1, 1, 1]
    kept = until_sheared(rows, 0.035)
    assert list(kept[:, HEADER.index("time")]) == [0.0, 0.01, 0.02, 0.03]
    assert len(until_sheared(rows, "nan")) == 6 and len(until_sheared(rows, None)) == 6
