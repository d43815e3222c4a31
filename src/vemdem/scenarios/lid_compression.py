"""`scenario = "lid_compression"`: a rigid lid presses a settled pack and lifts off again (the
paper's Fig. 7).

The pack stays in its box (floor and four walls). A horizontal lid starts at `lid.start` above
the floor (7 mm), moves down at `lid.speed` to `lid.end` (4.9 mm) and back up at the same speed.
strain = (lid.start - lid height) / lid.start, force = the vertical force of the grains on the
lid (N, positive when pushed up). Outputs in DIR: force_strain.csv (header `phase,strain,force`,
one row per frame; phase `load` or `unload`), force_strain.png, summary.json (peak_force,
hysteresis_energy, residual_strain, ...; analysis.force_strain says how each is measured; also
pack_weight (N, at the run's density: mass scaling included), residual_force = 0.01 of it and
residual_strain_absolute, the strain where the unloading force falls to residual_force: one force
to compare runs whose peaks differ by orders of magnitude in pack weights; spring_back, what the
pack gave back from the turn to where the lid let go of it, split into the grains' deformation,
the contact layer's gaps and the grains' rearrangement), turn_state.npz and release_state.npz (the
pack at those two frames, in the `initial_state` format),
fluctuations.csv and fluctuations.png (the grains' velocity fluctuations and the inertia number
per frame: how quasi-static the cycle was, analysis.fluctuations) and the scene outputs
(walls.csv has the lid's force at every frame; `--resume` continues a run).
"""

from __future__ import annotations

import time
import warnings
from pathlib import Path

import numpy as np

from ..analysis.fluctuations import fluctuation_figures, lid_fluctuations, plot_fluctuations, write_fluctuations_csv
from ..analysis.force_strain import RESIDUAL_PACK_WEIGHTS, cycle_figures, plot_force_strain, write_force_strain_csv
from ..analysis.spring_back import PARTS, branch_strain_split, spring_back_shares
from ..config import ConfigError, tables
from ..config.build import MassScalingWarning, scene_from, solver_options_from
from ..contact.walls import Motion, PlaneWall, box_walls
from ..driver.loop import simulate
from ..driver.summary import run_summary
from ..io.results import wall_force_record, write_json
from ..io.state import StateFileError, friction_arrays, load_state, save_state
from ..solver.api import make_integrator
from .identity import run_identity
from .pack import initial_state_from

RESUMABLE = True  # `vemdem run ... --resume` continues from DIR/checkpoint.npz
SCHEMA = tables.LID_COMPRESSION
TURN_STATE = "turn_state.npz"  # the pack at the lid's turning point (io.state format)
RELEASE_STATE = "release_state.npz"  # the pack where the lid lets go of it (spring_back below)
# The grains' own deformation's share of the spring-back above which a mass-scaled run says so: the
# 515-grain pack's was 29-31 % at mass scaling 1e6 and 0 at the real density (docs/results.md)
GRAINS_SPRING_BACK = 0.1


def lid_wall(lid: dict, centre) -> tuple[PlaneWall, float]:
    """The lid (normal down) and the duration of the cycle."""
    half = (lid["start"] - lid["end"]) / lid["speed"]
    motion = Motion((0.0, half, 2.0 * half), ((0.0, 0.0, 0.0), (0.0, 0.0, lid["end"] - lid["start"]), (0.0, 0.0, 0.0)))
    point = np.array([centre[0], centre[1], lid["start"]])
    return PlaneWall(point, np.array([0.0, 0.0, -1.0]), motion, "lid"), 2.0 * half


def lid_curve(walls_csv: Path, lid: PlaneWall, start: float, turn: float):
    """(phase, strain, force) of every frame, from the lid's rows of walls.csv: the one record
    that holds every frame of a run resumed from a checkpoint (the loop truncates it to the
    checkpoint's frame and appends), where frames kept in memory would start at the resume."""
    times, force = wall_force_record(walls_csv, lid.name)
    height = start + np.array([lid.motion.displacement(t)[2] for t in times])
    phase = np.where(times <= turn * (1 + 1e-12), "load", "unload")
    return phase, (start - height) / start, force


