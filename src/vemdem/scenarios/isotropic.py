"""`scenario = "isotropic"`: isotropic compression of a cuboid sample between six servo walls
(docs/isotropic.md).

The settled pack stays where it settled; its box becomes a cell of six frictionless walls
(lab/cell.py), each steered by a servo (lab/servo.py) to the stage's stress: the `[[stages]]` in
turn, each ending when all six hold it within `servo.stress_tolerance` with the sample at rest,
or at its time or volumetric strain limit (lab/path.py). Each servo's speed is capped at the
speed that gives `servo.inertia_number` at the stage's stress along the sample's side.

p = the six walls' mean stress (each wall's force over the face it closes); volumetric strain =
1 - V / V_0 (compression positive) from the sample as built; bulk modulus = dp / d(volumetric
strain) from one stage's end to the next's.

Outputs in DIR: isotropic.csv (one row per frame: HEADER), summary.json (mean_stress_Pa,
volumetric_strain and bulk_modulus_Pa, one per stage end; stages), fabric.csv and the scene
outputs; `--resume` continues a run from inside any stage.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..config import lab_tables
from ..geometry.mass import body_volumes
from ..lab.cell import BoxCell
from ..lab.path import LoadPath, Stage, unbalanced_force
from ..lab.run import Frames, run_path, write_summary
from ..lab.servo import Servo, quasi_static_rate
from .identity import run_identity
from .lab import output_of, sample_in, servo_options

RESUMABLE = True
SCHEMA = lab_tables.ISOTROPIC
HEADER = ("time", "stage", "p", "sigma_x", "sigma_y", "sigma_z", "volumetric_strain", "void_ratio", "unbalanced")
WALLS = ("floor", "wall -x", "wall +x", "wall -y", "wall +y", "top")


def cell_for(cfg: dict, initial) -> BoxCell:
    """Six frictionless walls, all moving."""
    return BoxCell(initial, cfg["sample"]["gap"], moving=WALLS, frictionless=WALLS)


def stages_for(cfg: dict, cell: BoxCell, density: float) -> list[Stage]:
    """The config's stages, each servo capped at the speed that gives servo.inertia_number at the
    stage's stress along the sample's side it closes."""
    lengths = np.array([cell.height0, *(cell.box[0],) * 2, *(cell.box[1],) * 2, cell.height0])
    inertia = cfg["servo"]["inertia_number"]
    return [Stage((s["stress"],) * 6, s["max_time"], s["max_strain"],
                  max_speed=tuple(quasi_static_rate(inertia, s["stress"], density, cell.grain_size) * lengths),
                  key=f"stages[{k}].stress")
            for k, s in enumerate(cfg["stages"])]  # fmt: skip


def row(cell: BoxCell, path: LoadPath, scene, state, contact, indices: list) -> list:
    t = state.t
    s = cell.stresses(contact.wall_reactions, indices, WALLS, t)
    solids = float(np.sum(body_volumes(state.x, *scene.surface_triangles(), scene.n_grains)))
    unbalanced = unbalanced_force(state, scene.bodies.lumped, scene.bodies.vertex_ptr, contact)
    return [t, min(path.current, len(path.stages) - 1), np.mean(s), np.mean(s[1:3]), np.mean(s[3:5]),
            np.mean(s[[0, 5]]), path.strain(t, None), cell.volume(t) / solids - 1.0, unbalanced]  # fmt: skip


def measures(records: list[dict]) -> dict:
    """The mean stress and volumetric strain where each stage ended, and the bulk modulus from the
    last stage's end to this one's (None for the first: its strain is mostly the walls seating)."""
    p = [r.get("mean_stress_end") for r in records]  # none where a stage had not ended
    ev = [r.get("volumetric_strain_end") for r in records]
    bulk = [None] + [(p[k] - p[k - 1]) / (ev[k] - ev[k - 1]) if None not in (p[k], p[k - 1]) and ev[k] != ev[k - 1]
                     else None for k in range(1, len(records))]  # fmt: skip
    return {"mean_stress_Pa": p, "volumetric_strain": ev, "bulk_modulus_Pa": bulk}


def run(cfg: dict, out_dir: Path, base_dir=None, progress=None, resume: bool = False) -> dict:
    sample = sample_in(cfg, out_dir, base_dir, progress, resume, cell_for)
    out_dir, t_start = sample.out_dir, sample.t_start
    cell, scene = sample.cell, sample.scene
    servos = [Servo(scene.contact, cell.wall[n], (lambda t, n=n: cell.area(n, t)), gain=cfg["servo"]["gain"])
              for n in WALLS]  # fmt: skip
    volume0 = cell.volume(0.0)

    def strain(t: float, start=None) -> float:  # from the sample as built, whatever the stage
        return 1.0 - cell.volume(t) / volume0

    def at_end(state, info, stage: int) -> dict:  # the six walls' reactions where the stage ended
        return {"mean_stress_end": float(np.mean([s.stress for s in servos])), "volumetric_strain_end": strain(state.t)}

    path = LoadPath(servos, stages_for(cfg, cell, scene.material.density), strain, scene.bodies.lumped,
                    scene.bodies.vertex_ptr, at_end=at_end, region=cell.region, **servo_options(cfg))  # fmt: skip
    indices = [scene.contact.wall_names.index(n) for n in WALLS]
    frames = Frames("isotropic.csv", HEADER, lambda state, contact: row(cell, path, scene, state, contact, indices))
    duration = sum(s["max_time"] for s in cfg["stages"]) + len(cfg["stages"]) * cfg["output"]["every"]
    identity = run_identity(cfg, SCHEMA)
    result, _ = run_path(scene, sample.integrator, path, sample.initial, out_dir,
                         duration=duration, output=output_of(cfg), identity=identity, frames=frames,
                         volume=cell.volume, progress=progress, resume=resume)  # fmt: skip
    records = path.stage_records()
    return write_summary(out_dir, "isotropic", scene, result, t_start, records, state_path=sample.state_path,
                         fingerprint=identity.fingerprint, **measures(records), sample_start_height=cell.height0,
                         grain_size=cell.grain_size)  # fmt: skip
