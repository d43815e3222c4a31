"""The config reference page, generated from the schemas of `config.tables` and `config.lab_tables`.

`python -m vemdem.config.reference > docs/reference/config.md` writes it: every scenario, its keys
and tables, each key with its type, default, meaning (`Field.doc`) and the values it accepts (the
choices of a choice key, the bound its check states). A test regenerates the page and compares, so
the page cannot fall behind them.

Nothing here is hand-written about a key: a table or a key added to `tables.py` (or `lab_tables.py`)
appears in the page when it is regenerated. Scenario schemas are found as the module-level dicts of
those modules with a `scenario` key; shared tables (material, solver, ...) as the other module-level tables, each shown
once, and a scenario's table that is a shared one with other defaults (`with_defaults`) is shown as
that table plus the defaults it changes.
"""

from __future__ import annotations

import sys
from dataclasses import replace

from . import lab_tables, tables
from .schema import REQUIRED, AutoOrNumber, Field, TableList

COMMAND = "python -m vemdem.config.reference > docs/reference/config.md"

_TYPES = {float: "number", int: "integer", str: "string", bool: "boolean", list: "list", AutoOrNumber: '"auto" or number'}

# values a check is probed with, by the key's type: each problem a check names for one of them is a
# bound it states (the checks return a message for a value they refuse, None otherwise)
_PROBES = {
    float: [-1e300, -1e3, -1.5, -1.0, -0.5, 0.0, 1e-300, 1e-6, 0.5, 1.0, 1.5, 60.0, 90.0, 1e3, 1e300],
    AutoOrNumber: [-1.0, 0.0, 1e300],
    int: [-(10**12), -1, 0, 1, 2, 3, 4, 8, 10**3, 10**12],
    str: ["", "x"],
    list: [[], ["x"], [["x"]], [0.0, 0.0], [[0.0, 0.0, 0.0], [1.0]], [float("nan")] * 3, [1e300, 0.0, 0.0],
           [[1e300, 0.0, 0.0]]],
    bool: [],
}


# ------------------------------------------------------------------------------------ the schemas
def _is_table(obj) -> bool:
    """A schema table: a non-empty dict of Fields, tables and arrays of tables."""
    return (
        isinstance(obj, dict)
        and bool(obj)
        and all(isinstance(k, str) for k in obj)
        and all(isinstance(v, (Field, TableList)) or _is_table(v) for v in obj.values())
    )


def _is_scenario(obj) -> bool:
    spec = obj.get("scenario") if isinstance(obj, dict) else None
    return _is_table(obj) and isinstance(spec, Field) and isinstance(spec.kind, tuple) and len(spec.kind) == 1


def scenario_schemas() -> dict[str, dict]:
    """Scenario name -> its schema, in the order `tables.py`, then `lab_tables.py`, define them."""
    return {obj["scenario"].kind[0]: obj for obj in _constants().values() if _is_scenario(obj)}


def _constants() -> dict:
    """The module-level names of the schema modules, the lab tests' after the rest."""
    return {**vars(tables), **{k: v for k, v in vars(lab_tables).items() if k not in vars(tables)}}


def _changed_defaults(table: dict, base: dict) -> dict | None:
    """The defaults `table` changes when it is `base` with other defaults (with_defaults), else None."""
    if not isinstance(table, dict) or list(table) != list(base):
        return None
    changed = {}
    for key, spec in table.items():
        ref = base[key]
        if isinstance(spec, Field) and isinstance(ref, Field):
            if replace(spec, default=ref.default) != ref:
                return None
            if not _same(spec.default, ref.default):
                changed[key] = spec.default
        elif spec != ref:
            return None
    return changed


def _same(a, b) -> bool:
    return type(a) is type(b) and a == b


def shared_tables() -> dict[str, dict]:
    """Module constant -> table, for the tables scenarios share (a table that is an earlier one with
    other defaults, as PAPER_MATERIAL is MATERIAL's, is not one of its own)."""
    out: dict[str, dict] = {}
    for name, obj in _constants().items():
        if not name.isupper() or not _is_table(obj) or _is_scenario(obj):
            continue
        if any(_changed_defaults(obj, base) is not None for base in out.values()):
            continue
        out[name] = obj
    return out


def _base_of(table, shared: dict[str, dict]):
    """(constant, changed defaults) of the shared table `table` is, with the fewest changes; None."""
    best = None
    for name, base in shared.items():
        changed = _changed_defaults(table, base)
        if changed is not None and (best is None or len(changed) < len(best[1])):
            best = (name, changed)
    return best