def _fluctuations(out_dir: Path, scene, lid: PlaneWall, start: float, meta: dict) -> dict:
    """fluctuations.csv and .png: how far from quasi-static the cycle was (analysis.fluctuations)."""
    area = float(meta["box"][0]) * float(meta["box"][1])
    rows = lid_fluctuations(out_dir / "grains.csv", out_dir / "walls.csv", lid, start, meta["floor"], area,
                            scene.grain_size, scene.material.density)  # fmt: skip
    write_fluctuations_csv(out_dir / "fluctuations.csv", rows)
    speed = abs(float(lid.motion.velocity(0.0)[2]))
    plot_fluctuations(rows, out_dir / "fluctuations.png", f"{scene.n_grains} grains, lid speed {speed:.3g} m/s")
    return fluctuation_figures(rows)


def lid_index(scene, lid: PlaneWall) -> int:
    """The lid's row in ContactResult.wall_reactions (mesh walls first, then the planes)."""
    return scene.contact.wall_names.index(lid.name)


def _state_keeper(out_dir: Path, grains, meta: dict, n_load: int, lid: int, release_force: float):
    """The frame hook that keeps the pack at the lid's turn (frame n_load) and where it lets go of
    the pack: the first unloading frame whose lid force is at most release_force."""

    def keep(frame, state, contact):
        released = frame > n_load and contact.wall_reactions[lid][2] <= release_force
        if frame == n_load or (released and not (out_dir / RELEASE_STATE).is_file()):
            save_state(out_dir / (TURN_STATE if frame == n_load else RELEASE_STATE), grains, state.x, state.v,
                       {**meta, "time": state.t}, friction_arrays(state.history))  # fmt: skip

    return keep


def spring_back(scene, out_dir: Path, end) -> dict:
    """What the pack gave back from the lid's turn to where the lid let go of it (`to` = "release",
    release_state.npz), or to the cycle's end (`to` = "end") where it never did: the zz component
    of the best-fit strain of the grains' branch vectors ("branch_strain", positive: the pack grew)
    and its exact split into the grains' deformation, the contact layer's gaps, the contacts'
    tangential motion and the grains' rotations (analysis.spring_back), over the grain-to-grain
    contacts at the turn."""
    if not (out_dir / TURN_STATE).is_file():
        return {"error": f"no {TURN_STATE}: the run did not keep the lid's turn (a run resumed from a folder that an "
                         f"older vemdem wrote)"}  # fmt: skip
    try:
        turn = load_state(out_dir / TURN_STATE)
        t = float(turn.meta["time"])
        if (out_dir / RELEASE_STATE).is_file():
            release = load_state(out_dir / RELEASE_STATE)
            to, t_to, x_to = "release", float(release.meta["time"]), release.x
        else:
            to, t_to, x_to = "end", float(end.t), end.x
        records = scene.contact.grain_contacts(turn.x, t)
        parts = branch_strain_split(scene.bodies.reference, scene.bodies.vertex_ptr, turn.x, x_to, *records)
    except (StateFileError, ValueError) as exc:
        return {"error": str(exc)}
    out = {"to": to, "time_turn": t, "time_to": t_to, "records": len(records[0]),
           "branch_strain": float(parts["total"][2, 2])}  # fmt: skip
    out.update({name: float(parts[name][2, 2]) for name in PARTS})
    return out


