"""Checkpoints: the whole integrator state after a frame, written atomically, so that
`vemdem run ... --resume` continues to the same result, bit for bit."""

from __future__ import annotations

import json
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..contact.model import ContactHistory
from ..io.state import UNREADABLE_NPZ
from ..solver.state import RunStats, State, StepControl


class CheckpointError(ValueError):
    """A checkpoint is missing, unreadable or belongs to another config; str(e) names the file."""


# The checkpoint's layout, saved in every checkpoint as its `format` entry. Raise it when an entry
# changes its meaning or a reader needs a new one, and read each older number here on purpose or
# refuse it in one line (a checkpoint read by guesswork resumes another run than the one it holds).
# 0: the checkpoints of vemdem 0.1.0 written before the number; the earliest of them lack books
#    added later (the walls' work, the linear solver's counters, the resumes' changes, the wall
#    time), which then start again at the resume
# 1: format 0 with its number
FORMAT = 1
READABLE_FORMATS = (0, 1)


class ResumeChangeWarning(UserWarning):
    """A run resumed with changed step-control keys: from there on it is not the uninterrupted run."""


@dataclass(frozen=True)
class RunIdentity:
    """What makes a run this run, for --resume: the config keys it does not take from their
    defaults (`choices`, see config.choices) and their digest. `legacy` is the digest of the whole
    checked config, which checkpoints written before the schema-growth rule carry: still accepted,
    so that a run started then can be continued."""

    fingerprint: str
    choices: dict = field(default_factory=dict)
    legacy: str = ""
    # the keys a resume may change ('solver.dt_max' -> the schema's default): how the run steps, not
    # what it models, so that a stalled run can be given another Newton budget without a restart
    adjustable: dict = field(default_factory=dict)

    def accepts(self, stored: str | None) -> bool:
        """Whether a fingerprint stored by a checkpoint or a stage's summary is this run's."""
        return stored is not None and stored in (self.fingerprint, self.legacy)


@dataclass
class WallWork:
    """The work the moving walls did on the grains since the run began (history.csv "wall_work"):
    the trapezoidal rule of each step (ContactModel.wall_work), so the grains' force on the walls
    at the last step (`force`, at time `t`) is carried to the next, and through checkpoints."""

    work: float
    force: np.ndarray  # (n_walls, 3) force of the grains on each wall at t
    t: float

    def add(self, contact, t: float, force: np.ndarray) -> None:
        self.work += contact.wall_work(self.t, t, self.force, force)
        self.force, self.t = force, t


def save_checkpoint(path: Path, state: State, control: StepControl, stats: RunStats, frame: int,
                    identity: RunIdentity, walls: WallWork | None = None, carried: dict | None = None,
                    changes: list | None = None, wall_seconds: float | None = None,
                    control_state: dict | None = None):  # fmt: skip
    """`carried`: the integrator's own (Integrator.carried), e.g. the linear solver's hold; `changes`: the
    step-control keys earlier resumes changed (Resumed.changes); `wall_seconds`: the time-loop's wall time
    of the run so far, all its parts (None: unknown, a run resumed from a checkpoint that kept none)."""
    tmp = path.with_suffix(".tmp.npz")
    h = state.history
    books = {} if walls is None else {"wall_work": walls.work, "wall_force": walls.force, "wall_t": walls.t}
    np.savez(tmp, format=FORMAT, t=state.t, x=state.x, v=state.v, a=state.a, dissipated=state.dissipated,
             power=state.power,
             keys=h.keys, c_prev=h.c_prev, gt=h.gt, stick=h.stick, dt=control.dt, easy_streak=control.easy_streak,
             accepted=stats.accepted, rejected=stats.rejected, newton=stats.newton_iterations,
             krylov=stats.krylov_iterations, frame=frame, fingerprint=identity.fingerprint,
             choices=json.dumps(identity.choices, sort_keys=True, default=str),
             rejections=json.dumps(stats.rejections), energy_gains=stats.energy_gains,
             frozen_pair_steps=stats.frozen_pair_steps, stick_break_steps=stats.stick_break_steps,
             damping_hold_steps=stats.damping_hold_steps, tangent_blocks=stats.tangent_blocks,
             exact_tangent_blocks=stats.exact_tangent_blocks,
             carried=json.dumps(carried or {}, sort_keys=True), resume_changes=json.dumps(changes or []), **books,
             **({} if wall_seconds is None else {"wall_seconds": wall_seconds}),
             **({} if control_state is None else {"control": json.dumps(control_state, sort_keys=True)}),
             **{f"body_{k}": v for k, v in state.bodies.items()})  # fmt: skip
    tmp.replace(path)  # atomic: an interrupted write never leaves a broken checkpoint


