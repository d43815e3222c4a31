"""The compiled passes behind the explicit step's limits and Verlet list (contact/ccd.py) against
the NumPy expressions they replace, on random grains, velocities, planes and pairs."""

import numpy as np
import pytest

from vemdem.contact.ccd import grain_speeds, max_displacement, max_pair_speed, plane_closing_time, plane_distances


@pytest.fixture
def grains():
    rng = np.random.default_rng(11)
    vptr = np.cumsum([0] + list(rng.integers(4, 12, size=9)))
    n = vptr[-1]
    return rng, vptr, rng.normal(size=(n, 3)), rng.normal(size=(n, 3)), rng.uniform(0.5, 2.0, size=n)


def _per_grain(vptr):
    return [slice(vptr[g], vptr[g + 1]) for g in range(len(vptr) - 1)]


def test_max_displacement_is_the_largest_row_norm(grains):
    rng, _, x, _, _ = grains
    x0 = x + rng.normal(scale=1e-3, size=x.shape)
    assert max_displacement(x, x0) == pytest.approx(np.linalg.norm(x - x0, axis=1).max(), rel=1e-14)
    assert max_displacement(x[:0], x0[:0]) == 0.0


def test_grain_speeds_are_the_mass_weighted_centre_and_the_largest_speed_about_it(grains):
    _, vptr, _, v, mass = grains
    c, r = grain_speeds(v, mass, vptr)
    for g, sl in enumerate(_per_grain(vptr)):
        centre = mass[sl] @ v[sl] / mass[sl].sum()
        np.testing.assert_allclose(c[g], centre, rtol=1e-13, atol=1e-15)
        assert r[g] == pytest.approx(np.linalg.norm(v[sl] - centre, axis=1).max(), rel=1e-12)


def test_plane_distances_are_each_grains_lowest_vertex(grains):
    _, vptr, x, _, _ = grains
    point, normal = np.array([0.1, -0.2, -1.5]), np.array([0.3, 0.4, np.sqrt(0.75)])
    d = plane_distances(x, vptr, point, normal)
    np.testing.assert_allclose(d, [((x[sl] - point) @ normal).min() for sl in _per_grain(vptr)], rtol=1e-13)


def test_max_pair_speed_bounds_every_pair(grains):
    rng, vptr, _, v, mass = grains
    c, r = grain_speeds(v, mass, vptr)
    G = len(vptr) - 1
    pairs = np.array([[0, 1], [2, 5], [3, 8], [4, G], [7, G + 1]])  # the last two: a grain and a mesh wall
    walls = rng.normal(size=(2, 3))
    expected = max(
        np.linalg.norm(c[a] - (c[b] if b < G else walls[b - G])) + r[a] + (r[b] if b < G else 0.0) for a, b in pairs
    )
    assert max_pair_speed(c, r, pairs, G, walls) == pytest.approx(expected, rel=1e-14)


def test_plane_closing_time_is_the_first_entry_into_the_layer():
    dist = np.array([5.0, 0.5, 2.0, 3.0])  # the second already inside the layer (gbar 1)
    approach = np.array([1.0, 0.0, -4.0, 2.0])  # the third moves away: only its spin r counts
    r = np.array([0.5, 2.0, 1.0, 0.0])
    gbar, f = 1.0, 0.5
    speeds = np.maximum(approach, 0) + r
    d = np.maximum(dist, gbar)
    expected = np.min((np.maximum(d - gbar, 0) + f * np.minimum(d, gbar)) / speeds)
    assert plane_closing_time(dist, approach, r, gbar, f) == pytest.approx(expected, rel=1e-15)
    assert expected == pytest.approx(0.25)  # the grain inside the layer, spinning at 2: f gbar / 2
