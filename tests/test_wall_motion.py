"""A wall's prescribed motion: piecewise-linear displacement, held before the first and after the
last time, and its velocity the slope of the segment (contact.walls.Motion)."""

import numpy as np
import pytest

from vemdem.contact.walls import Motion

LID = Motion((0.0, 0.1, 0.3, 0.35), ((0, 0, 0), (0, 0, -1e-3), (0, 0, -1.5e-3), (1e-4, 2e-4, 3e-4)))


def test_displacement_is_numpys_piecewise_linear_interpolation_to_the_bit():
    times = np.r_[-1.0, 0.0, 0.1, np.nextafter(0.1, 0), np.nextafter(0.1, 1), 0.3, 0.35, 0.5,
                  np.random.default_rng(0).uniform(-0.1, 0.5, 2000)]  # fmt: skip
    table = np.asarray(LID.displacements, float)
    for t in times:
        reference = np.array([np.interp(t, LID.times, table[:, a]) for a in range(3)])
        assert np.array_equal(LID.displacement(t), reference)


def test_displacement_is_held_at_both_ends_and_a_fixed_wall_stays():
    assert np.array_equal(LID.displacement(-5.0), [0, 0, 0])
    assert np.array_equal(LID.displacement(7.0), [1e-4, 2e-4, 3e-4])
    assert np.array_equal(Motion().displacement(3.0), [0, 0, 0])
    d = LID.displacement(0.2)
    d[:] = 1.0  # a caller's copy: the motion itself is unchanged
    assert LID.displacement(0.2)[2] == pytest.approx(-1.25e-3)


@pytest.mark.parametrize("t", [0.05, 0.2, 0.32])
def test_velocity_is_the_slope_of_the_displacement(t):
    h = 1e-6
    slope = (LID.displacement(t + h) - LID.displacement(t - h)) / (2 * h)
    assert np.allclose(LID.velocity(t), slope, rtol=1e-7, atol=1e-12)
    assert np.array_equal(LID.velocity(0.6), [0, 0, 0])
