"""Bad input gets exit status 2, one line on stderr naming the key or file, no traceback, and no
output folder left behind (docs/errors.md). Each case mutates the `drop` example (a `scene` run) or
a `pile` example, or breaks a file the config names."""

import copy
import tomllib

import numpy as np
import pytest

from vemdem.scenarios.registry import example_text

DROP = tomllib.loads(example_text("drop"))
PILE = tomllib.loads(example_text("pile"))
COMPRESSION = tomllib.loads(example_text("grain_compression"))
LID = tomllib.loads(example_text("paper-compression"))
TRIAXIAL = tomllib.loads(example_text("triaxial"))
SHEAR = tomllib.loads(example_text("direct-shear"))


def dump(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, float):
        return repr(value) if np.isfinite(value) else ("nan" if np.isnan(value) else ("inf" if value > 0 else "-inf"))
    if isinstance(value, list):
        return "[" + ", ".join(dump(v) for v in value) + "]"
    return str(value)


def to_toml(cfg: dict) -> str:
    """Enough TOML for these configs: scalars and tables first, then arrays of tables."""
    lines = []

    def table(prefix, d):
        for k, v in d.items():
            if not isinstance(v, dict) and not (isinstance(v, list) and v and isinstance(v[0], dict)):
                lines.append(f"{k} = {dump(v)}")
        for k, v in d.items():
            if isinstance(v, dict):
                lines.append(f"[{prefix}{k}]")
                table(f"{prefix}{k}.", v)
            elif isinstance(v, list) and v and isinstance(v[0], dict):
                for item in v:
                    lines.append(f"[[{prefix}{k}]]")
                    table(f"{prefix}{k}.", item)

    table("", cfg)
    return "\n".join(lines) + "\n"


def setter(path: str, value):
    def apply(cfg):
        node = cfg
        keys = path.split(".")
        for k in keys[:-1]:
            node = node[int(k)] if isinstance(node, list) else node.setdefault(k, {})
        if value is DELETE:
            del node[keys[-1]]
        else:
            node[keys[-1]] = value

    return apply


DELETE = object()

