"""`scenario = "scene"`: any set of grains and walls under gravity, integrated in time.

Outputs in DIR: summary.json, history.csv (energies), grains.csv (centroid position and velocity of
every grain at every frame), walls.csv (force of the grains on every wall at every frame),
grains.pvd + grains/*.vtu (ParaView), checkpoint.npz (the state at the last frame:
`vemdem run ... --resume` continues from it to the same result).
"""

from __future__ import annotations

import hashlib
import json
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..config import REQUIRED, ConfigError, Field, TableList, positive, vector3
from ..contact.defaults import default_contact_laws
from ..contact.forces import contact_points
from ..contact.model import ContactHistory, PenetrationError
from ..contact.walls import MeshWall, Motion, PlaneWall
from ..geometry.factory import GRAIN_SCHEMA, make_grain
from ..geometry.shapes import rotation_matrix
from ..io.results import CsvLog, write_json
from ..io.vtk import PvdSeries
from ..scene import Scene
from ..solver.explicit import ExplicitIntegrator, ExplicitParameters, advance_explicit, explicit_initial_state
from ..solver.newmark import NewmarkParameters, RunStats, State, StepControl, advance, initial_state
from ..vem.element import evaluate, projected_cauchy_stress
from .grain_compression import MATERIAL_SCHEMA, VEM_SCHEMA, material_from, vem_options_from


def _non_negative(v):
    return None if v >= 0 else "must be >= 0"


SCENE_GRAIN_SCHEMA = dict(GRAIN_SCHEMA)
SCENE_GRAIN_SCHEMA.pop("truncate")
SCENE_GRAIN_SCHEMA.update(
    {
        "position": Field(list, REQUIRED, vector3, "centroid (m)"),
        "rotation": Field(list, [0.0, 0.0, 0.0], vector3, "rotation vector (rad)"),
        "velocity": Field(list, [0.0, 0.0, 0.0], vector3, "initial velocity (m/s)"),
    }
)

WALL_SCHEMA = {
    "type": Field(("plane", "mesh"), REQUIRED),
    "point": Field(list, [0.0, 0.0, 0.0], vector3, "plane: a point on it"),
    "normal": Field(list, [0.0, 0.0, 1.0], vector3, "plane: normal pointing towards the grains"),
    "file": Field(str, "", doc="mesh: surface file (STL/OBJ/PLY)"),
    "flip": Field(bool, False, doc="mesh: reverse the faces (normals must face the grains)"),
    "name": Field(str, "", doc="label in outputs"),
    "removed_at": Field(float, None, _non_negative, "time at which the wall disappears (s)"),
    "times": Field(list, [0.0], doc="times of the piecewise-linear displacement history (s)"),
    "displacements": Field(list, [[0.0, 0.0, 0.0]], doc="rigid displacement at each time (m)"),
}

CONTACT_SCHEMA = {
    "mu_s": Field(float, 0.0, _non_negative, "static friction coefficient"),
    "mu_d": Field(float, None, _non_negative, "dynamic friction coefficient [mu_s]"),
    "activation_gap": Field(float, None, positive, "m [0.01 grain size]"),
    "penalty": Field(float, None, positive, "eps1 [from 10 grain weights at the switch gap]"),
    "switch_factor": Field(float, None, lambda v: None if 0 < v < 1 else "must be in (0, 1)"),
    "penalty_exponent": Field(float, None, lambda v: None if v >= 1 else "must be >= 1"),
    "barrier_exponent": Field(float, None, lambda v: None if v < -1 else "must be < -1"),
    "tangential_penalty": Field(float, None, positive, "N/m [the normal stiffness at the switch gap]"),
    "tangential_viscosity": Field(float, None, _non_negative, "N s/m [0]"),
    "damping_ratio": Field(float, None, _non_negative, "normal damping ratio [0.5]"),
}

