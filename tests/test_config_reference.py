"""docs/reference/config.md is generated from config/tables.py, and says every key it holds."""

from pathlib import Path

from vemdem.config import reference, tables
from vemdem.config.schema import Field, TableList
from vemdem.scenarios.registry import SCENARIOS

PAGE = Path(__file__).resolve().parents[1] / "docs" / "reference" / "config.md"


def test_the_committed_page_is_the_generated_one():
    assert PAGE.read_text() == reference.markdown(), (
        f"docs/reference/config.md is stale (config/tables.py changed): regenerate it with `{reference.COMMAND}`"
    )


def test_every_registered_scenario_has_its_schema_in_the_page():
    assert set(reference.scenario_schemas()) == set(SCENARIOS)
    page = reference.markdown()
    for name in SCENARIOS:
        assert f'scenario = "{name}"' in page


def _keys(table, prefix=""):
    for key, spec in table.items():
        if isinstance(spec, Field):
            yield key, spec
        else:
            yield from _keys(spec.schema if isinstance(spec, TableList) else spec, f"{prefix}{key}.")


def test_every_key_of_every_scenario_is_in_the_page_with_its_doc():
    page = reference.markdown()
    for schema in reference.scenario_schemas().values():
        for key, spec in _keys(schema):
            assert f"| `{key}` |" in page, key
            assert " ".join(spec.doc.split()).replace("|", "\\|") in page, key


def test_the_bounds_are_the_checks_own_messages():
    frames = tables.LID_COMPRESSION["lid"]["frames"]
    assert reference.bounds(frames) == ["must be > 0", "must be at most 50,000 per phase"]
    assert reference.bounds(tables.SOLVER["gamma"]) == ["must be in [0.5, 1]"]
    assert reference.bounds(tables.CONTACT["barrier_exponent"]) == ["must be in [-10, -1)"]
    assert reference.bounds(tables.MATERIAL["density"]) == ["must be in [1, 1e5] kg/m^3"]
    assert reference.bounds(tables.SCENE_GRAIN["position"]) == ["must be a list of 3 finite numbers",
                                                               "must have a magnitude of at most 1e3 m"]
    assert reference.bounds(tables.WALL["times"]) == ["must be a list of finite numbers", "must be times within +-1e4 s"]
    assert reference.bounds(tables.WALL["flip"]) == []


def test_a_shared_table_with_other_defaults_is_shown_with_them():
    page = reference.markdown()
    assert "the shared table [`[solver]`](#table-solver), with the defaults `integrator = \"explicit\"`" in page
    assert "`E = 9e10`, `nu = 0.16`" in page