@dataclass
class Resumed:
    """What a checkpoint gives back: the state and the run's books at its frame. `walls` is None for
    a format-0 checkpoint that kept no walls' work (the book then starts again at the resume);
    `carried` is {} for one that kept no linear-solver counters (the linear solver then starts afresh).
    `changes`: the step-control keys this and earlier resumes changed, each {key, then, now, time,
    frame} (summary.json "resume_changes"); [] for a run resumed as it was started. `wall_seconds`:
    the time loop's wall time up to the checkpoint, over all parts; None for a checkpoint that kept
    none (a format-0 one, or a run resumed from one: the total is unknown)."""

    state: State
    stats: RunStats
    frame: int
    walls: WallWork | None
    carried: dict
    changes: list = field(default_factory=list)
    wall_seconds: float | None = None
    control: dict | None = None  # a load path's own state (lab/path.py); None where the run has none


def _check_state(path: Path, state: State, dt: float, frame: int, shape: tuple | None, end: tuple | None) -> None:
    """A checkpoint whose numbers cannot be a run's (damaged, or written for other grains or a
    shorter run: `end` = (frames, duration)): a CheckpointError naming what, before the run
    truncates its outputs to the checkpoint's time."""
    fault = None
    if shape is not None and not (state.x.shape == state.v.shape == state.a.shape == tuple(shape)):
        fault = f"positions of shape {state.x.shape}, where this scene's vertices are {tuple(shape)}"
    elif not all(np.all(np.isfinite(f)) for f in (state.x, state.v, state.a)):
        fault = "non-finite positions, velocities or accelerations"
    elif not all(np.all(np.isfinite(b)) for b in state.bodies.values() if np.asarray(b).dtype.kind == "f"):
        fault = f"non-finite body states ({', '.join(sorted(state.bodies))})"
    elif not (np.isfinite(state.t) and state.t >= 0.0):
        fault = f"time {state.t!r}"
    elif not (np.isfinite(dt) and dt > 0.0):
        fault = f"step {dt!r}"
    elif frame < 0:
        fault = f"frame {frame}"
    elif not (np.isfinite(state.dissipated) and np.isfinite(state.power)):
        fault = "non-finite energy books"
    elif end is not None and (frame > end[0] or state.t > end[1] * (1 + 1e-9)):
        fault = f"frame {frame}, t = {state.t:.6g} s, beyond this run's {end[0]} frames and {end[1]:g} s"
    if fault:
        raise CheckpointError(f"--resume: {path} holds {fault}: not a checkpoint of this run; "
                              "remove it and run again without --resume")  # fmt: skip


def load_checkpoint(path: Path, control: StepControl, identity: RunIdentity, shape: tuple | None = None,
                    end: tuple | None = None) -> Resumed:  # fmt: skip
    """The run at a checkpoint, read in one pass; control.dt and easy_streak are restored in place.
    Anything unreadable, from another config or of the wrong shape (`shape`: the scene's vertex
    array) or with numbers no run makes (non-finite, negative time, past `end` = (frames, duration))
    is a CheckpointError naming the file. A config that differs only in identity.adjustable keys is accepted, with a
    ResumeChangeWarning."""
    if not path.is_file():
        raise CheckpointError(f"--resume: no checkpoint at {path}")
    try:
        with np.load(path, allow_pickle=False) as d:
            _check_format(d, path, "--resume: ")
            changes = _config_changes(d, path, identity)
            history = ContactHistory(d["keys"], d["c_prev"], d["gt"], d["stick"].astype(bool))
            bodies = {k.removeprefix("body_"): d[k] for k in d.files if k.startswith("body_")}
            state = State(float(d["t"]), d["x"], d["v"], d["a"], history, float(d["dissipated"]), float(d["power"]),
                          bodies)  # fmt: skip
            control.dt = float(d["dt"])
            control.easy_streak = int(d["easy_streak"])
            resumed = Resumed(state, _run_stats(d), int(d["frame"]), _wall_work(d), _carried(d), _earlier_changes(d),
                              _wall_seconds(d), _control(d))  # fmt: skip
        _check_state(path, state, control.dt, resumed.frame, shape, end)
    except CheckpointError:
        raise
    except UNREADABLE_NPZ as exc:
        raise CheckpointError(f"--resume: {path} is not a readable checkpoint ({type(exc).__name__}); "
                              "remove it and run again without --resume") from None  # fmt: skip
    if changes:
        # a lowered dt_max or a raised dt_min holds from the first step on
        control.dt = min(max(control.dt, control.dt_min), control.dt_max)
        resumed.changes += [{**c, "time": state.t, "frame": resumed.frame} for c in changes]
        said = "; ".join(f"{c['key']} {c['then']} -> {c['now']}" for c in changes)
        warnings.warn(ResumeChangeWarning(
            f"--resume: {path.parent} goes on from t = {state.t:.6g} s with {said} (step control only; from here on "
            "the run is not the uninterrupted run's, to the bit; summary.json \"resume_changes\")"), stacklevel=2)
    return resumed