SOLVER_SCHEMA = {
    "integrator": Field(("implicit", "explicit"), "implicit", doc="implicit Newmark or explicit central differences"),
    "beta": Field(float, 0.3, lambda v: None if 0 < v <= 0.5 else "must be in (0, 0.5]"),
    "gamma": Field(float, 0.5, lambda v: None if 0.5 <= v <= 1 else "must be in [0.5, 1]"),
    "dt": Field(float, 1e-5, positive, "initial time step (s)"),
    "dt_min": Field(float, 1e-10, positive, "the run stops below this step (s)"),
    "dt_max": Field(float, 1e-4, positive, "largest step (s)"),
    "max_iterations": Field(int, 15, positive, "Newton iterations before a step is rejected"),
    "impact_steps": Field(
        float, 0.0, _non_negative, "implicit: contact-impact step control, steps per half contact oscillation (0: off)"
    ),
    "entry_fraction": Field(
        float,
        0.05,
        lambda v: None if 0 < v <= 1 else "must be in (0, 1]",
        "implicit: share of the activation gap an approaching pair may close per step",
    ),
    "safety": Field(
        float, 0.5, lambda v: None if 0 < v <= 1 else "must be in (0, 1]", "explicit: share of the critical step taken"
    ),
    "mass_damping": Field(float, 0.0, _non_negative, "Rayleigh mass-proportional damping alpha (1/s), for settling"),
    "mass_scaling": Field(
        float,
        1.0,
        lambda v: None if v >= 1 else "must be >= 1",
        "density factor for inertia, weight and contact scales (docs/dynamics.md)",
    ),
}

SCHEMA = {
    "scenario": Field(("scene",), REQUIRED),
    "gravity": Field(list, [0.0, 0.0, -9.81], vector3, "m/s^2"),
    "duration": Field(float, REQUIRED, positive, "simulated time (s)"),
    "material": MATERIAL_SCHEMA,
    "vem": VEM_SCHEMA,
    "contact": CONTACT_SCHEMA,
    "solver": SOLVER_SCHEMA,
    "grains": TableList(SCENE_GRAIN_SCHEMA, min_items=1),
    "walls": TableList(WALL_SCHEMA),
    "output": {
        "every": Field(float, 1e-3, positive, "simulated time between written frames (s)"),
        "vtk": Field(bool, True, doc="write the ParaView series grains.pvd"),
    },
}

HISTORY_HEADER = ["time", "kinetic", "strain", "gravity", "contact", "dissipated", "n_contacts"]
GRAINS_HEADER = ["time", "grain", "x", "y", "z", "vx", "vy", "vz"]
WALLS_HEADER = ["time", "wall", "name", "fx", "fy", "fz"]  # force of the grains on each wall (N)


# ---------------------------------------------------------------------------- building the scene
def place_grain(spec: dict, base_dir):
    grain = make_grain(spec, base_dir)
    grain = grain.translated(-grain.centroid).rotated(rotation_matrix(spec["rotation"]))
    return grain.translated(spec["position"])


def _motion(spec: dict, where: str) -> Motion:
    try:
        return Motion(tuple(spec["times"]), tuple(tuple(d) for d in spec["displacements"]),
                      np.inf if spec["removed_at"] is None else spec["removed_at"])  # fmt: skip
    except (ValueError, TypeError) as exc:
        raise ConfigError(f"{where}: {exc}") from None


def build_walls(specs: list, base_dir):
    planes, meshes = [], []
    for i, spec in enumerate(specs):
        where = f"walls[{i}]"
        name = spec["name"] or f"wall {i}"
        motion = _motion(spec, where)
        if spec["type"] == "plane":
            if np.linalg.norm(spec["normal"]) == 0:
                raise ConfigError(f"{where}.normal: must not be the zero vector")
            planes.append(PlaneWall(np.array(spec["point"], float), np.array(spec["normal"], float), motion, name))
        else:
            if not spec["file"]:
                raise ConfigError(f"{where}.file: required for a mesh wall")
            path = Path(spec["file"])
            path = path if path.is_absolute() or base_dir is None else Path(base_dir) / path
            if not path.is_file():
                raise ConfigError(f"{where}.file: {path} not found")
            meshes.append(MeshWall.from_file(path, motion, flip=spec["flip"]))
    return planes, meshes


