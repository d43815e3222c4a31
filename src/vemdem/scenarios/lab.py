"""What the shear tests share (scenarios.triaxial, scenarios.direct_shear): two stages, a
consolidation by servo walls and a shear at a constant speed, their records and checkpoints; the
contact law set for the test's load; the time loop around them and the summary's common keys."""

from __future__ import annotations

import warnings
from dataclasses import asdict
from pathlib import Path

import numpy as np

from ..driver.loop import simulate
from ..driver.summary import run_summary
from ..driver.stages import StageNotReached, StageRecord, from_jsonable, jsonable, unbalanced_force
from ..io.results import CsvLog, write_json

STAGES = ("consolidation", "shear")

# The contact law's reference force in units of stress x d^2: the mean stress of a sand near its
# peak (sigma_1 about 4 sigma_3) is about twice the confining stress, and a pair slides once its
# force is carried with an elastic slip within the contact layer, up to 2 / (mu (1 - switch
# factor)) reference forces (9.5 at mu 0.3): the strong chains at the peak stay inside that
REFERENCE_STRESS = 2.0


def contact_at_stress(cfg: dict, stress: float, grain_size: float) -> dict:
    """The config with the contact law set for the test's load: unless `[contact] reference_force`
    is given, REFERENCE_STRESS `stress` d^2, `stress` the confining stress or a shear box's normal
    stress (docs/contact.md: the weight's force, the default elsewhere, would leave the contacts at
    nanometre gaps where the barrier is stiffest, and the friction springs needing more slip than
    the contact layer is thick before a pair slides)."""
    if cfg["contact"]["reference_force"] is not None:
        return cfg
    force = REFERENCE_STRESS * stress * grain_size**2
    return {**cfg, "contact": {**cfg["contact"], "reference_force": force}}


class TwoStagePath:
    """The time loop's control of a shear test: every servo measured after every accepted step;
    stage 0 (consolidation) ends "reached" when `consolidated()` and the sample is at rest, stage 1
    (shear) when `sheared(t)` names its end; either at its max_time. A test gives `begin(t)` (where
    a stage begins, kept in `start`), `consolidated()`, `sheared(t)`, `progress(t)` (the record's
    end_strain) and `steer(t)`; `motions` are steered motions beyond the servos' (carried too)."""

    def __init__(self, servos: list, target: float, max_time: tuple, cfg_servo: dict, lumped, vertex_ptr,
                 motions: tuple = ()):  # fmt: skip
        self.servos, self.target, self.max_time = servos, float(target), tuple(float(t) for t in max_time)
        self.stress_tolerance = cfg_servo["stress_tolerance"]
        self.unbalanced_tolerance = cfg_servo["unbalanced_tolerance"]
        self.lumped, self.vertex_ptr, self.motions = lumped, vertex_ptr, tuple(motions)
        self.current = 0
        self.records: list[StageRecord] = []
        self.start = None

    @property
    def done(self) -> bool:
        return self.current >= len(STAGES)

    def stop(self, state) -> bool:
        return self.done

    def held(self, servo) -> bool:
        return abs(servo.stress - servo.target) <= self.stress_tolerance * servo.target

    def __call__(self, state, info) -> None:
        t = state.t
        for servo in self.servos:
            servo.keep_secant = self.current >= 1  # the shear deforms the sample under the holding walls
            servo.measure(info.wall_reactions, info.ints, info.floats, t)
        if not self.done:
            self._book(state, info)
        self.steer(t)

    def _book(self, state, info) -> None:
        t = state.t
        if not self.records or self.records[-1].stage != self.current:
            self.start = self.begin(t)
            self.records.append(StageRecord(self.current, self.target, t, self.servos[-1].stress, 0.0))
        rec = self.records[-1]
        rec.steps += 1
        rec.newton_iterations += int(info.iterations)
        reason = self._ended(rec, state, info)
        if reason:
            rec.end_time, rec.end_stress, rec.end_reason = t, self.servos[-1].stress, reason
            rec.end_strain = self.progress(t)
            self.current += 1
        rec.largest_speed = max(rec.largest_speed, max(abs(s.motion.speed) for s in self.servos))

    def _ended(self, rec: StageRecord, state, info) -> str:
        if self.current == 0:
            if self.consolidated():
                rec.unbalanced = unbalanced_force(state, self.lumped, self.vertex_ptr, info.contact)
                if rec.unbalanced <= self.unbalanced_tolerance:
                    return "reached"
        elif reason := self.sheared(state.t):
            return reason
        if state.t - rec.start_time >= self.max_time[self.current]:
            rec.unbalanced = unbalanced_force(state, self.lumped, self.vertex_ptr, info.contact)
            return "max_time"
        return ""

    # ---------------------------------------------------------------- checkpoints
    def carried(self) -> dict:
        return {"servos": [s.carried() for s in self.servos], "motions": [m.carried() for m in self.motions],
                "current": self.current, "records": [jsonable(asdict(r)) for r in self.records],
                "start": None if self.start is None else list(self.start)}  # fmt: skip

    def carry_on(self, carried: dict) -> None:
        for servo, c in zip(self.servos, carried["servos"]):
            servo.carry_on(c)
        for motion, c in zip(self.motions, carried["motions"]):
            motion.carry_on(c)
        self.current = int(carried["current"])
        self.records = [StageRecord(**from_jsonable(r)) for r in carried["records"]]
        self.start = None if carried["start"] is None else tuple(float(v) for v in carried["start"])

    def stage_records(self, progress_name: str = "end_strain") -> list[dict]:
        """The records as summary.json's `stages`, each named; end_strain under `progress_name`."""
        out = []
        for r in self.records:
            d = asdict(r)
            d.pop("at_end")
            d[progress_name] = d.pop("end_strain")
            out.append(jsonable({**d, "name": STAGES[r.stage]}))
        return out


