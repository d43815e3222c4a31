"""`scenario = "pack"`: sand grains settle by gravity into an open box (the paper's section 3).

N random sand grains (seeded) are placed without overlap in a column above the box
(geometry.packing.column_packing), fall and settle until the mean kinetic energy per grain is
below `settle.kinetic_threshold` m g d (scenarios.granular.at_rest). Outputs in DIR: state.npz
(the settled pack, the `initial_state` of pile_collapse and lid_compression), summary.json
(n_grains, pack_height, packing_fraction, settled, ...) and the scene outputs (history.csv,
grains.csv, walls.csv, grains.pvd, checkpoint.npz; `--resume` continues a run).
"""

from __future__ import annotations

import time
from pathlib import Path

from ..config import REQUIRED, ConfigError, Field, positive
from ..geometry.packing import column_packing
from ..io.results import write_json
from ..io.state import save_state
from .granular import SETTLING_DAMPING, at_rest, box_planes, common_tables, kinetic_ratio, pack_measures, with_defaults
from .scene import config_fingerprint, run_summary, scene_from, simulate


def _fraction(v):
    return None if 0 <= v < 1 else "must be in [0, 1)"


SCHEMA = {
    "scenario": Field(("pack",), REQUIRED),
    "n_grains": Field(int, 515, positive, "number of grains"),
    "seed": Field(int, 0, doc="seeds the sizes, shapes, orientations and positions"),
    "grains": {
        "size": Field(float, 1.45e-3, positive, "mean equivalent diameter (m)"),
        "size_spread": Field(float, 0.1, _fraction, "sizes uniform in size (1 +- size_spread)"),
        "vertices": Field(int, 30, lambda v: None if v >= 8 else "must be >= 8", "vertices per grain"),
        "elongation": Field(float, 0.8, lambda v: None if 0 < v <= 1 else "must be in (0, 1]"),
        "flatness": Field(float, 0.8, lambda v: None if 0 < v <= 1 else "must be in (0, 1]"),
        "roughness": Field(float, 0.15, _fraction),
        "clearance": Field(float, 0.02, lambda v: None if v >= 0 else "must be >= 0",
                           "gap between grains in the column, in circumscribed radii"),  # fmt: skip
    },
    "box": {
        "width": Field(float, 8e-3, positive, "x side (m)"),
        "depth": Field(float, 8e-3, positive, "y side (m)"),
    },
    **common_tables(mu_s=0.6, mu_d=0.5, every=5e-3),
}
# Settling is preparation, not the experiment: a mass damping of 20 1/s caps the fall at about
# g / 20 = 0.5 m/s, so grains from the top of a 100 mm column do not hit the pack at 1.4 m/s,
# where the barrier stiffens and the explicit step fell to 6e-7 s (docs/results.md)
SCHEMA["solver"] = with_defaults(SCHEMA["solver"], mass_damping=SETTLING_DAMPING)


def place(cfg: dict):
    g = cfg["grains"]
    shape = {"n_vertices": g["vertices"], "elongation": g["elongation"], "flatness": g["flatness"],
             "roughness": g["roughness"]}  # fmt: skip
    try:
        return column_packing(cfg["n_grains"], size=g["size"], size_spread=g["size_spread"],
                              box=(cfg["box"]["width"], cfg["box"]["depth"]), clearance=g["clearance"],
                              seed=cfg["seed"], shape_params=shape)  # fmt: skip
    except ValueError as exc:
        raise ConfigError(f"grains: {exc}") from None


def run(cfg: dict, out_dir: Path, base_dir=None, progress=None, resume: bool = False) -> dict:
    t_start = time.perf_counter()
    out_dir = Path(out_dir)
    packing = place(cfg)
    scene = scene_from(packing.grains, cfg, box_planes(packing.box))
    lumped = cfg["solver"]["integrator"] == "explicit"
    settle = cfg["settle"]
    result = simulate(scene, cfg["solver"], out_dir, duration=settle["max_time"], every=cfg["output"]["every"],
                      vtk=cfg["output"]["vtk"], fingerprint=config_fingerprint(cfg), resume=resume,
                      progress=progress, stop=at_rest(scene, settle, lumped))  # fmt: skip
    state = result.state
    measures = pack_measures(scene, state.x, packing.box)
    meta = {
        "scenario": "pack",
        "box": list(packing.box),
        "centre": list(packing.centre),
        "floor": packing.floor,
        "grain_size": cfg["grains"]["size"],
        "seed": cfg["seed"],
        "time": state.t,
        **measures,
    }
    save_state(out_dir / "state.npz", packing.grains, state.x, state.v, meta)
    summary = run_summary("pack", cfg, scene, result, t_start)
    summary.update(measures)
    summary["settled"] = result.stopped_early
    summary["kinetic_ratio"] = kinetic_ratio(scene, state.v, lumped)
    summary["column_height"] = packing.column_height
    summary["state_file"] = "state.npz"
    write_json(out_dir / "summary.json", summary)
    return summary