# (id, base config, mutation, text the one-line message must contain)
CONFIG_CASES = [
    ("unknown top key", DROP, setter("colour", "red"), "colour"),
    ("unknown table key", DROP, setter("material.colour", 1.0), "material.colour"),
    ("missing scenario", DROP, setter("scenario", DELETE), "scenario"),
    ("unknown scenario", DROP, setter("scenario", "avalanche"), "scenario"),
    ("missing duration", DROP, setter("duration", DELETE), "duration"),
    ("negative duration", DROP, setter("duration", -1.0), "duration"),
    ("zero duration", DROP, setter("duration", 0.0), "duration"),
    ("nan duration", DROP, setter("duration", float("nan")), "duration"),
    ("inf duration", DROP, setter("duration", float("inf")), "duration"),
    ("string duration", DROP, setter("duration", "long"), "duration"),
    ("missing E", DROP, setter("material.E", DELETE), "material.E"),
    ("negative E", DROP, setter("material.E", -1e9), "material.E"),
    ("nu too large", DROP, setter("material.nu", 0.5), "material.nu"),
    ("negative density", DROP, setter("material.density", -1.0), "material.density"),
    ("mu_d above mu_s", DROP, setter("contact.mu_d", 0.9), "contact.mu_d"),
    ("negative mu_s", DROP, setter("contact.mu_s", -0.1), "contact.mu_s"),
    ("unknown integrator", DROP, setter("solver.integrator", "leapfrog"), "solver.integrator"),
    ("unknown linear solver", DROP, setter("solver.linear", "cg"), "solver.linear"),
    ("dt_min above dt_max", DROP, setter("solver.dt_min", 1e-3), "solver.dt_min"),
    ("easy_iterations above max_iterations", DROP, setter("solver.easy_iterations", 20), "solver.easy_iterations"),
    ("gamma below 1/2", DROP, setter("solver.gamma", 0.4), "solver.gamma"),
    ("negative energy_growth", DROP, setter("solver.energy_growth", -1.0), "solver.energy_growth"),
    ("mass scaling below 1", DROP, setter("solver.mass_scaling", 0.5), "solver.mass_scaling"),
    ("unknown grain model", DROP, setter("model", {"grains": "soft"}), "model.grains"),
    ("no grains", DROP, setter("grains", []), "grains"),
    ("grain without position", DROP, setter("grains.0.position", DELETE), "grains[0].position"),
    ("position of two numbers", DROP, setter("grains.0.position", [0.0, 1.0]), "grains[0].position"),
    ("unknown shape", DROP, setter("grains.0.shape", "sphere"), "grains[0].shape"),
    ("too few vertices", DROP, setter("grains.0.vertices", 3), "grains[0].vertices"),
    ("negative size", DROP, setter("grains.0.size", -1e-3), "grains[0].size"),
    ("missing grain file", DROP, lambda c: (setter("grains.0.shape", "file")(c), setter("grains.0.file", "nowhere.stl")(c)),
     "nowhere.stl: grain file not found"),
    ("file shape without a file", DROP, setter("grains.1.shape", "file"), "grains[1].file"),
    # the file once won without a word
    ("random shape and a file", DROP, setter("grains.0.file", "grain.stl"), "grains[0].shape"),
    ("overlapping grains", DROP, setter("grains.1.position", [0.0, 0.0, 1.3e-3]), "grains[0] and grains[1]"),
    ("grain behind the floor", DROP, setter("grains.0.position", [0.0, 0.0, 0.1e-3]), "grains[0]"),
    ("unknown wall type", DROP, setter("walls.0.type", "sphere"), "walls[0].type"),
    ("zero wall normal", DROP, setter("walls.0.normal", [0.0, 0.0, 0.0]), "walls[0].normal"),
    ("missing wall mesh", DROP, setter("walls", [{"type": "mesh", "file": "lid.obj"}]), "lid.obj"),
    ("tiny output interval", DROP, setter("output.every", 1e-12), "output.every"),
    ("negative output interval", DROP, setter("output.every", -1e-3), "output.every"),
    ("vtk not a bool", DROP, setter("output.vtk", "yes"), "output.vtk"),
    ("pile: zero grains", PILE, setter("pack.n_grains", 0), "pack.n_grains"),
    ("pile: negative seed", PILE, setter("pack.seed", -1), "pack.seed"),
    ("pile: pack mu_d above mu_s", PILE, setter("pack.mu_d", 2.0), "pack.mu_d"),
    ("pile: missing initial state", PILE, lambda c: (setter("initial_state", "none/state.npz")(c), c.pop("pack")),
     "none/state.npz"),
    ("pile: box of zero width", PILE, setter("pack.box.width", 0.0), "pack.box.width"),
    ("pile: threshold zero", PILE, setter("settle.kinetic_threshold", 0.0), "settle.kinetic_threshold"),
    ("pile: settle min_time above max_time", PILE, setter("settle.min_time", 5.0), "settle.min_time"),
    ("scenario not a string", DROP, setter("scenario", ["scene"]), "scenario"),
    ("gravity of booleans", DROP, setter("gravity", [True, False, 0.0]), "gravity"),
    # a NaN in a wall's motion once crashed the process (an out-of-bounds write in the plane pairs' kernel)
    ("nan wall time", DROP, setter("walls.0.times", [0.0, float("nan")]), "walls[0].times"),
    ("nan wall displacement", DROP, lambda c: (setter("walls.0.times", [0.0, 1.0])(c), setter(
        "walls.0.displacements", [[0.0, 0.0, 0.0], [0.0, 0.0, float("nan")]])(c)), "walls[0].displacements"),
    ("wall displacement of two numbers", DROP, setter("walls.0.displacements", [[0.0, 0.0]]), "walls[0].displacements"),
    # the law's checks once all failed together on a non-finite penalty, and the first named the gap
    ("infinite reference force", DROP, setter("contact.reference_force", 1e300), "reference_force"),
    # a Newton tolerance of 1 or more accepted the first iterate: forces 5 % off at 18 % strain, silently
    ("compression: rtol of 1e30", COMPRESSION, setter("solver.rtol", 1e30), "solver.rtol"),
    ("lid: a billion frames", LID, setter("lid.frames", 10**9), "lid.frames"),
    # magnitudes no grain run meets, each refused by name with its bound: a density of 1e300 once ran
    # to its end on overflow warnings, a grain of 1e300 m ended in an OverflowError
    ("density of 1e300", DROP, setter("material.density", 1e300), "material.density: must be in [1, 1e5] kg/m^3"),
    ("density of 1e-3", DROP, setter("material.density", 1e-3), "material.density: must be in [1, 1e5] kg/m^3"),
    ("E of 1 Pa", DROP, setter("material.E", 1.0), "material.E: must be in [1e3, 1e13] Pa"),
    ("E of 1e300", DROP, setter("material.E", 1e300), "material.E: must be in [1e3, 1e13] Pa"),
    ("grain of 1e300 m", DROP, setter("grains.0.size", 1e300), "grains[0].size: must be in [1e-7, 10] m"),
    ("grain of 1e-9 m", DROP, setter("grains.0.size", 1e-9), "grains[0].size: must be in [1e-7, 10] m"),
    ("grain at 1e300 m", DROP, setter("grains.1.position", [0.0, 0.0, 1e300]), "grains[1].position: must have a "
     "magnitude of at most 1e3 m"),
    ("grain at 1e300 m/s", DROP, setter("grains.1.velocity", [0.0, 0.0, -1e300]), "grains[1].velocity: must have a "
     "magnitude of at most 1e3 m/s"),
    ("grain turned by 1e300 rad", DROP, setter("grains.1.rotation", [0.0, 0.0, 1e300]), "grains[1].rotation"),
    ("gravity of 1e300", DROP, setter("gravity", [0.0, 0.0, -1e300]), "gravity: must have a magnitude of at most 1e4"),
    ("duration of 1e300 s", DROP, setter("duration", 1e300), "duration: must be in (0, 1e4] s"),
    ("dt_min of 1e-300 s", DROP, setter("solver.dt_min", 1e-300), "solver.dt_min: must be in [1e-15, 10] s"),
    ("wall point at 1e300 m", DROP, setter("walls.0.point", [0.0, 0.0, -1e300]), "walls[0].point"),
    ("wall times of 1e300 s", DROP, setter("walls.0.times", [0.0, 1e300]), "walls[0].times: must be times within"),
    ("wall displacement of 1e300 m", DROP, lambda c: (setter("walls.0.times", [0.0, 1.0])(c), setter(
        "walls.0.displacements", [[0.0, 0.0, 0.0], [0.0, 0.0, 1e300]])(c)), "walls[0].displacements"),
    ("activation gap of 1e300 m", DROP, setter("contact.activation_gap", 1e300), "contact.activation_gap: must be in"),
    # each once ended in "run failed: OverflowError" or "ZeroDivisionError" from the contact law's scales
    ("switch factor of 1e-300", DROP, setter("contact.switch_factor", 1e-300), "contact.switch_factor: must be in"),
    ("barrier exponent of -1e300", DROP, setter("contact.barrier_exponent", -1e300), "contact.barrier_exponent"),
    ("penalty exponent of 1e300", DROP, setter("contact.penalty_exponent", 1e300), "contact.penalty_exponent"),
    # Qhull's page-long complaint once
    ("elongation of 1e-300", DROP, setter("grains.0.elongation", 1e-300), "grains[0].elongation: must be in [0.01, 1]"),
    ("mass damping of 1e300", DROP, setter("solver.mass_damping", 1e300),
     "solver.mass_damping: must be in [0, 1e6] 1/s"),
    ("mass scaling of 1e300", DROP, setter("solver.mass_scaling", 1e300), "solver.mass_scaling: must be in [1, 1e8]"),
    # a singular mass matrix once, every step rejected down to TimeStepTooSmall
    ("beta_mass of 0", DROP, setter("vem.beta_mass", 0.0), "vem.beta_mass: must be in (0, 1]"),
    # the load's stabilisation share, as the mass's: the paper's beta_e is positive
    ("beta_load of 0", DROP, setter("vem.beta_load", 0.0), "vem.beta_load: must be in (0, 1]"),
    # the loop cut its only frame to the run's end
    ("output.every above duration", DROP, setter("output.every", 1.0),
     "output.every: must not exceed duration (0.02 s)"),
    ("pile: output.every above settle.max_time", PILE, setter("output.every", 5.0),
     "output.every: must not exceed settle.max_time"),
    ("pile: settle.max_time of 1e300 s", PILE, setter("settle.max_time", 1e300),
     "settle.max_time: must be in (0, 1e4]"),
    ("pile: box of 1e300 m", PILE, setter("pack.box.width", 1e300), "pack.box.width: must be in [1e-7, 10] m"),
    ("pile: clearance of 1e300", PILE, setter("pack.grains.clearance", 1e300), "pack.grains.clearance: must be in"),
    ("lid: speed of 1e-300", LID, setter("lid.speed", 1e-300), "lid.speed: must be in [1e-6, 1e3] m/s"),
    ("lid: start at 1e300 m", LID, setter("lid.start", 1e300), "lid.start: must be in [1e-7, 10] m"),
    # counts: more is a typo that runs out of memory or time
    ("pile: a billion grains", PILE, setter("pack.n_grains", 10**9), "pack.n_grains: must be from 1 to 1,000,000"),
    ("pile: a million vertices", PILE, setter("pack.grains.vertices", 10**6),
     "pack.grains.vertices: must be from 8 to 1,000"),
    ("a million vertices", DROP, setter("grains.0.vertices", 10**6), "grains[0].vertices: must be from 4 to 1,000"),
    ("a billion Newton iterations", DROP, setter("solver.max_iterations", 10**9),
     "solver.max_iterations: must be from 1 to 1,000"),
    ("compression: a billion load steps", COMPRESSION, setter("loading.steps", 10**9),
     "loading.steps: must be from 1 to 100,000"),
    ("compression: a billion iterations", COMPRESSION, setter("solver.max_iterations", 10**9), "solver.max_iterations"),
    ("triaxial: no confining stress", TRIAXIAL, lambda c: c["consolidation"].pop("stress"), "consolidation.stress"),
    ("triaxial: negative confining stress", TRIAXIAL, setter("consolidation.stress", -50e3),
     "consolidation.stress: must be in (0, 1e9] Pa"),
    ("triaxial: nan confining stress", TRIAXIAL, setter("consolidation.stress", float("nan")), "consolidation.stress"),
    ("triaxial: strain past the sample", TRIAXIAL, setter("shear.max_strain", 1.5), "shear.max_strain"),
    ("triaxial: not quasi-static", TRIAXIAL, setter("shear.inertia_number", 0.5), "shear.inertia_number"),
    ("direct shear: no normal stress", SHEAR, lambda c: c["normal"].pop("stress"), "normal.stress"),
    ("direct shear: negative normal stress", SHEAR, setter("normal.stress", -1.0), "normal.stress"),
    ("direct shear: split at the floor", SHEAR, setter("sample.split", 0.0), "sample.split"),
    ("direct shear: travel of a whole box", SHEAR, setter("shear.max_displacement", 1.0), "shear.max_displacement"),
]


