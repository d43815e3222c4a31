"""`scenario = "oedometer"`: a settled pack in a rigid box, loaded by a stress-controlled lid along
a vertical stress path (docs/oedometer.md).

The pack stays in its box (floor and four fixed side walls, which measure the lateral stress). A
horizontal lid starts `lid.gap` mean grain sizes above the pack's highest point and is steered by
a servo (lab/servo.py) through the `[[stages]]` in turn: each stage holds its target stress
until it is reached with the sample at rest, or ends at its time or strain limit (lab/path.py;
the box is a lab/cell.py BoxCell). The lid's speed is capped where it would make the test faster
than quasi-static: at most the speed that gives `servo.inertia_number` at the stage's target
stress.

axial strain = lid travel / the lid's starting height above the floor; sigma_v = the lid's force
over its area; sigma_h = the side walls' mean normal force over their loaded area (box side x
sample height); void ratio = box section x sample height / the grains' current volume - 1.

Outputs in DIR: oedometer.csv (one row per frame: analysis.oedometer.HEADER), oedometer.png (e
against log sigma_v; sigma_h against sigma_v; the lid's force against the strain), summary.json
(K0, constrained_modulus_loading_Pa, constrained_modulus_unloading_Pa, hysteresis_energy,
residual_strain, max_inertia_number, stages: what each stage did, largest_grain_strain with one
warning line where a grain passed the element's validated 20 %), fabric_rose_stages.png (the
contact normals' rose where each stage ended), fabric.csv and the scene outputs; `--resume`
continues a run from inside any stage.
"""

from __future__ import annotations

import time
import warnings
from pathlib import Path

import numpy as np

from ..analysis.microstructure import coordination, love_weber_stress, pair_contacts, plot_fabric_rose
from ..analysis.oedometer import (
    HEADER,
    VALIDATED_STRAIN,
    grain_strain_maxima,
    grain_strain_summary,
    inertia_number,
    oedometer_figures,
    plot_oedometer,
    read_rows,
    turning_points,
)
from ..config import ConfigError, lab_tables
from ..config.build import scene_from, solver_options_from
from ..config.lab_rules import lid_area_problem
from ..geometry.mass import body_volumes
from ..lab.cell import SIDES, BoxCell
from ..lab.path import LoadPath, Stage, unbalanced_force
from ..lab.run import Frames, run_path, write_summary
from ..lab.servo import Servo
from ..solver.api import make_integrator
from .identity import run_identity
from .lab import check_sample, output_of, quasi_static_drive, servo_options, warn_if_not_quasi_static
from .pack import initial_state_from, pack_config

RESUMABLE = True
SCHEMA = lab_tables.OEDOMETER
# the contact network where each stage ended (normals, normal forces), for fabric_rose_stages.png
ROSE_FILE = "roses/stage_{}.npz"


class GrainStrainWarning(UserWarning):
    """A grain was strained past the range one virtual element per grain was validated in."""


