"""A stress-controlled (servo) wall: its normal motion follows a target normal stress.

After every accepted step at time t the wall is steered for the next one. With n the wall's
normal (pointing at the grains), R its reaction (the grains' force on it), A its loaded area and
sigma* the target,

    N = -R . n                          the compressive normal force it carries
    e = sigma* A - N                    the force it lacks (> 0: push on)
    K = sum of k(g) over its records    d N / d(travel) with the grains held (contact.law)
    k = dN / dd if in [K / STIFFNESS_RANGE, K]          (the last step's secant: the sample's stiffness)
      = K otherwise; a holding wall (keep_secant) takes min(the last secant inside the range with
        |dN| >= RESOLUTION N, K) instead
    s = clip(gain e' / (k h), -v_max, v_max)    its speed along n until the next steering,
    e' = clip(e, -RAMP N, RAMP N) where N > 0   (a loaded wall asks for at most RAMP of its force)
    s = v_max while N < SEATING sigma* A          (seating: the wall closes on a sample that does not resist yet)

h the step just taken. Each step moves the wall by gain e / k. With the wall's own contact layer's
K alone this is the servo of the established DEM codes (PFC's, YADE's TriaxialStressController):
the sample behind that layer is softer than it (its contacts in series), so K over-estimates the
stiffness and the error shrinks by (1 - gain k_sample / K) per step without overshooting; in a
pack of 90 GPa grains under a lid that factor was 0.9995 (a sample a thousand times softer than
the lid's layer), a stage held for seconds of simulated time. The secant dN/dd of the last step is
the sample's own stiffness, and makes the error shrink by (1 - gain) per step on a linear sample
(tests/test_servo.py). Outside [K / STIFFNESS_RANGE, K] it is no stiffness but the sample's own
motion (a rearranging or creeping pack whose force fell while the wall advanced, or rose while it
stood): the layer's K is taken then. A wall that holds its stress while the sample is deformed
from elsewhere (a triaxial's lateral walls in the shear, a shear box's lid) sees such a secant at
every step, its force raised by the platen while it backs off; on the layer's K its lag grows to
r K / (gain k_sample) for a force raised by r per step, against r / gain on the sample's
stiffness: a flexible triaxial's lateral walls, on implicit steps a hundred times the rigid
grains' explicit ones, let the confining stress rise from 50 kPa to 507 kPa at 7 % axial strain.
Such a wall keeps its last good secant instead (keep_secant). Not every wall does: a cube pressed
between the floor and a lid that kept it swung about its target in a limit cycle (+-3 %) where
the layer's K, 15 % stiffer, let it settle (docs/servo.md). A clipped secant made the 60-grain
oedometer's lid swing between its speed caps at every step (docs/servo.md). The step length
cancels, so a halved step moves the wall by as much per step. Where no record touches the wall
(K = 0) it moves at v_max towards or away from the grains. v_max is the real speed cap: the
scenario sets it from the inertia number the test must stay below (docs/servo.md).

A wall with mass under a force was the other choice: its extra degree of freedom would enter
every Newton system and the explicit step's stability, where this law needs neither (docs/servo.md).
"""

from __future__ import annotations

import numpy as np

from ..contact.walls import ServoMotion

# How much softer than the wall's contact layer the servo may take the sample to be
STIFFNESS_RANGE = 1e4
# Below this share of its target force a wall seats at its speed cap: a loose pack under it
# rearranges rather than resists, its secant is no stiffness, and the layer's K and the RAMP
# (a quarter of a force near 0) made the lid creep (the 60-grain oedometer: 4.7 kPa of 25 after
# 0.44 s of simulated time, docs/servo.md)
SEATING = 0.1
# The smallest force change, as a share of the force, whose secant a holding wall keeps for the
# sample's stiffness: the last steps of a convergence move the wall by what rounding and the
# sample's own jitter change its force by, and such a secant, kept, is noise (30 % off on a linear
# spring)
RESOLUTION = 1e-3
# The largest share of its force a loaded wall asks for in one step: a jump of the target (a stage
# four times the last) linearised on the last step's secant overshot by 7 % on a barrier, whose
# stiffness grows with its force; in steps of at most a quarter it does not (tests/test_servo.py)
RAMP = 0.25