def assert_one_line_error(code, err, needle):
    assert code == 2, err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert "Traceback" not in err
    assert needle in lines[0], lines[0]


@pytest.mark.parametrize("base,mutate,needle", [c[1:] for c in CONFIG_CASES], ids=[c[0] for c in CONFIG_CASES])
def test_bad_config_is_one_line_naming_the_cause(tmp_path, cli, base, mutate, needle):
    cfg = copy.deepcopy(base)
    mutate(cfg)
    path = tmp_path / "job.toml"
    path.write_text(to_toml(cfg))
    code, _, err = cli("run", path, "--out", tmp_path / "out", "--quiet")
    assert_one_line_error(code, err, needle)
    assert not (tmp_path / "out").exists()


def good_drop(tmp_path, **changes):
    cfg = copy.deepcopy(DROP)
    cfg["duration"] = 1e-3
    cfg["output"] = {"every": 1e-3, "vtk": False}
    for k, v in changes.items():
        setter(k, v)(cfg)
    path = tmp_path / "job.toml"
    path.write_text(to_toml(cfg))
    return path


FILE_CASES = {
    "empty grain file": ("grain.stl", b"", "grain.stl"),
    "binary garbage grain file": ("grain.stl", bytes(range(256)) * 4, "grain.stl"),
    "unknown grain file extension": ("grain.xyz", b"1 2 3\n", "grain.xyz"),
    "open surface grain file": ("grain.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 2 4\n", "grain.obj"),
    # merged into one point by the duplicate-vertex rounding, before the polyhedron's own check
    "nan vertex in a grain file": ("grain.obj", b"v 0 0 0\nv 1e-3 0 0\nv 0 1e-3 0\nv nan 0 1e-3\n"
                                   b"f 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n", "non-finite coordinates"),
    # an OverflowError in the surface's checks once, naming no file
    "grain file at 1e300 m": ("grain.obj", b"v 0 0 0\nv 1e300 0 0\nv 0 1e300 0\nv 0 0 1e300\n"
                              b"f 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n", "grain.obj: coordinates beyond 1000 m"),
}


