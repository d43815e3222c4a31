"""A pack truly at rest takes implicit steps (docs/dynamics.md "A pack truly at rest").

tests/data/pack30_mu015.npz (30 sand grains settled at the real density, friction history included)
is first quieted: 0.02 s with the pack stage's mass damping raised to 100 1/s leaves its fastest
vertex at about 5e-7 m/s. From there a step's displacement is so small that a correction tolerance
relative to it asked for less than the linear solve can resolve (1e-14 grain sizes against the
1e-13 m it attains): every dt failed in 15 Newton iterations. The tolerance's floor is now 1e-12
grain sizes; the test fails with the old floor."""

from pathlib import Path

import numpy as np
import pytest

from vemdem.config.build import scene_from
from vemdem.contact.model import ContactHistory
from vemdem.contact.walls import box_walls
from vemdem.io.state import load_state
from vemdem.scenarios.registry import checked_config
from vemdem.solver.linear import make_linear_solver
from vemdem.solver.newmark import NewmarkParameters, advance, newmark_step
from vemdem.solver.state import RunStats, State, StepControl

PACK = Path(__file__).parent / "data" / "pack30_mu015.npz"
BETA, GAMMA = 0.3025, 0.6  # the implicit defaults (solver/api.py)
CONFIG = {"scenario": "pile_collapse", "initial_state": str(PACK), "solver": {"integrator": "implicit", "mass_scaling": 1.0}}


@pytest.fixture(scope="module")
def quiet_pack():
    cfg, _ = checked_config(CONFIG)
    s = load_state(PACK)
    m = s.meta
    scene = scene_from(s.grains, cfg, box_walls(*m["box"], m["floor"], tuple(m["centre"])))
    f = s.friction
    history = ContactHistory(f["keys"], f["c_prev"], f["gt"], f["stick"].astype(bool))
    state = State(0.0, s.x.copy(), s.v.copy(), np.zeros_like(s.x), history)
    damped = NewmarkParameters(BETA, GAMMA, linear=make_linear_solver("auto"), mass_damping=100.0)
    state, _ = advance(scene, state, 0.02, StepControl(dt=1e-5, dt_max=1e-4), damped, None, RunStats())
    return scene, state


def fastest(state) -> float:
    return float(np.linalg.norm(state.v, axis=1).max())


def test_the_quieted_pack_is_at_rest(quiet_pack):
    _, state = quiet_pack
    assert fastest(state) < 1e-5  # m/s: a 1e-3 s step moves no vertex by more than 1e-8 m


@pytest.mark.parametrize("dt", [1e-4, 1e-3])
def test_a_pack_at_rest_takes_a_step_and_stays_at_rest(quiet_pack, dt):
    scene, state = quiet_pack
    params = NewmarkParameters(BETA, GAMMA, linear=make_linear_solver("auto"))
    new, info = newmark_step(scene, state, dt, params)  # raised StepRejected with the old floor
    assert info.iterations <= 8
    assert fastest(new) < 1e-5
    moved = np.abs(scene.grain_centroids(new.x) - scene.grain_centroids(state.x)).max()
    assert moved < 1e-6 * scene.grain_size
