"""`scenario = "direct_shear"`: a split shear box (docs/direct-shear.md).

The settled pack stays where it settled; its box becomes a shear box split at `sample.split` of
the pack's height: the lower half (the floor and its two x sides, finite rectangles up to the
split) can move along x, the upper half's two x sides (from `sample.opening` mean grain sizes
above the split up, past the lid) stay,
the two y sides are frictionless planes along the shear, and a lid starts `sample.gap` mean
grain sizes above the pack. The floor and the lid are rough (the grains' friction): a shear box's
plates carry the shear into the sample. Two stages:

1. consolidation: the lid's servo (model/servo.py) brings it to the normal stress; the stage
   ends when it holds it within `servo.stress_tolerance` with the sample at rest, or at
   `normal.max_time`;
2. shear: the lower half moves along +x at a constant speed (the shear rate speed / H that gives
   `shear.inertia_number` at the normal stress, H the sample's height) while the lid's servo holds
   the normal stress; the stage ends at `shear.max_displacement` of the box's length, or at its
   `max_time`. The halves' walls are one-sided rectangles that move apart by the travel, with
   `sample.opening` between them (below the smallest grain, checked). Where the halves' ends no
   longer face each other, two horizontal plates close the box as a lab box's frames do: the lower
   half's -x end carries a plate at the split that reaches outwards past the travel (the upper
   half's grains above the lower half's vacated end rest on it), and the upper half's +x end a
   plate just above the split that reaches outwards past the travel (it holds down the lower
   half's grains that have moved out under it); docs/direct-shear.md says where the test stands.

sigma_n = the lid's force over the box's section, tau = the force the lower half (its floor and
sides) carries along x over the same section; the vertical displacement is the lid's rise.

Outputs in DIR: shear.csv (one row per frame: analysis.direct_shear.HEADER), shear.png,
summary.json (phi_peak_deg, phi_residual_deg, dilation_angle_deg, max_inertia_number, the peak
and residual failure states, stages),
fabric.csv and the scene outputs; `--resume` continues a run from inside either stage.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ..analysis.direct_shear import HEADER, envelope_panel, envelopes, plot_envelopes, plot_shear, shear_figures
from ..analysis.microstructure import coordination
from ..config import ConfigError, lab_tables
from ..config.build import activation_gap_from, scene_from, solver_options_from
from ..contact.walls import MeshWall, PlaneWall, ServoMotion
from ..driver.stages import unbalanced_force
from ..geometry.mass import body_volumes
from ..model.bodies import equivalent_diameters
from ..model.servo import Servo
from ..solver.api import make_integrator
from .identity import run_identity
from .lab import STAGES, TwoStagePath, contact_at_stress, run_stages, write_summary
from .pack import initial_state_from

RESUMABLE = True
SCHEMA = lab_tables.DIRECT_SHEAR
# A sweep over `key` gives Coulomb envelopes (sweep.add_envelopes): `fit` of a group's summaries,
# `panel` and `plot` its figure
ENVELOPE = {"key": "normal.stress", "fit": envelopes, "panel": envelope_panel, "plot": plot_envelopes}
LOWER = ("floor", "lower -x", "lower +x", "lower -x plate")  # the walls that move with the lower half


def _quad(corners, normal) -> tuple[np.ndarray, np.ndarray]:
    """A planar rectangle through four corners in order, its two triangles wound so that their
    normals point along `normal` (a mesh wall pushes grains along its triangles' normals)."""
    v = np.asarray(corners, dtype=float)
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    if np.dot(np.cross(v[1] - v[0], v[2] - v[0]), normal) < 0:
        faces = faces[:, ::-1]
    return v, faces


def _side(x: float, y0: float, y1: float, z0: float, z1: float, inward: float) -> tuple[np.ndarray, np.ndarray]:
    """A rectangle in the plane x = const from (y0, z0) to (y1, z1), facing `inward` (+1 or -1) along x."""
    return _quad([[x, y0, z0], [x, y1, z0], [x, y1, z1], [x, y0, z1]], (inward, 0.0, 0.0))


def _plate(z: float, x0: float, x1: float, y0: float, y1: float, up: float) -> tuple[np.ndarray, np.ndarray]:
    """A rectangle in the plane z = const over [x0, x1] x [y0, y1], facing `up` (+1 or -1) along z."""
    return _quad([[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]], (0.0, 0.0, up))


class ShearBox:
    """The walls of a split box around a settled pack, and its measures."""

    def __init__(self, cfg: dict, initial):
        meta = initial.meta
        self.box, self.floor = tuple(float(v) for v in meta["box"]), float(meta["floor"])
        cx, cy = (float(v) for v in meta["centre"])
        volumes = np.array([g.volume for g in initial.grains])
        sizes = equivalent_diameters(volumes)
        self.grain_size, smallest = float(np.mean(sizes)), float(np.min(sizes))
        self.travel_max = cfg["shear"]["max_displacement"] * self.box[0]
        self.opening = cfg["sample"]["opening"] * self.grain_size
        if self.opening >= smallest:
            raise ConfigError(f"sample.opening: {self.opening * 1e3:.3g} mm between the halves would let the smallest "
                              f"grain ({smallest * 1e3:.3g} mm) out; take less than "
                              f"{smallest / self.grain_size:.3g}")  # fmt: skip
        top = float(initial.x[:, 2].max())
        self.height0 = top - self.floor + cfg["sample"]["gap"] * self.grain_size
        split = self.floor + cfg["sample"]["split"] * (top - self.floor)
        above = self.floor + self.height0 + 2.0 * self.grain_size  # the upper sides reach past the lid
        below = self.floor - self.grain_size
        hx, hy = 0.5 * self.box[0], 0.5 * self.box[1]
        self.drive = ServoMotion((1.0, 0.0, 0.0))  # the lower half's motion, shared by its walls
        self.frame = ServoMotion((0.0, 0.0, 1.0))  # the upper half's rise with the sample, shared by its walls
        lower, upper = [], []
        for name, x, inward in (("-x", cx - hx, 1.0), ("+x", cx + hx, -1.0)):
            v, f = _side(x, cy - hy, cy + hy, below, split, inward)
            lower.append(MeshWall(v, f, self.drive, f"lower {name}"))
            v, f = _side(x, cy - hy, cy + hy, split + self.opening, above, inward)
            upper.append(MeshWall(v, f, self.frame, f"upper {name}"))
        # the frames' plates, reaching a grain past the travel outwards from the halves' ends; their
        # inner edges stand back from the sides' edges by twice the contact layer, so that a grain
        # pressed on a side near the split is not pushed by the plate's edge too
        reach = self.travel_max + self.grain_size
        back = 2.0 * activation_gap_from(cfg, self.grain_size)
        v, f = _plate(split, cx - hx - reach, cx - hx - back, cy - hy, cy + hy, 1.0)
        lower.append(MeshWall(v, f, self.drive, "lower -x plate"))
        v, f = _plate(split + self.opening, cx + hx + back, cx + hx + reach, cy - hy, cy + hy, -1.0)
        upper.append(MeshWall(v, f, self.frame, "upper +x plate"))
        floor = PlaneWall(np.array([cx, cy, self.floor]), np.array([0.0, 0.0, 1.0]), self.drive, "floor")
        sides = [PlaneWall(np.array([cx, cy - hy, self.floor]), np.array([0.0, 1.0, 0.0]), name="wall -y",
                           frictionless=True),
                 PlaneWall(np.array([cx, cy + hy, self.floor]), np.array([0.0, -1.0, 0.0]), name="wall +y",
                           frictionless=True)]  # fmt: skip
        self.lid = PlaneWall(np.array([cx, cy, self.floor + self.height0]), np.array([0.0, 0.0, -1.0]),
                             ServoMotion((0.0, 0.0, -1.0)), "lid")  # fmt: skip
        self.walls = [floor, *sides, self.lid]
        self.meshes = lower + upper
        self.area = self.box[0] * self.box[1]

    def height(self, t: float) -> float:
        return self.height0 - self.lid.motion.travel(t)

    def volume(self, t: float) -> float:
        return self.area * self.height(t)

    def stresses(self, reactions: np.ndarray, lid: int, lower: list[int]) -> tuple[float, float]:
        """(sigma_n, tau): the lid's normal stress and the shear stress the lower half carries (Pa)."""
        sigma_n = float(reactions[lid, 2]) / self.area  # the grains push the lid up
        tau = -float(np.sum(reactions[lower, 0])) / self.area  # the half pushes the grains along +x
        return sigma_n, tau


class DirectShearPath(TwoStagePath):
    """The lid's servo throughout; the lower half held, then driven at a constant speed once the
    consolidation has ended (scenarios.lab.TwoStagePath)."""

    def __init__(self, cell: ShearBox, servo: Servo, cfg: dict, speed: float, lumped, vertex_ptr):
        super().__init__([servo], cfg["normal"]["stress"], (cfg["normal"]["max_time"], cfg["shear"]["max_time"]),
                         cfg["servo"], lumped, vertex_ptr, motions=(cell.drive, cell.frame))  # fmt: skip
        self.cell, self.speed = cell, float(speed)

    def begin(self, t: float) -> tuple:
        return t, self.cell.drive.travel(t), self.cell.lid.motion.travel(t)

    def displacements(self, t: float) -> tuple[float, float]:
        """(shear, vertical) displacement from where the current stage began: the lower half's
        travel and the lid's rise."""
        _, x0, z0 = self.start if self.start is not None else (0.0, 0.0, 0.0)
        return self.cell.drive.travel(t) - x0, -(self.cell.lid.motion.travel(t) - z0)

    def progress(self, t: float) -> float:
        return self.displacements(t)[0] / self.cell.box[0]

    def consolidated(self) -> bool:
        return self.held(self.servos[0])

    def sheared(self, t: float) -> str:
        return "max_displacement" if self.displacements(t)[0] >= self.cell.travel_max else ""

    def steer(self, t: float) -> None:
        self.servos[0].steer(t)
        self.cell.drive.steer(t, self.speed if self.current == 1 else 0.0)
        self.cell.frame.steer(t, self.frame_speed(t) if self.current == 1 else 0.0)

    def frame_speed(self, t: float) -> float:
        """The upper frame rides with the lid's rise from the shear's start, never below where it
        stood (a lab box's upper frame lifts with a dilating sample, so that a grain caught at its
        edge lifts it instead of being crushed; it does not sink into the lower one)."""
        up = -self.cell.lid.motion.speed
        rise, lifted = self.displacements(t)[1], self.cell.frame.travel(t)
        if up > 0.0:
            return up if rise >= lifted else 0.0
        return up if lifted > 0.0 else 0.0


def frame_row(cell: ShearBox, path: DirectShearPath, scene, state, contact, walls: tuple, density: float) -> list:
    t = state.t
    sigma_n, tau = cell.stresses(contact.wall_reactions, *walls)
    x, y = path.displacements(t)
    solids = float(np.sum(body_volumes(state.x, *scene.surface_triangles(), scene.n_grains)))
    records = contact.records(scene.contact.all_positions(state.x, t))
    z_m = coordination(records.a, records.b, scene.n_grains)["mechanical_coordination"]
    rate = abs(cell.drive.speed) / cell.height(t)
    inertia = rate * cell.grain_size / np.sqrt(sigma_n / density) if sigma_n > 0 else np.inf
    ratio = tau / sigma_n if sigma_n > 0 else np.nan
    stage = min(path.current, len(STAGES) - 1)
    unbalanced = unbalanced_force(state, scene.bodies.lumped, scene.bodies.vertex_ptr, contact)
    return [t, stage, x, y, sigma_n, tau, ratio, cell.volume(t) / solids - 1.0, z_m, inertia, unbalanced,
            cell.frame.travel(t)]  # fmt: skip


def run(cfg: dict, out_dir: Path, base_dir=None, progress=None, resume: bool = False) -> dict:
    t_start = time.perf_counter()
    out_dir = Path(out_dir)
    initial, state_path = initial_state_from(cfg, base_dir, out_dir, progress, resume)
    cell = ShearBox(cfg, initial)
    sigma_n = cfg["normal"]["stress"]
    scene = scene_from(initial.grains, contact_at_stress(cfg, sigma_n, cell.grain_size), cell.walls, cell.meshes)
    integrator = make_integrator(solver_options_from(cfg), scene)
    density = scene.material.density
    rate = cfg["shear"]["inertia_number"] * np.sqrt(sigma_n / density) / cell.grain_size
    cap = cfg["servo"]["inertia_number"] * np.sqrt(sigma_n / density) / cell.grain_size * cell.height0
    servo = Servo(scene.contact, cell.lid, cell.area, gain=cfg["servo"]["gain"], max_speed=cap, target=sigma_n)
    speed = rate * cell.height0
    path = DirectShearPath(cell, servo, cfg, speed, scene.bodies.lumped, scene.bodies.vertex_ptr)
    names = scene.contact.wall_names
    walls = (names.index("lid"), [names.index(n) for n in LOWER])
    identity = run_identity(cfg, SCHEMA)
    shear_time = min(cfg["shear"]["max_time"], cell.travel_max / speed)
    duration = cfg["normal"]["max_time"] + shear_time + 2 * cfg["output"]["every"]
    result, rows = run_stages(scene, integrator, out_dir, cfg, identity, initial, path, "shear.csv", HEADER,
                              lambda state, contact: frame_row(cell, path, scene, state, contact, walls, density),
                              lambda t, x: cell.volume(t), duration, progress, resume)  # fmt: skip
    figures = shear_figures(rows)
    title = f"{scene.n_grains} grains ({cfg['model']['grains']}), sigma_n = {sigma_n / 1e3:g} kPa, {integrator.name}"
    plot_shear(rows, out_dir / "shear.png", title, figures)
    return write_summary("direct_shear", scene, result, t_start, out_dir, figures,
                         path.stage_records("end_displacement_share"), cell, state_path, identity,
                         normal_stress_Pa=sigma_n, shear_speed=speed)  # fmt: skip