@pytest.mark.parametrize("name,content,needle", list(FILE_CASES.values()), ids=list(FILE_CASES))
def test_bad_grain_file_is_one_line_naming_it(tmp_path, cli, name, content, needle):
    (tmp_path / name).write_bytes(content)
    path = good_drop(tmp_path, **{"grains.0.shape": "file", "grains.0.file": name})
    code, _, err = cli("run", path, "--out", tmp_path / "out", "--quiet")
    assert_one_line_error(code, err, needle)


WALL_CASES = {
    "unknown wall mesh extension": ("lid.xyz", b"1 2 3\n", "lid.xyz"),
    "empty wall mesh": ("lid.obj", b"", "lid.obj"),
    "wall mesh without faces": ("lid.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\n", "lid.obj"),
    # a NaN vertex once reduced the wall to a point, and the grains fell through it without a word
    "nan vertex in a wall mesh": ("lid.obj", b"v -0.01 -0.01 0.01\nv 0.01 -0.01 0.01\nv 0.01 0.01 0.01\n"
                                  b"v nan 0.01 0.01\nf 1 3 2\nf 1 4 3\n", "non-finite coordinates"),
    # a lid above the grains whose normals face up, away from them: they once fell through it unseen
    "wall mesh facing away": ("lid.obj", b"v -0.01 -0.01 0.01\nv 0.01 -0.01 0.01\nv 0.01 0.01 0.01\n"
                              b"v -0.01 0.01 0.01\nf 1 2 3\nf 1 3 4\n", "flip = true"),
    "wall mesh at 1e300 m": ("lid.obj", b"v -0.01 -0.01 0.01\nv 0.01 -0.01 0.01\nv 0.01 0.01 1e300\n"
                             b"v -0.01 0.01 0.01\nf 1 3 2\nf 1 4 3\n", "lid.obj: coordinates beyond 1000 m"),
}


