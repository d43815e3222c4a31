"""`scenario = "pile_collapse"`: a settled pack loses its four walls and spreads on the floor.

Starts from a `pack` state file (`initial_state = "path/state.npz"`, relative to the working
directory or to the config file) and runs until the pile is at rest (settle table) or
settle.max_time. The angle of repose is measured from the final free surface
(analysis.repose: a line fitted to the tops of the surface grains on the flank, its uncertainty
from the spread between azimuthal sectors and the fit; docs/repose.md). Outputs in DIR:
summary.json (angle_of_repose_deg, angle_of_repose_uncertainty_deg, pile_height, runout, ...),
pile.png (side view with the fitted slope), state.npz (the final pile), and the scene outputs
(history.csv, grains.csv, walls.csv, grains.pvd, checkpoint.npz; `--resume` continues a run).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ..analysis.repose import angle_of_repose, plot_heap, plot_pile
from ..config import REQUIRED, Field
from ..io.results import write_json
from ..io.state import save_state
from .granular import (
    at_rest,
    box_planes,
    common_tables,
    initial_state_from,
    kinetic_ratio,
    pack_stage_schema,
    with_defaults,
)
from .pack import SCHEMA as PACK_SCHEMA
from .scene import config_fingerprint, run_summary, scene_from, simulate

SCHEMA = {
    "scenario": Field(("pile_collapse",), REQUIRED),
    "initial_state": Field(str, "", doc="state.npz written by a pack run [settle the [pack] table first]"),
    "pack": pack_stage_schema(PACK_SCHEMA),
    **common_tables(mu_s=0.6, mu_d=0.5, every=5e-3),
}
SCHEMA["settle"] = with_defaults(SCHEMA["settle"], min_time=0.05)  # the pile must first start to move


def measure_pile(scene, x, meta: dict):
    """Angle of repose (when the heap has a flank to fit), pile height and runout at positions x.
    pile_height: highest grain top above the floor; runout: largest horizontal distance of a grain
    centroid from the box axis, minus the box's half width (as analysis.repose measures them, but
    also for a heap too flat for an angle)."""
    n = scene.n_vertices
    centroids = scene.grain_centroids(x)
    centre = tuple(meta.get("centre", (0.0, 0.0)))
    floor = meta.get("floor", 0.0)
    figures = {
        "pile_height": float(x[:, 2].max() - floor),
        "runout": float(np.hypot(centroids[:, 0] - centre[0], centroids[:, 1] - centre[1]).max()) - 0.5 * min(meta["box"]),
    }  # fmt: skip
    size = float(np.mean(np.cbrt(6.0 * scene.elements.volume / np.pi)))
    try:
        result = angle_of_repose(centroids, size, vertices=x, vertex_grain=scene.contact.topology.vertex_grain[:n],
                                 floor=floor, centre=centre)  # fmt: skip
    except ValueError as exc:
        return None, {"angle_of_repose_deg": float("nan"), "angle_of_repose_error": str(exc), **figures}
    return result, {
        "angle_of_repose_deg": result.angle_deg,
        "angle_of_repose_uncertainty_deg": result.uncertainty_deg,
        **figures,
        "surface_plan": result.plan,
    }


def run(cfg: dict, out_dir: Path, base_dir=None, progress=None, resume: bool = False) -> dict:
    t_start = time.perf_counter()
    out_dir = Path(out_dir)
    initial, path = initial_state_from(cfg, base_dir, out_dir, progress, resume)
    meta = initial.meta
    # the four walls are gone from t = 0: only the floor remains
    floor = box_planes(tuple(meta["box"]), tuple(meta["centre"]), meta["floor"])[:1]
    scene = scene_from(initial.grains, cfg, floor)
    lumped = cfg["solver"]["integrator"] == "explicit"
    settle = cfg["settle"]
    result = simulate(scene, cfg["solver"], out_dir, duration=settle["max_time"], every=cfg["output"]["every"],
                      vtk=cfg["output"]["vtk"], fingerprint=config_fingerprint(cfg), x0=initial.x, v0=initial.v,
                      resume=resume, progress=progress, stop=at_rest(scene, settle, lumped))  # fmt: skip
    state = result.state
    repose, figures = measure_pile(scene, state.x, meta)
    mu = cfg["contact"]
    title = f"{scene.n_grains} grains, mu_s = {mu['mu_s']:g}, mu_d = {mu['mu_s'] if mu['mu_d'] is None else mu['mu_d']:g}"
    if repose is not None:
        plot_pile(repose, scene.grain_centroids(state.x), out_dir / "pile.png", title=title)
    else:
        plot_heap(scene.grain_centroids(state.x), tuple(meta["centre"]), out_dir / "pile.png", title,
                  note=f"no angle of repose: {figures['angle_of_repose_error']}")  # fmt: skip
    save_state(out_dir / "state.npz", initial.grains, state.x, state.v, {**meta, "scenario": "pile_collapse",
                                                                          "time": state.t})  # fmt: skip
    summary = run_summary("pile_collapse", cfg, scene, result, t_start)
    summary.update(figures)
    summary["settled"] = result.stopped_early
    summary["kinetic_ratio"] = kinetic_ratio(scene, state.v, lumped)
    summary["initial_state"] = str(path)
    write_json(out_dir / "summary.json", summary)
    return summary
