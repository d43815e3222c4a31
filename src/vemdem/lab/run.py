"""One run for every laboratory test: its load path through the shared time loop, its own CSV
written at every frame, and its summary.

A test hands over typed options (no config dict: the scenario reads its tables): the path (the
loop's control and stop), the initial state, how often to write a frame, and `Frames`, its CSV's
name, header and one row per frame.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..driver.loop import simulate
from ..driver.summary import run_summary
from ..io.results import CsvLog, write_json
from .path import LoadPath
from .path import StageNotReached


@dataclass(frozen=True)
class Frames:
    """A test's own CSV: `table` in the run's folder, columns `header`, `row(state, contact)` per frame."""

    table: str
    header: tuple
    row: object


@dataclass(frozen=True)
class Output:
    """How often a frame is written (s), with or without its ParaView files."""

    every: float
    vtk: bool


def run_path(scene, integrator, path: LoadPath, initial, out_dir: Path, *, duration: float, output: Output,
             identity, frames: Frames, volume, progress=None, resume: bool = False):  # fmt: skip
    """The time loop with `path` as its control and stop, from `initial` (a hand-over state) or
    from the folder's checkpoint where `resume` finds one; `volume(t)` the sample's. Warns once
    per stage that did not end at its target (lab.path.LoadPath.unfinished). Returns (the loop's
    result, the CSV's rows: a row per frame, an empty cell as NaN)."""
    resume_here = resume and (out_dir / "checkpoint.npz").is_file()
    csv_path = out_dir / frames.table
    log = {}

    def on_frame(frame, state, contact):
        if not log:  # opened at the first frame: a resumed run's loop has cut the file back to its checkpoint by then
            log["csv"] = CsvLog(csv_path, list(frames.header), mode="a" if resume_here and csv_path.is_file() else "w")
        log["csv"].write(*frames.row(state, contact))

    try:
        result = simulate(scene, integrator, out_dir, duration=duration, every=output.every, vtk=output.vtk,
                          identity=identity, x0=initial.x, v0=initial.v, friction0=initial.friction,
                          resume=resume_here, progress=progress, stop=path.stop, control=path, on_frame=on_frame,
                          frame_csvs=(frames.table,), volume=lambda t, x: volume(t))  # fmt: skip
    finally:
        if log:
            log["csv"].close()
    for line in path.unfinished():
        warnings.warn(StageNotReached(line), stacklevel=3)
    return result, np.atleast_2d(np.genfromtxt(csv_path, delimiter=",", skip_header=1))


def write_summary(out_dir: Path, scenario: str, scene, result, t_start: float, stages: list, *, state_path,
                  fingerprint: str, **measures) -> dict:  # fmt: skip
    """summary.json of a lab test: the run's common keys, the test's `measures`, what each stage
    did, where the sample came from and the config's fingerprint."""
    summary = run_summary(scenario, scene, result, t_start)
    summary.update(measures)
    summary.update({"stages": stages, "initial_state": str(state_path), "config_fingerprint": fingerprint})
    write_json(Path(out_dir) / "summary.json", summary)
    return summary