@pytest.mark.parametrize("name,content,needle", list(WALL_CASES.values()), ids=list(WALL_CASES))
def test_bad_wall_mesh_is_one_line_naming_it(tmp_path, cli, name, content, needle):
    (tmp_path / name).write_bytes(content)
    walls = [{"type": "plane", "name": "floor", "point": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0]},
             {"type": "mesh", "file": name}]  # fmt: skip
    path = good_drop(tmp_path, walls=walls)
    code, _, err = cli("run", path, "--out", tmp_path / "out", "--quiet")
    assert_one_line_error(code, err, needle)


STATE_CASES = {
    "empty state file": b"",
    "truncated zip": b"PK\x03\x04" + b"\x00" * 40,
    "text instead of npz": b"not a state\n",
}


@pytest.mark.parametrize("content", list(STATE_CASES.values()), ids=list(STATE_CASES))
def test_bad_initial_state_is_one_line_naming_it(tmp_path, cli, content):
    (tmp_path / "state.npz").write_bytes(content)
    cfg = copy.deepcopy(PILE)
    del cfg["pack"]  # a [pack] beside initial_state is refused on its own
    cfg["initial_state"] = "state.npz"
    path = tmp_path / "job.toml"
    path.write_text(to_toml(cfg))
    code, _, err = cli("run", path, "--out", tmp_path / "out", "--quiet")
    assert_one_line_error(code, err, "state.npz")