def checkpoint_books(path: Path) -> dict:
    """Where the run at a checkpoint stands, read without its config (`vemdem status`): simulated time,
    frames written, the step it goes on with, the books of steps and iterations, earlier resumes' changes.
    A CheckpointError naming the file when it cannot be read."""
    try:
        with np.load(path, allow_pickle=False) as d:
            _check_format(d, path)
            stats = _run_stats(d)
            books = {"time": float(d["t"]), "frame": int(d["frame"]), "step": float(d["dt"]),
                     "n_steps": stats.accepted, "n_rejected_steps": stats.rejected,
                     "rejections": dict(sorted(stats.rejections.items())),
                     "n_newton_iterations": stats.newton_iterations, "n_krylov_iterations": stats.krylov_iterations,
                     "newton_iterations_per_step": stats.newton_iterations / max(stats.accepted, 1),
                     "n_energy_gain_steps": stats.energy_gains, "resume_changes": _earlier_changes(d),
                     "wall_seconds_total": _wall_seconds(d)}  # fmt: skip
    except CheckpointError:
        raise
    except UNREADABLE_NPZ as exc:
        raise CheckpointError(f"{path} is not a readable checkpoint ({type(exc).__name__})") from None
    return books


def step_changes(path: Path, identity: RunIdentity) -> list[dict]:
    """What load_checkpoint would accept of `identity` against the checkpoint at `path`, without
    loading the run: [] for the same config, the changed step-control keys ({key, then, now}), or a
    CheckpointError naming the other keys that changed (a finished stage asks this of its own)."""
    try:
        with np.load(path, allow_pickle=False) as d:
            _check_format(d, path, "--resume: ")
            return _config_changes(d, path, identity)
    except CheckpointError:  # a ValueError too: the refusal itself, not an unreadable file
        raise
    except UNREADABLE_NPZ as exc:
        raise CheckpointError(f"--resume: {path} is not a readable checkpoint ({type(exc).__name__})") from None


def _check_format(d, path: Path, prefix: str = "") -> None:
    """A CheckpointError naming the file, its format and the ones this version reads, for a checkpoint
    of a format it cannot read (a newer vemdem's, or a damaged number); 0 where it has none."""
    number = d["format"] if "format" in d.files else np.array(0)
    found = number.item() if number.ndim == 0 else number.tolist()
    if type(found) is int and found in READABLE_FORMATS:  # not a bool, a float or a text
        return
    readable = ", ".join(map(str, READABLE_FORMATS))
    advice = ": resume it with the vemdem that wrote it, or run again without --resume" if prefix else ""
    raise CheckpointError(f"{prefix}{path} is a checkpoint of format {found!r}; this vemdem reads formats {readable} "
                          f"(it writes {FORMAT}){advice}")  # fmt: skip


def _config_changes(d, path: Path, identity: RunIdentity) -> list[dict]:
    """The step-control keys a resumed config changed against the open checkpoint `d`, each {key, then,
    now} ([] for the same config); a CheckpointError naming the first keys that differ when any other key
    changed (or the checkpoint keeps no choices to compare)."""
    if identity.accepts(str(d["fingerprint"])):
        return []
    then = json.loads(str(d["choices"])) if "choices" in d.files else None
    refused = f"--resume: {path} was written by a different config"
    if then is None:
        raise CheckpointError(refused)
    old, new = _flat(then), _flat(identity.choices)
    keys = sorted(k for k in old.keys() | new.keys() if old.get(k, "default") != new.get(k, "default"))
    fixed = [k for k in keys if k not in identity.adjustable]
    if fixed or not keys:
        allowed = f"; --resume may change only {', '.join(identity.adjustable)}" if identity.adjustable else ""
        raise CheckpointError(refused + _changes(old, new, fixed) + allowed)

    def value(tree, k):
        return tree.get(k, identity.adjustable[k])

    return [{"key": k, "then": value(old, k), "now": value(new, k)} for k in keys]


