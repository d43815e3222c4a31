"""`scenario = "triaxial"`: drained triaxial compression of a cuboid sample between six walls
(docs/triaxial.md).

The settled pack stays where it settled; its box becomes a cell of six frictionless walls: the
floor (the bottom platen, fixed), four lateral walls and a top platen that starts `sample.gap`
mean grain sizes above the pack's highest point. Two stages:

1. consolidation: the top platen and the four lateral walls are each steered by a servo
   (lab/servo.py) to the confining stress; the stage ends when all five hold it within
   `servo.stress_tolerance` with the sample at rest (the unbalanced force ratio below
   `servo.unbalanced_tolerance`, lab/path.py), or at its `max_time`;
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
from ..geometry.mass import body_volumes
from ..lab.cell import SIDES, BoxCell
from ..lab.path import Drive, LoadPath, Stage, unbalanced_force
from ..lab.run import Frames, run_path, write_summary
from ..lab.servo import Servo, quasi_static_rate
from .identity import run_identity
from .lab import check_every, output_of, sample_in, servo_options, warn_unmeasured

RESUMABLE = True
SCHEMA = lab_tables.TRIAXIAL
LOADED = (*SIDES, "top")  # the servo walls: the lateral ones, then the top platen


def cell_for(cfg: dict, initial) -> BoxCell:
    """Six frictionless walls: the floor stays, the lateral walls and the top platen move."""
    return BoxCell(initial, cfg["sample"]["gap"], moving=LOADED, frictionless=("floor", *LOADED))


def mark(cell: BoxCell):
    """What a stage's strains are measured from: (its start time, the sample's height and volume)."""
    return lambda t: (t, cell.height(t), cell.volume(t))


def strains(cell: BoxCell, start: tuple | None, t: float) -> tuple[float, float]:
    """(axial, volumetric) strain from the sample where the current stage began."""
    _, h0, v0 = start if start is not None else (0.0, cell.height0, cell.volume(0.0))
    return 1.0 - cell.height(t) / h0, 1.0 - cell.volume(t) / v0


def servos_for(cell: BoxCell, contact, cfg: dict, density: float) -> list[Servo]:
    """The lateral walls' servos and the top platen's, each capped at the speed that strains the
    sample along its axis at the rate of `servo.inertia_number` at the confining stress."""
    sigma_c = cfg["consolidation"]["stress"]
    rate = quasi_static_rate(cfg["servo"]["inertia_number"], sigma_c, density, cell.grain_size)
    lengths = (cell.box[0], cell.box[0], cell.box[1], cell.box[1], cell.height0)
    return [Servo(contact, cell.wall[name], (lambda t, name=name: cell.area(name, t)), gain=cfg["servo"]["gain"],
                  max_speed=rate * length, target=sigma_c)
            for name, length in zip(LOADED, lengths)]  # fmt: skip


def stages_for(cfg: dict, shear_rate: float) -> list[Stage]:
    """Consolidation by the five servos; shear by the platen at a constant strain rate over the
    consolidated height, the lateral servos holding the confining stress."""
    sigma_c = cfg["consolidation"]["stress"]
    key = "consolidation.stress"
    return [Stage((sigma_c,) * 5, cfg["consolidation"]["max_time"], rates=(None,), name="consolidation", key=key),
            Stage((sigma_c,) * 4 + (None,), cfg["shear"]["max_time"], cfg["shear"]["max_strain"],
                  rates=(shear_rate,), name="shear", key=key)]  # fmt: skip


def frame_row(cell: BoxCell, path: LoadPath, scene, state, contact, indices: list, density: float) -> list:
    t = state.t
    stress = cell.stresses(contact.wall_reactions, indices, LOADED, t)
    sigma_1, sigma_3 = float(stress[4]), float(np.mean(stress[:4]))
    q, p = sigma_1 - sigma_3, (sigma_1 + 2.0 * sigma_3) / 3.0
    axial, volumetric = strains(cell, path.start, t)
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
    stage = min(path.current, len(path.stages) - 1)
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
    sigma_c = cfg["consolidation"]["stress"]
    sample = sample_in(cfg, out_dir, base_dir, progress, resume, cell_for, sigma_c)
    out_dir, t_start = sample.out_dir, sample.t_start
    cell, scene, integrator = sample.cell, sample.scene, sample.integrator
    density = scene.material.density
    shear_rate = quasi_static_rate(cfg["shear"]["inertia_number"], sigma_c, density, cell.grain_size)
    path = LoadPath(servos_for(cell, scene.contact, cfg, density), stages_for(cfg, shear_rate),
                    lambda t, start: strains(cell, start, t)[0], scene.bodies.lumped, scene.bodies.vertex_ptr,
                    drives=[Drive(cell.wall["top"].motion, lambda start: start[1])], mark=mark(cell),
                    region=cell.region, **servo_options(cfg))  # fmt: skip
    indices = [scene.contact.wall_names.index(n) for n in LOADED]
    frames = Frames("triaxial.csv", HEADER,
                    lambda state, contact: frame_row(cell, path, scene, state, contact, indices, density))
    shear_time = min(cfg["shear"]["max_time"], cfg["shear"]["max_strain"] / shear_rate)
    check_every(cfg, cfg["consolidation"]["max_time"] + shear_time,
                "consolidation.max_time, then the shear to shear.max_strain at shear.inertia_number")
    duration = cfg["consolidation"]["max_time"] + shear_time + 2 * cfg["output"]["every"]
    identity = run_identity(cfg, SCHEMA)
    result, rows = run_path(scene, integrator, path, sample.initial, out_dir, duration=duration, output=output_of(cfg),
                            identity=identity, frames=frames, volume=cell.volume, progress=progress,
                            resume=resume)  # fmt: skip
    records = path.stage_records()
    rows = until_sheared(rows, records[1]["end_time"] if len(records) > 1 else None)
    figures = triaxial_figures(rows, sigma_c)
    warn_unmeasured(figures)
    shear_rows = rows[rows[:, 1] == 1]
    e0 = float(shear_rows[0, 8]) if len(shear_rows) else None
    title = f"{scene.n_grains} grains ({cfg['model']['grains']}), sigma_3 = {sigma_c / 1e3:g} kPa, {integrator.name}"
    plot_triaxial(rows, out_dir / "triaxial.png", title, figures)
    return write_summary(out_dir, "triaxial", scene, result, t_start, records, state_path=sample.state_path,
                         fingerprint=identity.fingerprint, **figures, confining_stress_Pa=sigma_c,
                         axial_strain_rate=shear_rate, preparation=preparation(cfg, e0),
                         sample_start_height=cell.height0, grain_size=cell.grain_size)  # fmt: skip


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
