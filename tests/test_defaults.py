"""One source for every default: the schema (config/tables.py). The classes a run is built from
take their defaults from it (solver/defaults.py); a class default that differs from its key's is a
failing test here, whichever side changed. Keys the package removed are refused by name."""

import dataclasses
import inspect

import pytest

from vemdem.config import ConfigError, tables
from vemdem.config.build import solver_options_from
from vemdem.scenarios.registry import checked_config
from vemdem.solver.api import SolverOptions, make_integrator
from vemdem.solver.explicit import ExplicitParameters
from vemdem.solver.linear.woodbury import WOODBURY_MAX_DOFS
from vemdem.solver.newmark import NewmarkParameters
from vemdem.solver.rigid_implicit import RigidNewmark
from vemdem.solver.state import StepControl
from vemdem.vem.element import VemOptions

SOLVER = tables.SOLVER
# a class field named otherwise than its [solver] key
RENAMED = {"xtol": "newton_xtol"}
# NewmarkParameters.linear holds the solver object `[solver] linear` names (make_linear_solver)
NOT_THE_KEY = {"linear"}


def _defaults(cls) -> dict:
    return {f.name: f.default for f in dataclasses.fields(cls) if f.default is not dataclasses.MISSING}


def _disagreements(defaults: dict, table: dict, skip=()) -> list[str]:
    """A key whose schema default is None leaves it to the class (the budget: test below)."""
    out = []
    for name, value in defaults.items():
        key = RENAMED.get(name, name)
        if name in skip or not isinstance(table.get(key), tables.Field) or table[key].default is None:
            continue
        if table[key].default != value:
            out.append(f"{name} = {value!r}, the schema's {key} = {table[key].default!r}")
    return out


@pytest.mark.parametrize("cls", [SolverOptions, StepControl, NewmarkParameters, ExplicitParameters])
def test_the_solver_classes_defaults_are_the_schemas(cls):
    assert _disagreements(_defaults(cls), SOLVER, skip=NOT_THE_KEY if cls is NewmarkParameters else ()) == []


def test_solver_options_has_every_solver_key_but_the_scenes_mass_scalings():
    """Every [solver] key reaches the integrators through SolverOptions (mass_scaling and
    selective_mass_scaling: the scene's, its material and its body model's)."""
    assert set(_defaults(SolverOptions)) == set(SOLVER) - {"mass_scaling", "selective_mass_scaling"}


def test_the_rigid_integrator_and_the_linear_solver_defaults_are_the_schemas():
    signature = inspect.signature(RigidNewmark.__init__).parameters
    rigid = {k: p.default for k, p in signature.items() if p.default is not inspect.Parameter.empty}
    assert _disagreements(rigid, SOLVER) == []
    assert rigid["max_iterations"] == tables.RIGID_NEWTON_ITERATIONS
    assert WOODBURY_MAX_DOFS == SOLVER["woodbury_dofs"].default


def test_the_newton_budgets_where_max_iterations_is_not_set():
    """`max_iterations` unset: 15 for the flexible grains' Newton, 25 for the rigid grains' quasi-Newton."""
    assert SOLVER["max_iterations"].default is None
    assert NewmarkParameters().max_iterations == tables.NEWTON_ITERATIONS == 15
    assert SolverOptions().newton_budget(rigid=False) == 15
    assert SolverOptions().newton_budget(rigid=True) == tables.RIGID_NEWTON_ITERATIONS == 25
    assert SolverOptions(max_iterations=40).newton_budget(rigid=True) == 40


def test_the_vem_options_defaults_are_the_schemas():
    assert _disagreements(_defaults(VemOptions), tables.VEM) == []
    assert set(_defaults(VemOptions)) == set(tables.VEM)


def test_a_default_config_gives_the_classes_defaults():
    """What config/build.py makes of an empty [solver] table is SolverOptions() itself."""
    cfg, _ = checked_config({"scenario": "scene", "duration": 1e-3, "material": {"E": 1e9, "nu": 0.3},
                             "grains": [{"position": [0.0, 0.0, 0.01]}]})  # fmt: skip
    assert solver_options_from(cfg) == SolverOptions()


def test_the_rigid_implicit_integrator_honours_max_iterations():
    """`[solver] max_iterations` is the rigid grains' Newton budget too (a stalled rigid run can be
    given more on --resume); unset, their own 25."""
    from vemdem.contact.defaults import default_contact_laws
    from vemdem.contact.walls import PlaneWall
    from vemdem.geometry import cube
    from vemdem.model.scene import Scene
    from vemdem.vem.material import Material

    material = Material(1e9, 0.3, 2200.0)
    law, friction = default_contact_laws(1e-3, material.E, material.density, 9.81)
    floor = PlaneWall((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), name="floor")
    scene = Scene.build([cube(1e-3).translated((0.0, 0.0, 1e-3))], material, law, friction, planes=[floor],
                        grain_model="rigid")  # fmt: skip
    assert make_integrator(SolverOptions(), scene).integrator.max_iterations == 25
    assert make_integrator(SolverOptions(max_iterations=7), scene).integrator.max_iterations == 7


@pytest.mark.parametrize("table, key", [(table, key) for dotted in tables.REMOVED for table, key in [dotted.split(".")]])
def test_a_removed_key_is_refused_by_name(table, key):
    raw = {"scenario": "scene", "duration": 1e-3, "material": {"E": 1e9, "nu": 0.3},
           "grains": [{"position": [0.0, 0.0, 0.01]}], table: {key: 1}}  # fmt: skip
    with pytest.raises(ConfigError, match=rf"^{table}\.{key}: this key was removed \(.+\); delete it$"):
        checked_config(raw)


def test_an_unknown_key_is_still_unknown():
    with pytest.raises(ConfigError, match=r"^solver\.nope: unknown key"):
        checked_config({"scenario": "scene", "duration": 1e-3, "material": {"E": 1e9, "nu": 0.3},
                        "grains": [{"position": [0.0, 0.0, 0.01]}], "solver": {"nope": 1}})  # fmt: skip
