"""`scenario = "tilting_box"`: a settled pack in its box is tilted until its surface avalanches.

The tilting-box test of granular materials (docs/repose.md): the maximum angle of stability (the
surface's angle when it avalanches) and the angle of repose after the avalanche, from one box.
The box (the pack's floor and four walls) stays put and gravity turns in its frame: tilted by theta
about the y axis, +x end down, g(theta) = |g| (sin theta, 0, -cos theta) (analysis.tilt). Turning
gravity at tilt.rate is tilting the box at that rate less the inertial forces of the turn,
Omega^2 r and 2 Omega x v: at 20 deg/s and r = 10 mm they are 1e-4 g and, for grains at 10 mm/s,
1e-3 g.

Gravity turns to tilt.start at t = 0 and stays there until the pack is at rest again (settle
table); the tilt then grows at tilt.rate until the avalanche, found at a frame by one of two marks
(tilt.avalanche):

- "kinetic": the mean kinetic energy per grain passes tilt.avalanche_kinetic m g d. In a pack a
  few grains wide this fires on the first burst of rearrangement, which need not set the surface
  flowing (docs/results.md: in four of six boxes 3 grains wide the surface layer slipped 0.08-0.22
  grain sizes from the start of the tilt to the end of the run);
- "surface": the surface layer (the grains no other covers when the tilting begins,
  analysis.tilt.surface_grains; all grains when fewer than 5 are) has slipped downhill (+x, along
  the floor) by tilt.surface_slip grain sizes on average since the tilting began: the surface
  flows. The slip grows from rest as the tilt passes the surface's angle of stability, so the
  mark comes later than the onset by the time the layer takes to slip that far (for a block on a
  plane tilted at omega: (6 s / (g sqrt(1 + mu^2) omega))^(1/3)).

The tilt is held from that frame on
and the run goes on until the grains are at rest again (settle table, min_time counted from the
avalanche) or settle.max_time after it. A box still at rest at tilt.max ends the run with no
avalanche.

tilt.sides = "mirrors" makes the box's +-y sides frictionless mirror planes: in a box a few
grains wide, frictional side walls carry part of the pack's weight and hold its surface up to
tilts far past its angle of stability (docs/results.md).

Starts from a `pack` state file (`initial_state`) or settles the `[pack]` table first (as
pile_collapse). Outputs in DIR: summary.json (angle_of_avalanche_deg, tilt_at_avalanche_deg,
angle_of_repose_deg with their uncertainties, fill_height_grains, ...; energy: the balance from the
avalanche on, when gravity no longer turns), tilt.png (the box seen along y, the surface fits, the
kinetic energy and the tilt against time), tilt_3d.png, tilt.json (the avalanche, kept for
`--resume`), state.npz, and the scene outputs (history.csv, grains.csv, walls.csv, grains.pvd,
checkpoint.npz; `--resume` continues a run).
"""

from __future__ import annotations

import csv
import json
import time
from pathlib import Path

import numpy as np

from ..analysis.plots import plot_grains_3d
from ..analysis.tilt import MIN_SURFACE_GRAINS, fit_surface, plot_tilt, surface_grains, tilted_gravity
from ..config import tables
from ..config.build import scene_from, solver_options_from
from ..contact.walls import box_walls, mirrored
from ..driver.loop import simulate
from ..driver.summary import energy_balance, run_summary
from ..io.results import write_json
from ..io.state import friction_arrays, save_state
from ..solver.api import make_integrator
from .granular import kinetic_ratio, rest_energy
from .identity import run_identity
from .pack import initial_state_from

RESUMABLE = True  # `vemdem run ... --resume` continues from DIR/checkpoint.npz (and DIR/tilt.json)
SCHEMA = tables.TILTING_BOX


