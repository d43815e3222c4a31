"""Every shipped example runs (docs' gallery: "every example runs in the test suite").

Each example's own TOML (`vemdem example NAME`) is run through its own scenario, integrator, grain
model, material and contact choices, reduced by a few overrides (fewer and coarser grains, a
smaller box, shorter times, fewer frames, no ParaView series) so that the whole gallery runs in a
few minutes. An example that starts from another's output (`initial_state`) is run from that
example's reduced run, at the path its own config names (the chain its comments document).

A reduction never changes the tables that make an example what it is (material, contact, solver,
model, vem): the test checks that they are the example's own. A new example needs a reduction in
REDUCTIONS (and, if it starts from `initial_state`, an entry in UPSTREAM): the test of an example
without one fails and says so.
"""

from __future__ import annotations

import copy
import json
import math
import os
import re
import shlex
import shutil
import tomllib
from pathlib import Path

import numpy as np
import pytest

from vemdem.io.state import load_state
from vemdem.scenarios.registry import (EXAMPLE_FILES, EXAMPLES, checked_config, example_text, pack_stage, settle_pack,
                                       write_example)

def merged(base: dict, changes: dict) -> dict:
    """`base` with `changes` applied: tables merged key by key, anything else (lists included) replaced."""
    out = copy.deepcopy(base)
    for key, value in changes.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = merged(out[key], value)
        else:
            out[key] = copy.deepcopy(value)
    return out


def small_pack(size: float, n_grains: int = 4) -> dict:
    """A [pack] of a few coarse grains of the example's size in a box about 2.5 grain sizes wide."""
    box = round(2.5 * size, 6)
    return {"n_grains": n_grains, "grains": {"size": size, "vertices": 8}, "box": {"width": box, "depth": box}}


def _raw_size(raw: dict, default: float = 1.45e-3) -> float:
    grains = raw.get("pack", raw).get("grains", {})
    return grains.get("size", default) if isinstance(grains, dict) else default


# -------------------------------------------------------------------------------- reductions
def reduce_scene(raw):
    grains = [merged(g, {"vertices": min(g.get("vertices", 30), 12)}) for g in raw["grains"]]
    return merged(raw, {"grains": grains, "duration": 4e-3, "output": {"every": 1e-3, "vtk": False}})


def reduce_grain_compression(raw):
    return merged(raw, {"grain": {"vertices": 12}, "loading": {"steps": 4}, "output": {"vtk": False}})


def reduce_pack(raw):
    # the pack scenario's [pack]-like keys are at the top level
    pack = small_pack(_raw_size(raw))
    return merged(raw, {**pack, "settle": {"max_time": 0.2}, "output": {"every": 1e-2, "vtk": False}})


def reduce_pile_collapse(raw):
    pack = small_pack(_raw_size(raw)) if "initial_state" not in raw else {}
    return merged(raw, {"pack": pack, "settle": {"min_time": 0.02, "max_time": 0.03},
                        "output": {"every": 1e-2, "vtk": False}})  # fmt: skip


def reduce_lid_compression(raw):
    # six grains: two layers, so the lid's top grain can give way (four stand in one layer on the
    # floor, and a lid pressing them deforms grains: 1e-6 s implicit steps at the real density);
    # the lid's start and end follow the settled pack (lid_on_pack, after the pack stage)
    return merged(raw, {"pack": small_pack(_raw_size(raw), n_grains=6), "settle": {"kinetic_threshold": 1e-2},
                        "lid": {"speed": 0.08, "frames": 6}, "output": {"vtk": False}})  # fmt: skip


def lid_on_pack(raw, pack):
    """The lid from a tenth of a grain size above the settled pack's top to a tenth below it: it
    meets the pack on its way down (the example's 7 -> 4.9 mm is for its 110 grains)."""
    top, size = float(pack.x[:, 2].max()), _raw_size(raw)
    return merged(raw, {"lid": {"start": top + 0.1 * size, "end": top - 0.1 * size}})


def reduce_poured_heap(raw):
    size = _raw_size(raw)
    # the disc reaches beyond the box's far corner (measured from the corner that stays)
    return merged(raw, {"pack": small_pack(size), "source": {"lift_speed": 0.2}, "disc": {"radius": 6 * size},
                        "settle": {"min_time": 0.02, "max_time": 0.05},
                        "output": {"every": 1e-2, "vtk": False}})  # fmt: skip