def _wall_seconds(d) -> float | None:
    """The time loop's wall time over the run's parts (None: a format-0 checkpoint, or a run resumed
    from one, kept none)."""
    return float(d["wall_seconds"]) if "wall_seconds" in d.files else None


def _earlier_changes(d) -> list:
    """The step-control changes of earlier resumes (early format-0 checkpoints keep none)."""
    if "resume_changes" not in d.files:
        return []
    changes = json.loads(str(d["resume_changes"]))
    if not isinstance(changes, list) or not all(isinstance(c, dict) for c in changes):
        raise ValueError("resume_changes: not a list of objects")
    return changes


def _run_stats(d) -> RunStats:
    krylov = int(d["krylov"]) if "krylov" in d.files else 0
    stats = RunStats(int(d["accepted"]), int(d["rejected"]), int(d["newton"]), krylov)
    if "rejections" in d.files:
        stats.rejections = json.loads(str(d["rejections"]))
        stats.energy_gains = int(d["energy_gains"])
    # the books below came one by one over format 0's life: an early checkpoint lacks the later ones
    if "frozen_pair_steps" in d.files:
        stats.frozen_pair_steps = int(d["frozen_pair_steps"])
    if "stick_break_steps" in d.files:
        stats.stick_break_steps = int(d["stick_break_steps"])
    if "damping_hold_steps" in d.files:
        stats.damping_hold_steps = int(d["damping_hold_steps"])
    if "tangent_blocks" in d.files:
        stats.tangent_blocks = int(d["tangent_blocks"])
        stats.exact_tangent_blocks = int(d["exact_tangent_blocks"])
    return stats


def _wall_work(d) -> WallWork | None:
    if "wall_work" not in d.files:
        return None
    return WallWork(float(d["wall_work"]), d["wall_force"].copy(), float(d["wall_t"]))


def _carried(d) -> dict:
    """The integrator's own part (Integrator.carry_on). vemdem writes a JSON object of counters: nested
    objects whose leaves are integers; anything else is a damaged file (ValueError)."""
    if "carried" not in d.files:
        return {}
    carried = json.loads(str(d["carried"]))
    if not _counters(carried):
        raise ValueError("carried: not an object of integer counters")
    return carried


def _control(d) -> dict | None:
    """The load control's own state (a servo's path, a load path's stage: lab/path.py), a JSON
    object; anything else is a damaged file (ValueError)."""
    if "control" not in d.files:
        return None
    control = json.loads(str(d["control"]))
    if not isinstance(control, dict):
        raise ValueError("control: not an object")
    return control


def _counters(tree) -> bool:
    if isinstance(tree, dict):
        return all(isinstance(k, str) and (_counters(v) or _integer(v)) for k, v in tree.items())
    return False


def _integer(value) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _changes(old: dict, new: dict, keys: list, shown: int = 3) -> str:
    """' (key: value then, value now; ...)' for the first of `keys` (flat, differing), '' for none."""
    if not keys:
        return ""
    items = [f"{k}: {old.get(k, 'default')} then, {new.get(k, 'default')} now" for k in keys[:shown]]
    more = f"; {len(keys) - shown} more" if len(keys) > shown else ""
    return " (" + "; ".join(items) + more + ")"


def _flat(tree, prefix: str = "") -> dict:
    """{'solver.dt_max': 1e-4, 'grains[0].size': ...} from nested tables and arrays of tables."""
    if isinstance(tree, dict):
        out = {}
        for k, v in tree.items():
            out.update(_flat(v, f"{prefix}.{k}" if prefix else str(k)))
        return out
    if isinstance(tree, list) and tree and all(isinstance(v, dict) for v in tree):
        out = {f"{prefix}.count": len(tree)}
        for i, v in enumerate(tree):
            out.update(_flat(v, f"{prefix}[{i}]"))
        return out
    return {prefix: tree}


def truncate_csv(path: Path, t_max: float):
    """Keep the header and the rows written up to the checkpoint (a resumed run rewrites the rest)."""
    lines = path.read_text().splitlines(keepends=True)
    keep = [lines[0]] + [ln for ln in lines[1:] if float(ln.split(",")[0]) <= t_max]
    path.write_text("".join(keep))