class Tilt:
    """The tilt against time: tilt.start from t = 0 until the pack is at rest there again (the turn
    to tilt.start shakes it), then tilt.rate more per second up to tilt.max, held from the
    avalanche on. `stop` and `after_step` are the time loop's hooks (a driver.loop.Control). The
    two events (tilting from, avalanche; with the surface mark, the surface layer and where it
    stood) are kept in DIR/tilt.json, written at the frame that finds them, after that frame's
    checkpoint: a resumed run reads them back or, resuming from that very frame, finds them again."""

    def __init__(self, scene, cfg: dict, meta: dict, out_dir: Path, lumped: bool, resume: bool):
        self.scene, self.meta, self.lumped = scene, meta, lumped
        tilt, self.settle = cfg["tilt"], cfg["settle"]
        self.start, self.rate, self.max = tilt["start"], tilt["rate"], tilt["max"]
        self.threshold = tilt["avalanche_kinetic"]
        self.mark, self.slip = tilt["avalanche"], tilt["surface_slip"]
        self.g = float(np.linalg.norm(scene.gravity))
        self.path = out_dir / "tilt.json"
        events = json.loads(self.path.read_text()) if resume and self.path.is_file() else {}
        self.tilting_from, self.onset = events.get("tilting_from"), events.get("avalanche")
        self.surface = events.get("surface")  # {"grains": [...], "x": [...]}: the layer when the tilting began
        self.rest_limit = self.settle["kinetic_threshold"] * rest_energy(scene) * scene.n_grains
        scene.gravity[:] = self.gravity(0.0)

    @property
    def full_tilt_time(self) -> float:
        return (self.max - self.start) / self.rate

    def angle(self, t: float) -> float:
        if self.tilting_from is None:
            return self.start
        held = t if self.onset is None else min(t, self.onset["time"])
        return min(self.start + self.rate * max(held - self.tilting_from, 0.0), self.max)

    def gravity(self, t: float) -> np.ndarray:
        return tilted_gravity(self.angle(t), self.g)

    def after_step(self, state, info) -> None:
        self.scene.gravity[:] = self.gravity(state.t)

    def carried(self) -> None:
        """None: the gravity turned since the last frame is found again from the frame's time by
        `stop`, so the loop checkpoints this run at frames only."""
        return None

    def carry_on(self, carried: dict) -> None:
        pass

    def stop(self, state) -> bool:
        self.scene.gravity[:] = self.gravity(state.t)  # a resumed run starts here
        energy = self.scene.kinetic_energy(state.v, self.lumped)
        at_rest = state.t >= self.settle["min_time"] and energy < self.rest_limit
        if self.tilting_from is None:
            if at_rest:
                self.tilting_from = state.t
                if self.mark == "surface":
                    self.surface = self._surface_layer(state)
                self._save()
            return state.t >= self.settle["max_time"]  # never at rest at tilt.start
        if self.onset is None:
            if self._avalanching(state, energy):
                self._record_onset(state)
                return False
            return state.t >= self.tilting_from + self.full_tilt_time + self.settle["min_time"]  # at rest at tilt.max
        return state.t - self.onset["time"] >= self.settle["min_time"] and energy < self.rest_limit

    def _avalanching(self, state, energy: float) -> bool:
        if self.mark == "kinetic":
            return energy > self.threshold * rest_energy(self.scene) * self.scene.n_grains
        return self.surface_slip(state) >= self.slip * self.scene.grain_size

    def _surface_layer(self, state) -> dict:
        centroids = self.scene.grain_centroids(state.x)
        top = surface_grains(centroids, self.meta["box"], self.meta["centre"], self.scene.grain_size)
        if len(top) < MIN_SURFACE_GRAINS:  # a grain or a few: they are the surface
            top = np.arange(self.scene.n_grains)
        return {"grains": top.tolist(), "x": centroids[top, 0].tolist()}

    def surface_slip(self, state) -> float:
        """Mean downhill (+x) slip of the surface layer since the tilting began (m)."""
        grains = np.asarray(self.surface["grains"], dtype=np.int64)
        return float(np.mean(self.scene.grain_centroids(state.x)[grains, 0] - np.asarray(self.surface["x"])))

    def _record_onset(self, state) -> None:
        angle = self.angle(state.t)
        self.onset = {"time": state.t, "tilt_deg": angle}
        if self.mark == "surface":
            self.onset["surface_slip_grains"] = self.surface_slip(state) / self.scene.grain_size
        try:
            s = fit_surface(self.scene.grain_centroids(state.x), angle, self.meta["box"], self.meta["centre"],
                            self.scene.grain_size)  # fmt: skip
            self.onset.update(angle_deg=s.angle_deg, stderr_deg=s.stderr_deg, intercept=s.intercept, slope=s.slope)
        except ValueError as exc:
            self.onset.update(angle_deg=None, error=str(exc))
        self._save()

    def _save(self) -> None:
        events = {"tilting_from": self.tilting_from, "avalanche": self.onset}
        if self.surface is not None:
            events["surface"] = self.surface
        self.path.write_text(json.dumps(events, indent=2) + "\n")


