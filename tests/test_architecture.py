"""The import rules of docs/architecture.md, checked on the source: a rule broken in review is a
failing test here, not a comment."""

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src" / "vemdem"

# room -> rooms it may import (a room always may import itself). A dotted entry allows one module.
ALLOWED = {
    "geometry": set(),
    "portable": set(),  # runs before NumPy and numba load: imports nothing of vemdem (nor them)
    "vem": {"geometry"},
    "contact": {"geometry"},
    "model": {"vem", "contact", "geometry"},
    # config.tables: the [solver] keys' defaults, read by solver.defaults alone (test below)
    "solver": {"model", "contact", "geometry", "config.tables"},
    # analysis.microstructure: the frames' fabric.csv (plain arrays in, numbers out: it runs nothing)
    "driver": {"solver", "model", "io", "contact.model", "portable", "analysis.microstructure"},
    "io": {"geometry", "contact.walls"},
    "analysis": {"io", "geometry"},
    "config": {"model", "vem", "contact", "geometry", "io", "solver.api"},
    # the laboratory: typed options in (never a config), the loop and the walls below it, no kernel
    "lab": {"driver", "model", "contact.walls", "analysis", "solver.api", "solver.state", "io", "geometry"},
    "scenarios": {"config", "driver", "lab", "solver.api", "solver.statics", "solver.state", "model", "geometry",
                  "io", "analysis", "contact.walls"},  # fmt: skip
    "verification": {"solver", "model", "vem", "geometry", "scenarios.plates", "contact.defaults"},
    "cli": {"config", "scenarios.registry", "driver.checkpoint", "driver.loop", "sweep"},
    "sweep": {"config", "scenarios.registry", "analysis.seeds"},
}
# finer rules inside a room
FORBIDDEN = {
    "solver": {"vem", "contact.pairs", "contact.law", "contact.narrow", "scenarios", "driver", "config.build",
               "config.reference", "config.schema", "io"},
    "config.schema": {"model", "vem", "contact", "io", "solver", "scenarios", "driver"},
    "config.tables": {"model", "vem", "contact", "io", "solver", "scenarios", "driver"},
    "config.checks": {"model", "vem", "contact", "io", "solver", "scenarios", "driver"},
    "config.lab_tables": {"model", "vem", "contact", "io", "solver", "scenarios", "driver"},
    "config.rules": {"model", "vem", "contact", "io", "solver", "scenarios", "driver"},
    "config.lab_rules": {"model", "vem", "contact", "io", "solver", "scenarios", "driver"},
}


def _modules():
    for path in sorted(SRC.rglob("*.py")):
        rel = path.relative_to(SRC).with_suffix("")
        parts = [p for p in rel.parts if p != "__init__"]
        yield ".".join(parts), path, path.name == "__init__.py"


def _imports(module: str, path: Path, is_package: bool):
    """Every vemdem module this file imports, as a dotted name below vemdem."""
    tree = ast.parse(path.read_text())
    package = module.split(".") if is_package else module.split(".")[:-1]
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - node.level + 1] if node.level > 1 else package
                target = ".".join([*base, node.module] if node.module else base)
            elif node.module and node.module.startswith("vemdem"):
                target = node.module.removeprefix("vemdem").lstrip(".")
            else:
                continue
            names = [f"{target}.{a.name}" if target else a.name for a in node.names]
            yield from (n if (SRC / n.replace(".", "/")).with_suffix(".py").exists() or (SRC / n.replace(".", "/")).is_dir()
                        else target for n in names)  # fmt: skip
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.startswith("vemdem."):
                    yield a.name.removeprefix("vemdem.")


def _matches(target: str, rule: str) -> bool:
    return target == rule or target.startswith(rule + ".")


def _violations():
    out = []
    for module, path, is_package in _modules():
        room = module.split(".")[0]
        if room not in ALLOWED:
            continue
        for target in _imports(module, path, is_package):
            if not target or _matches(target, room):
                if any(_matches(module, m) and _matches(target, f) for m, fs in FORBIDDEN.items() for f in fs):
                    out.append(f"{module} imports {target}")
                continue
            allowed = any(_matches(target, rule) for rule in ALLOWED[room])
            forbidden = any(_matches(module, m) and _matches(target, f) for m, fs in FORBIDDEN.items() for f in fs)
            if not allowed or forbidden:
                out.append(f"{module} imports {target}")
    return out


def test_every_room_is_listed():
    rooms = {m.split(".")[0] for m, _, _ in _modules()} - {"", "__main__"}
    assert rooms <= set(ALLOWED), f"rooms without rules: {sorted(rooms - set(ALLOWED))}"


def test_import_rules_hold():
    assert _violations() == []


@pytest.mark.parametrize("source,module,expected", [
    ("from ..vem.element import evaluate\n", "solver.newmark", "solver.newmark imports vem.element"),
    ("from ..scenarios import pack\n", "driver.loop", "driver.loop imports scenarios.pack"),
    ("from ..model.scene import Scene\n", "contact.ccd", "contact.ccd imports model.scene"),
    ("from ..config import tables\n", "lab.path", "lab.path imports config.tables"),
    ("from ..vem.element import evaluate\n", "lab.cell", "lab.cell imports vem.element"),
])  # fmt: skip
def test_a_broken_rule_is_caught(tmp_path, monkeypatch, source, module, expected):
    """The checker itself: a forbidden import planted in a copy of the tree is reported."""
    import shutil

    copy = tmp_path / "vemdem"
    shutil.copytree(SRC, copy, ignore=shutil.ignore_patterns("__pycache__"))
    path = copy / (module.replace(".", "/") + ".py")
    path.write_text(source + path.read_text())
    monkeypatch.setattr(__import__(__name__), "SRC", copy)
    assert expected in _violations()


def test_only_solver_defaults_reads_the_config_room():
    """The integrators' parameter classes take the [solver] keys' defaults from the schema through
    solver/defaults.py alone; config/tables.py imports nothing of the solver room (FORBIDDEN above),
    so the two never import each other in a circle."""
    readers = sorted(module for module, path, package in _modules() if module.startswith("solver.")
                     and any(_matches(t, "config") for t in _imports(module, path, package)))  # fmt: skip
    assert readers == ["solver.defaults"]


def test_the_value_lists_config_tables_repeats_agree_with_their_owners():
    """config/tables.py may not import solver/ (FORBIDDEN above), so it repeats the names the solver
    room owns: integrators and linear solvers. A name added on one side only would be refused by
    the config check or accepted there and refused by SolverOptions."""
    from vemdem.config import tables
    from vemdem.solver import api
    from vemdem.solver.linear import NAMES

    assert tables.INTEGRATORS == api.INTEGRATORS
    assert tables.LINEAR_SOLVERS == NAMES


def test_the_time_loop_declares_its_control_hook_and_probes_nothing():
    """The loop asks a control for what `driver.loop.Control` declares, never whether it has it."""
    from vemdem.driver import loop

    source = (SRC / "driver" / "loop.py").read_text()
    assert "hasattr(" not in source
    assert {"after_step", "carried", "carry_on"} <= set(vars(loop.Control))
