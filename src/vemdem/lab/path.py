"""A load path: stages over a test's servo walls (lab/servo.py) and constant-speed drives.

A stage names, for every servo, a target normal stress (Pa), or None where the servo lets a drive
move its wall; for every drive a rate (1/s), 0 where it holds its wall, or None where a servo
steers that wall in the stage. A stage ends

- "reached", in a stage that drives nothing: every servo with a target holds it within
  `stress_tolerance` AND the sample is at rest, its unbalanced force ratio below
  `unbalanced_tolerance`:

      unbalanced = mean over grains |sum_i m_i a_i| / mean over contact records |f|,

  the net force on each grain (the lumped masses are the consistent mass matrix's row sums, so
  sum_i m_i a_i is the grain's exact net force) against the mean contact force (YADE's
  unbalancedForce);
- at its `limit` (by default "max_strain"): the test's strain passed `max_strain`, in a stage that
  drives a wall (a shear's end), or in a loading one (a target the sample cannot reach there: an
  unloading stage always reaches its target, a wall that lets go of the sample is pushed back);
- "max_time": `max_time` seconds of simulated time after it began.

After the last stage the servos hold its targets and the drives stop. The test's strain is
`strain(t, start)`, `start` the test's own `mark(t)` where the stage began (the sample's height
there, say): a test measures its strain from where it likes.

The path is the time loop's control (driver.loop.Control: after every accepted step) and its
`stop` (at frames, once the last stage has ended). Everything it decides from is carried through
checkpoints, so a run resumed inside any stage goes on bit for bit. It books, per stage, the
reported servo's work on the sample (the trapezoidal rule of each step: N dd), the overshoot past
its target, the steps and the Newton iterations: the records `stage_records` returns.
"""

from __future__ import annotations

import warnings
from dataclasses import asdict, dataclass, field

import numpy as np


class StageNotReached(UserWarning):
    """A stage ended at its time or strain limit, not at its target."""


class StageTooLong(UserWarning):
    """A stage's steps so far project to days of wall time before its max_time."""


# A stage is projected to its end (its max_time, or its strain limit at its drive's rate) from its
# mean step over its first PROJECTED_AFTER steps; past MANY_STEPS it would run for hours at the few
# hundred to few thousand steps per second a laboratory sample takes (a target the contact law
# carries only at steps of nanoseconds)
PROJECTED_AFTER = 1000
MANY_STEPS = 1e7


class SampleFailed(RuntimeError):
    """The sample came apart: its state became non-finite, or a grain left the cell (a force the
    contact law could not carry). str(e) names the stage, its target and the key that set it."""


def _per_wall(values) -> tuple:
    """One value per wall: a single number (or None) stands for one wall."""
    return (values,) if values is None or np.ndim(values) == 0 else tuple(values)


@dataclass(frozen=True)
class Stage:
    stress: tuple  # per servo: its target normal stress (Pa), or None (a drive moves its wall)
    max_time: float  # s after the stage began
    max_strain: float = np.inf  # the stage ends at `limit` where the test's strain passes it
    max_speed: tuple = ()  # per servo: its speed cap in this stage (m/s); empty: the cap it was built with
    rates: tuple = ()  # per drive: its rate (1/s), 0 (held) or None (a servo steers its wall here)
    name: str = ""  # the record's name (summary.json `stages`), where the test names its stages
    limit: str = "max_strain"  # the end reason at max_strain
    key: str = ""  # where the test's input set its target (a config key), named where the sample fails in it

    def __post_init__(self):
        object.__setattr__(self, "stress", _per_wall(self.stress))
        object.__setattr__(self, "max_speed", _per_wall(self.max_speed))
        object.__setattr__(self, "rates", tuple(self.rates))

    @property
    def drives(self) -> bool:
        """A wall moves at a set speed: the servos hold their targets against it."""
        return any(r for r in self.rates)

    @property
    def target(self) -> float:
        """The stress a record reports against: the last servo's target, else the largest one."""
        if self.stress[-1] is not None:
            return float(self.stress[-1])
        return float(max(s for s in self.stress if s is not None))