def scene_from(grains: list, cfg: dict, planes: list, meshes: list = ()) -> Scene:
    """A scene of placed grains and walls with the config's material, vem, contact and solver
    (mass scaling) settings; the contact laws' scales come from the mean grain size."""
    material = material_from(cfg)
    # mass scaling: every mass-born quantity (inertia, weight, contact force scale) grows alike, so
    # rigid-grain kinematics are unchanged and only the elastic (and explicit-step) time scales move
    material = replace(material, density=material.density * cfg["solver"]["mass_scaling"])
    size = float(np.mean([np.cbrt(6 * g.volume / np.pi) for g in grains]))
    overrides = {k: v for k, v in cfg["contact"].items() if k not in ("mu_s", "mu_d") and v is not None}
    try:
        law, friction = default_contact_laws(size, material.E, material.density, float(np.linalg.norm(cfg["gravity"])),
                                             cfg["contact"]["mu_s"], cfg["contact"]["mu_d"], **overrides)  # fmt: skip
    except ValueError as exc:
        raise ConfigError(f"contact: {exc}") from None
    return Scene.build(grains, material, law, friction, list(planes), list(meshes), cfg["gravity"], vem_options_from(cfg))


def build_scene(cfg: dict, base_dir=None) -> tuple[Scene, np.ndarray]:
    grains = [place_grain(g, base_dir) for g in cfg["grains"]]
    planes, meshes = build_walls(cfg["walls"], base_dir)
    scene = scene_from(grains, cfg, planes, meshes)
    v0 = np.vstack([np.tile(g["velocity"], (grain.n_vertices, 1)) for g, grain in zip(cfg["grains"], grains)])
    return scene, v0


# ---------------------------------------------------------------------------- checkpoints
def config_fingerprint(cfg: dict) -> str:
    return hashlib.sha256(json.dumps(cfg, sort_keys=True, default=str).encode()).hexdigest()


def save_checkpoint(path: Path, state: State, control: StepControl, stats: RunStats, frame: int, fingerprint: str):
    tmp = path.with_suffix(".tmp.npz")
    h = state.history
    np.savez(tmp, t=state.t, x=state.x, v=state.v, a=state.a, dissipated=state.dissipated, power=state.power,
             keys=h.keys, c_prev=h.c_prev, gt=h.gt, stick=h.stick, dt=control.dt, easy_streak=control.easy_streak,
             accepted=stats.accepted, rejected=stats.rejected, newton=stats.newton_iterations, frame=frame,
             fingerprint=fingerprint)  # fmt: skip
    tmp.replace(path)  # atomic: an interrupted write never leaves a broken checkpoint


def load_checkpoint(path: Path, control: StepControl, fingerprint: str):
    if not path.is_file():
        raise ConfigError(f"--resume: no checkpoint at {path}")
    d = np.load(path)
    if str(d["fingerprint"]) != fingerprint:
        raise ConfigError(f"--resume: {path} was written by a different config")
    history = ContactHistory(d["keys"], d["c_prev"], d["gt"], d["stick"].astype(bool))
    state = State(float(d["t"]), d["x"], d["v"], d["a"], history, float(d["dissipated"]), float(d["power"]))
    control.dt = float(d["dt"])
    control.easy_streak = int(d["easy_streak"])
    stats = RunStats(int(d["accepted"]), int(d["rejected"]), int(d["newton"]))
    return state, stats, int(d["frame"])


def _truncate_csv(path: Path, t_max: float):
    """Keep the header and the rows written up to the checkpoint (a resumed run rewrites the rest)."""
    lines = path.read_text().splitlines(keepends=True)
    keep = [lines[0]] + [ln for ln in lines[1:] if float(ln.split(",")[0]) <= t_max]
    path.write_text("".join(keep))


