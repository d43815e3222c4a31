"""`scenario = "triaxial"`: drained triaxial compression of a cuboid sample between six walls
(docs/triaxial.md).

The settled pack stays where it settled; its box becomes a cell of six frictionless walls: the
floor (the bottom platen, fixed), four lateral walls and a top platen that starts `sample.gap`
mean grain sizes above the pack's highest point. Two stages:

1. consolidation: the top platen and the four lateral walls are each steered by a servo
   (model/servo.py) to the confining stress; the stage ends when all five hold it within
   `servo.stress_tolerance` with the sample at rest (the unbalanced force ratio below
   `servo.unbalanced_tolerance`, driver/stages.py), or at its `max_time`;
2. shear: the top platen moves down at a constant speed (the axial strain rate that gives
   `shear.inertia_number` at the confining stress, over the consolidated height) while the
   lateral walls' servos hold the confining stress; the stage ends at `shear.max_strain` of axial
   strain, or at its `max_time`.

Frictionless walls: the platens' friction would restrain the sample's ends (a barrel instead of a
homogeneous strain), which the established DEM triaxials leave out as well.

sigma_1 = the top platen's force over its area (the sample's current section), sigma_3 = the mean
over the lateral walls of force over area (side x current height), q = sigma_1 - sigma_3, p =
(sigma_1 + 2 sigma_3) / 3; axial strain = 1 - H / H_c and volumetric strain = 1 - V / V_c
(compression positive) from the sample where its stage began (as built for consolidation,
consolidated for shear); void ratio = V / the grains' volume - 1.

Outputs in DIR: triaxial.csv (one row per frame: analysis.triaxial.HEADER), triaxial.png (q/p and
the volumetric strain against the axial strain), summary.json (phi_peak_deg, phi_cs_deg with its
spread, dilatancy_angle_deg, E50_Pa, max_inertia_number, preparation, stages), fabric.csv and the
scene outputs; `--resume` continues a run from inside either stage.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ..analysis.microstructure import anisotropy, coordination, fabric_tensor, love_weber_stress, pair_contacts
from ..analysis.triaxial import (
    FAILURE_STATES,
    HEADER,
    envelopes,
    plot_envelopes,
    plot_triaxial,
    triaxial_figures,
    until_sheared,
)
from ..config import lab_tables
from ..config.build import scene_from, solver_options_from
from ..contact.walls import PlaneWall, ServoMotion
from ..driver.stages import unbalanced_force
from ..geometry.mass import body_volumes
from ..model.bodies import equivalent_diameters
from ..model.servo import Servo
from ..solver.api import make_integrator
from .identity import run_identity
from .lab import STAGES, TwoStagePath, contact_at_stress, run_stages, write_summary
from .pack import initial_state_from

RESUMABLE = True
SCHEMA = lab_tables.TRIAXIAL
LATERAL = ("wall -x", "wall +x", "wall -y", "wall +y")


class TriaxialCell:
    """The six walls of one sample and its measures: dimensions from the walls' travel."""

    def __init__(self, cfg: dict, initial):
        meta = initial.meta
        self.box, self.floor = tuple(float(v) for v in meta["box"]), float(meta["floor"])
        cx, cy = (float(v) for v in meta["centre"])
        self.grain_size = float(np.mean(equivalent_diameters(np.array([g.volume for g in initial.grains]))))
        self.height0 = float(initial.x[:, 2].max()) - self.floor + cfg["sample"]["gap"] * self.grain_size
        hx, hy = 0.5 * self.box[0], 0.5 * self.box[1]
        sides = (((cx - hx, cy), (1.0, 0.0)), ((cx + hx, cy), (-1.0, 0.0)), ((cx, cy - hy), (0.0, 1.0)),
                 ((cx, cy + hy), (0.0, -1.0)))  # fmt: skip
        self.lateral = [PlaneWall(np.array([x, y, self.floor]), np.array([nx, ny, 0.0]), ServoMotion((nx, ny, 0.0)),
                                  name,
                                  frictionless=True)
                        for ((x, y), (nx, ny)), name in zip(sides, LATERAL)]  # fmt: skip
        self.top = PlaneWall(np.array([cx, cy, self.floor + self.height0]), np.array([0.0, 0.0, -1.0]),
                             ServoMotion((0.0, 0.0, -1.0)), "top", frictionless=True)  # fmt: skip
        floor = PlaneWall(np.array([cx, cy, self.floor]), np.array([0.0, 0.0, 1.0]), name="floor", frictionless=True)
        self.walls = [floor, *self.lateral, self.top]

    # ------------------------------------------------------------------ dimensions
    def widths(self, t: float) -> tuple[float, float]:
        d = [w.motion.travel(t) for w in self.lateral]
        return self.box[0] - d[0] - d[1], self.box[1] - d[2] - d[3]

    def height(self, t: float) -> float:
        return self.height0 - self.top.motion.travel(t)

    def volume(self, t: float) -> float:
        wx, wy = self.widths(t)
        return wx * wy * self.height(t)

    def areas(self, t: float) -> list[float]:
        """Loaded areas of the lateral walls (in LATERAL's order) and of the top platen."""
        wx, wy, h = *self.widths(t), self.height(t)
        return [wy * h, wy * h, wx * h, wx * h, wx * wy]

    def stresses(self, reactions: np.ndarray, indices: list[int], normals: np.ndarray, t: float) -> tuple[float, float]:
        """(sigma_1, sigma_3): the top platen's stress and the lateral walls' mean stress (Pa)."""
        force = -np.einsum("ij,ij->i", reactions[indices], normals)
        stress = force / np.array(self.areas(t))
        return float(stress[4]), float(np.mean(stress[:4]))


