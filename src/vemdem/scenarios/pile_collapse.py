"""`scenario = "pile_collapse"`: a settled pack loses its four walls and spreads on the floor,
or (`[collapse] open = "front"`) loses only its +x wall and runs out along the channel the others
form, leaving a wedge on the back wall (a two-dimensional collapse), or (`open = "corner"`) loses
its +x and +y walls and spreads into the quadrant of the other two, which stay as frictionless
mirror planes: a quarter of the heap that a column four times as large leaves.

Starts from a `pack` state file (`initial_state = "path/state.npz"`, relative to the config file)
or settles the `[pack]` table first, and runs until the pile is at rest (settle table) or
settle.max_time. The angle of repose is measured from the final free surface
(analysis.repose: a line fitted to the tops of the surface grains on the flank, its uncertainty
from the spread between azimuthal sectors and the fit; docs/repose.md). Outputs in DIR:
summary.json (angle_of_repose_deg, angle_of_repose_uncertainty_deg, pile_height, runout, ...),
pile.png (side view with the fitted slope), pile_3d.png (3D view), state.npz (the final pile), and the scene outputs
(history.csv, grains.csv, walls.csv, grains.pvd, checkpoint.npz; `--resume` continues a run).
"""

from __future__ import annotations

import time
from pathlib import Path

from ..analysis.plots import plot_grains_3d
from ..analysis.repose import measure_pile, pile_axis, plot_heap, plot_pile, repose_headline
from ..config import tables
from ..config.build import scene_from, solver_options_from
from ..contact.walls import box_walls, corner_mirrors
from ..driver.loop import simulate
from ..driver.summary import run_summary
from ..io.results import write_json
from ..io.state import friction_arrays, save_state
from ..solver.api import make_integrator
from .granular import at_rest, kinetic_ratio
from .identity import run_identity
from .pack import initial_state_from

RESUMABLE = True  # `vemdem run ... --resume` continues from DIR/checkpoint.npz
headline = repose_headline  # the line `vemdem run` ends with
SCHEMA = tables.PILE_COLLAPSE


def standing_walls(meta: dict, opened: str) -> list:
    """The walls left at t = 0: the floor; for a channel ("front") the back (-x) and side walls too;
    for a corner the -x and -y walls, frictionless (mirror planes: the grains along them move as
    if their mirror images were there)."""
    box = (*meta["box"], meta["floor"], tuple(meta["centre"]))
    floor, back, _front, side_lo, side_hi = box_walls(*box)
    if opened == "front":
        return [floor, back, side_lo, side_hi]
    if opened == "corner":
        return [floor, *corner_mirrors(*box)]
    return [floor]


def run(cfg: dict, out_dir: Path, base_dir=None, progress=None, resume: bool = False) -> dict:
    t_start = time.perf_counter()
    out_dir = Path(out_dir)
    initial, path = initial_state_from(cfg, base_dir, out_dir, progress, resume)
    meta = initial.meta
    opened = cfg["collapse"]["open"]
    scene = scene_from(initial.grains, cfg, standing_walls(meta, opened))
    integrator = make_integrator(solver_options_from(cfg), scene)
    settle = cfg["settle"]
    identity = run_identity(cfg, SCHEMA)
    resume_here = resume and (out_dir / "checkpoint.npz").is_file()  # a run stopped in its pack stage starts here
    result = simulate(scene, integrator, out_dir, duration=settle["max_time"], every=cfg["output"]["every"],
                      vtk=cfg["output"]["vtk"], identity=identity, x0=initial.x, v0=initial.v,
                      friction0=initial.friction, resume=resume_here, progress=progress,
                      stop=at_rest(scene, settle, integrator.lumped))  # fmt: skip
    state = result.state
    centroids = scene.grain_centroids(state.x)
    repose, figures = measure_pile(centroids, state.x, scene.contact.topology.vertex_grain[: scene.n_vertices],
                                   scene.grain_size, meta, opened)  # fmt: skip
    friction = scene.contact.friction
    title = f"{scene.n_grains} grains, mu_s = {friction.mu_s:g}, mu_d = {friction.mu_d:g}"
    if repose is not None:
        plot_pile(repose, centroids, out_dir / "pile.png", title=title)
    else:
        centre, plan, _, _ = pile_axis(meta, opened)
        plot_heap(centroids, centre, out_dir / "pile.png", title,
                  note=f"no angle of repose: {figures['angle_of_repose_error']}", plan=plan)  # fmt: skip
    plot_grains_3d(out_dir / "pile_3d.png", state.x, *scene.surface_triangles(), title=f"the heap: {title}",
                   floor_z=meta["floor"])  # fmt: skip
    save_state(out_dir / "state.npz", initial.grains, state.x, state.v,
               {**meta, "scenario": "pile_collapse", "time": state.t}, friction_arrays(state.history))  # fmt: skip
    summary = run_summary("pile_collapse", scene, result, t_start)
    summary.update(figures)
    summary["collapse_open"] = cfg["collapse"]["open"]
    summary["settled"] = result.stopped_early
    summary["kinetic_ratio"] = kinetic_ratio(scene, state.v, integrator.lumped)
    summary["initial_state"] = str(path)
    summary["config_fingerprint"] = identity.fingerprint
    write_json(out_dir / "summary.json", summary)
    return summary
