"""A load path: stages that end on a condition, over one servo wall (model/servo.py).

A stage holds the servo at a target stress. It ends

- "reached": the wall's stress is within `stress_tolerance` of the target AND the sample is at
  rest, its unbalanced force ratio below `unbalanced_tolerance`:

      unbalanced = mean over grains |sum_i m_i a_i| / mean over contact records |f|,

  the net force on each grain (the lumped masses are the consistent mass matrix's row sums, so
  sum_i m_i a_i is the grain's exact net force) against the mean contact force (YADE's
  unbalancedForce);
- "max_time": `max_time` seconds of simulated time after it began;
- "max_strain": a loading stage's strain passed `max_strain`: a target the sample cannot reach
  there (an unloading stage always reaches its target: a wall that lets go of the sample is
  pushed back).

The path is the time loop's `control` hook (every accepted step) and its `stop` (at frames, when
the last stage has ended). Everything it decides from is carried through checkpoints (`carried`),
so a run resumed inside any stage goes on bit for bit. It also books, per stage, the wall's work
on the sample (the trapezoidal rule of each step: N dd), the overshoot past the target, the steps
and the Newton iterations: the records `stage_records` returns.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np


class StageNotReached(UserWarning):
    """A stage ended at its time or strain limit, not at its target."""


@dataclass(frozen=True)
class Stage:
    stress: float  # target normal stress on the servo wall (Pa)
    max_time: float  # s after the stage began
    max_strain: float = np.inf  # a loading stage ends when the strain (e.g. axial) passes it
    max_speed: float = np.inf  # the servo's speed cap in this stage (m/s)


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
    end_reason: str = ""  # reached | max_time | max_strain | "" (not ended)
    unbalanced: float = np.nan  # at the end
    overshoot: float = 0.0  # largest stress past the target, over the target (loading: above; unloading: below)
    work: float = 0.0  # the wall's work on the sample over the stage (J)
    steps: int = 0
    newton_iterations: int = 0
    largest_speed: float = 0.0  # the wall's largest speed (m/s)
    at_end: dict = field(default_factory=dict)  # the test's own measures where the stage ended (LoadPath.at_end)

    @property
    def loading(self) -> bool:
        return self.target >= self.start_stress


@dataclass
class LoadPath:
    """The stages of one servo wall. `strain(state)` gives the test's strain (e.g. axial); `lumped`
    the vertices' lumped masses; `vertex_ptr` the grains' vertex ranges."""

    servo: object
    stages: list
    strain: object
    lumped: np.ndarray
    vertex_ptr: np.ndarray
    stress_tolerance: float = 0.01
    unbalanced_tolerance: float = 0.01
    at_end: object = None  # at_end(state, info) -> dict: what the test measures where a stage ends
    current: int = 0
    records: list = field(default_factory=list)
    _last: tuple | None = None  # (travel, force) at the last step: the work's trapezoid

    def __post_init__(self):
        if not self.stages:
            raise ValueError("load path: no stages")
        self._enter(0)

    def _enter(self, k: int) -> None:
        self.servo.target, self.servo.max_speed = self.stages[k].stress, self.stages[k].max_speed

    @property
    def done(self) -> bool:
        return self.current >= len(self.stages)

    def stop(self, state) -> bool:
        """The time loop's `stop`: the last stage has ended."""
        return self.done

    def __call__(self, state, info) -> None:
        if self.done:
            self.servo(state, info)  # hold the last target until the frame ends
            return
        servo = self.servo
        servo.measure(info.wall_reactions, info.ints, info.floats, state.t)
        if not self.records or self.records[-1].stage != self.current:
            self.records.append(StageRecord(self.current, self.stages[self.current].stress, state.t, servo.stress,
                                            self.strain(state)))  # fmt: skip
            self._last = None
        rec = self.records[-1]
        self._book(rec, state, info)
        reason = self._ended(self.stages[self.current], rec, state, info)
        if reason:
            rec.end_time, rec.end_stress, rec.end_strain, rec.end_reason = state.t, servo.stress, self.strain(state), reason
            if self.at_end is not None:
                rec.at_end = self.at_end(state, info)
            self.current += 1
            if not self.done:
                self._enter(self.current)
        servo.steer(state.t)
        rec.largest_speed = max(rec.largest_speed, abs(servo.motion.speed))

    def _book(self, rec: StageRecord, state, info) -> None:
        servo = self.servo
        travel = servo.travel_at(state.t)
        if self._last is not None:
            travel0, force0 = self._last
            rec.work += 0.5 * (force0 + servo.force) * (travel - travel0)
        self._last = (travel, servo.force)
        rec.steps += 1
        rec.newton_iterations += int(info.iterations)
        past = (servo.stress - rec.target) if rec.loading else (rec.target - servo.stress)
        rec.overshoot = max(rec.overshoot, past / max(rec.target, 1e-300))

    def _ended(self, stage: Stage, rec: StageRecord, state, info) -> str:
        servo = self.servo
        if abs(servo.stress - stage.stress) <= self.stress_tolerance * stage.stress:
            rec.unbalanced = unbalanced_force(state, self.lumped, self.vertex_ptr, info.contact)
            if rec.unbalanced <= self.unbalanced_tolerance:
                return "reached"
        if state.t - rec.start_time >= stage.max_time:
            rec.unbalanced = unbalanced_force(state, self.lumped, self.vertex_ptr, info.contact)
            return "max_time"
        if rec.loading and self.strain(state) > stage.max_strain:
            return "max_strain"
        return ""

    # ---------------------------------------------------------------- checkpoints
    def carried(self) -> dict:
        return {"servo": self.servo.carried(), "current": self.current,
                "records": [jsonable(asdict(r)) for r in self.records],
                "last": None if self._last is None else list(self._last)}  # fmt: skip

    def carry_on(self, carried: dict) -> None:
        self.current = int(carried["current"])
        self.servo.carry_on(carried["servo"])
        self.records = [StageRecord(**from_jsonable(r)) for r in carried["records"]]  # at_end: a dict of floats
        self._last = None if carried["last"] is None else tuple(carried["last"])

    def stage_records(self) -> list[dict]:
        out = []
        for r in self.records:
            d = asdict(r)
            extra = d.pop("at_end")
            out.append(jsonable({**d, **extra, "loading": r.loading}))
        return out


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