class Oedometer:
    """The box, the lid and the measures of one test (the frames' rows and the stages' ends)."""

    def __init__(self, cfg: dict, initial):
        # a lubricated ring: side friction would carry part of the lid's load (up on loading, down
        # on unloading), so the lid's stress would not be the sample's
        self.cell = BoxCell(initial, cfg["lid"]["gap"], top="lid", moving=("lid",), top_area=cfg["lid"]["area"],
                            frictionless=() if cfg["ring"]["friction"] else SIDES)  # fmt: skip
        self.grains, self.lid, self.walls = initial.grains, self.cell.wall["lid"], self.cell.walls
        self.area, self.grain_size, self.height0 = self.cell.section(0.0), self.cell.grain_size, self.cell.height0

    def bind(self, scene, out_dir: Path, stages: list) -> None:
        self.scene, self.out_dir, self.stages = scene, Path(out_dir), stages
        (self.out_dir / ROSE_FILE).parent.mkdir(parents=True, exist_ok=True)
        names = scene.contact.wall_names
        self.lid_index = names.index("lid")
        self.side_index = [names.index(n) for n in SIDES]
        self.faces, self.face_grain = scene.surface_triangles()

    # ------------------------------------------------------------------ measures
    def height(self, t: float) -> float:
        return self.cell.height(t)

    def strain(self, t: float, start=None) -> float:
        return 1.0 - self.height(t) / self.height0

    def sigma_h(self, reactions: np.ndarray, t: float) -> float:
        return float(np.mean(self.cell.stresses(reactions, self.side_index, SIDES, t)))

    def at_stage_end(self, state, info, stage: int) -> dict:
        """The lateral stress and the contacts' sigma_zz (Love-Weber) where a stage ends: at rest, the
        latter is the lid's stress measured inside the sample. The contacts' normals and forces
        there are kept for the rose of the turning points (ROSE_FILE, one per stage)."""
        records = info.contact.records(self.scene.contact.all_positions(state.x, state.t))
        volume = self.area * self.height(state.t)
        pairs = pair_contacts(records.a, records.b, records.normal, records.force, self.scene.n_grains)
        np.savez(self.out_dir / ROSE_FILE.format(stage), t=state.t, target=self.stages[stage].target,
                 normals=pairs.normal, fn=pairs.fn)  # fmt: skip
        return {"sigma_h_end": self.sigma_h(info.wall_reactions, state.t),
                "sigma_v_contacts_end": love_weber_zz(self.scene, state.x, records, volume)}  # fmt: skip

    def row(self, state, contact, stage: int, density: float) -> list:
        h = self.height(state.t)
        force = float(contact.wall_reactions[self.lid_index][2])
        sigma_v = force / self.area
        solids = float(np.sum(body_volumes(state.x, self.faces, self.face_grain, self.scene.n_grains)))
        total = self.area * h
        speed = float(self.lid.motion.speed)
        records = contact.records(self.scene.contact.all_positions(state.x, state.t))
        lw = love_weber_zz(self.scene, state.x, records, total)
        z_m = coordination(records.a, records.b, self.scene.n_grains)["mechanical_coordination"]
        unbalanced = unbalanced_force(state, self.scene.bodies.lumped, self.scene.bodies.vertex_ptr, contact)
        return [state.t, stage, sigma_v, self.sigma_h(contact.wall_reactions, state.t), 1.0 - h / self.height0,
                total / solids - 1.0, solids / total, z_m,
                inertia_number(speed, h, self.grain_size, sigma_v, density), h, speed, force, lw, unbalanced]  # fmt: skip


def plot_stage_roses(out_dir: Path, records: list[dict]) -> None:
    """fabric_rose_stages.png: the contact normals' rose and the normal forces' distribution where
    each stage ended (the turning points of the path), one row per stage."""
    frames = []
    for r in records:
        path = out_dir / ROSE_FILE.format(r["stage"])
        if r["end_reason"] and path.is_file():
            with np.load(path) as d:
                label = f"stage {r['stage']}: {float(d['target']) / 1e3:g} kPa, {r['end_reason']} (t = {float(d['t']):.4g} s)"
                frames.append((label, d["normals"], d["fn"]))
    if frames:
        plot_fabric_rose(out_dir / "fabric_rose_stages.png", frames)


def love_weber_zz(scene, x, records, volume: float) -> float:
    """sigma_zz of the contacts' stress tensor (Love-Weber: the sum over grains of f (x) (x_c -
    x_g) over the sample volume; analysis.microstructure): the lid's stress, measured inside."""
    sigma = love_weber_stress(records.a, records.b, records.point, records.force, scene.grain_centroids(x), volume)
    return float(sigma[2, 2])


def stages_from(cfg: dict, density: float, height: float, grain_size: float) -> list[Stage]:
    """The config's stages, each with the servo's speed cap: the lid speed that gives the inertia
    number servo.inertia_number at the stage's target (rate = speed / height)."""
    inertia = cfg["servo"]["inertia_number"]
    return [Stage(s["stress"], s["max_time"], s["max_strain"],
                  max_speed=inertia * height * np.sqrt(s["stress"] / density) / grain_size, key=f"stages[{k}].stress")
            for k, s in enumerate(cfg["stages"])]  # fmt: skip


