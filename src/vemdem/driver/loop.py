"""The time loop every dynamic scenario shares.

    simulate(scene, integrator, out_dir, duration=, every=, ...) -> Run

A frame (history.csv, grains.csv, walls.csv, ParaView) every `every` s up to `duration`, a
checkpoint after each frame, and inside a frame at least every CHECKPOINT_EVERY_S wall seconds
where the integrator resumes bit for bit from any step (implicit Newmark); after each frame `stop(state)` may end the run early (deterministic:
a resumed run stops at the same frame); after every accepted step `control.after_step(state,
info)` may act on the scene (e.g. move a servo wall from the reactions in `info.wall_reactions`),
which is how stress-controlled tests drive their walls (a `Control`). Scenarios are short recipes
over this loop.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

import numpy as np

from ..contact.model import ContactHistory, PenetrationError
from ..model.scene import Scene
from ..solver.api import Integrator
from ..solver.state import RunStats, State, StepInfo
from .checkpoint import CheckpointError, RunIdentity, WallWork, load_checkpoint, save_checkpoint, truncate_csv
from .frames import FRAME_CSVS, FrameWriter


# Between frames, a progress line at most this often (wall seconds): a frame of a jammed lid cycle
# takes minutes, and a bar that only moves per frame looks like a hang.
PROGRESS_EVERY_S = 5.0

# Inside a frame, a checkpoint at least this often (wall seconds): a frame of the 515-grain lid
# cycle's jam took 20-80 minutes, all of it lost when the run was stopped before the frame's end.
CHECKPOINT_EVERY_S = 600.0


class Control(Protocol):
    """What the loop asks of a load control (a servo's path, a lab test's stages, a tilting box's
    gravity). `after_step` runs after every accepted step and may act on the scene it was built
    for (a wall's steered motion, the scene's gravity), never on the loop's own state.
    `carried()` is everything it decides from, for a checkpoint: a dict that `carry_on` takes back
    on a resume, so the run goes on bit for bit from inside a frame; None where it keeps what a
    checkpoint does not carry, so the loop checkpoints at frames only."""

    def after_step(self, state: State, info: StepInfo) -> None: ...

    def carried(self) -> dict | None: ...

    def carry_on(self, carried: dict) -> None: ...


class InitialStateError(ValueError):
    """The initial state is not admissible (a grain behind a wall): str(e) names the cause."""


@dataclass
class Run:
    """What the shared time loop hands back to a scenario."""

    state: State
    stats: RunStats
    stopped_early: bool  # `stop` ended the run before `duration`
    last_contact: object  # the ContactResult at the last frame
    integrator: Integrator
    wall_seconds: float = 0.0
    out_dir: Path | None = None  # where its frames are (summary: the energy balance from history.csv)
    resume_changes: list = field(default_factory=list)  # step-control keys resumes changed (checkpoint.Resumed)
    # the time loop's wall time of the parts before this one (a resumed run; None: a checkpoint kept none)
    earlier_wall_seconds: float | None = 0.0


def simulate(scene: Scene, integrator: Integrator, out_dir: Path, *, duration: float, every: float, vtk: bool,
             identity: RunIdentity, x0=None, v0=None, friction0: dict | None = None, resume: bool = False, progress=None,
             stop=None, control: Control | None = None, on_frame=None, frame_csvs: tuple = (),
             volume=None) -> Run:  # fmt: skip
    """`on_frame(frame, state, contact)`, where given, sees every frame (its state and ContactResult)
    once it is written and before its checkpoint, so a run resumed from a frame's checkpoint has
    been through that frame's hook (the lid keeps the states where it turns and lets go).
    `frame_csvs`: the scenario's own per-frame CSVs in out_dir (time first), cut back with the
    loop's own on a resume. `volume(t, x)`: the sample's volume, where the scenario knows it (fabric.csv's
    Love-Weber stress)."""
    t_start = time.perf_counter()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    steps = integrator.control
    ckpt = out_dir / "checkpoint.npz"
    n_frames = _n_frames(duration, every)

    def checkpoint(st: State, frames_written: int) -> None:
        wall = None if earlier is None else earlier + time.perf_counter() - t_start
        own = control.carried() if control is not None else None  # a servo's path, a lab test's stage
        save_checkpoint(ckpt, st, steps, stats, frames_written, identity, walls, integrator.carried(), changes, wall, own)

    if resume:
        resumed = load_checkpoint(ckpt, steps, identity, scene.bodies.reference.shape, (n_frames, duration))
        state, stats, frame = resumed.state, resumed.stats, resumed.frame
        for name in FRAME_CSVS + tuple(frame_csvs):
            # the FrameWriter starts a missing fabric.csv afresh (a run from before it was written),
            # a scenario its own CSVs
            if name not in FRAME_CSVS[:3] and not (out_dir / name).is_file():
                continue
            truncate_csv(out_dir / name, state.t)
        writer = FrameWriter(scene, out_dir, vtk, resume_frames=frame + 1, lumped=integrator.lumped, volume=volume)
        last_contact = contact_now(scene, state)
        walls = resumed.walls or WallWork(0.0, last_contact.wall_reactions, state.t)
        integrator.carry_on(resumed.carried)
        if control is not None and control.carried() is not None:
            if resumed.control is None:
                raise CheckpointError(f"--resume: {ckpt} holds no state of this run's load control; start the run "
                                      "again without --resume")  # fmt: skip
            control.carry_on(resumed.control)
        changes, earlier = resumed.changes, resumed.wall_seconds
    else:
        try:
            history = ContactHistory(**friction0) if friction0 is not None else None
            state = integrator.initial_state(x0=x0, v0=v0, history=history)
        except PenetrationError as exc:
            raise InitialStateError(f"walls: a grain starts behind a wall ({exc})") from None
        stats, frame, changes, earlier = RunStats(), 0, [], 0.0
        writer = FrameWriter(scene, out_dir, vtk, resume_frames=None, lumped=integrator.lumped, volume=volume)
        last_contact = contact_now(scene, state)
        walls = WallWork(0.0, last_contact.wall_reactions, state.t)
        writer.write(state, scene.bodies.evaluate(state.x, force=False).total_energy, last_contact, walls.work)
        checkpoint(state, frame)
    last = {"shown": time.perf_counter(), "saved": time.perf_counter()}
    # Only an integrator that carries nothing between its steps but the checkpointed state and step
    # control continues bit for bit from a checkpoint written between two steps: the explicit ones
    # renew their pair search at every `advance` call, so they checkpoint at frames only.
    # A control may keep what it did since the last frame (the tilting box's gravity), which a
    # checkpoint does not carry (its `carried()` is None): such runs checkpoint at frames only too.
    inside_frames = getattr(integrator, "checkpoints_inside_frames", False) and (
        control is None or control.carried() is not None)

    def on_step(st, info, h):
        last["info"] = info
        walls.add(scene.contact, st.t, info.wall_reactions)
        if control is not None:
            control.after_step(st, info)
        if inside_frames and time.perf_counter() - last["saved"] >= CHECKPOINT_EVERY_S:
            # `frame` counts the frames written: a resumed run writes frame + 1 at its time
            checkpoint(st, frame)
            last["saved"] = time.perf_counter()
        if progress and time.perf_counter() - last["shown"] >= PROGRESS_EVERY_S:
            last["shown"] = time.perf_counter()
            progress(frame, n_frames, f"t = {st.t:.6g} s, step {h:.2e} s (inside frame {frame + 1})")

    # `stop` is asked at frames only: a run resumed from inside a frame goes on to that frame's end
    at_frame = state.t >= min(frame * every, duration) * (1 - 1e-12)
    stopped = stop is not None and frame > 0 and at_frame and stop(state)
    try:
        while frame < n_frames and not stopped:
            t_next = min((frame + 1) * every, duration)
            t_wall = time.perf_counter()
            steps_before, t_before, newton_before = stats.accepted, state.t, stats.newton_iterations
            state, stats = integrator.advance(state, t_next, on_step, stats)
            frame += 1
            last_contact = last["info"].contact
            writer.write(state, last["info"].strain_energy, last_contact, walls.work)
            if on_frame is not None:
                on_frame(frame, state, last_contact)
            checkpoint(state, frame)
            last["saved"] = time.perf_counter()
            if progress:
                taken = stats.accepted - steps_before
                rate = taken / max(time.perf_counter() - t_wall, 1e-9)
                # the frame's mean step: its last one is cut to land on the frame's time
                mean_dt = (state.t - t_before) / max(taken, 1)
                # implicit: Newton's iterations per step, what a stalled run's budget is judged by (docs/errors.md)
                newton = (stats.newton_iterations - newton_before) / max(taken, 1)
                per_step = f", {newton:.1f} Newton it./step" if newton > 0 else ""
                progress(frame, n_frames, f"t = {state.t:.4g} s, {rate:.1f} steps/s, mean dt = {mean_dt:.2e} s{per_step}")
                last["shown"] = time.perf_counter()
            stopped = stop is not None and stop(state)
    finally:
        writer.close()
    return Run(state, stats, bool(stopped), last_contact, integrator, time.perf_counter() - t_start, out_dir, changes,
               earlier)  # fmt: skip


def _n_frames(duration: float, every: float) -> int:
    return int(np.ceil(duration / every - 1e-9))


def contact_now(scene: Scene, state: State):
    """The contact state at a frame (for the energies, the reactions and the ParaView points)."""
    cand = scene.contact.search(state.x, state.t)
    return scene.contact.evaluate(state.x, state.t, cand, state.history, v=state.v)