# ------------------------------------------------------------------------------------ the cells
def _value(v) -> str:
    """A default as it would be written in TOML."""
    if v is None:
        return "not set"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return '""' if v == "" else f'"{v}"'
    if isinstance(v, float):
        text = f"{v:g}" if float(f"{v:g}") == v else repr(v)
        mantissa, e, exponent = text.partition("e")
        return mantissa + e + (str(int(exponent)) if e else "")  # 9e10, 1e-5: TOML, as people write them
    if isinstance(v, list):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    return str(v)


def bounds(spec: Field) -> list[str]:
    """The problems the key's check names for values it refuses: the bounds it states."""
    if spec.check is None or isinstance(spec.kind, tuple):
        return []
    out: list[str] = []
    for probe in _PROBES.get(spec.kind, []):
        try:
            problem = spec.check(probe)
        except Exception:  # a probe of a shape the check does not expect: it states nothing here
            continue
        if problem and problem not in out:
            out.append(problem)
    return out


def _type(spec: Field) -> str:
    return "choice" if isinstance(spec.kind, tuple) else _TYPES.get(spec.kind, getattr(spec.kind, "__name__", "?"))


def _allowed(spec: Field) -> str:
    if isinstance(spec.kind, tuple):
        return ", ".join(f"`{_value(k)}`" for k in spec.kind)
    return "; ".join(bounds(spec))


def _default(spec: Field) -> str:
    if spec.default is REQUIRED:
        return "**required**"
    return "not set" if spec.default is None else f"`{_value(spec.default)}`"


# the `scenario` key of each schema: the one key whose meaning is the page's own structure
SCENARIO_MEANING = "the kind of run: picks the schema of this section"


def _trailing_bracket(text: str) -> int:
    """Where the bracket that ends `text` opens (brackets may nest), or -1."""
    if not text.endswith("]"):
        return -1
    depth = 0
    for i in range(len(text) - 1, -1, -1):
        depth += {"]": 1, "[": -1}.get(text[i], 0)
        if depth == 0:
            return i
    return -1


def meaning(key: str, spec: Field) -> str:
    """The key's meaning as the page shows it. A bracket at the end of a doc says what a default
    "not set" stands for (docs' convention); where a table sets a default of its own (a contact
    table with damping_ratio = 0.05) that bracket would contradict the default column, so it goes."""
    doc = " ".join(spec.doc.split())
    if not doc and key == "scenario":
        return SCENARIO_MEANING
    start = _trailing_bracket(doc)
    if start >= 0 and spec.default is not REQUIRED and spec.default not in (None, ""):
        doc = doc[:start].rstrip()
    return doc


def _cell(text: str) -> str:
    return " ".join(str(text).split()).replace("|", "\\|")


def _rows(table: dict) -> list[str]:
    fields = [(k, s) for k, s in table.items() if isinstance(s, Field)]
    if not fields:
        return []
    lines = ["| key | type | default | meaning | allowed |", "|---|---|---|---|---|"]
    for key, spec in fields:
        cells = [f"`{key}`", _type(spec), _default(spec), meaning(key, spec), _allowed(spec)]
        lines.append("| " + " | ".join(_cell(c) for c in cells) + " |")
    return lines + [""]


# ------------------------------------------------------------------------------------ the page
def _anchor(*parts: str) -> str:
    return "-".join(p.lower().replace("_", "-").replace(".", "-") for p in parts)


def _label(path: str, spec) -> str:
    return f"[[{path}]]" if isinstance(spec, TableList) else f"[{path}]"