def warn_if_grains_spring_back(scene, back: dict) -> None:
    """A mass-scaled run whose grains gave back more than GRAINS_SPRING_BACK of the pack's spring-back
    themselves: their elasticity, scaled with the loads, is in its residual strain and hysteresis."""
    shares = spring_back_shares(back)
    if scene.mass_scaling == 1.0 or shares is None:
        return
    share = shares["deformation"]
    if share > GRAINS_SPRING_BACK:
        warnings.warn(MassScalingWarning(
            f"solver.mass_scaling = {scene.mass_scaling:g}: the grains' own elasticity gave back {share:.0%} of what "
            f"the pack gave back after the lid turned (summary.json spring_back), so the residual strain and the "
            f"hysteresis hold it; at the real density that share was below 0.01 % in the 515-grain pack "
            f"(docs/results.md, \"What the spring-back is made of\")"), stacklevel=2)  # fmt: skip


def pack_weight(scene) -> float:
    """The grains' weight (N) at the scene's density, mass scaling included."""
    return float(np.sum(scene.bodies.body_mass) * np.linalg.norm(scene.gravity))


def run(cfg: dict, out_dir: Path, base_dir=None, progress=None, resume: bool = False) -> dict:
    t_start = time.perf_counter()
    out_dir = Path(out_dir)
    initial, path = initial_state_from(cfg, base_dir, out_dir, progress, resume)
    meta = initial.meta
    lid, duration = lid_wall(cfg["lid"], meta["centre"])
    top = float(initial.x[:, 2].max()) - meta["floor"]
    if top >= cfg["lid"]["start"]:
        raise ConfigError(f"lid.start: the pack reaches {top * 1e3:.3g} mm above the floor, above the lid's start "
                          f"{cfg['lid']['start'] * 1e3:.3g} mm (settle fewer grains or raise lid.start)")  # fmt: skip
    scene = scene_from(initial.grains, cfg, box_walls(*meta["box"], meta["floor"], tuple(meta["centre"])) + [lid])
    integrator = make_integrator(solver_options_from(cfg), scene)
    every = 0.5 * duration / cfg["lid"]["frames"]
    identity = run_identity(cfg, SCHEMA)
    resume_here = resume and (out_dir / "checkpoint.npz").is_file()  # a run stopped in its pack stage starts here
    if not resume_here:  # never another run's turn or release
        for name in (TURN_STATE, RELEASE_STATE):
            (out_dir / name).unlink(missing_ok=True)
    weight = pack_weight(scene)
    residual_force = RESIDUAL_PACK_WEIGHTS * weight
    keep_states = _state_keeper(out_dir, initial.grains, meta, cfg["lid"]["frames"], lid_index(scene, lid),
                                residual_force)  # fmt: skip
    result = simulate(scene, integrator, out_dir, duration=duration, every=every, vtk=cfg["output"]["vtk"],
                      identity=identity, x0=initial.x, v0=initial.v,
                      friction0=initial.friction, resume=resume_here,
                      progress=progress, on_frame=keep_states)  # fmt: skip
    phase, strain, force = lid_curve(out_dir / "walls.csv", lid, cfg["lid"]["start"], 0.5 * duration)
    write_force_strain_csv(out_dir / "force_strain.csv", phase, strain, force)
    try:
        figures = cycle_figures(phase, strain, force, cfg["lid"]["start"], zero_force=residual_force)
    except ValueError as exc:  # e.g. the lid never reached the pack: the curve is still written
        figures = {"cycle_error": str(exc)}
    back = spring_back(scene, out_dir, result.state)
    warn_if_grains_spring_back(scene, back)
    plot_force_strain(phase, strain, force, out_dir / "force_strain.png",
                      {**figures, "spring_back": back} if "peak_force" in figures else None)  # fmt: skip
    summary = run_summary("lid_compression", scene, result, t_start)
    summary.update(figures)
    summary["pack_weight"] = weight
    summary["residual_force"] = residual_force
    summary["spring_back"] = back
    summary["fluctuations"] = _fluctuations(out_dir, scene, lid, cfg["lid"]["start"], meta)
    summary["pack_top"] = top
    summary["initial_state"] = str(path)
    summary["config_fingerprint"] = identity.fingerprint
    write_json(out_dir / "summary.json", summary)
    return summary
