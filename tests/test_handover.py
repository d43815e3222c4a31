"""The state handed from one stage to the next (io/state.py) keeps the friction history:
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


@pytest.mark.filterwarnings("ignore::vemdem.config.build.MassScalingWarning")  # 1e6 on purpose: the scaling changes
def test_a_pack_from_another_mass_scaling_is_settled_again(tmp_path):
    """A pack settled at scaling 1e4 carries the strain of that weight; a collapse at 1e6 first
    settles it again in its box at 1e6 (DIR/reequilibrate): the grains' strain energy grows with
    the weight, by about the ratio of the scalings."""
    import csv
    import json

    from vemdem.scenarios.registry import checked_config

    box = 3.2e-3
    pack_cfg, pack = checked_config({"scenario": "pack", "n_grains": 4, "seed": 5, "grains": {"vertices": 8, "size": 1.2e-3},
                                     "box": {"width": box, "depth": box}, "settle": {"kinetic_threshold": 1e-2},
                                     "output": {"vtk": False}})  # fmt: skip
    pack.run(pack_cfg, tmp_path / "pack")
    cfg, pile = checked_config({"scenario": "pile_collapse", "initial_state": str(tmp_path / "pack" / "state.npz"),
                                "solver": {"mass_scaling": 1e6}, "settle": {"max_time": 0.01, "min_time": 0.01},
                                "output": {"vtk": False}})  # fmt: skip
    pile.run(cfg, tmp_path / "pile")
    again = load_state(tmp_path / "pile" / "reequilibrate" / "state.npz")
    assert again.meta["mass_scaling"] == 1e6 and again.meta["reequilibrated_from"] == 1e4

    def strain(folder):
        with (folder / "history.csv").open() as fh:
            return float(list(csv.DictReader(fh))[-1]["strain"])

    ratio = strain(tmp_path / "pile" / "reequilibrate") / strain(tmp_path / "pack")
    # the grains' elastic energy goes as force^2 / stiffness, the forces as the weight: (1e6 / 1e4)^2 = 1e4
    # (measured 6.3e3: the contact network moves a little as it takes the new loads); 1 without it
    assert 2e3 < ratio < 3e4, ratio
    summary = json.loads((tmp_path / "pile" / "reequilibrate" / "summary.json").read_text())
    assert summary["settled"] and summary["mass_scaling"] == 1e6
    # run again into the same folder: the settled stage is reused, not run twice
    before = (tmp_path / "pile" / "reequilibrate" / "state.npz").stat().st_mtime_ns
    pile.run(cfg, tmp_path / "pile")
    assert (tmp_path / "pile" / "reequilibrate" / "state.npz").stat().st_mtime_ns == before


@pytest.mark.filterwarnings("ignore::vemdem.config.build.MassScalingWarning")
def test_a_lid_run_at_another_mass_scaling_settles_its_pack_again(tmp_path):
    """lid_compression has no output.every (its frames follow the lid); settling its pack again at
    another scaling once stopped with a KeyError traceback."""
    from vemdem.scenarios.registry import checked_config

    box = 3.2e-3
    pack_cfg, pack = checked_config({"scenario": "pack", "n_grains": 4, "seed": 5, "grains": {"vertices": 8, "size": 1.2e-3},
                                     "box": {"width": box, "depth": box}, "settle": {"kinetic_threshold": 1e-2},
                                     "output": {"vtk": False}})  # fmt: skip
    pack.run(pack_cfg, tmp_path / "pack")
    top = float(load_state(tmp_path / "pack" / "state.npz").x[:, 2].max())
    cfg, lid = checked_config({"scenario": "lid_compression", "initial_state": str(tmp_path / "pack" / "state.npz"),
                               "lid": {"start": top + 2e-4, "end": top + 1e-4, "speed": 0.05, "frames": 4},
                               "solver": {"mass_scaling": 1e6, "integrator": "explicit"}, "output": {"vtk": False}})  # fmt: skip
    lid.run(cfg, tmp_path / "lid")
    assert load_state(tmp_path / "lid" / "reequilibrate" / "state.npz").meta["mass_scaling"] == 1e6
    assert (tmp_path / "lid" / "force_strain.csv").is_file()
