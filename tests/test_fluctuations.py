"""analysis.fluctuations: the grains' velocities against the lid's affine field, and the inertia number."""

import csv
import json

import numpy as np
import pytest

from vemdem.analysis.fluctuations import (
    HEADER,
    INERTIA,
    RMS,
    STRAIN,
    W,
    affine_fluctuations,
    fluctuation_figures,
    inertia_number,
    lid_fluctuations,
    plot_fluctuations,
    write_fluctuations_csv,
)
from vemdem.scenarios.lid_compression import lid_wall

FLOOR, D = 0.2e-3, 1e-3


def _affine(z, height, w):
    v = np.zeros((len(z), 3))
    v[:, 2] = w * (z - FLOOR) / (height - FLOOR)
    return v


def test_a_pack_moving_with_the_affine_field_has_no_fluctuation():
    z = np.linspace(FLOOR, 5e-3, 40)
    for w in (-0.02, 0.03):
        assert affine_fluctuations(z, _affine(z, 6e-3, w), FLOOR, 6e-3, w, D) == (0.0, 0.0)


def test_fluctuations_are_the_departures_from_the_affine_field_in_units_of_rate_d():
    rng = np.random.default_rng(3)
    z = rng.uniform(FLOOR, 5e-3, 200)
    height, w = 6e-3, -0.02
    extra = rng.normal(scale=0.01, size=(200, 3))
    rms, median = affine_fluctuations(z, _affine(z, height, w) + extra, FLOOR, height, w, D)
    unit = 0.02 / (height - FLOOR) * D
    speed = np.sqrt((extra**2).sum(axis=1))
    assert rms == pytest.approx(np.sqrt(np.mean(speed**2)) / unit, rel=1e-12)
    assert median == pytest.approx(np.median(speed) / unit, rel=1e-12)
    # a rigid drift of every grain sideways by u is u / (rate d) of fluctuation
    drift = _affine(z, height, w) + np.array([0.005, 0.0, 0.0])
    assert affine_fluctuations(z, drift, FLOOR, height, w, D)[0] == pytest.approx(0.005 / unit, rel=1e-12)


def test_no_affine_field_without_a_moving_lid_above_the_floor():
    z = np.array([1e-3])
    with pytest.raises(ValueError, match="no affine field"):
        affine_fluctuations(z, np.zeros((1, 3)), FLOOR, FLOOR, -0.02, D)
    with pytest.raises(ValueError, match="no affine field"):
        affine_fluctuations(z, np.zeros((1, 3)), FLOOR, 5e-3, 0.0, D)


def test_inertia_number():
    # rate 4 1/s, d 1 mm, P = rho (m^2/s^2 = 1): I = 4e-3; it grows as sqrt(rho) and falls as 1/sqrt(P)
    assert inertia_number(4.0, 1e-3, 2200.0, 2200.0) == pytest.approx(4e-3, rel=1e-14)
    assert inertia_number(4.0, 1e-3, 2200.0, 4 * 2200.0) == pytest.approx(8e-3, rel=1e-14)
    assert inertia_number(4.0, 1e-3, 4 * 2200.0, 2200.0) == pytest.approx(2e-3, rel=1e-14)
    assert inertia_number(4.0, 1e-3, 0.0, 2200.0) == float("inf")


def _write_run(folder, lid, start, times, forces, z, extra):
    """grains.csv and walls.csv of a lid run whose grains move with the affine field plus `extra`."""
    with (folder / "grains.csv").open("w", newline="") as fh:
        out = csv.writer(fh)
        out.writerow(["time", "grain", "x", "y", "z", "vx", "vy", "vz"])
        for t in times:
            height = start + lid.motion.displacement(t)[2]
            v = _affine(z, height, lid.motion.velocity(t)[2]) + extra
            out.writerows([[t, g, 0.0, 0.0, z[g], *v[g]] for g in range(len(z))])
    with (folder / "walls.csv").open("w", newline="") as fh:
        out = csv.writer(fh)
        out.writerow(["time", "wall", "name", "fx", "fy", "fz"])
        for t, f in zip(times, forces):
            out.writerows([[t, 0, "floor", 0.0, 0.0, -f], [t, 1, "lid", 0.0, 0.0, f]])


def test_a_lid_run_frame_by_frame(tmp_path):
    start, end, speed, area, rho = 7e-3, 5e-3, 0.02, 64e-6, 2200.0
    lid, duration = lid_wall({"start": start, "end": end, "speed": speed}, (0.0, 0.0))
    times = np.linspace(0.0, duration, 11)  # the 6th frame is the turning point, the last the end
    forces = np.r_[0.0, 0.0, 0.5, 2.0, 4.0, 5.0, 3.0, 1.0, 0.2, 0.0, 0.0]
    z = np.linspace(FLOOR, 4e-3, 30)
    extra = np.zeros((30, 3))
    extra[::2, 0] = 0.01  # every other grain drifts sideways at 1 cm/s
    _write_run(tmp_path, lid, start, times, forces, z, extra)
    rows = lid_fluctuations(tmp_path / "grains.csv", tmp_path / "walls.csv", lid, start, FLOOR, area, D, rho)
    assert rows.shape == (10, len(HEADER))  # the end of the cycle (lid at rest) is left out
    for row, t, f in zip(rows, times, forces):
        height = start + lid.motion.displacement(t)[2]
        rate = speed / (height - FLOOR)
        assert row[W] == pytest.approx(-speed if t < 0.5 * duration else speed)
        assert row[STRAIN] == pytest.approx((start - height) / start)
        assert row[RMS] == pytest.approx(np.sqrt(0.5) * 0.01 / (rate * D), rel=1e-9)
        expected = rate * D / np.sqrt(f / area / rho) if f > 0 else np.inf
        assert row[INERTIA] == pytest.approx(expected, rel=1e-12)
    write_fluctuations_csv(tmp_path / "fluctuations.csv", rows)
    with (tmp_path / "fluctuations.csv").open() as fh:
        assert tuple(next(csv.reader(fh))) == HEADER
    back = np.genfromtxt(tmp_path / "fluctuations.csv", delimiter=",", skip_header=1)
    np.testing.assert_array_equal(back, rows)
    figures = fluctuation_figures(rows)
    pressed = np.isfinite(rows[:, INERTIA])
    assert figures["inertia_number_min"] == rows[pressed, INERTIA].min()
    assert figures["frames_quasi_static"] == int((rows[pressed, INERTIA] < 1e-3).sum())
    json.dumps(figures, allow_nan=False)
    plot_fluctuations(rows, tmp_path / "fluctuations.png", "test")
    assert (tmp_path / "fluctuations.png").stat().st_size > 10_000


def test_a_lid_that_never_pressed_gives_null_with_a_reason():
    rows = np.array([[0.0, -0.02, 0.0, 0.0, np.inf, 1.0, 1.0]])
    figures = fluctuation_figures(rows)
    assert figures["inertia_number_min"] is None and "never pressed" in figures["reason"]
    json.dumps(figures, allow_nan=False)
    quasi = fluctuation_figures(np.array([[0.0, -0.02, 0.0, 1.0, 0.1, 2.0, 1.0]]))
    assert quasi["rms_fluctuation_quasi_static_median"] is None and "no frame below" in quasi["reason"]