class Drive:
    """A wall moved at a constant speed along its steered motion: rate x `length(start)`, the
    sample's length along it where the stage began (`start`, the test's mark)."""

    def __init__(self, motion, length):
        self.motion, self.length = motion, length

    def speed(self, t: float, rate: float, start: tuple) -> float:
        return rate * self.length(start)


@dataclass
class StageRecord:
    """What one stage did (summary.json `stages`)."""

    stage: int
    target: float
    start_time: float
    start_stress: float
    start_strain: float
    end_time: float = np.nan
    end_stress: float = np.nan
    end_strain: float = np.nan
    end_reason: str = ""  # reached | max_time | the stage's limit | "" (not ended)
    unbalanced: float = np.nan  # at the end
    overshoot: float = 0.0  # largest stress past the target, over the target (loading: above; unloading: below)
    work: float = 0.0  # the reported wall's work on the sample over the stage (J)
    steps: int = 0
    newton_iterations: int = 0
    largest_speed: float = 0.0  # the servo walls' largest speed (m/s)
    at_end: dict = field(default_factory=dict)  # the test's own measures where the stage ended (LoadPath.at_end)

    @property
    def loading(self) -> bool:
        return self.target >= self.start_stress


@dataclass
class LoadPath:
    """The stages of a test's servos and drives. `strain(t, start)` is the test's strain,
    `mark(t)` what it measures it from (kept where each stage begins); `lumped` the vertices'
    lumped masses, `vertex_ptr` the grains' vertex ranges; `at_end(state, info, stage)` what the
    test measures where a stage ends. The records report the last servo's stress (the wall along
    the test's axis)."""

    servos: list
    stages: list
    strain: object
    lumped: np.ndarray
    vertex_ptr: np.ndarray
    drives: list = field(default_factory=list)
    mark: object = None
    stress_tolerance: float = 0.01
    unbalanced_tolerance: float = 0.01
    at_end: object = None
    region: tuple | None = None  # (lower, upper) corners no vertex may leave: a grain out of them flew out
    current: int = 0
    records: list = field(default_factory=list)
    start: tuple | None = None  # the test's mark where the current stage began
    _last: tuple | None = None  # (travel, force) of the reported servo at the last step: the work's trapezoid

    def __post_init__(self):
        if not self.stages:
            raise ValueError("load path: no stages")
        if self.mark is None:
            self.mark = lambda t: (t,)
        self._enter(0)

    @property
    def done(self) -> bool:
        return self.current >= len(self.stages)

    @property
    def stage(self) -> Stage:
        """The stage being run, or the last one once the path is done (its targets held)."""
        return self.stages[min(self.current, len(self.stages) - 1)]

    def stop(self, state) -> bool:
        """The time loop's `stop`: the last stage has ended."""
        return self.done

    def _enter(self, k: int) -> None:
        stage = self.stages[k]
        for i, servo in enumerate(self.servos):
            if stage.stress[i] is not None:
                servo.target = stage.stress[i]
            if stage.max_speed:
                servo.max_speed = stage.max_speed[i]

    # ---------------------------------------------------------------- the control hook
    def after_step(self, state, info) -> None:
        """Measure every servo at the accepted state, book the stage, end it where it ends, and
        steer the walls for the next step."""
        stage = self.stage
        for servo in self.servos:
            servo.keep_secant = stage.drives  # a driven sample deforms under the holding walls
            servo.measure(info.wall_reactions, info.ints, info.floats, state.t)
        self._check_sample(state)
        rec = None if self.done else self._book(state, info)
        self._steer(state.t)
        if rec is not None:
            rec.largest_speed = max(rec.largest_speed, max(abs(s.motion.speed) for s in self.servos))

    def _open(self, state) -> StageRecord:
        """The current stage's record, opened at its first step."""
        if not self.records or self.records[-1].stage != self.current:
            self.start = tuple(float(v) for v in self.mark(state.t))
            stage = self.stages[self.current]
            self.records.append(StageRecord(self.current, stage.target, state.t, self.servos[-1].stress,
                                            self.strain(state.t, self.start)))  # fmt: skip
            self._last = None
        return self.records[-1]

    def _book(self, state, info) -> StageRecord:
        rec, servo, stage = self._open(state), self.servos[-1], self.stages[self.current]
        travel = servo.travel_at(state.t)
        if self._last is not None:
            rec.work += 0.5 * (self._last[1] + servo.force) * (travel - self._last[0])
        self._last = (travel, servo.force)
        rec.steps += 1
        if rec.steps == PROJECTED_AFTER:
            self._warn_if_endless(stage, rec, state.t)
        rec.newton_iterations += int(info.iterations)
        if stage.stress[-1] is not None:
            past = (servo.stress - rec.target) if rec.loading else (rec.target - servo.stress)
            rec.overshoot = max(rec.overshoot, past / max(rec.target, 1e-300))
        reason = self._ended(stage, rec, state, info)
        if reason:
            rec.end_time, rec.end_stress, rec.end_reason = state.t, servo.stress, reason
            rec.end_strain = self.strain(state.t, self.start)
            if self.at_end is not None:
                rec.at_end = self.at_end(state, info, self.current)
            self.current += 1
            if not self.done:
                self._enter(self.current)
                # the next stage begins here: a frame written at this state is the next stage's and
                # its strain is measured from here (opened at the next step, a frame at this one
                # carried the next stage's number with the strain of the stage before, and the
                # triaxial's E50 from that row read 1.5-2 times its curve's)
                self._open(state)
        return rec

    def _check_sample(self, state) -> None:
        """SampleFailed where the sample came apart at this step, before a frame writes it: a
        non-finite position or wall force (once written as inf in a test's table and summary), or
        a vertex out of `region` (grains that flew out of the cell; the walls then chase nothing
        until the stage's max_time)."""
        low, high = state.x.min(axis=0), state.x.max(axis=0)  # NaN propagates through both
        forces = [servo.force for servo in self.servos]
        if np.all(np.isfinite(low)) and np.all(np.isfinite(high)) and np.all(np.isfinite(forces)):
            if self.region is None or (np.all(low >= self.region[0]) and np.all(high <= self.region[1])):
                return
            lo, hi = self.region
            vertex = int(np.flatnonzero(np.any((state.x < lo) | (state.x > hi), axis=1))[0])
            grain = int(np.searchsorted(self.vertex_ptr, vertex, side="right")) - 1
            what = f"grain {grain} left the cell at t = {state.t:.6g} s: the grains flew apart"
        else:
            what = f"the sample's state became non-finite at t = {state.t:.6g} s"
        raise SampleFailed(f"{self._label()}: {what} (a force the contact law could not carry); the test stopped "
                           "there, without a summary: a lower target")  # fmt: skip

    def _warn_if_endless(self, stage, rec, t: float) -> None:
        """StageTooLong where the stage's mean step so far would take more than MANY_STEPS to its
        end: legal, and it may still reach its target first, so a warning, not a stop."""
        rate = max((abs(r) for r in stage.rates if r), default=0.0)
        horizon = min(stage.max_time, stage.max_strain / rate) if rate else stage.max_time
        mean = (t - rec.start_time) / rec.steps
        steps = horizon / mean if mean > 0 else np.inf
        if steps > MANY_STEPS:
            warnings.warn(StageTooLong(
                f"{self._label()}: {steps:.2g} steps to its end ({horizon:g} s) at its mean step so far "
                f"({mean:.2g} s), hours of wall time unless it reaches its target first: the contact law carries "
                "this load only at such steps; a lower target or a shorter max_time"), stacklevel=2)  # fmt: skip

    def _label(self) -> str:
        """The current stage in words: its name or number, its target and the key that set it."""
        k = min(self.current, len(self.stages) - 1)
        stage = self.stages[k]
        target = f"{stage.key} = {stage.target:g} Pa" if stage.key else f"{stage.target:g} Pa"
        return f"{stage.name or f'stage {k}'} ({target})"

    def held(self, servo) -> bool:
        return abs(servo.stress - servo.target) <= self.stress_tolerance * servo.target

    def _ended(self, stage: Stage, rec: StageRecord, state, info) -> str:
        steered = [s for s, target in zip(self.servos, stage.stress) if target is not None]
        if not stage.drives and all(self.held(s) for s in steered):
            rec.unbalanced = self.unbalanced(state, info)
            if rec.unbalanced <= self.unbalanced_tolerance:
                return "reached"
        if (stage.drives or rec.loading) and self.strain(state.t, self.start) >= stage.max_strain:
            return stage.limit
        if state.t - rec.start_time >= stage.max_time:
            rec.unbalanced = self.unbalanced(state, info)
            return "max_time"
        return ""

    def unbalanced(self, state, info) -> float:
        return unbalanced_force(state, self.lumped, self.vertex_ptr, info.contact)

    def _steer(self, t: float) -> None:
        """The servos with a target in the stage (after the last: its targets held), then the
        drives: at their rate in a running stage, held once the path is done."""
        stage = self.stage
        for servo, target in zip(self.servos, stage.stress):
            if target is not None:
                servo.steer(t)
        for drive, rate in zip(self.drives, stage.rates):
            if rate is None:
                continue
            speed = drive.speed(t, rate, self.start) if rate and not self.done else 0.0
            drive.motion.steer(t, speed)

    # ---------------------------------------------------------------- checkpoints
    def carried(self) -> dict:
        return {"servos": [s.carried() for s in self.servos], "drives": [d.motion.carried() for d in self.drives],
                "current": self.current, "records": [jsonable(asdict(r)) for r in self.records],
                "start": None if self.start is None else list(self.start),
                "last": None if self._last is None else list(self._last)}  # fmt: skip

    def carry_on(self, carried: dict) -> None:
        for servo, c in zip(self.servos, carried["servos"]):
            servo.carry_on(c)
        for drive, c in zip(self.drives, carried["drives"]):
            drive.motion.carry_on(c)
        self.current = int(carried["current"])
        self.records = [StageRecord(**from_jsonable(r)) for r in carried["records"]]  # at_end: a dict of floats
        self.start = None if carried["start"] is None else tuple(float(v) for v in carried["start"])
        self._last = None if carried["last"] is None else tuple(carried["last"])

    def stage_records(self, strain_name: str = "end_strain") -> list[dict]:
        """The records as summary.json's `stages`: the test's measures at each end with them, the
        stage's name where it has one, the strain at the end under `strain_name`."""
        out = []
        for r in self.records:
            d = asdict(r)
            extra = d.pop("at_end")
            d[strain_name] = d.pop("end_strain")
            name = self.stages[r.stage].name
            out.append(jsonable({**d, **extra, "loading": r.loading, **({"name": name} if name else {})}))
        return out

    def unfinished(self) -> list[str]:
        """One line per stage that did not end at its target: a stage that drives nothing and did
        not reach its targets at rest, or one that ran out of time or of the run."""
        lines = []
        for r in self.records:
            stage, reason = self.stages[r.stage], r.end_reason
            label = stage.name or f"stage {r.stage} ({r.target:g} Pa)"
            if not reason:
                lines.append(f"{label} had not ended when the run did")
            elif reason == "max_time" or (reason != "reached" and not stage.drives):
                wall = self.servos[-1].wall.name
                lines.append(f"{label} ended at its {reason} with the {wall} at {r.end_stress:.4g} Pa")
        return lines


def unbalanced_force(state, lumped: np.ndarray, vertex_ptr: np.ndarray, contact) -> float:
    """Mean |net force| over the grains over the mean |contact force| over the records (module
    docstring); inf where no record carries a force. Rigid grains carry their net force in the
    state (`bodies["force"]`; their vertices' accelerations are not kept)."""
    if "force" in state.bodies:
        net = state.bodies["force"]
    else:
        net = np.add.reduceat(lumped[:, None] * state.a, vertex_ptr[:-1], axis=0)
    forces = np.linalg.norm(contact.pair_force, axis=1) if contact is not None and contact.n_contacts else np.zeros(0)
    scale = float(forces.mean()) if len(forces) else 0.0
    return float(np.linalg.norm(net, axis=1).mean() / scale) if scale > 0 else np.inf


def jsonable(d: dict) -> dict:
    """inf and nan as strings (JSON has neither); everything else as it is."""
    return {k: (repr(float(v)) if isinstance(v, float) and not np.isfinite(v) else v) for k, v in d.items()}


def from_jsonable(d: dict) -> dict:
    return {k: (float(v) if v in ("inf", "-inf", "nan") else v) for k, v in d.items()}