class _Page:
    def __init__(self):
        self.shared = shared_tables()
        self.scenarios = scenario_schemas()
        self.rendered: list[tuple[dict, str, str]] = []  # (table, anchor, "`[label]` of scenario")
        # shared constant -> where it is used: (scenario, label, changed defaults)
        self.uses: dict[str, list] = {name: [] for name in self.shared}
        for scenario, schema in self.scenarios.items():
            for path, spec in self._tables(schema):
                table = spec.schema if isinstance(spec, TableList) else spec
                found = _base_of(table, self.shared)
                if found:
                    self.uses[found[0]].append((scenario, _label(path, spec), found[1]))

    def _tables(self, table: dict, prefix: str = ""):
        """(dotted path, spec) of the tables below `table`, not below shared ones."""
        for key, spec in table.items():
            if isinstance(spec, Field):
                continue
            path = prefix + key
            yield path, spec
            inner = spec.schema if isinstance(spec, TableList) else spec
            if _base_of(inner, self.shared) is None:
                yield from self._tables(inner, path + ".")

    def _shared_heading(self, name: str) -> str:
        uses = self.uses[name]
        return f"`{uses[0][1]}`" if uses else f"`{name}`"

    def render(self) -> str:
        out = [
            "# Config reference",
            "",
            f"<!-- generated from src/vemdem/config/tables.py and lab_tables.py by `{COMMAND}`: do not edit by hand -->",
            "",
            "A run is one TOML file; its `scenario` key picks the schema below. Every key is checked "
            "before anything runs: an unknown key, a missing required key, a value of the wrong type or "
            "outside its bounds stops the run with one line naming the key ([Errors](../errors.md)). "
            "A key without a default is required; a default \"not set\" means the value is derived "
            "where the run starts (the meaning says from what, in brackets) or that the feature is off.",
            "",
            "Columns: the key, its type (a *choice* takes one of the allowed strings), its default, its "
            "meaning and unit, and the values it accepts (the bound its check states). Numbers may be "
            "written as integers (`1` for `1.0`); lengths are in metres, times in seconds. Rules that tie "
            "several keys together (for example `contact.mu_d` at most `contact.mu_s`, `solver.dt_min` at most "
            "`solver.dt_max`, `lid.end` below `lid.start`, the frame count of `output.every`, `initial_state` "
            "never beside a `[pack]` table) are checked after the keys, by `vemdem.config.rules.check_rules`; "
            "a laboratory test's (`output.every` within its stages' `max_time`, `lid.area` against the box, "
            "at least 4 grains) by `vemdem.config.lab_rules` ([what a lab test "
            "refuses](../servo.md#what-a-lab-test-refuses)).",
            "",
            f"This page is generated from `src/vemdem/config/tables.py` and `lab_tables.py`: `{COMMAND}` rewrites it.",
            "",
            "## Scenarios",
            "",
        ]
        for scenario in self.scenarios:
            out.append(f'- [`scenario = "{scenario}"`](#{_anchor("scenario", scenario)})')
        out += ["- [Shared tables](#shared-tables)", ""]
        for scenario, schema in self.scenarios.items():
            out += self._scenario(scenario, schema)
        out += ["## Shared tables", "", "The tables several scenarios use, each key once.", ""]
        for name, table in self.shared.items():
            out += self._shared(name, table)
        return "\n".join(out).rstrip("\n") + "\n"

    def _scenario(self, scenario: str, schema: dict) -> list[str]:
        out = [f'## `scenario = "{scenario}"` {{#{_anchor("scenario", scenario)}}}', ""]
        out += _rows(schema)
        listing, full = [], []
        for path, spec in self._tables(schema):
            label = _label(path, spec)
            table = spec.schema if isinstance(spec, TableList) else spec
            found = _base_of(table, self.shared)
            extra = f" (at least {spec.min_items})" if isinstance(spec, TableList) and spec.min_items else ""
            if found:
                name, changed = found
                line = f"- `{label}`{extra}: the shared table [{self._shared_heading(name)}](#{_anchor('table', name)})"
                if changed:
                    line += ", with the defaults " + ", ".join(f"`{k} = {_value(v)}`" for k, v in changed.items())
                listing.append(line)
                continue
            anchor = _anchor(scenario, path)
            same = next(((a, where) for t, a, where in self.rendered if t == table), None)
            if same:
                listing.append(f"- `{label}`{extra}: as [{same[1]}](#{same[0]})")
                continue
            self.rendered.append((table, anchor, f"`{label}` of `{scenario}`"))
            listing.append(f"- [`{label}`](#{anchor}){extra}")
            full += [f"### `{label}` {{#{anchor}}}", ""] + (_rows(table) or ["Tables only: see below.", ""])
        if listing:
            out += ["Tables:", ""] + listing + [""]
        return out + full

    def _shared(self, name: str, table: dict) -> list[str]:
        out = [f"### {self._shared_heading(name)} {{#{_anchor('table', name)}}}", ""]
        uses = self.uses[name]
        if uses:
            by = []
            for scenario, label, changed in uses:
                note = f"`{scenario}`" + (f" (`{label}`)" if label != uses[0][1] else "")
                by.append(note + (" with other defaults" if changed else ""))
            out += ["Used by " + ", ".join(by) + ".", ""]
        out += _rows(table)
        base = uses[0][1].strip("[]") if uses else name.lower()
        for key, inner in table.items():  # its own tables (a wall's [walls.servo])
            if isinstance(inner, dict):
                label = f"[{base}.{key}]"
                out += [f"#### `{label}` {{#{_anchor('table', name, key)}}}", ""] + _rows(inner)
        return out


def markdown() -> str:
    """The config reference page (Markdown), from the schemas of `config.tables` and `config.lab_tables`."""
    return _Page().render()


def main() -> None:
    """Write the page to stdout: `python -m vemdem.config.reference > docs/reference/config.md`."""
    sys.stdout.write(markdown())


if __name__ == "__main__":
    main()
