"""A run that fails says why in words: Python's own complaint (an overflow) is explained, an
internal error keeps its traceback and says it is a bug; and a wall normal of any finite scale,
which once overflowed, is the same plane."""

import copy

import numpy as np
import pytest
from test_bad_input import DROP, good_drop


def _failing_run(exc):
    def run(*args, **kwargs):
        raise exc

    return run


def test_an_overflow_in_a_run_is_explained_not_just_named(tmp_path, cli, monkeypatch):
    """A run that fails on Python's own complaint ("OverflowError: (34, 'Numerical result out of
    range')", which a 1e300 m grain once gave) says what it means for the run, in one line."""
    import vemdem.scenarios.scene as scene_mod

    monkeypatch.setattr(scene_mod, "run", _failing_run(OverflowError(34, "Numerical result out of range")))
    code, _, err = cli("run", good_drop(tmp_path), "--out", tmp_path / "out", "--quiet")
    failed = [ln for ln in err.splitlines() if ln.startswith("vemdem: run failed: ")]
    assert code == 1 and "Traceback" not in err and len(failed) == 1
    assert "a number overflowed" in failed[0] and "report it with the config" in failed[0]


def test_an_internal_error_keeps_its_traceback_and_says_it_is_a_bug(tmp_path, cli, monkeypatch):
    import vemdem.scenarios.scene as scene_mod

    monkeypatch.setattr(scene_mod, "run", _failing_run(TypeError("unsupported operand")))
    code, _, err = cli("run", good_drop(tmp_path), "--out", tmp_path / "out", "--quiet")
    assert code == 1 and "Traceback" in err
    last_but_one = err.strip().splitlines()[-2]
    assert last_but_one.startswith("vemdem: run failed: an internal error (TypeError: unsupported operand)")
    assert "a bug in vemdem" in last_but_one


@pytest.mark.parametrize("scale", [1e300, 1e-300, 2.0])
def test_a_wall_normal_of_any_finite_scale_is_the_same_plane(scale):
    """The normal's norm, squared on the way, once overflowed to inf (a normal of 1e300: the wall
    lost its normal, and a grain above it was "behind" it) or underflowed to 0 (1e-300: "the zero
    vector")."""
    from vemdem.config.build import build_walls

    spec = copy.deepcopy(DROP["walls"][0]) | {"normal": [0.0, 0.0, scale], "removed_at": None, "file": "",
                                              "flip": False, "frictionless": False, "times": [0.0],
                                              "displacements": [[0.0, 0.0, 0.0]]}  # fmt: skip
    (plane,), _ = build_walls([spec])
    np.testing.assert_array_equal(plane.normal, [0.0, 0.0, 1.0])