@pytest.mark.parametrize("content", list(STATE_CASES.values()), ids=list(STATE_CASES))
def test_bad_checkpoint_is_one_line_and_never_suggests_pickle(tmp_path, cli, content):
    path = good_drop(tmp_path)
    out = tmp_path / "out"
    assert cli("run", path, "--out", out, "--quiet")[0] == 0
    (out / "checkpoint.npz").write_bytes(content)
    code, _, err = cli("run", path, "--out", out, "--quiet", "--resume")
    assert_one_line_error(code, err, "checkpoint")
    assert "pickle" not in err


DAMAGED_ENTRIES = {
    "carried, not JSON": ("carried", "{not json"),
    "carried, a list": ("carried", "[1, 2]"),
    "carried, a text counter": ("carried", '{"linear": {"hold": "two"}}'),
    "carried, a boolean counter": ("carried", '{"linear": {"hold": true}}'),
    "resume_changes, not JSON": ("resume_changes", "{not json"),
    "resume_changes, an object": ("resume_changes", '{"key": "solver.dt"}'),
    "resume_changes, numbers": ("resume_changes", "[1, 2]"),
}


@pytest.mark.parametrize("entry, content", list(DAMAGED_ENTRIES.values()), ids=list(DAMAGED_ENTRIES))
def test_checkpoint_with_a_damaged_entry_is_one_line(tmp_path, cli, entry, content):
    """The integrator's own part of a checkpoint (the linear solver's counters and hold) and the earlier
    resumes' step-control changes are read with the rest: a damaged entry is the checkpoint's one-line
    error, not a traceback from the solver or the summary."""
    path = good_drop(tmp_path)
    out = tmp_path / "out"
    assert cli("run", path, "--out", out, "--quiet")[0] == 0
    with np.load(out / "checkpoint.npz", allow_pickle=False) as d:
        entries = {k: d[k] for k in d.files}
    entries[entry] = np.array(content)
    np.savez(out / "checkpoint.npz", **entries)
    code, _, err = cli("run", path, "--out", out, "--quiet", "--resume")
    assert_one_line_error(code, err, "checkpoint.npz")


def test_a_mesh_lid_facing_the_grains_is_accepted(tmp_path, cli):
    """The placement check of mesh walls refuses a lid whose normals face away (WALL_CASES), not one
    that faces the grains."""
    (tmp_path / "lid.obj").write_bytes(b"v -0.01 -0.01 0.01\nv 0.01 -0.01 0.01\nv 0.01 0.01 0.01\n"
                                       b"v -0.01 0.01 0.01\nf 1 3 2\nf 1 4 3\n")  # fmt: skip
    walls = [{"type": "plane", "name": "floor", "point": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0]},
             {"type": "mesh", "file": "lid.obj"}]  # fmt: skip
    code, _, err = cli("run", good_drop(tmp_path, walls=walls), "--out", tmp_path / "out", "--quiet")
    assert code == 0, err