# ---------------------------------------------------------------------------- the integrator
class Stepper:
    """The integrator the config asks for, behind one interface (both share every force kernel)."""

    def __init__(self, scene: Scene, s: dict):
        self.scene = scene
        self.explicit = s["integrator"] == "explicit"
        self.control = StepControl(dt=s["dt"], dt_min=s["dt_min"], dt_max=s["dt_max"],
                                   impact_steps=s["impact_steps"], entry_fraction=s["entry_fraction"])  # fmt: skip
        if self.explicit:
            self.integrator = ExplicitIntegrator(scene, ExplicitParameters(safety=s["safety"],
                                                                           mass_damping=s["mass_damping"]))  # fmt: skip
        else:
            self.params = NewmarkParameters(beta=s["beta"], gamma=s["gamma"], max_iterations=s["max_iterations"],
                                            mass_damping=s["mass_damping"])  # fmt: skip

    def initial_state(self, v0=None, x0=None) -> State:
        if self.explicit:
            return explicit_initial_state(self.scene, self.integrator, x0=x0, v0=v0)
        return initial_state(self.scene, x0=x0, v0=v0)

    def advance(self, state: State, t_end: float, on_step, stats: RunStats):
        if self.explicit:
            return advance_explicit(self.integrator, state, t_end, self.control, on_step, stats)
        return advance(self.scene, state, t_end, self.control, self.params, on_step, stats)


# ---------------------------------------------------------------------------- the run
class FrameWriter:
    def __init__(self, scene: Scene, out_dir: Path, vtk: bool, resume_frames: int | None, lumped: bool = False):
        self.scene = scene
        self.lumped = lumped  # the explicit integrator's energies use its lumped mass
        self.out_dir = out_dir
        mode = "a" if resume_frames is not None else "w"
        self.history = CsvLog(out_dir / "history.csv", HISTORY_HEADER, mode)
        self.grains = CsvLog(out_dir / "grains.csv", GRAINS_HEADER, mode)
        self.walls = CsvLog(out_dir / "walls.csv", WALLS_HEADER, mode)
        self.wall_names = [m.name for m in scene.contact.meshes] + [p.name for p in scene.contact.planes]
        self.vtk = PvdSeries(out_dir, "grains", keep=resume_frames) if vtk else None
        n_grain_faces = scene.contact.topology.grain_face_ptr[scene.n_grains]
        self.faces = scene.contact.topology.faces[:n_grain_faces]
        self.face_grain = scene.contact.topology.face_grain[:n_grain_faces]

    def write(self, state: State, strain: float, contact_result):
        s = self.scene
        self.history.write(state.t, s.kinetic_energy(state.v, self.lumped), strain, s.gravity_energy(state.x, self.lumped),
                           contact_result.energy, state.dissipated, contact_result.n_contacts)  # fmt: skip
        c = s.grain_centroids(state.x)
        vc = s.grain_centroids(state.v)
        self.grains.write_rows([[state.t, g, *c[g], *vc[g]] for g in range(s.n_grains)])
        self.walls.write_rows([[state.t, w, name, *contact_result.wall_reactions[w]]
                               for w, name in enumerate(self.wall_names)])  # fmt: skip
        if self.vtk is not None:
            self._write_vtk(state, contact_result)

    def _write_vtk(self, state, cr):
        s = self.scene
        x_all = s.contact.all_positions(state.x, state.t)
        points = contact_points(x_all, cr.ints, cr.floats) if cr.n_contacts else np.zeros((0, 3))
        n, m = s.n_vertices, len(points)
        sigma = projected_cauchy_stress(s.elements, state.x).reshape(-1, 9)
        cells_tri = self.faces
        cells_pt = (n + np.arange(m)).reshape(-1, 1)
        force = np.vstack([np.zeros((n, 3)), cr.pair_force]) if m else np.zeros((n, 3))
        self.vtk.write(
            state.t,
            np.vstack([state.x, points]),
            [("triangle", cells_tri), ("vertex", cells_pt)],
            point_data={"velocity": np.vstack([state.v, np.zeros((m, 3))]), "contact_force": force},
            cell_data={
                "grain": [self.face_grain, np.full(m, -1)],
                "cauchy_stress": [sigma[self.face_grain], np.zeros((m, 9))],
            },
        )

    def close(self):
        self.history.close()
        self.grains.close()
        self.walls.close()


@dataclass
class Run:
    """What the shared time loop hands back to a scenario."""

    state: State
    stats: RunStats
    stopped_early: bool  # `stop` ended the run before `duration`
    last_contact: object  # the ContactResult at the last frame