class TriaxialPath(TwoStagePath):
    """Consolidation by the five servos, then shear by the platen at a constant speed with the four
    lateral servos (scenarios.lab.TwoStagePath)."""

    def __init__(self, cell: TriaxialCell, servos: list[Servo], cfg: dict, shear_rate: float, lumped, vertex_ptr):
        super().__init__(servos, cfg["consolidation"]["stress"],
                         (cfg["consolidation"]["max_time"], cfg["shear"]["max_time"]), cfg["servo"], lumped,
                         vertex_ptr)  # fmt: skip
        self.cell, self.max_strain, self.rate = cell, float(cfg["shear"]["max_strain"]), float(shear_rate)
        cell.now = 0.0  # the time the servos' areas are taken at

    def __call__(self, state, info) -> None:
        self.cell.now = state.t  # the servos' areas are the sample's at this step
        super().__call__(state, info)

    def begin(self, t: float) -> tuple:
        return t, self.cell.height(t), self.cell.volume(t)

    def strains(self, t: float) -> tuple[float, float]:
        """(axial, volumetric) strain from the sample where the current stage began."""
        _, h0, v0 = self.start if self.start is not None else (0.0, self.cell.height0, self.cell.volume(0.0))
        return 1.0 - self.cell.height(t) / h0, 1.0 - self.cell.volume(t) / v0

    def progress(self, t: float) -> float:
        return self.strains(t)[0]

    def consolidated(self) -> bool:
        return all(self.held(s) for s in self.servos)

    def sheared(self, t: float) -> str:
        return "max_strain" if self.strains(t)[0] >= self.max_strain else ""

    def steer(self, t: float) -> None:
        lateral, top = self.servos[:4], self.servos[4]
        for servo in lateral:
            servo.steer(t)
        if self.current == 0:
            top.steer(t)
        else:  # shear (and after it, the platen held): constant speed over the consolidated height
            top.motion.steer(t, self.rate * self.start[1] if self.current == 1 else 0.0)


def servos_for(cell: TriaxialCell, contact, cfg: dict, density: float) -> list[Servo]:
    """The lateral walls' servos and the top platen's, each capped at the speed that strains the
    sample along its axis at the rate of `servo.inertia_number` at the confining stress."""
    sigma_c = cfg["consolidation"]["stress"]
    rate = cfg["servo"]["inertia_number"] * np.sqrt(sigma_c / density) / cell.grain_size
    lengths = (cell.box[0], cell.box[0], cell.box[1], cell.box[1], cell.height0)
    servos = []
    for k, (wall, length) in enumerate(zip([*cell.lateral, cell.top], lengths)):
        area = (lambda k=k: cell.areas(cell.now)[k])
        servos.append(Servo(contact, wall, area, gain=cfg["servo"]["gain"], max_speed=rate * length, target=sigma_c))
    return servos


def frame_row(cell: TriaxialCell, path: TriaxialPath, scene, state, contact, walls: tuple, density: float) -> list:
    t = state.t
    sigma_1, sigma_3 = cell.stresses(contact.wall_reactions, *walls, t)
    q, p = sigma_1 - sigma_3, (sigma_1 + 2.0 * sigma_3) / 3.0
    axial, volumetric = path.strains(t)
    solids = float(np.sum(body_volumes(state.x, *scene.surface_triangles(), scene.n_grains)))
    records = contact.records(scene.contact.all_positions(state.x, t))
    z_m = coordination(records.a, records.b, scene.n_grains)["mechanical_coordination"]
    pairs = pair_contacts(records.a, records.b, records.normal, records.force, scene.n_grains)
    a = anisotropy(fabric_tensor(pairs.normal)) if len(pairs.normal) else np.nan
    wx, wy = cell.widths(t)
    h = cell.height(t)
    # the largest strain rate of the three axes: the platen's, or a lateral wall pair's
    rates = [abs(path.servos[4].motion.speed) / h, abs(path.servos[0].motion.speed + path.servos[1].motion.speed) / wx,
             abs(path.servos[2].motion.speed + path.servos[3].motion.speed) / wy]  # fmt: skip
    inertia = max(rates) * cell.grain_size / np.sqrt(p / density) if p > 0 else np.inf
    stage = min(path.current, len(STAGES) - 1)
    # the stress inside the sample, from its contacts: the walls' stresses checked independently
    lw = love_weber_stress(records.a, records.b, records.point, records.force, scene.grain_centroids(state.x),
                           cell.volume(t))  # fmt: skip
    return [t, stage, axial, volumetric, sigma_1, sigma_3, q, p, cell.volume(t) / solids - 1.0, z_m, a, inertia,
            lw[2, 2], 0.5 * (lw[0, 0] + lw[1, 1]),
            unbalanced_force(state, scene.bodies.lumped, scene.bodies.vertex_ptr, contact)]  # fmt: skip