class Servo:
    """Steers one wall whose motion is a ServoMotion along its inward normal. `target` (Pa) may be
    changed between steps (a load path's stages, lab/path.py). `area` (m^2): a number, or a
    function of the time for a wall whose loaded area changes with the sample (a triaxial cell's)."""

    def __init__(self, contact, wall, area, *, gain: float = 0.3, max_speed: float = np.inf, target: float = 0.0):
        if not isinstance(wall.motion, ServoMotion):
            raise ValueError(f"servo: wall {wall.name!r} has a prescribed motion, not a steered one")
        if not 0 < gain <= 1:
            raise ValueError(f"servo: gain must be in (0, 1], got {gain!r}")
        if not max_speed > 0:
            raise ValueError(f"servo: max_speed must be > 0, got {max_speed!r}")
        self.contact, self.wall = contact, wall
        self.index = contact.wall_names.index(wall.name)
        self.normal = _inward_normal(wall)
        self.area = area if callable(area) else (lambda t, a=float(area): a)
        self.t = 0.0  # the time of the last measurement: the loaded area is taken there
        self.gain, self.max_speed, self.target = float(gain), float(max_speed), float(target)
        self.force = 0.0  # N at the last step
        self.stiffness = 0.0  # the stiffness the last step's speed used (N/m: k in the module docstring)
        self._last = None  # (travel, force) at the last measurement: the secant
        self._secant = None  # the last resolved secant inside the range: the sample's stiffness (N/m)
        self.keep_secant = False  # a holding wall: where the secant says nothing, its last good one

    @property
    def motion(self) -> ServoMotion:
        return self.wall.motion

    @property
    def stress(self) -> float:
        """The wall's measured normal stress at the last step (Pa, compressive positive)."""
        return self.force / self.area(self.t)

    def measure(self, reactions: np.ndarray, ints: np.ndarray, floats: np.ndarray, t: float) -> None:
        """The wall's force and the stiffness its next speed uses, at the accepted state at time t."""
        self.t = t
        self.force = float(-reactions[self.index] @ self.normal)
        layer = float(self.contact.wall_stiffness(ints, floats)[self.index])
        travel = self.travel_at(t)
        self.stiffness = layer if not self.keep_secant or self._secant is None else min(self._secant, layer)
        if self._last is not None and travel != self._last[0]:
            secant = (self.force - self._last[1]) / (travel - self._last[0])
            if layer / STIFFNESS_RANGE <= secant <= layer:
                self.stiffness = secant
                if abs(self.force - self._last[1]) >= RESOLUTION * abs(self.force):
                    self._secant = secant
        self._last = (travel, self.force)

    def speed(self, h: float) -> float:
        """The speed along the normal for the next step, from the last measurement (module docstring)."""
        target = self.target * self.area(self.t)
        error = target - self.force
        if self.force < SEATING * target:
            return self.max_speed
        if self.force > 0.0:  # at most RAMP of its force per step: the barrier stiffens faster than any secant
            error = float(np.clip(error, -RAMP * self.force, RAMP * self.force))
        if error == 0.0:
            return 0.0
        if self.stiffness <= 0.0 or h <= 0.0:
            return float(np.sign(error) * self.max_speed)
        return float(np.clip(self.gain * error / (self.stiffness * h), -self.max_speed, self.max_speed))

    def steer(self, t: float) -> None:
        """Set the speed for the step after time t from the last measurement (the step just taken
        began where the path was last steered)."""
        self.motion.steer(t, self.speed(t - self.motion.t0))

    def after_step(self, state, info) -> None:
        """Measure at the accepted state, steer for the next step."""
        self.measure(info.wall_reactions, info.ints, info.floats, state.t)
        self.steer(state.t)

    def travel_at(self, t: float) -> float:
        """How far the wall has moved towards the grains by time t (m)."""
        return self.motion.travel(t)

    def carried(self) -> dict:
        """The path and the secant's last point, exactly, for a checkpoint."""
        return {"motion": self.motion.carried(), "last": None if self._last is None else list(self._last),
                "secant": self._secant, "target": self.target, "max_speed": self.max_speed}  # fmt: skip

    def carry_on(self, carried: dict) -> None:
        self.motion.carry_on(carried["motion"])
        self._last = None if carried["last"] is None else tuple(float(v) for v in carried["last"])
        secant = carried.get("secant")  # absent from a checkpoint written before the secant was kept
        self._secant = None if secant is None else float(secant)
        self.target, self.max_speed = float(carried["target"]), float(carried["max_speed"])


class ServoWalls:
    """Servo walls, each steered towards a target stress that is piecewise-linear in time (held
    after its last time): the time loop's control (driver.loop.Control) for a scene's
    `[walls.servo]` tables."""

    def __init__(self, servos: list[Servo], schedules: list[tuple]):
        self.servos = servos
        self.schedules = [(np.asarray(t, float), np.asarray(s, float)) for t, s in schedules]

    def after_step(self, state, info) -> None:
        for servo, (times, stresses) in zip(self.servos, self.schedules):
            servo.target = float(np.interp(state.t, times, stresses))
            servo.after_step(state, info)

    def carried(self) -> dict:
        return {"servos": [s.carried() for s in self.servos]}

    def carry_on(self, carried: dict) -> None:
        for servo, c in zip(self.servos, carried["servos"]):
            servo.carry_on(c)


def quasi_static_rate(inertia_number: float, stress: float, density: float, grain_size: float) -> float:
    """The strain rate (1/s) whose inertia number I = rate d / sqrt(stress / density) is the one
    given: the rate a lab test's walls stay quasi-static at (below 1e-3)."""
    return inertia_number * np.sqrt(stress / density) / grain_size


def _inward_normal(wall) -> np.ndarray:
    """The unit axis a servo wall moves along, towards the grains: a plane's normal; a mesh wall's
    ServoMotion axis (it is given one)."""
    n = getattr(wall, "normal", None)
    return np.asarray(wall.motion.axis if n is None else n, float)