def simulate(scene: Scene, solver: dict, out_dir: Path, *, duration: float, every: float, vtk: bool,
             fingerprint: str, x0=None, v0=None, resume: bool = False, progress=None, stop=None) -> Run:  # fmt: skip
    """The time loop every dynamic scenario shares: a frame (history.csv, grains.csv, walls.csv,
    ParaView) every `every` s up to `duration`, a checkpoint after each frame, and after each frame
    `stop(state)` may end the run early (deterministic: a resumed run stops at the same frame)."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    stepper = Stepper(scene, solver)
    control = stepper.control
    ckpt = out_dir / "checkpoint.npz"
    n_frames = int(np.ceil(duration / every - 1e-9))
    if resume:
        state, stats, frame = load_checkpoint(ckpt, control, fingerprint)
        for name in ("history.csv", "grains.csv", "walls.csv"):
            _truncate_csv(out_dir / name, state.t)
        writer = FrameWriter(scene, out_dir, vtk, resume_frames=frame + 1, lumped=stepper.explicit)
        last_contact = _contact_now(scene, state)
    else:
        try:
            state = stepper.initial_state(v0, x0)
        except PenetrationError as exc:
            raise ConfigError(f"walls: a grain starts behind a wall ({exc})") from None
        stats, frame = RunStats(), 0
        writer = FrameWriter(scene, out_dir, vtk, resume_frames=None, lumped=stepper.explicit)
        last_contact = _contact_now(scene, state)
        writer.write(state, evaluate(scene.elements, state.x, force=False).total_energy, last_contact)
        save_checkpoint(ckpt, state, control, stats, frame, fingerprint)
    last = {}

    def on_step(st, info, h):
        last["info"] = info

    stopped = stop is not None and frame > 0 and stop(state)
    try:
        while frame < n_frames and not stopped:
            t_next = min((frame + 1) * every, duration)
            t_wall = time.perf_counter()
            steps_before = stats.accepted
            state, stats = stepper.advance(state, t_next, on_step, stats)
            frame += 1
            last_contact = last["info"].contact
            writer.write(state, last["info"].strain_energy, last_contact)
            save_checkpoint(ckpt, state, control, stats, frame, fingerprint)
            if progress:
                rate = (stats.accepted - steps_before) / max(time.perf_counter() - t_wall, 1e-9)
                progress(frame, n_frames, f"t = {state.t:.4g} s, {rate:.1f} steps/s, dt = {control.dt:.2e} s")
            stopped = stop is not None and stop(state)
    finally:
        writer.close()
    return Run(state, stats, bool(stopped), last_contact)


def run_summary(scenario: str, cfg: dict, scene: Scene, run: Run, t_start: float) -> dict:
    """The summary fields every dynamic scenario writes."""
    stats, state = run.stats, run.state
    return {
        "scenario": scenario,
        "integrator": cfg["solver"]["integrator"],
        "n_grains": scene.n_grains,
        "n_vertices": scene.n_vertices,
        "n_steps": stats.accepted,
        "n_rejected_steps": stats.rejected,
        "n_newton_iterations": stats.newton_iterations,
        "simulated_time": state.t,
        "mean_time_step": state.t / max(stats.accepted, 1),
        "wall_seconds": time.perf_counter() - t_start,
        "contact": {
            "activation_gap": scene.contact.law.activation_gap,
            "penalty": scene.contact.law.penalty,
            "tangential_penalty": scene.contact.friction.tangential_penalty,
            "damping_ratio": scene.contact.friction.damping_ratio,
        },  # fmt: skip
    }


def run(cfg: dict, out_dir: Path, base_dir=None, progress=None, resume: bool = False) -> dict:
    t_start = time.perf_counter()
    scene, v0 = build_scene(cfg, base_dir)
    result = simulate(scene, cfg["solver"], out_dir, duration=cfg["duration"], every=cfg["output"]["every"],
                      vtk=cfg["output"]["vtk"], fingerprint=config_fingerprint(cfg), v0=v0, resume=resume,
                      progress=progress)  # fmt: skip
    summary = run_summary("scene", cfg, scene, result, t_start)
    write_json(Path(out_dir) / "summary.json", summary)
    return summary


def _contact_now(scene: Scene, state: State):
    """The contact state at a frame (for the energies, the reactions and the ParaView points)."""
    cand = scene.contact.search(state.x, state.t)
    return scene.contact.evaluate(state.x, state.t, cand, state.history, v=state.v)