def preparation(cfg: dict, figures_e0: float) -> dict:
    """How the sample was prepared: a pack settled with less friction than it is sheared with is
    denser (the established way to make dense and loose samples of one grain)."""
    pack_mu, mu = cfg["pack"]["mu_s"], cfg["contact"]["mu_s"]
    return {"name": "dense" if pack_mu < mu else "loose", "pack_mu_s": pack_mu, "test_mu_s": mu,
            "void_ratio_consolidated": figures_e0}  # fmt: skip


def run(cfg: dict, out_dir: Path, base_dir=None, progress=None, resume: bool = False) -> dict:
    t_start = time.perf_counter()
    out_dir = Path(out_dir)
    initial, state_path = initial_state_from(cfg, base_dir, out_dir, progress, resume)
    cell = TriaxialCell(cfg, initial)
    sigma_c = cfg["consolidation"]["stress"]
    scene = scene_from(initial.grains, contact_at_stress(cfg, sigma_c, cell.grain_size), cell.walls)
    integrator = make_integrator(solver_options_from(cfg), scene)
    density = scene.material.density
    servos = servos_for(cell, scene.contact, cfg, density)
    shear_rate = cfg["shear"]["inertia_number"] * np.sqrt(sigma_c / density) / cell.grain_size
    path = TriaxialPath(cell, servos, cfg, shear_rate, scene.bodies.lumped, scene.bodies.vertex_ptr)
    names = scene.contact.wall_names
    indices = [names.index(n) for n in (*LATERAL, "top")]
    normals = np.array([w.normal for w in (*cell.lateral, cell.top)])
    identity = run_identity(cfg, SCHEMA)

    def row(state, contact):
        cell.now = state.t
        return frame_row(cell, path, scene, state, contact, (indices, normals), density)

    shear_time = min(cfg["shear"]["max_time"], cfg["shear"]["max_strain"] / shear_rate)
    duration = cfg["consolidation"]["max_time"] + shear_time + 2 * cfg["output"]["every"]
    result, rows = run_stages(scene, integrator, out_dir, cfg, identity, initial, path, "triaxial.csv", HEADER, row,
                              lambda t, x: cell.volume(t), duration, progress, resume)  # fmt: skip
    records = path.stage_records()
    rows = until_sheared(rows, records[1]["end_time"] if len(records) > 1 else None)
    figures = triaxial_figures(rows)
    shear_rows = rows[rows[:, 1] == 1]
    e0 = float(shear_rows[0, 8]) if len(shear_rows) else None
    title = f"{scene.n_grains} grains ({cfg['model']['grains']}), sigma_3 = {sigma_c / 1e3:g} kPa, {integrator.name}"
    plot_triaxial(rows, out_dir / "triaxial.png", title, figures)
    return write_summary("triaxial", scene, result, t_start, out_dir, figures, records, cell,
                         state_path, identity, confining_stress_Pa=sigma_c, axial_strain_rate=shear_rate,
                         preparation=preparation(cfg, e0))  # fmt: skip


def envelope_panel(title: str, summaries: list[dict], fit: dict) -> tuple:
    """One panel of a sweep's envelope.png: the tests' peak states and the peak and critical-state
    envelopes (analysis.triaxial.plot_envelopes)."""
    (_, s3_key, s1_key), _ = FAILURE_STATES
    have = [s for s in summaries if isinstance(s.get(s3_key), float) and isinstance(s.get(s1_key), float)]
    peak = {"phi_deg": fit["envelope_phi_peak_deg"], "cohesion_Pa": fit["envelope_cohesion_peak_Pa"]}
    cs = ({"phi_deg": fit["envelope_phi_cs_deg"], "cohesion_Pa": fit["envelope_cohesion_cs_Pa"]}
          if "envelope_phi_cs_deg" in fit else None)  # fmt: skip
    return title, [s[s3_key] for s in have], [s[s1_key] for s in have], peak, cs


# A sweep over `key` gives Mohr-Coulomb envelopes (sweep.add_envelopes): `fit` of a group's
# summaries, `panel` and `plot` its figure
ENVELOPE = {"key": "consolidation.stress", "fit": envelopes, "panel": envelope_panel, "plot": plot_envelopes}