def pack_config_for(cfg: dict) -> dict:
    """The pack stage's config: the pack settles under the test's law (the material's, or a given
    reference force's), so that the test does not begin with a jump of every contact's force
    (docs/oedometer.md)."""
    return pack_config(cfg, cfg["contact"]["reference_force"])


def run(cfg: dict, out_dir: Path, base_dir=None, progress=None, resume: bool = False) -> dict:
    t_start = time.perf_counter()
    out_dir = Path(out_dir)
    initial, state_path = initial_state_from(cfg, base_dir, out_dir, progress, resume, pack_config_for(cfg))
    check_sample(cfg, initial)
    warn_if_not_quasi_static(cfg)
    test = Oedometer(cfg, initial)
    problem = lid_area_problem(cfg["lid"]["area"], test.cell.box[0] * test.cell.box[1], f"the box of {state_path}")
    if problem:
        raise ConfigError(problem)
    largest = max(s["stress"] for s in cfg["stages"])
    scene = scene_from(initial.grains, cfg, test.walls, quasi_static=quasi_static_drive(cfg, largest))
    integrator = make_integrator(solver_options_from(cfg), scene)
    density = scene.material.density
    stages = stages_from(cfg, density, test.height0, test.grain_size)
    test.bind(scene, out_dir, stages)
    servo = Servo(scene.contact, test.lid, test.area, gain=cfg["servo"]["gain"])
    path = LoadPath([servo], stages, test.strain, scene.bodies.lumped, scene.bodies.vertex_ptr,
                    at_end=test.at_stage_end, region=test.cell.region, **servo_options(cfg))  # fmt: skip
    frames = Frames("oedometer.csv", HEADER,
                    lambda state, contact: test.row(state, contact, min(path.current, len(stages) - 1), density))
    # a stage begins at the step after the last one ended and ends at the first step past its
    # max_time: up to a frame per stage on top of the stages' times lets the last one end at its limit
    duration = float(sum(s.max_time for s in stages)) + len(stages) * cfg["output"]["every"]
    identity = run_identity(cfg, SCHEMA)
    result, _ = run_path(scene, integrator, path, initial, out_dir, duration=duration, output=output_of(cfg),
                         identity=identity, frames=frames, volume=lambda t: test.area * test.height(t),
                         progress=progress, resume=resume)  # fmt: skip
    records = path.stage_records()
    rows = read_rows(out_dir / "oedometer.csv")
    figures = oedometer_figures(records, rows)
    title = f"{scene.n_grains} grains, E = {scene.material.E:.3g} Pa, {integrator.name}"
    plot_oedometer(rows, turning_points(records), out_dir / "oedometer.png", title, test.area)
    plot_stage_roses(out_dir, records)
    return write_summary(out_dir, "oedometer", scene, result, t_start, records, state_path=state_path,
                         fingerprint=identity.fingerprint, **figures,
                         largest_grain_strain=grain_strains(out_dir), lid_start_height=test.height0,
                         lid_area=test.area, grain_size=test.grain_size)  # fmt: skip


def grain_strains(out_dir: Path) -> dict:
    """The grains' largest strains over the run, with one warning where a grain passed the
    element's validated range."""
    strains = grain_strain_summary(grain_strain_maxima(out_dir / "grains.csv"))
    if strains["grains_past_validated_range"]:
        warnings.warn(GrainStrainWarning(
            f"{strains['grains_past_validated_range']} grains strained past the single element's validated range "
            f"({VALIDATED_STRAIN:.0%}): the largest {strains['max']:.1%} (grain {strains['grain']}); their forces there "
            "are the element's, not checked against refined FE (docs/oedometer.md)"), stacklevel=3)  # fmt: skip
    return strains