def reduce_tilting_box(raw):
    size = _raw_size(raw)
    pack = small_pack(size, n_grains=8)
    pack["box"] = {"width": 6 * size, "depth": 3 * size}
    # a box 6 x 3 grain sizes (the example's mirror sides kept); a fast tilt, still from its start
    return merged(raw, {"pack": pack, "tilt": {"rate": 200.0, "max": 40.0},
                        "settle": {"min_time": 0.02, "max_time": 0.05},
                        "output": {"every": 1e-2, "vtk": False}})  # fmt: skip


def per_stress_law(raw, stress, size=1.2e-3):
    """The per-stress law at 2 sigma d^2 where the example gives no reference force: the gallery
    runs the examples' files and stages, not their law (tests/test_material_law.py does)."""
    if raw.get("contact", {}).get("reference_force") is not None:
        return {}
    return {"contact": {"reference_force": 2 * stress * size**2}}


def reduce_oedometer(raw):
    # the oedometers: a fixed small path; their files, and that every stage ended
    return merged(raw, {"pack": {"n_grains": 4, "grains": {"size": 1.2e-3, "vertices": 8},
                                 "box": {"width": 3.2e-3, "depth": 3.2e-3}},
                        "stages": [{"stress": 200.0, "max_time": 0.01}, {"stress": 100.0, "max_time": 0.005}],
                        "servo": {"inertia_number": 1e-2}, "lid": {"gap": 0.01},
                        "output": {"every": 2e-3, "vtk": False}, **per_stress_law(raw, 200.0)})  # fmt: skip


def reduce_triaxial(raw):
    # a few grains, a low confining stress reached fast, a short shear: the files, both stages
    return merged(raw, {"pack": {"n_grains": 6, "grains": {"size": 1.2e-3, "vertices": 8},
                                 "box": {"width": 3.2e-3, "depth": 3.2e-3}},
                        "consolidation": {"stress": 2e3, "max_time": 0.01},
                        "shear": {"max_strain": 0.02, "inertia_number": 1e-2, "max_time": 0.01},
                        "servo": {"inertia_number": 1e-2}, "sample": {"gap": 0.01},
                        "output": {"every": 2e-3, "vtk": False}, **per_stress_law(raw, 2e3)})  # fmt: skip


def reduce_direct_shear(raw):
    # a few grains, a low normal stress reached fast, a short shear: the files, both stages
    return merged(raw, {"pack": {"n_grains": 8, "grains": {"size": 1.2e-3, "vertices": 8},
                                 "box": {"width": 4.0e-3, "depth": 3.2e-3}},
                        "normal": {"stress": 2e3, "max_time": 0.01},
                        "shear": {"max_displacement": 0.05, "inertia_number": 1e-2, "max_time": 0.01},
                        "servo": {"inertia_number": 1e-2}, "sample": {"gap": 0.01},
                        "output": {"every": 2e-3, "vtk": False}, **per_stress_law(raw, 2e3)})  # fmt: skip


def reduce_isotropic(raw):
    # a few grains, a short path of low stresses reached fast: the files, every stage ended
    return merged(raw, {"pack": {"n_grains": 6, "grains": {"size": 1.2e-3, "vertices": 8},
                                 "box": {"width": 3.2e-3, "depth": 3.2e-3}},
                        "stages": [{"stress": 2e3, "max_time": 0.01}, {"stress": 4e3, "max_time": 0.01}],
                        "servo": {"inertia_number": 1e-2}, "sample": {"gap": 0.01},
                        "output": {"every": 2e-3, "vtk": False}, **per_stress_law(raw, 4e3)})  # fmt: skip


REDUCTIONS = {
    "drop": reduce_scene,
    "grain_compression": reduce_grain_compression,
    "oedometer": reduce_oedometer,
    "paper-collapse-high": reduce_pile_collapse,
    "paper-collapse-high-implicit": reduce_pile_collapse,
    "paper-collapse-low": reduce_pile_collapse,
    "paper-collapse-low-implicit": reduce_pile_collapse,
    "paper-collapse-mid": reduce_pile_collapse,
    "paper-collapse-mid-implicit": reduce_pile_collapse,
    "paper-compression": reduce_lid_compression,
    "paper-compression-implicit": reduce_lid_compression,
    "paper-oedometer": reduce_oedometer,
    "soft-oedometer": reduce_oedometer,
    "paper-pack": reduce_pack,
    "paper-pack-implicit": reduce_pack,
    "pile": reduce_pile_collapse,
    "pile-flexible": reduce_pile_collapse,
    "poured-heap": reduce_poured_heap,
    "tilting-box": reduce_tilting_box,
    "triaxial": reduce_triaxial,
    "direct-shear": reduce_direct_shear,
    "triaxial-flexible": reduce_triaxial,
    "triaxial-two-shapes": reduce_triaxial,
    "isotropic": reduce_isotropic,
}