def _nan_at_first(a):
    a = a.astype(float)
    a.flat[0] = np.nan
    return a


# numbers no run writes: each once went on (a negative time ran 10,000 steps, a NaN velocity gave a
# traceback, a NaN position corrupted the heap) after the outputs had been truncated to the checkpoint
DAMAGED_NUMBERS = {
    "nan position": ("x", _nan_at_first, "non-finite positions"),
    "nan velocity": ("v", _nan_at_first, "non-finite positions"),
    "positions of another scene": ("x", lambda a: a[:-3], "positions of shape"),
    "nan time": ("t", lambda a: np.array(np.nan), "time nan"),
    "negative time": ("t", lambda a: np.array(-1.0), "time -1.0"),
    "time beyond the run": ("t", lambda a: np.array(10.0), "beyond this run's"),
    "zero step": ("dt", lambda a: np.array(0.0), "step 0.0"),
    "negative frame": ("frame", lambda a: np.array(-5), "frame -5"),
    "nan energy books": ("dissipated", lambda a: np.array(np.nan), "energy books"),
}


@pytest.mark.parametrize("entry, change, needle", list(DAMAGED_NUMBERS.values()), ids=list(DAMAGED_NUMBERS))
def test_checkpoint_with_impossible_numbers_is_one_line_and_keeps_the_outputs(tmp_path, cli, entry, change, needle):
    path = good_drop(tmp_path)
    out = tmp_path / "out"
    assert cli("run", path, "--out", out, "--quiet")[0] == 0
    (out / "summary.json").unlink()  # a run that stopped before its end
    before = (out / "history.csv").read_bytes()
    with np.load(out / "checkpoint.npz", allow_pickle=False) as d:
        entries = {k: d[k] for k in d.files}
    entries[entry] = change(entries[entry])
    np.savez(out / "checkpoint.npz", **entries)
    code, _, err = cli("run", path, "--out", out, "--quiet", "--resume")
    assert_one_line_error(code, err, needle)
    assert (out / "history.csv").read_bytes() == before


def test_overwrite_keeps_the_earlier_results_when_the_new_config_fails(tmp_path, cli):
    """A mistake the scenario finds (a missing grain file) once left the folder empty: --overwrite
    had removed the earlier run's outputs before it."""
    out = tmp_path / "out"
    assert cli("run", good_drop(tmp_path), "--out", out, "--quiet")[0] == 0
    before = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()}
    missing = good_drop(tmp_path, **{"grains.0.shape": "file", "grains.0.file": "nowhere.stl"})
    code, _, err = cli("run", missing, "--out", out, "--quiet",
                       "--overwrite")  # fmt: skip
    assert code == 2 and "nowhere.stl: grain file not found" in err and "earlier results" in err
    assert {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()} == before
    assert not (out / ".vemdem-replaced").exists()
    # and a good run replaces them, leaving nothing aside
    assert cli("run", good_drop(tmp_path, duration=2e-3), "--out", out, "--quiet", "--overwrite")[0] == 0
    assert not (out / ".vemdem-replaced").exists()
    assert (out / "history.csv").read_bytes() != before["history.csv"]


@pytest.mark.parametrize("summary", ["[1, 2]", '{"wall_seconds": "abc", "simulated_time": 1.0}'])
def test_status_of_a_damaged_summary_is_one_line(tmp_path, cli, summary):
    out = tmp_path / "out"
    assert cli("run", good_drop(tmp_path), "--out", out, "--quiet")[0] == 0
    (out / "summary.json").write_text(summary)
    code, _, err = cli("status", out)
    assert_one_line_error(code, err, "damaged")


