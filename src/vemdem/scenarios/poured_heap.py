"""`scenario = "poured_heap"`: a settled pack flows out from under its rising box onto a disc.

The angle of repose of a heap built by grains rolling down its own flank, beside the paper's
collapse (which measures a deposit: docs/results.md). The box around a settled pack is the hopper:
its four sides, finite rectangles (contact.walls.box_sides), rise at `source.lift_speed` (slow
against the grains' settling speed), and the grains flow out under their bottom edges onto a floor
disc of radius `disc.radius` centred under the box (the lifting-cylinder test of granular
materials, a moving source whose outlet rises with the heap). Grains that roll off the rim land on
a catch floor `disc.catch_depth` below and are left out of the heap. The run stops when every
grain is at rest (settle table), after the sides have cleared the pack.

Starts from a `pack` state file (`initial_state`) or settles the `[pack]` table first (as
pile_collapse). The angle comes from the heap's free surface as in pile_collapse (analysis.repose;
docs/repose.md); `angle_fixed_base_deg` = atan(pile_height / radius), the classical fixed-base
estimate, is beside it. Outputs in DIR: summary.json (angle_of_repose_deg,
angle_of_repose_uncertainty_deg, angle_fixed_base_deg, pile_height, heap_grains, lost_grains, ...),
heap.png (side view with the fitted slope), heap_3d.png, state.npz, and the scene outputs
(history.csv, grains.csv, walls.csv, grains.pvd, checkpoint.npz; `--resume` continues a run).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ..analysis.plots import plot_grains_3d
from ..analysis.repose import measure_pile, pile_axis, plot_heap, plot_pile, repose_headline
from ..config import ConfigError, tables
from ..config.build import scene_from, solver_options_from
from ..contact.walls import Motion, PlaneWall, box_sides, corner_mirrors, disc_wall
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
SCHEMA = tables.POURED_HEAP


def heap_centre(meta: dict, opened: str) -> tuple[float, float]:
    """Where the disc is centred: the pile's axis (under the box, or the corner of its two
    standing sides), as the collapse measures from it."""
    return tuple(pile_axis(meta, opened)[0])


def hopper_walls(meta: dict, top: float, cfg: dict) -> tuple[list, list, float]:
    """(planes, meshes, lift time): the catch floor; the disc and the box's rising sides. With
    `source.open = "corner"` the -x and -y sides stay, as infinite frictionless planes (mirror
    planes, as pile_collapse's corner), and the disc is centred on their corner."""
    (w, d), centre, floor = meta["box"], tuple(meta["centre"]), meta["floor"]
    opened = cfg["source"]["open"]
    middle = heap_centre(meta, opened)
    radius = cfg["disc"]["radius"]
    reach = np.hypot(w, d) if opened == "corner" else 0.5 * np.hypot(w, d)
    if radius <= reach:
        where = "the corner" if opened == "corner" else "its centre"
        raise ConfigError(f"disc.radius: the disc ({radius:g} m) must reach beyond the box's corners "
                          f"({reach:.3g} m from {where})")  # fmt: skip
    height = top - floor
    lift = 1.5 * height  # the sides' bottom edges end half a pack height above its top
    lift_time = lift / cfg["source"]["lift_speed"]
    rising = Motion(times=(0.0, lift_time), displacements=((0.0, 0.0, 0.0), (0.0, 0.0, lift)))
    sides = box_sides(w, d, floor, 1.1 * height, centre, rising)
    disc = disc_wall(radius, floor, middle)
    catch = PlaneWall(np.array([middle[0], middle[1], floor - cfg["disc"]["catch_depth"]]), np.array([0.0, 0.0, 1.0]),
                      name="catch floor")  # fmt: skip
    planes = [catch]
    if opened == "corner":
        sides = [side for side in sides if side.name in ("side +x", "side +y")]
        planes += corner_mirrors(w, d, floor, centre)
    return planes, [disc, *sides], lift_time


def heap_part(on_disc: np.ndarray, x: np.ndarray, vertex_grain: np.ndarray):
    """(x, vertex_grain) of the grains on the disc alone, grains renumbered 0..k-1."""
    keep = on_disc[vertex_grain]
    renumber = np.cumsum(on_disc) - 1
    return x[keep], renumber[vertex_grain[keep]]


def run(cfg: dict, out_dir: Path, base_dir=None, progress=None, resume: bool = False) -> dict:
    t_start = time.perf_counter()
    out_dir = Path(out_dir)
    initial, path = initial_state_from(cfg, base_dir, out_dir, progress, resume)
    meta = dict(initial.meta)
    planes, meshes, lift_time = hopper_walls(meta, float(initial.x[:, 2].max()), cfg)
    scene = scene_from(initial.grains, cfg, planes, meshes)
    integrator = make_integrator(solver_options_from(cfg), scene)
    settle = dict(cfg["settle"], min_time=max(cfg["settle"]["min_time"], lift_time))
    # no friction history handed over: the pack's floor plane becomes the disc's triangles, and a
    # pair key of the plane would name a disc triangle here (contact.model.pair_keys)
    identity = run_identity(cfg, SCHEMA)
    resume_here = resume and (out_dir / "checkpoint.npz").is_file()  # a run stopped in its pack stage starts here
    result = simulate(scene, integrator, out_dir, duration=max(settle["max_time"], lift_time),
                      every=cfg["output"]["every"], vtk=cfg["output"]["vtk"], identity=identity, x0=initial.x,
                      v0=initial.v, resume=resume_here, progress=progress,
                      stop=at_rest(scene, settle, integrator.lumped))  # fmt: skip
    state = result.state
    summary = run_summary("poured_heap", scene, result, t_start)
    summary.update(measure_heap(scene, state, meta, cfg["disc"]["radius"], out_dir, cfg["source"]["open"]))
    summary["source_open"] = cfg["source"]["open"]
    summary["lift_time"] = lift_time
    summary["settled"] = result.stopped_early
    summary["kinetic_ratio"] = kinetic_ratio(scene, state.v, integrator.lumped)
    summary["initial_state"] = str(path)
    summary["config_fingerprint"] = identity.fingerprint
    save_state(out_dir / "state.npz", initial.grains, state.x, state.v,
               {**meta, "scenario": "poured_heap", "time": state.t, "disc_radius": cfg["disc"]["radius"]},
               friction_arrays(state.history))  # fmt: skip
    write_json(out_dir / "summary.json", summary)
    return summary


def measure_heap(scene, state, meta: dict, radius: float, out_dir: Path, opened: str = "all") -> dict:
    """The heap on the disc (grains above it): angle, height, counts, and its pictures. A corner
    heap is measured from the corner, as pile_collapse's (analysis.repose, plan "corner")."""
    centroids = scene.grain_centroids(state.x)
    centre, floor = heap_centre(meta, opened), meta["floor"]
    reach = np.hypot(centroids[:, 0] - centre[0], centroids[:, 1] - centre[1])
    on_disc = (centroids[:, 2] > floor) & (reach < radius + scene.grain_size)
    friction = scene.contact.friction
    title = f"poured heap: {int(on_disc.sum())} grains, mu_s = {friction.mu_s:g}, mu_d = {friction.mu_d:g}"
    # measured as the pile of a box as wide as the disc (the runout it implies is not reported):
    # centred on the disc, or with its corner on the disc's centre
    box = {"box": [2 * radius, 2 * radius], "centre": [centre[0] + radius, centre[1] + radius]} \
        if opened == "corner" else {"box": [2 * radius, 2 * radius]}  # fmt: skip
    if on_disc.sum() >= 2:
        vertex_grain = scene.contact.topology.vertex_grain[: scene.n_vertices]
        repose, figures = measure_pile(centroids[on_disc], *heap_part(on_disc, state.x, vertex_grain),
                                       scene.grain_size, {**meta, **box}, opened)  # fmt: skip
    else:
        repose, figures = None, {"angle_of_repose_deg": None, "angle_of_repose_error": "no grain stayed on the disc",
                                 "pile_height": 0.0}  # fmt: skip
    if repose is not None:
        plot_pile(repose, centroids[on_disc], out_dir / "heap.png", title=title)
    else:
        plot_heap(centroids[on_disc], tuple(centre), out_dir / "heap.png", title,
                  note=f"no angle of repose: {figures['angle_of_repose_error']}",
                  plan="corner" if opened == "corner" else "round")  # fmt: skip
    plot_grains_3d(out_dir / "heap_3d.png", state.x, *scene.surface_triangles(), title=title, floor_z=floor)
    figures.pop("runout", None)  # the disc's rim bounds the heap: no runout to speak of
    return {**figures, "angle_fixed_base_deg": float(np.degrees(np.arctan2(figures["pile_height"], radius))),
            "disc_radius": radius, "heap_grains": int(on_disc.sum()), "lost_grains": int((~on_disc).sum())}  # fmt: skip
