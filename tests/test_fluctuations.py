"""analysis.fluctuations: the grains' velocity fluctuations (beyond the lid's affine field and each
layer's mean flow) and the inertia number."""

import csv
import json
import warnings

import numpy as np
import pytest

from vemdem.analysis.fluctuations import (
    HEADER,
    INERTIA,
    RMS,
    STRAIN,
    W,
    fluctuation_figures,
    inertia_number,
    lid_fluctuations,
    plot_fluctuations,
    velocity_fluctuations,
    write_fluctuations_csv,
)
from vemdem.scenarios.lid_compression import lid_wall

FLOOR, D = 0.2e-3, 1e-3


def _affine(z, height, w):
    v = np.zeros((len(z), 3))
    v[:, 2] = w * (z - FLOOR) / (height - FLOOR)
    return v


def _layers(n_layers: int, per_layer: int) -> np.ndarray:
    """Grain heights: n_layers layers one grain size thick from the floor, per_layer grains in each."""
    rng = np.random.default_rng(5)
    return FLOOR + D * (np.repeat(np.arange(n_layers), per_layer) + rng.uniform(0.01, 0.99, n_layers * per_layer))


def test_a_pack_moving_with_the_affine_field_has_no_fluctuation():
    z = _layers(6, 7)
    for w in (-0.02, 0.03):
        rms, median = velocity_fluctuations(z, _affine(z, 6e-3, w), FLOOR, 6e-3, w, D)
        assert rms < 1e-12 and median < 1e-12


def test_a_mean_flow_of_each_layer_is_not_fluctuation():
    # the top layers follow the lid while the bottom ones rest (a loose pack compacting from the
    # top), with a sideways shear layer by layer: what is left is only the affine field's spread
    # inside each layer, |z - <z>_layer| rate, far below the fluctuations of a jam (15-30 rate d)
    z = _layers(5, 8)
    v = np.zeros((len(z), 3))
    v[z > FLOOR + 3 * D, 2] = -0.02
    v[:, 0] = 0.003 * np.floor((z - FLOOR) / D)
    rms, median = velocity_fluctuations(z, v, FLOOR, 6e-3, -0.02, D)
    spread = np.concatenate([zl - zl.mean() for zl in np.split(z, 5)])  # _layers orders them by layer
    assert rms == pytest.approx(np.sqrt(np.mean(spread**2)) / D, rel=1e-10)
    assert median == pytest.approx(np.median(np.abs(spread)) / D, rel=1e-10)
    assert rms < 0.3  # about d / sqrt(12) = 0.29 d for heights spread evenly through a layer


def test_fluctuations_are_departures_from_the_layer_mean_in_units_of_rate_d():
    # in every layer half the grains drift sideways at u and half do not: each departs from its
    # layer's mean by u / 2, on top of any affine motion
    z = _layers(5, 8)
    height, w, u = 6e-3, -0.02, 0.01
    v = _affine(z, height, w)
    v[::2, 0] += u
    unit = 0.02 / (height - FLOOR) * D
    rms, median = velocity_fluctuations(z, v, FLOOR, height, w, D)
    assert rms == pytest.approx(0.5 * u / unit, rel=1e-12)
    assert median == pytest.approx(0.5 * u / unit, rel=1e-12)
    # a uniform drift of the whole pack is mean flow, not fluctuation
    assert velocity_fluctuations(z, v + [0.0, 0.004, 0.0], FLOOR, height, w, D)[0] == pytest.approx(rms, rel=1e-12)


def test_no_affine_field_without_a_moving_lid_above_the_floor():
    z = np.array([1e-3])
    with pytest.raises(ValueError, match="no affine field"):
        velocity_fluctuations(z, np.zeros((1, 3)), FLOOR, FLOOR, -0.02, D)
    with pytest.raises(ValueError, match="no affine field"):
        velocity_fluctuations(z, np.zeros((1, 3)), FLOOR, 5e-3, 0.0, D)


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
    z = _layers(3, 10)
    extra = np.zeros((30, 3))
    extra[::2, 0] = 0.01  # in every layer, half the grains drift sideways at 1 cm/s
    _write_run(tmp_path, lid, start, times, forces, z, extra)
    rows = lid_fluctuations(tmp_path / "grains.csv", tmp_path / "walls.csv", lid, start, FLOOR, area, D, rho)
    assert rows.shape == (10, len(HEADER))  # the end of the cycle (lid at rest) is left out
    for row, t, f in zip(rows, times, forces):
        height = start + lid.motion.displacement(t)[2]
        rate = speed / (height - FLOOR)
        assert row[W] == pytest.approx(-speed if t < 0.5 * duration else speed)
        assert row[STRAIN] == pytest.approx((start - height) / start)
        assert row[RMS] == pytest.approx(0.5 * 0.01 / (rate * D), rel=1e-9)
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


@pytest.mark.parametrize("pressed", [0, 1])
def test_the_figure_of_a_lid_that_barely_or_never_pressed_is_drawn_without_warnings(tmp_path, pressed):
    rows = np.array([[0.0, -0.02, 0.0, 0.0, np.inf, 1.0, 0.5], [0.01, -0.02, 0.03, 0.0, np.inf, 0.0, 0.0]])
    rows[1, [3, 4]] = (1.0, 2e-3) if pressed else (0.0, np.inf)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # matplotlib's singular-limits warning reached the users
        plot_fluctuations(rows, tmp_path / "f.png")
    assert (tmp_path / "f.png").stat().st_size > 10_000