def test_a_step_control_change_on_resume_is_one_warning_line(tmp_path, cli):
    out = tmp_path / "out"
    assert cli("run", good_drop(tmp_path), "--out", out, "--quiet")[0] == 0
    code, _, err = cli("run", good_drop(tmp_path, **{"solver.max_iterations": 30}), "--out", out, "--quiet", "--resume")
    assert code == 0
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("vemdem: warning: --resume: ")
    assert "solver.max_iterations 15 -> 30" in lines[0] and "resume_changes" in lines[0]


def test_non_utf8_config(tmp_path, cli):
    path = tmp_path / "job.toml"
    path.write_bytes(b"scenario = \"scene\"\nname = \"\xff\xfe\"\n")
    code, _, err = cli("run", path, "--out", tmp_path / "out", "--quiet")
    assert_one_line_error(code, err, "job.toml")


def test_malformed_toml(tmp_path, cli):
    path = tmp_path / "job.toml"
    path.write_text("scenario = \"scene\"\n[material\nE = 1\n")
    code, _, err = cli("run", path, "--out", tmp_path / "out", "--quiet")
    assert_one_line_error(code, err, "job.toml")


def test_missing_config_file(tmp_path, cli):
    code, _, err = cli("run", tmp_path / "nowhere.toml", "--out", tmp_path / "out", "--quiet")
    assert_one_line_error(code, err, "nowhere.toml")


def _written_checkpoint(tmp_path, cli):
    """A drop run's folder cut back to a run that stopped before its end, and its config."""
    path = good_drop(tmp_path)
    out = tmp_path / "out"
    assert cli("run", path, "--out", out, "--quiet")[0] == 0
    (out / "summary.json").unlink()
    return path, out


def _with_entries(checkpoint, **changes):
    with np.load(checkpoint, allow_pickle=False) as d:
        entries = {k: d[k] for k in d.files}
    entries.update(changes)
    entries = {k: v for k, v in entries.items() if v is not None}
    np.savez(checkpoint, **entries)


def test_every_checkpoint_carries_its_format(tmp_path, cli):
    from vemdem.driver.checkpoint import FORMAT

    _, out = _written_checkpoint(tmp_path, cli)
    with np.load(out / "checkpoint.npz", allow_pickle=False) as d:
        assert d["format"].item() == FORMAT == 1


# a newer vemdem's checkpoint, and numbers no vemdem writes
UNKNOWN_FORMATS = {"newer": (np.array(2), "format 2"), "negative": (np.array(-1), "format -1"),
                   "a float": (np.array(1.0), "format 1.0"), "a text": (np.array("one"), "format 'one'"),
                   "a boolean": (np.array(True), "format True"), "a list": (np.array([0, 1]), "format [0, 1]")}  # fmt: skip


@pytest.mark.parametrize("number, needle", list(UNKNOWN_FORMATS.values()), ids=list(UNKNOWN_FORMATS))
def test_a_checkpoint_of_an_unknown_format_is_one_line_and_keeps_the_outputs(tmp_path, cli, number, needle):
    path, out = _written_checkpoint(tmp_path, cli)
    before = (out / "history.csv").read_bytes()
    _with_entries(out / "checkpoint.npz", format=number)
    code, _, err = cli("run", path, "--out", out, "--quiet", "--resume")
    assert_one_line_error(code, err, f"--resume: {out / 'checkpoint.npz'} is a checkpoint of {needle}; ")
    assert "this vemdem reads formats 0, 1 (it writes 1)" in err
    assert (out / "history.csv").read_bytes() == before
    code, _, err = cli("status", out)
    assert_one_line_error(code, err, f"is a checkpoint of {needle}; this vemdem reads formats 0, 1")


def test_a_checkpoint_without_a_format_number_resumes_as_format_0(tmp_path, cli):
    """The checkpoints written before the number: the same entries, read as they always were."""
    path, out = _written_checkpoint(tmp_path, cli)
    _with_entries(out / "checkpoint.npz", format=None)
    assert cli("status", out)[0] == 0
    code, _, err = cli("run", path, "--out", out, "--quiet", "--resume")
    assert code == 0, err