# examples whose reduction depends on their settled [pack]: (raw, pack state) -> raw, applied after
# the pack stage has settled into DIR/pack (registry.pack_stage / settle_pack, which the run reuses)
AFTER_PACK = {"paper-compression": lid_on_pack, "paper-compression-implicit": lid_on_pack}

# examples that start from another example's output: (that example, the file in its output folder
# that their `initial_state` names)
UPSTREAM = {
    **{f"paper-collapse-{h}": ("paper-pack", "state.npz") for h in ("high", "mid", "low")},
    **{f"paper-collapse-{h}-implicit": ("paper-pack-implicit", "state.npz") for h in ("high", "mid", "low")},
    "pile-flexible": ("pile", "pack/state.npz"),
}

# the main outputs each scenario's docstring names, besides summary.json (non-empty files)
OUTPUTS = {
    "scene": ["history.csv", "grains.csv", "walls.csv"],
    "grain_compression": ["force_strain.csv", "force_strain.png"],
    "pack": ["state.npz", "history.csv", "grains.csv", "walls.csv"],
    "pile_collapse": ["pile.png", "pile_3d.png", "state.npz", "history.csv", "grains.csv", "walls.csv"],
    "lid_compression": ["force_strain.csv", "force_strain.png", "turn_state.npz", "release_state.npz",
                        "fluctuations.csv", "history.csv", "walls.csv"],
    "poured_heap": ["heap.png", "heap_3d.png", "state.npz", "history.csv", "grains.csv", "walls.csv"],
    "tilting_box": ["tilt.png", "tilt_3d.png", "tilt.json", "state.npz", "history.csv", "grains.csv", "walls.csv"],
    "oedometer": ["oedometer.csv", "fabric.csv"],
    "triaxial": ["triaxial.csv", "triaxial.png", "fabric.csv"],
    "direct_shear": ["shear.csv", "shear.png", "fabric.csv"],
    "isotropic": ["isotropic.csv", "fabric.csv"],
}  # fmt: skip

# summary numbers each scenario must report as finite numbers (not null) even reduced
FINITE = {
    "scene": [],
    "grain_compression": ["max_force"],
    "pack": ["pack_height", "packing_fraction"],
    "pile_collapse": ["pile_height", "runout"],
    "lid_compression": ["peak_force", "pack_weight"],
    "poured_heap": ["pile_height"],
    "tilting_box": ["fill_height_grains"],
    "oedometer": [],
    "triaxial": [],
    "direct_shear": [],
    "isotropic": [],
}


# -------------------------------------------------------------------------------- running
@pytest.fixture(scope="module")
def gallery(tmp_path_factory):
    """run(name) -> (output folder, summary, config) of the reduced example, run once per module:
    an example another one starts from is run once for both."""
    done = {}

    def run(name):
        if name not in done:
            assert name in REDUCTIONS, f"add a reduction for example {name} to REDUCTIONS in tests/test_gallery.py"
            raw = REDUCTIONS[name](tomllib.loads(example_text(name)))
            base = tmp_path_factory.mktemp(name)
            write_example(name, base)  # the config's own files beside it (an example's grain shapes)
            if raw.get("initial_state"):
                assert name in UPSTREAM, (f"example {name} starts from initial_state = "
                                          f"{raw['initial_state']!r}: add the example that writes it to UPSTREAM "
                                          "in tests/test_gallery.py")  # fmt: skip
                source, inside = UPSTREAM[name]
                source_out, _, _ = run(source)
                target = base / raw["initial_state"]  # relative to the config file: base is its folder
                target.parent.mkdir(parents=True, exist_ok=True)
                shutil.copyfile(source_out / inside, target)
            out = base / "out"
            if name in AFTER_PACK:
                _, pack_config = pack_stage(raw)
                settle_pack(pack_config, out / "pack")
                raw = AFTER_PACK[name](raw, load_state(out / "pack" / "state.npz"))
            cfg, module = checked_config(raw)
            summary = module.run(cfg, out, base_dir=base)
            done[name] = (out, summary, cfg)
        return done[name]

    return run


# columns where infinity is a documented value: the inertia number of a frame whose lid carries no
# load (analysis.fluctuations.inertia_number)
MAY_BE_INFINITE = {"inertia_number"}


def _numeric_columns_finite(path):
    rows = np.atleast_1d(np.genfromtxt(path, delimiter=",", names=True, dtype=None, encoding="utf-8"))
    assert len(rows) >= 1, f"{path.name}: no rows"
    for column in rows.dtype.names:
        values = rows[column]
        if not np.issubdtype(values.dtype, np.number):
            continue
        ok = ~np.isnan(values) if column in MAY_BE_INFINITE else np.isfinite(values)
        assert np.all(ok), f"{path.name}: column {column} holds {values[~ok][:3]}"
    return rows


