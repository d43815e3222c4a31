"""`scenario = "pack"`: sand grains settle by gravity into an open box (the paper's section 3).

N random sand grains (seeded) are placed without overlap in a column above the box
(geometry.packing.column_packing), fall and settle until the mean kinetic energy per grain is
below `settle.kinetic_threshold` m g d (scenarios.granular.at_rest). Outputs in DIR: state.npz
(the settled pack, the `initial_state` of pile_collapse and lid_compression), summary.json
(n_grains, pack_height, packing_fraction, settled, ...) and the scene outputs (history.csv,
grains.csv, walls.csv, grains.pvd, checkpoint.npz; `--resume` continues a run).

The pack stage of pile_collapse and lid_compression (`[pack]` instead of `initial_state`) runs
here too (`initial_state_from`): settled into DIR/pack, reused only when its summary carries the
fingerprint of the same pack config, resumed with the run.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from ..analysis.pack import pack_measures
from ..analysis.plots import plot_grains_3d
from ..config import ConfigError, apply_schema, tables
from ..config.build import resolve_path, scene_from, solver_options_from
from ..config.tables import SETTLING_DAMPING
from ..contact.walls import box_walls
from ..driver.checkpoint import CheckpointError, step_changes
from ..driver.loop import simulate
from ..driver.summary import run_summary
from ..geometry.packing import SurfaceShapes, column_packing
from ..geometry.polyhedron import GeometryError
from ..io.results import write_json
from ..io.state import GranularState, StateFileError, friction_arrays, load_state, save_state
from ..io.surfaces import load_surface
from ..solver.api import make_integrator
from .granular import at_rest, kinetic_ratio
from .identity import run_identity

RESUMABLE = True  # `vemdem run ... --resume` continues from DIR/checkpoint.npz
SCHEMA = tables.PACK


def grain_maker(grains: dict, base_dir=None):
    """The `[grains]` table's maker: a built-in shape's name, or the user's surfaces (shape =
    'file') as a SurfaceShapes. A surface that is no valid grain is a ConfigError naming it."""
    if grains["shape"] != "file":
        return grains["shape"]
    surfaces = []
    for name in grains["files"]:
        try:
            surfaces.append(load_surface(resolve_path(name, base_dir)))
        except GeometryError as exc:
            raise ConfigError(f"grains.files: {exc}") from None
    return SurfaceShapes(surfaces, grains["fractions"] or None)


def place(cfg: dict, base_dir=None):
    g = cfg["grains"]
    shape = {"n_vertices": g["vertices"], "elongation": g["elongation"], "flatness": g["flatness"],
             "roughness": g["roughness"]}  # fmt: skip
    make = grain_maker(g, base_dir)
    try:
        return column_packing(cfg["n_grains"], size=g["size"], size_spread=g["size_spread"],
                              box=(cfg["box"]["width"], cfg["box"]["depth"]), clearance=g["clearance"],
                              seed=cfg["seed"], shape_params=shape, shape=make)  # fmt: skip
    except ValueError as exc:
        raise ConfigError(f"grains: {exc}") from None


def grain_files_resolved(pack_cfg: dict, base_dir) -> dict:
    """A pack config whose grains' files are absolute: a pack stage settles where its config file
    is not, and its fingerprint then names the same files from any folder."""
    files = pack_cfg["grains"].get("files") or []
    if not files or base_dir is None:
        return pack_cfg
    absolute = [str(resolve_path(f, Path(base_dir).resolve())) for f in files]
    return {**pack_cfg, "grains": {**pack_cfg["grains"], "files": absolute}}


def run(cfg: dict, out_dir: Path, base_dir=None, progress=None, resume: bool = False) -> dict:
    t_start = time.perf_counter()
    out_dir = Path(out_dir)
    packing = place(cfg, base_dir)
    scene = scene_from(packing.grains, cfg, box_walls(*packing.box))
    integrator = make_integrator(solver_options_from(cfg), scene)
    settle = cfg["settle"]
    identity = run_identity(cfg, SCHEMA)
    result = simulate(scene, integrator, out_dir, duration=settle["max_time"], every=cfg["output"]["every"],
                      vtk=cfg["output"]["vtk"], identity=identity, resume=resume, progress=progress,
                      stop=at_rest(scene, settle, integrator.lumped))  # fmt: skip
    state = result.state
    measures = pack_measures(scene.bodies.volume, scene.grain_centroids(state.x), packing.box)
    meta = {
        "scenario": "pack",
        "box": list(packing.box),
        "centre": list(packing.centre),
        "floor": packing.floor,
        "grain_size": cfg["grains"]["size"],
        "seed": cfg["seed"],
        "time": state.t,
        "mass_scaling": scene.mass_scaling,
        **measures,
    }
    save_state(out_dir / "state.npz", packing.grains, state.x, state.v, meta, friction_arrays(state.history))
    plot_grains_3d(out_dir / "pack_3d.png", state.x, *scene.surface_triangles(),
                   title=f"the settled pack: {scene.n_grains} grains", floor_z=packing.floor)  # fmt: skip
    summary = run_summary("pack", scene, result, t_start)
    summary.update(measures)
    summary["settled"] = result.stopped_early
    summary["kinetic_ratio"] = kinetic_ratio(scene, state.v, integrator.lumped)
    summary["column_height"] = packing.column_height
    summary["state_file"] = "state.npz"
    summary["config_fingerprint"] = identity.fingerprint
    write_json(out_dir / "summary.json", summary)
    return summary


# ---------------------------------------------------------------------------- the pack stage
def pack_config(cfg: dict, reference_force: float | None = None) -> dict:
    """A complete `pack` config from a scenario's [pack] table; the pack settles with the same
    material, vem and solver settings, its own friction and the default normal damping
    (lid_compression's light damping is for the lid cycle), and the weight's contact law unless
    `reference_force` names the law the test will load it with (a pack settled under the weight's
    law meets a stiffer law with every contact's force multiplied by their ratio) or the test's
    law is the material's (`[contact] law = "material"` without a reference force: the pack
    settles under it, one law throughout)."""
    table = dict(cfg["pack"])
    material = cfg["contact"].get("law", "weight") == "material" and cfg["contact"]["reference_force"] is None
    contact = dict(cfg["contact"], mu_s=table.pop("mu_s"), mu_d=table.pop("mu_d"), damping_ratio=None,
                   reference_force=reference_force, law="material" if material else "weight",
                   layer_modulus=cfg["contact"].get("layer_modulus") if material else None)  # fmt: skip
    solver = dict(cfg["solver"], mass_damping=table.pop("mass_damping"))
    model = cfg["model"]
    if table.pop("model") == "rigid":
        model, solver = {**model, "grains": "rigid"}, dict(solver, integrator="explicit")
    raw = {"scenario": "pack", **table, "gravity": cfg["gravity"], "material": cfg["material"], "vem": cfg["vem"],
           "model": model, "contact": contact, "solver": solver,
           "settle": {"kinetic_threshold": cfg["settle"]["kinetic_threshold"]}, "output": {"vtk": False}}  # fmt: skip
    # through the pack's schema: every key it leaves out (a value None: not set) takes the pack
    # scenario's own default, and a key the pack does not know is an error here, not a silent extra
    return apply_schema(_set_only(raw), SCHEMA)


def _set_only(table: dict) -> dict:
    """`table` without its keys whose value is None (not set), in its inner tables too."""
    return {k: _set_only(v) if isinstance(v, dict) else v for k, v in table.items() if v is not None}


def _stage_fingerprint(pack_dir: Path):
    try:
        return json.loads((pack_dir / "summary.json").read_text()).get("config_fingerprint")
    except (OSError, ValueError):
        return None


def _steps_only(stage_dir: Path, identity) -> bool:
    """Whether a finished stage's config differs from `identity` in step-control keys alone."""
    try:
        step_changes(stage_dir / "checkpoint.npz", identity)
    except CheckpointError:
        return False
    return True


def settle_stage(pack_cfg: dict, pack_dir: Path, progress=None, resume: bool = False) -> None:
    """Settle a pack stage into pack_dir, unless it holds one settled from the same pack config
    (kept); one from another config is refused. An interrupted stage is continued by resume. A
    resume that changed the step control only (driver.checkpoint.step_changes) keeps a settled
    pack as it is: the change is for the stage that goes on, and recorded there."""
    pack_dir = Path(pack_dir)
    if (pack_dir / "summary.json").is_file():
        identity = run_identity(pack_cfg, SCHEMA)
        if not (identity.accepts(_stage_fingerprint(pack_dir)) or resume and _steps_only(pack_dir, identity)):
            raise ConfigError(f"pack: {pack_dir} holds a pack settled from a different [pack] table or material; "
                              "use another --out, or --overwrite to settle it again")  # fmt: skip
        return
    resume_pack = resume and (pack_dir / "checkpoint.npz").is_file()
    stage = progress and (lambda i, n, text="": progress(i, n, "pack: " + text))
    run(pack_cfg, pack_dir, progress=stage, resume=resume_pack)


def initial_state_from(cfg: dict, base_dir, out_dir: Path, progress=None, resume: bool = False,
                       pack_cfg: dict | None = None):  # fmt: skip
    """The settled pack a scenario starts from: `initial_state` (relative to the config file) when
    given, else a pack settled now into DIR/pack from `pack_cfg` (by default pack_config(cfg); a
    scenario whose pack settles otherwise names it as its module's `pack_config_for`, which a
    sweep's shared packs use too). A finished pack stage is reused only when it was made by the
    same pack config; an interrupted one is continued by --resume."""
    if not cfg["initial_state"]:
        pack_dir = Path(out_dir) / "pack"
        path = pack_dir / "state.npz"
        pack_cfg = grain_files_resolved(pack_cfg if pack_cfg is not None else pack_config(cfg), base_dir)
        settle_stage(pack_cfg, pack_dir, progress, resume)
    else:
        path = resolve_path(cfg["initial_state"], base_dir)
    try:
        state = load_state(path)
    except StateFileError as exc:
        raise ConfigError(str(exc)) from None
    missing = [key for key in ("box", "floor", "centre") if key not in state.meta]
    if missing:
        raise ConfigError(f"initial_state: {path} does not come from a pack run (no {', '.join(missing)} recorded)")
    if state.meta.get("mass_scaling", 1.0) != cfg["solver"]["mass_scaling"]:
        state = reequilibrated(state, cfg, Path(out_dir) / "reequilibrate", progress, resume)
    return state, path


def reequilibrated(state: GranularState, cfg: dict, folder: Path, progress=None, resume: bool = False):
    """The pack settled again in its box at this run's mass scaling: a pack carries the strain of
    the weight it settled under (weight, contact forces and strain all scale with the mass
    scaling), so a run at another scaling would start from grains strained for other loads. Done
    once into DIR/reequilibrate, reused when its summary carries the same fingerprint, resumed
    with the run."""
    meta = state.meta
    stage = dict(cfg, settle=dict(cfg["settle"], min_time=0.0), solver=dict(cfg["solver"], mass_damping=SETTLING_DAMPING))
    identity = run_identity({"reequilibrate": stage, "pack_time": meta.get("time"), "seed": meta.get("seed")},
                            solver_at="reequilibrate.solver")  # fmt: skip
    if (folder / "summary.json").is_file():
        if identity.accepts(_stage_fingerprint(folder)) or resume and _steps_only(folder, identity):
            return load_state(folder / "state.npz")
    scene = scene_from(state.grains, stage, box_walls(*meta["box"], meta["floor"], tuple(meta["centre"])))
    integrator = make_integrator(solver_options_from(stage), scene)
    label = progress and (lambda i, n, text="": progress(i, n, "re-equilibrate: " + text))
    # lid_compression's output table has no `every` (its frames follow the lid): the pack's default
    every = cfg["output"].get("every", SCHEMA["output"]["every"].default)
    result = simulate(scene, integrator, folder, duration=stage["settle"]["max_time"], every=every,
                      vtk=False, identity=identity, x0=state.x, v0=np.zeros_like(state.v),
                      friction0=state.friction, resume=resume and (folder / "checkpoint.npz").is_file(),
                      progress=label, stop=at_rest(scene, stage["settle"], integrator.lumped))  # fmt: skip
    new_meta = {**meta, "mass_scaling": scene.mass_scaling, "reequilibrated_from": meta.get("mass_scaling", 1.0)}
    save_state(folder / "state.npz", state.grains, result.state.x, result.state.v, new_meta,
               friction_arrays(result.state.history))  # fmt: skip
    summary = run_summary("reequilibrate", scene, result)
    summary.update(settled=result.stopped_early, config_fingerprint=identity.fingerprint)
    write_json(folder / "summary.json", summary)
    return load_state(folder / "state.npz")
