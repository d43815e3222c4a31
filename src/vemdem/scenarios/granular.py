"""What the paper's granular scenarios (pack, pile_collapse, lid_compression) share: their config
tables and defaults, the rest criterion, the pack measures and the hand-over state file."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from ..config import ConfigError, Field, positive
from ..contact.walls import Motion, PlaneWall
from ..geometry.packing import centre_of_volume_height
from ..io.state import StateFileError, load_state
from ..scene import Scene
from .grain_compression import MATERIAL_SCHEMA, VEM_SCHEMA
from .scene import CONTACT_SCHEMA, SOLVER_SCHEMA


def with_defaults(schema: dict, **defaults) -> dict:
    """A copy of a schema table with other default values (the keys stay those of `schema`)."""
    out = dict(schema)
    for key, value in defaults.items():
        out[key] = replace(schema[key], default=value)
    return out


# The paper's sand (section 3): E = 90 GPa, nu = 0.16, 2200 kg/m^3.
PAPER_MATERIAL = with_defaults(MATERIAL_SCHEMA, E=90e9, nu=0.16, density=2200.0)

# Explicit with mass scaling: these runs follow grains for tenths of a second, where the stiff
# grains' elastic periods (~1e-7 s) would otherwise set the step (docs/results.md, docs/dynamics.md).
GRANULAR_SOLVER = with_defaults(SOLVER_SCHEMA, integrator="explicit", mass_scaling=1e6, dt_max=1e-4)

SETTLING_DAMPING = 20.0  # 1/s, mass damping while a pack settles (pack.py says why)

SETTLE_SCHEMA = {
    "kinetic_threshold": Field(
        float, 1e-3, positive, "at rest when the mean kinetic energy per grain is below this share of m g d"
    ),
    "min_time": Field(float, 0.02, lambda v: None if v >= 0 else "must be >= 0", "s before rest is checked"),
    "max_time": Field(float, 1.0, positive, "s of simulated time at most (the run stops, unsettled, then)"),
}


def common_tables(mu_s: float, mu_d: float, every: float) -> dict:
    return {
        "gravity": Field(list, [0.0, 0.0, -9.81], doc="m/s^2"),
        "material": PAPER_MATERIAL,
        "vem": VEM_SCHEMA,
        "contact": with_defaults(CONTACT_SCHEMA, mu_s=mu_s, mu_d=mu_d),
        "solver": GRANULAR_SOLVER,
        "settle": SETTLE_SCHEMA,
        "output": {
            "every": Field(float, every, positive, "simulated time between written frames (s)"),
            "vtk": Field(bool, True, doc="write the ParaView series grains.pvd"),
        },
    }


def rest_energy(scene: Scene) -> float:
    """m g d of the mean grain: the kinetic energy scale of 'at rest' (mass scaling cancels)."""
    mass = float(scene.mass.lumped.sum()) / scene.n_grains
    size = float(np.mean(np.cbrt(6.0 * scene.elements.volume / np.pi)))
    return mass * float(np.linalg.norm(scene.gravity)) * size


def at_rest(scene: Scene, settle: dict, lumped: bool):
    """stop(state) for the time loop: the mean kinetic energy per grain below kinetic_threshold
    m g d after min_time. A grain moving at v has v^2 / (2 g d) of that scale: 1e-3 is a grain
    of 1.45 mm at 5 mm/s."""
    limit = settle["kinetic_threshold"] * rest_energy(scene) * scene.n_grains

    def stop(state) -> bool:
        return state.t >= settle["min_time"] and scene.kinetic_energy(state.v, lumped) < limit

    return stop


def kinetic_ratio(scene: Scene, v: np.ndarray, lumped: bool) -> float:
    """Mean kinetic energy per grain over m g d (what `at_rest` compares with its threshold)."""
    return scene.kinetic_energy(v, lumped) / (rest_energy(scene) * scene.n_grains)


def pack_measures(scene: Scene, x: np.ndarray, box: tuple[float, float], floor: float = 0.0) -> dict:
    """pack_height: twice the height of the centre of volume above the floor (as
    geometry.packing.pack_height, which explains why); packing_fraction: grain volume over
    box x pack_height."""
    volume = scene.elements.volume
    height = centre_of_volume_height(volume, scene.grain_centroids(x)[:, 2] - floor)
    return {"pack_height": height, "packing_fraction": float(volume.sum()) / (box[0] * box[1] * height)}


def box_planes(box: tuple[float, float], centre=(0.0, 0.0), floor: float = 0.0, removed_at: float = np.inf):
    """Floor and four vertical walls; the vertical ones disappear at `removed_at`."""
    cx, cy = centre
    hx, hy = 0.5 * box[0], 0.5 * box[1]
    gone = Motion(removed_at=removed_at)
    return [
        PlaneWall(np.array([cx, cy, floor]), np.array([0.0, 0.0, 1.0]), name="floor"),
        PlaneWall(np.array([cx - hx, cy, floor]), np.array([1.0, 0.0, 0.0]), gone, "wall -x"),
        PlaneWall(np.array([cx + hx, cy, floor]), np.array([-1.0, 0.0, 0.0]), gone, "wall +x"),
        PlaneWall(np.array([cx, cy - hy, floor]), np.array([0.0, 1.0, 0.0]), gone, "wall -y"),
        PlaneWall(np.array([cx, cy + hy, floor]), np.array([0.0, -1.0, 0.0]), gone, "wall +y"),
    ]


def pack_stage_schema(pack_schema: dict) -> dict:
    """The `[pack]` table of pile_collapse and lid_compression: the pack scenario's own keys, used
    when no `initial_state` is given (the pack is then settled first, into DIR/pack)."""
    keys = ("n_grains", "seed", "grains", "box")
    table = {k: pack_schema[k] for k in keys}
    table["mu_s"] = Field(float, 0.6, lambda v: None if v >= 0 else "must be >= 0", "friction while settling")
    table["mu_d"] = Field(float, 0.5, lambda v: None if v >= 0 else "must be >= 0", "friction while settling")
    table["mass_damping"] = Field(float, SETTLING_DAMPING, lambda v: None if v >= 0 else "must be >= 0",
                                  "1/s, mass damping while settling")  # fmt: skip
    return table


def pack_config(cfg: dict) -> dict:
    """A complete `pack` config from a pile_collapse / lid_compression config's [pack] table; the
    pack settles with the same material, vem and solver settings, its own friction and the
    default normal damping (lid_compression's light damping is for the lid cycle)."""
    from .pack import SCHEMA as PACK_SCHEMA  # noqa: PLC0415 (pack imports this module)

    table = dict(cfg["pack"])
    contact = dict(cfg["contact"], mu_s=table.pop("mu_s"), mu_d=table.pop("mu_d"), damping_ratio=None)
    solver = dict(cfg["solver"], mass_damping=table.pop("mass_damping"))
    settle = {k: field.default for k, field in PACK_SCHEMA["settle"].items()}
    settle["kinetic_threshold"] = cfg["settle"]["kinetic_threshold"]
    return {"scenario": "pack", **table, "gravity": cfg["gravity"], "material": cfg["material"], "vem": cfg["vem"],
            "contact": contact, "solver": solver, "settle": settle,
            "output": {"every": PACK_SCHEMA["output"]["every"].default, "vtk": False}}  # fmt: skip


def initial_state_from(cfg: dict, base_dir, out_dir: Path, progress=None, resume: bool = False):
    """The settled pack a scenario starts from: `initial_state` when given, else a pack settled
    now into DIR/pack (kept: a resumed or repeated run with the same [pack] table reuses it)."""
    if not cfg["initial_state"]:
        from .pack import run as run_pack  # noqa: PLC0415

        pack_dir = Path(out_dir) / "pack"
        path = pack_dir / "state.npz"
        done = (pack_dir / "summary.json").is_file() and path.is_file()
        if not done:
            resume_pack = resume and (pack_dir / "checkpoint.npz").is_file()
            stage = progress and (lambda i, n, text="": progress(i, n, "pack: " + text))
            run_pack(pack_config(cfg), pack_dir, progress=stage, resume=resume_pack)
    else:
        path = Path(cfg["initial_state"])
        if not path.is_absolute() and base_dir is not None and not path.exists():
            path = Path(base_dir) / path  # relative to the config file when not to the working directory
    try:
        state = load_state(path)
    except StateFileError as exc:
        raise ConfigError(str(exc)) from None
    if "box" not in state.meta:
        raise ConfigError(f"initial_state: {path} does not come from a pack run (no box recorded)")
    return state, path
