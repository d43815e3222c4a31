"""`scenario = "direct_shear"`: a split shear box (docs/direct-shear.md).

The settled pack stays where it settled; its box becomes a shear box split at `sample.split` of
the pack's height: the lower half (the floor and its two x sides, finite rectangles up to the
split) can move along x, the upper half's two x sides (from `sample.opening` mean grain sizes
above the split up, past the lid) stay,
the two y sides are frictionless planes along the shear, and a lid starts `sample.gap` mean
grain sizes above the pack. The floor and the lid are rough (the grains' friction): a shear box's
plates carry the shear into the sample. Two stages:

1. consolidation: the lid's servo (lab/servo.py) brings it to the normal stress; the stage
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

from pathlib import Path

import numpy as np

from ..analysis.direct_shear import HEADER, envelope_panel, envelopes, plot_envelopes, plot_shear, shear_figures
from ..analysis.microstructure import coordination
from ..config import ConfigError, lab_tables
from ..config.build import activation_gap_from
from ..geometry.mass import body_volumes
from ..lab.path import Drive, LoadPath, Stage, unbalanced_force
from ..lab.run import Frames, run_path, write_summary
from ..lab.servo import Servo, quasi_static_rate
from ..lab.shear_box import LOWER, FrameRide, OpeningTooWide, ShearBox
from .identity import run_identity
from .lab import check_every, output_of, sample_in, servo_options, warn_unmeasured

RESUMABLE = True
SCHEMA = lab_tables.DIRECT_SHEAR
# A sweep over `key` gives Coulomb envelopes (sweep.add_envelopes): `fit` of a group's summaries,
# `panel` and `plot` its figure
ENVELOPE = {"key": "normal.stress", "fit": envelopes, "panel": envelope_panel, "plot": plot_envelopes}


def shear_box(cfg: dict, initial) -> ShearBox:
    """The split box of the `[sample]` and `[shear]` tables around the settled pack."""
    sample = cfg["sample"]
    try:
        return ShearBox(initial, gap=sample["gap"], split=sample["split"], opening=sample["opening"],
                        travel=cfg["shear"]["max_displacement"], layer=lambda size: activation_gap_from(cfg, size))
    except OpeningTooWide as exc:
        raise ConfigError(f"sample.opening: {exc}") from None


def stages_for(cfg: dict, rate: float) -> list[Stage]:
    """Consolidation by the lid's servo, the halves held; shear by the lower half at a constant
    shear rate, the upper frame riding with the lid."""
    sigma_n = cfg["normal"]["stress"]
    return [Stage(sigma_n, cfg["normal"]["max_time"], rates=(0.0, 0.0), name="consolidation", key="normal.stress"),
            Stage(sigma_n, cfg["shear"]["max_time"], cfg["shear"]["max_displacement"], rates=(rate, 1.0),
                  name="shear", limit="max_displacement", key="normal.stress")]  # fmt: skip


def frame_row(cell: ShearBox, path: LoadPath, scene, state, contact, walls: tuple, density: float) -> list:
    t = state.t
    sigma_n, tau = cell.stresses(contact.wall_reactions, *walls)
    x, y = cell.displacements(path.start, t)
    solids = float(np.sum(body_volumes(state.x, *scene.surface_triangles(), scene.n_grains)))
    records = contact.records(scene.contact.all_positions(state.x, t))
    z_m = coordination(records.a, records.b, scene.n_grains)["mechanical_coordination"]
    rate = abs(cell.drive.speed) / cell.height(t)
    inertia = rate * cell.grain_size / np.sqrt(sigma_n / density) if sigma_n > 0 else np.inf
    ratio = tau / sigma_n if sigma_n > 0 else np.nan
    stage = min(path.current, len(path.stages) - 1)
    unbalanced = unbalanced_force(state, scene.bodies.lumped, scene.bodies.vertex_ptr, contact)
    return [t, stage, x, y, sigma_n, tau, ratio, cell.volume(t) / solids - 1.0, z_m, inertia, unbalanced,
            cell.frame.travel(t)]  # fmt: skip


def run(cfg: dict, out_dir: Path, base_dir=None, progress=None, resume: bool = False) -> dict:
    sigma_n = cfg["normal"]["stress"]
    sample = sample_in(cfg, out_dir, base_dir, progress, resume, shear_box, cfg["normal"]["stress"])
    out_dir, t_start = sample.out_dir, sample.t_start
    cell, scene, integrator = sample.cell, sample.scene, sample.integrator
    density = scene.material.density
    rate = quasi_static_rate(cfg["shear"]["inertia_number"], sigma_n, density, cell.grain_size)
    cap = quasi_static_rate(cfg["servo"]["inertia_number"], sigma_n, density, cell.grain_size) * cell.height0
    servo = Servo(scene.contact, cell.lid, cell.area, gain=cfg["servo"]["gain"], max_speed=cap, target=sigma_n)
    path = LoadPath([servo], stages_for(cfg, rate), lambda t, start: cell.displacements(start, t)[0] / cell.box[0],
                    scene.bodies.lumped, scene.bodies.vertex_ptr, mark=cell.mark, region=cell.region,
                    **servo_options(cfg),
                    drives=[Drive(cell.drive, lambda start: cell.height0), FrameRide(cell)])  # fmt: skip
    names = scene.contact.wall_names
    walls = (names.index("lid"), [names.index(n) for n in LOWER])
    frames = Frames("shear.csv", HEADER,
                    lambda state, contact: frame_row(cell, path, scene, state, contact, walls, density))
    speed = rate * cell.height0
    shear_time = min(cfg["shear"]["max_time"], cell.travel_max / speed)
    check_every(cfg, cfg["normal"]["max_time"] + shear_time,
                "normal.max_time, then the shear to shear.max_displacement at shear.inertia_number")
    duration = cfg["normal"]["max_time"] + shear_time + 2 * cfg["output"]["every"]
    identity = run_identity(cfg, SCHEMA)
    result, rows = run_path(scene, integrator, path, sample.initial, out_dir, duration=duration, output=output_of(cfg),
                            identity=identity, frames=frames, volume=cell.volume, progress=progress,
                            resume=resume)  # fmt: skip
    figures = shear_figures(rows, sigma_n)
    warn_unmeasured(figures)
    title = f"{scene.n_grains} grains ({cfg['model']['grains']}), sigma_n = {sigma_n / 1e3:g} kPa, {integrator.name}"
    plot_shear(rows, out_dir / "shear.png", title, figures)
    return write_summary(out_dir, "direct_shear", scene, result, t_start, path.stage_records("end_displacement_share"),
                         state_path=sample.state_path, fingerprint=identity.fingerprint, **figures,
                         normal_stress_Pa=sigma_n, shear_speed=speed, sample_start_height=cell.height0,
                         grain_size=cell.grain_size)  # fmt: skip
