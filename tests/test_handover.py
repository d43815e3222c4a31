"""The state handed from one stage to the next (io/state.py) keeps the friction history (issue 17):
a run continued from a saved state follows the uninterrupted run, and without the history it
would not (every sticking contact restarts from zero elastic slip and the grain gives a little)."""

import numpy as np
import pytest

from vemdem.contact.model import ContactHistory
from vemdem.geometry import cube
from vemdem.io.state import friction_arrays, load_state, save_state
from vemdem.solver.api import SolverOptions, make_integrator
from vemdem.solver.state import RunStats

from test_at_rest import SIZE, tilted_scene

SETTLE, MORE = 0.02, 0.005


def _handover(tmp_path, integrator_name: str, mass_scaling: float):
    grain = cube(SIZE)
    scene = tilted_scene(grain, 0.8, mass_scaling)
    options = SolverOptions(integrator=integrator_name)
    run = make_integrator(options, scene)
    half, stats = run.advance(run.initial_state(), SETTLE, None, RunStats())
    assert len(half.history.keys) > 0 and np.abs(half.history.gt).max() > 0  # sticking, loaded springs
    save_state(tmp_path / "state.npz", [grain], half.x, half.v, {"box": [1, 1]}, friction_arrays(half.history))
    whole, _ = run.advance(half, SETTLE + MORE, None, stats)

    handed = load_state(tmp_path / "state.npz")
    ends = {}
    for name, history in (("kept", ContactHistory(**handed.friction)), ("dropped", None)):
        again = make_integrator(options, scene)
        start = again.initial_state(x0=handed.x, v0=handed.v, history=history)
        start.t = SETTLE
        ends[name], _ = again.advance(start, SETTLE + MORE, None, RunStats())
    return whole, ends


@pytest.mark.parametrize("integrator_name, mass_scaling", [("explicit", 1e6), ("implicit", 1.0)])
def test_a_handed_over_state_continues_the_run(tmp_path, integrator_name, mass_scaling):
    whole, ends = _handover(tmp_path, integrator_name, mass_scaling)
    kept = np.abs(ends["kept"].x - whole.x).max()
    dropped = np.abs(ends["dropped"].x - whole.x).max()
    assert kept <= 1e-4 * dropped, (kept, dropped)
    assert dropped > 1e-12 * SIZE


def test_state_files_without_friction_still_load(tmp_path):
    grain = cube(SIZE)
    save_state(tmp_path / "old.npz", [grain], grain.vertices, 0 * grain.vertices, {"box": [1, 1]})
    assert load_state(tmp_path / "old.npz").friction is None


def test_a_broken_friction_history_is_refused(tmp_path):
    from vemdem.io.state import StateFileError

    grain = cube(SIZE)
    bad = {"keys": np.array([3, 1]), "c_prev": np.zeros((2, 2)), "gt": np.zeros((2, 3)), "stick": np.ones(2, bool)}
    save_state(tmp_path / "bad.npz", [grain], grain.vertices, 0 * grain.vertices, {"box": [1, 1]}, bad)
    with pytest.raises(StateFileError, match="friction history"):
        load_state(tmp_path / "bad.npz")