@pytest.mark.parametrize("name", sorted(EXAMPLES))
def test_every_example_runs_reduced(gallery, name):
    if name not in REDUCTIONS:
        pytest.fail(f"add a reduction for example {name} to REDUCTIONS in tests/test_gallery.py")
    out, summary, cfg = gallery(name)
    scenario = cfg["scenario"]
    assert scenario == tomllib.loads(example_text(name))["scenario"]

    # the example's own choices, untouched by the reduction
    full, _ = checked_config(tomllib.loads(example_text(name)))
    for table in ("material", "contact", "solver", "model", "vem"):
        mine, theirs = cfg.get(table), full.get(table)
        lab = scenario in ("oedometer", "triaxial", "direct_shear", "isotropic")
        if table == "contact" and lab and theirs["reference_force"] is None:  # the one change allowed:
            mine = {**mine, "reference_force": None}  # the lab examples' law pinned (per_stress_law)
        assert mine == theirs, f"the reduction of {name} changed its [{table}]"

    # summary.json: written, strict JSON (no NaN or infinity), the scenario's own
    text = (out / "summary.json").read_text()

    def no_constants(token):
        raise AssertionError(f"summary.json of {name} holds {token}")

    on_disk = json.loads(text, parse_constant=no_constants)
    assert on_disk["scenario"] == scenario == summary["scenario"]

    for filename in OUTPUTS[scenario]:
        path = out / filename
        assert path.is_file() and path.stat().st_size > 0, f"{name}: {filename} missing or empty"

    if scenario == "oedometer":  # its files, finite stresses, and every stage ended (at its target or a limit)
        rows = np.genfromtxt(out / "oedometer.csv", delimiter=",", names=True)
        sigma_v = np.atleast_1d(rows["sigma_v"])
        assert len(sigma_v) >= 2 and np.all(np.isfinite(sigma_v))
        assert len(on_disk["stages"]) == 2
        assert all(s["end_reason"] in ("reached", "max_time", "max_strain") for s in on_disk["stages"]), on_disk["stages"]
        return

    if scenario in ("triaxial", "direct_shear"):  # files, finite stresses, both stages ended (at targets or limits)
        table, stress = ("triaxial.csv", "sigma_3") if scenario == "triaxial" else ("shear.csv", "sigma_n")
        rows = np.genfromtxt(out / table, delimiter=",", names=True)
        assert np.all(np.isfinite(rows[stress])) and set(np.unique(rows["stage"])) == {0.0, 1.0}
        assert [s["name"] for s in on_disk["stages"]] == ["consolidation", "shear"]
        assert all(s["end_reason"] in ("reached", "max_time", "max_strain") for s in on_disk["stages"]), on_disk["stages"]
        return

    if scenario == "isotropic":  # its files, a finite mean stress, every stage ended (at its target or a limit)
        rows = np.genfromtxt(out / "isotropic.csv", delimiter=",", names=True)
        assert np.all(np.isfinite(rows["p"])) and len(on_disk["stages"]) == 2
        ended = [s["end_reason"] for s in on_disk["stages"]]
        assert all(reason in ("reached", "max_time", "max_strain") for reason in ended), on_disk["stages"]
        return

    if "solver" in full and "integrator" in full["solver"]:  # the time-stepping scenarios
        assert on_disk["integrator"] == full["solver"]["integrator"]
        assert on_disk["grain_model"] == full["model"]["grains"]
        assert on_disk["mass_scaling"] == full["solver"]["mass_scaling"]
        assert on_disk["simulated_time"] > 0

    for filename in OUTPUTS[scenario]:
        if filename.endswith(".csv"):
            _numeric_columns_finite(out / filename)
    for key in FINITE[scenario]:
        value = on_disk[key]
        assert isinstance(value, (int, float)) and math.isfinite(value), f"{name}: summary {key} = {value!r}"

    if scenario == "scene":
        assert on_disk["n_grains"] == len(cfg["grains"])
    if scenario == "grain_compression":
        assert on_disk["max_force"] > 0  # the plates pressed the grain
    if scenario == "lid_compression":
        assert on_disk["peak_force"] > 0  # the lid met the reduced pack
    if "pack" in cfg and not cfg.get("initial_state"):
        # the [pack] stage settled into DIR/pack first
        assert (out / "pack" / "state.npz").is_file() and (out / "pack" / "summary.json").is_file()
    if name in UPSTREAM:
        assert summary["initial_state"].endswith(cfg["initial_state"])