def run_stages(scene, integrator, out_dir: Path, cfg: dict, identity, initial, path: TwoStagePath, table: str,
               header, row, volume, duration: float, progress=None, resume: bool = False):  # fmt: skip
    """The time loop with `path` as its control and one `row(state, contact)` of `table` (columns
    `header`) per frame; warns for a stage that ended at its time limit. Returns (the loop's
    result, the table's rows)."""
    resume_here = resume and (out_dir / "checkpoint.npz").is_file()
    csv_path = out_dir / table
    log = {}

    def on_frame(frame, state, contact):
        if not log:  # opened at the first frame: a resumed run's loop has cut the file back to its checkpoint by then
            log["csv"] = CsvLog(csv_path, list(header), mode="a" if resume_here and csv_path.is_file() else "w")
        log["csv"].write(*row(state, contact))

    try:
        result = simulate(scene, integrator, out_dir, duration=duration, every=cfg["output"]["every"],
                          vtk=cfg["output"]["vtk"], identity=identity, x0=initial.x, v0=initial.v,
                          friction0=initial.friction, resume=resume_here, progress=progress, stop=path.stop,
                          control=path, on_frame=on_frame, frame_csvs=(table,), volume=volume)  # fmt: skip
    finally:
        if log:
            log["csv"].close()
    for r in path.records:
        if r.end_reason in ("", "max_time"):
            ended = r.end_reason or "the run end"
            warnings.warn(StageNotReached(f"{STAGES[r.stage]} ended at {ended}, not at its target"), stacklevel=3)
    rows = np.atleast_2d(np.genfromtxt(csv_path, delimiter=",", skip_header=1))  # an empty cell: NaN
    return result, rows


def write_summary(scenario: str, scene, result, t_start: float, out_dir: Path, figures: dict, stages: list,
                  cell, state_path, identity, **extra) -> dict:  # fmt: skip
    """summary.json of a shear test: the run's, its measures (`figures`), `extra`, the stages and
    where the sample started."""
    summary = run_summary(scenario, scene, result, t_start)
    summary.update(figures)
    summary.update(extra)
    summary.update({"stages": stages, "sample_start_height": cell.height0, "grain_size": cell.grain_size,
                    "initial_state": str(state_path), "config_fingerprint": identity.fingerprint})  # fmt: skip
    write_json(out_dir / "summary.json", summary)
    return summary