def run(cfg: dict, out_dir: Path, base_dir=None, progress=None, resume: bool = False) -> dict:
    t_start = time.perf_counter()
    out_dir = Path(out_dir)
    initial, path = initial_state_from(cfg, base_dir, out_dir, progress, resume)
    meta = dict(initial.meta)
    walls = tilt_walls(meta, cfg["tilt"]["sides"])
    scene = scene_from(initial.grains, cfg, walls)
    integrator = make_integrator(solver_options_from(cfg), scene)
    resume_here = resume and (out_dir / "checkpoint.npz").is_file()  # a run stopped in its pack stage starts here
    tilt = Tilt(scene, cfg, meta, out_dir, integrator.lumped, resume_here)
    identity = run_identity(cfg, SCHEMA)
    result = simulate(scene, integrator, out_dir, duration=tilt.full_tilt_time + 2 * cfg["settle"]["max_time"],
                      every=cfg["output"]["every"], vtk=cfg["output"]["vtk"], identity=identity, x0=initial.x,
                      v0=initial.v, friction0=initial.friction, resume=resume_here, progress=progress,
                      stop=tilt.stop, control=tilt)  # fmt: skip
    state = result.state
    summary = run_summary("tilting_box", scene, result, t_start)
    summary.update(measure_tilt(scene, state, tilt, meta, out_dir))
    summary["sides"] = cfg["tilt"]["sides"]
    summary["settled"] = tilt.onset is not None and result.stopped_early
    summary["kinetic_ratio"] = kinetic_ratio(scene, state.v, integrator.lumped)
    summary["initial_state"] = str(path)
    summary["config_fingerprint"] = identity.fingerprint
    save_state(out_dir / "state.npz", initial.grains, state.x, state.v,
               {**meta, "scenario": "tilting_box", "time": state.t, "tilt_deg": tilt.angle(state.t)},
               friction_arrays(state.history))  # fmt: skip
    write_json(out_dir / "summary.json", summary)
    return summary


def tilt_walls(meta: dict, sides: str) -> list:
    """The pack's box; with sides = "mirrors" its +-y sides frictionless: a pack a few grains wide
    then slides as a slice of a wide one would, where frictional side walls hold it up (the wall
    friction carries a share of the weight that grows with depth over width: Janssen)."""
    walls = box_walls(*meta["box"], meta["floor"], tuple(meta["centre"]))
    return mirrored(walls, ("wall -y", "wall +y")) if sides == "mirrors" else walls


def measure_tilt(scene, state, tilt: Tilt, meta: dict, out_dir: Path) -> dict:
    """The angles at and after the avalanche, the energy balance after it, and the pictures."""
    angle = tilt.angle(state.t)
    centroids = scene.grain_centroids(state.x)
    onset = tilt.onset
    out = {"tilt_deg": angle, "fill_height_grains": (float(centroids[:, 2].max()) - meta["floor"]) / scene.grain_size}
    out["tilting_from"] = tilt.tilting_from  # s: the pack at rest again at tilt.start
    out["avalanche_mark"] = tilt.mark
    if onset is None:
        reason = (f"no avalanche up to tilt.max = {tilt.max:g} degrees" if tilt.tilting_from is not None else
                  f"the pack was not at rest at tilt.start = {tilt.start:g} degrees by settle.max_time: start lower")
        out.update(angle_of_avalanche_deg=None, tilt_at_avalanche_deg=None, avalanche_time=None,
                   angle_of_repose_deg=None, angle_of_repose_error=reason,
                   energy=None, energy_error="gravity turned all along: no stretch of the run kept its energy")  # fmt: skip
        after = None
    else:
        out.update(angle_of_avalanche_deg=onset["angle_deg"], angle_of_avalanche_uncertainty_deg=onset.get("stderr_deg"),
                   tilt_at_avalanche_deg=onset["tilt_deg"], avalanche_time=onset["time"])  # fmt: skip
        if tilt.surface is not None:
            out["surface_layer_grains"] = len(tilt.surface["grains"])
            out["surface_slip_at_avalanche_grains"] = onset.get("surface_slip_grains")
        if onset["angle_deg"] is None:
            out["angle_of_avalanche_error"] = onset["error"]
        try:
            after = fit_surface(centroids, angle, meta["box"], meta["centre"], scene.grain_size)
            out.update(angle_of_repose_deg=after.angle_deg, angle_of_repose_uncertainty_deg=after.stderr_deg,
                       surface_grains=len(after.grains))  # fmt: skip
        except ValueError as exc:
            after = None
            out.update(angle_of_repose_deg=None, angle_of_repose_error=str(exc))
        # gravity turned until the avalanche, working on the grains: the books close from there on
        out["energy"] = energy_balance(out_dir / "history.csv", since=onset["time"])
        out["energy_from"] = "avalanche"
    times, kinetic = _kinetic_history(out_dir / "history.csv")
    friction = scene.contact.friction
    title = f"tilting box: {scene.n_grains} grains, mu_s = {friction.mu_s:g}, mu_d = {friction.mu_d:g}"
    plot_tilt(out_dir / "tilt.png", centroids, angle, meta["box"], meta["centre"], meta["floor"],
              float(centroids[:, 2].max()) + scene.grain_size, after, onset, times,
              kinetic / (rest_energy(scene) * scene.n_grains), [tilt.angle(t) for t in times],
              tilt.threshold if tilt.mark == "kinetic" else None,
              title)  # fmt: skip
    plot_grains_3d(out_dir / "tilt_3d.png", state.x, *scene.surface_triangles(), title=title, floor_z=meta["floor"])
    return out


def _kinetic_history(history_csv: Path) -> tuple[np.ndarray, np.ndarray]:
    with open(history_csv) as fh:
        rows = list(csv.DictReader(fh))
    return np.array([float(r["time"]) for r in rows]), np.array([float(r["kinetic"]) for r in rows])
