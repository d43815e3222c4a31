"""docs/reference/config.md is generated from config/tables.py, and says every key it holds."""

import re
from pathlib import Path

from vemdem.config import lab_tables, reference, tables
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


# ------------------------------------------------------------------ what the page says, read back
def _rows_by_anchor(page: str) -> dict[str, dict[str, tuple[str, str]]]:
    """Heading anchor -> {key: (default cell, meaning cell)} of the table under that heading."""
    out: dict[str, dict[str, tuple[str, str]]] = {}
    anchor = None
    for line in page.splitlines():
        found = re.search(r"\{#([a-z0-9-]+)\}$", line)
        if line.startswith("#") and found:
            anchor = found.group(1)
            out[anchor] = {}
        elif anchor and line.startswith("| `"):
            cells = [c.strip() for c in re.split(r"(?<!\\)\|", line)[1:-1]]
            out[anchor][cells[0].strip("`")] = (cells[2], cells[3])
    return out


def _tables_of_scenario(page: str, scenario: str) -> dict[str, tuple[str, dict[str, str]]]:
    """A scenario's listing: table path -> (anchor, defaults it changes, as the page writes them)."""
    section = page.split(f'{{#{reference._anchor("scenario", scenario)}}}', 1)[1].split("\n## ", 1)[0]
    out = {}
    for line in section.splitlines():
        found = re.match(r"- \[?`\[\[?([a-z_.]+)\]\]?`.*?\(#([a-z0-9-]+)\)(?: \(at least \d+\))?"
                         r"(?:, with the defaults (.*))?$", line)
        if found:
            changed = dict(re.findall(r"`(\w+) = ([^`]+)`", found.group(3) or ""))
            out[found.group(1)] = (found.group(2), changed)
    return out


def test_every_row_of_the_page_has_a_meaning():
    rows = _rows_by_anchor(reference.markdown())
    empty = [f"{anchor}: {key}" for anchor, table in rows.items() for key, (_, text) in table.items() if not text]
    assert not empty, f"config reference rows without a meaning (Field.doc in config/tables.py): {empty}"


def test_the_page_gives_every_key_the_default_of_its_scenarios_schema():
    """Read the way a user reads it: the scenario's row or its table's row, and the defaults the
    scenario's listing says it changes; each equals the schema's, and a meaning never ends in the
    bracket of a "not set" default where the default is set."""
    page = reference.markdown()
    rows = _rows_by_anchor(page)
    for scenario, schema in reference.scenario_schemas().items():
        listing = _tables_of_scenario(page, scenario)
        for path, spec in _paths(schema):
            table, _, key = path.rpartition(".")
            if not table:
                anchor, changed = reference._anchor("scenario", scenario), {}
            else:
                head, rest = table, []
                while head not in listing:  # a table inside a shared one (walls.servo)
                    assert head, f"{scenario}: {table} is not in the scenario's listing"
                    head, _, tail = head.rpartition(".")
                    rest.insert(0, tail)
                anchor, changed = listing[head]
                anchor = "-".join([anchor, *rest])
            shown, text = rows[anchor][key]
            shown = f"`{changed[key]}`" if key in changed else shown
            assert shown == reference._default(spec), f"{scenario}: {path} is documented as {shown}"
            if shown != "not set" and key != "initial_state":
                assert not text.endswith("]") or key in changed, f"{scenario}: {path}: {text!r} beside {shown}"


def _paths(table, prefix=""):
    for key, spec in table.items():
        if isinstance(spec, Field):
            yield prefix + key, spec
        else:
            yield from _paths(spec.schema if isinstance(spec, TableList) else spec, f"{prefix}{key}.")


def test_a_bracket_for_a_not_set_default_goes_where_a_table_sets_one():
    contact = lab_tables.TRIAXIAL["contact"]
    assert reference.meaning("damping_ratio", contact["damping_ratio"]).endswith("critical damping")
    assert reference.meaning("damping_ratio", tables.CONTACT["damping_ratio"]).endswith("[0.5]")
    assert reference.meaning("scenario", tables.PACK["scenario"]) == reference.SCENARIO_MEANING