def test_the_tables_name_shipped_examples():
    """No reduction or chain is left for an example that is no longer shipped, and every chain
    starts from a shipped example."""
    assert set(REDUCTIONS) <= set(EXAMPLES), sorted(set(REDUCTIONS) - set(EXAMPLES))
    assert set(AFTER_PACK) | set(UPSTREAM) <= set(REDUCTIONS)
    assert {source for source, _ in UPSTREAM.values()} <= set(EXAMPLES)


# -------------------------------------------------------------------------------- the page's commands
GALLERY = Path(__file__).resolve().parents[1] / "docs" / "gallery.md"
# the scenarios that write DIR/state.npz (the start of another run); a run with a pack stage also
# writes DIR/pack/state.npz
STATE_WRITERS = {"pack", "pile_collapse", "poured_heap", "tilting_box"}
# the examples the gallery shows without a picture, and says so
NO_PICTURE = {"drop", "paper-pack", "paper-pack-implicit", "isotropic"}


def gallery_commands(text: str) -> list[list[str]]:
    """Each command of the page's bash blocks, split as the shell splits it (`&&` chains apart,
    comments dropped); the generic `NAME` line is a pattern, not a command."""
    commands = []
    for block in re.findall(r"```bash\n(.*?)```", text, re.S):
        for line in block.splitlines():
            words = shlex.split(line, comments=True)
            while words and "NAME" not in words:
                cut = words.index("&&") if "&&" in words else len(words)
                command, words = words[:cut], words[cut + 1 :]
                commands.append([Path(command[0]).name, *command[1:]])
    return commands


def test_the_gallery_commands_chain_as_written():
    """Run in one folder in the page's order, each command finds what it reads: a `vemdem run`
    a config an earlier `vemdem example` wrote, its `initial_state` (relative to the config) a state
    file an earlier run wrote, and an --out folder no earlier run used (which it would refuse)."""
    configs: dict[str, str] = {}  # config file -> the example written into it
    written: set[str] = set()  # state files the runs so far wrote
    used: set[str] = set()
    ran = []
    for words in gallery_commands(GALLERY.read_text()):
        if words[:2] == ["vemdem", "example"] and len(words) == 5 and words[3] == ">":
            assert words[2] in EXAMPLES, f"gallery: no example {words[2]!r}"
            assert not EXAMPLE_FILES.get(words[2]), f"gallery: {words[2]} names files: write it with --dir"
            configs[words[4]] = words[2]
        elif words[:2] == ["vemdem", "example"] and len(words) == 5 and words[3] == "--dir":
            assert words[2] in EXAMPLES, f"gallery: no example {words[2]!r}"
            configs[os.path.normpath(f"{words[4]}/{words[2]}.toml")] = words[2]
        elif words[:2] == ["vemdem", "run"]:
            config, out = words[2], Path(words[words.index("--out") + 1]).as_posix()
            assert config in configs, f"gallery: `vemdem run {config}` before a command writes {config}"
            assert out not in used, f"gallery: two runs write --out {out}"
            used.add(out)
            raw = tomllib.loads(example_text(configs[config]))
            if raw.get("initial_state"):
                start = os.path.normpath(Path(config).parent / raw["initial_state"])
                assert start in written, (f"gallery: {configs[config]} starts from {start}, which no earlier "
                                          f"command writes (written: {sorted(written)})")  # fmt: skip
            if raw["scenario"] in STATE_WRITERS:
                written.add(os.path.normpath(f"{out}/state.npz"))
            if pack_stage(raw) is not None:
                written.add(os.path.normpath(f"{out}/pack/state.npz"))
            ran.append(configs[config])
    assert sorted(ran) == sorted(EXAMPLES), "gallery: every example runs once, in a block of its own"


def test_the_gallery_shows_every_example_with_its_picture_or_says_it_has_none():
    text = GALLERY.read_text()
    sections = dict(re.findall(r"^### `([a-z_-]+)`\n(.*?)(?=^##)", text + "\n##", re.S | re.M))
    assert set(sections) == set(EXAMPLES)
    for name, section in sections.items():
        pictures = re.findall(r"!\[[^\]]*\]\((img/[^)]+)\)", section)
        if name in NO_PICTURE:
            assert not pictures and "No picture" in " ".join(section.split()), name
        else:
            assert pictures, f"gallery: {name} has no picture; add one, or add it to NO_PICTURE and say so"
            for picture in pictures:
                assert (GALLERY.parent / picture).is_file(), picture
    for name in NO_PICTURE:
        assert f"`{name}`" in text.split("## The first runs")[0], f"the gallery's introduction names {name}"
