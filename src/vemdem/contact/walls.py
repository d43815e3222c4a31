"""Rigid walls with a prescribed motion: planes and triangulated bodies (docs/contact.md).

A wall is fixed, removed at a given time, or moved along a piecewise-linear displacement
history. Planes touch grains through vertex-plane pairs only (no edge or face of a grain can
come closer to a plane than its vertices). Triangulated walls (a lid, a box, an STL surface)
use the same pair logic as grain-grain contact: they enter the contact topology as extra,
rigid surfaces whose vertices are prescribed, not unknowns.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np



@dataclass(frozen=True)
class Motion:
    """Piecewise-linear rigid displacement d(t) through (times, displacements); removal time."""

    times: tuple = (0.0,)
    displacements: tuple = ((0.0, 0.0, 0.0),)
    removed_at: float = np.inf

    def __post_init__(self):
        t = np.asarray(self.times, float)
        d = np.asarray(self.displacements, float)
        if t.ndim != 1 or d.shape != (len(t), 3):
            raise ValueError("wall motion: need one 3-vector displacement per time")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(d))):
            raise ValueError("wall motion: times and displacements must be finite numbers")
        if np.any(np.diff(t) <= 0):
            raise ValueError("wall motion: times must increase")

    # The arrays once per motion: a wall's position is asked for several times per Newton
    # iteration, and rebuilding them from the tuples was 5 % of a 40-grain run (profile: docs/results.md, the main job).
    @cached_property
    def _table(self) -> tuple[np.ndarray, np.ndarray]:
        return np.asarray(self.times, float), np.asarray(self.displacements, float)

    def displacement(self, t: float) -> np.ndarray:
        times, d = self._table
        if len(times) == 1 or t <= times[0]:  # a fixed wall, or not yet moving
            return d[0].copy()
        if t >= times[-1]:
            return d[-1].copy()
        k = int(np.searchsorted(times, t, side="right")) - 1
        # np.interp's own arithmetic, so that a moving wall is where it was before, to the bit
        return (d[k + 1] - d[k]) / (times[k + 1] - times[k]) * (t - times[k]) + d[k]

    def velocity(self, t: float) -> np.ndarray:
        times, d = self._table
        k = np.searchsorted(times, t, side="right") - 1
        if k < 0 or k >= len(times) - 1:
            return np.zeros(3)
        return (d[k + 1] - d[k]) / (times[k + 1] - times[k])

    def active(self, t: float) -> bool:
        return t < self.removed_at

    @cached_property  # asked at every step (the energy books' wall work)
    def moves(self) -> bool:
        """Whether the displacement history ever changes (a removal alone is not a motion)."""
        return bool(np.ptp(np.asarray(self.displacements, float), axis=0).any())


class ServoMotion:
    """A wall's motion along one axis, steered step by step (a stress-controlled wall, lab/servo.py).

    Between two steerings it is linear in time: d(t) = d0 + (t - t0) s u, u the unit axis, s the
    speed set at t0. `steer(t, s)` starts the next segment at t, where the wall then is, so the
    path stays continuous. The segment before t0 is kept, so that a step's wall work (d(t1) -
    d(t0) over the step just taken) and the integrators' look-back over one step read the path as
    it was. The integrators ask it what they ask a Motion (displacement, velocity, active, moves);
    `version` counts the steerings, so caches keyed on time alone can tell the path changed."""

    removed_at = np.inf
    moves = True

    def __init__(self, axis):
        u = np.asarray(axis, float)
        if u.shape != (3,) or not np.all(np.isfinite(u)) or np.linalg.norm(u) == 0:
            raise ValueError("servo motion: the axis must be a non-zero finite 3-vector")
        self.axis = u / np.linalg.norm(u)
        self.t0, self.d0, self.speed = 0.0, np.zeros(3), 0.0
        self.t_prev, self.d_prev = 0.0, np.zeros(3)
        self.version = 0

    def displacement(self, t: float) -> np.ndarray:
        if t >= self.t0 or self.t0 <= self.t_prev:
            return self.d0 + (t - self.t0) * self.speed * self.axis
        if t <= self.t_prev:
            return self.d_prev.copy()
        return self.d_prev + (self.d0 - self.d_prev) * ((t - self.t_prev) / (self.t0 - self.t_prev))

    def velocity(self, t: float) -> np.ndarray:
        if t >= self.t0 or self.t0 <= self.t_prev:
            return self.speed * self.axis
        return (self.d0 - self.d_prev) / (self.t0 - self.t_prev)

    def active(self, t: float) -> bool:
        return True

    def travel(self, t: float) -> float:
        """How far the wall has moved along its axis by time t (m)."""
        return float(self.displacement(t) @ self.axis)

    def steer(self, t: float, speed: float) -> None:
        """From t on, move at `speed` (m/s) along the axis (negative: against it)."""
        if not np.isfinite(speed):
            raise ValueError(f"servo motion: non-finite speed {speed!r} at t = {t:g} s")
        d = self.displacement(t)
        self.t_prev, self.d_prev = self.t0, self.d0
        self.t0, self.d0, self.speed = float(t), d, float(speed)
        self.version += 1

    def carried(self) -> dict:
        """The path's state, exactly (JSON floats round-trip), for a checkpoint."""
        return {"t0": self.t0, "d0": self.d0.tolist(), "speed": self.speed, "t_prev": self.t_prev,
                "d_prev": self.d_prev.tolist(), "version": self.version}  # fmt: skip

    def carry_on(self, carried: dict) -> None:
        self.t0, self.speed, self.t_prev = float(carried["t0"]), float(carried["speed"]), float(carried["t_prev"])
        self.d0, self.d_prev = np.array(carried["d0"], float), np.array(carried["d_prev"], float)
        self.version = int(carried["version"])


@dataclass(frozen=True)
class PlaneWall:
    point: np.ndarray
    normal: np.ndarray  # points towards the grains
    motion: Motion = field(default_factory=Motion)
    name: str = "plane"
    # A frictionless wall (mu_s = mu_d = 0 on its pairs, the normal law and damping unchanged) is a
    # mirror plane: the grains next to it move as if their mirror images were there (a corner
    # collapse is a quarter of the heap four times its size, docs/repose.md).
    frictionless: bool = False

    def __post_init__(self):
        n = np.asarray(self.normal, float)
        if not np.all(np.isfinite(n)) or np.linalg.norm(n) == 0:
            raise ValueError(f"wall {self.name}: normal must be a non-zero finite vector")
        object.__setattr__(self, "normal", n / np.linalg.norm(n))
        object.__setattr__(self, "point", np.asarray(self.point, float))

    def point_at(self, t: float) -> np.ndarray:
        return self.point + self.motion.displacement(t)


@dataclass(frozen=True)
class MeshWall:
    """A rigid triangulated surface (open or closed); faces oriented towards the grains."""

    vertices: np.ndarray
    faces: np.ndarray
    motion: Motion = field(default_factory=Motion)
    name: str = "mesh"
    frictionless: bool = False  # as for PlaneWall

    def vertices_at(self, t: float) -> np.ndarray:
        return np.asarray(self.vertices, float) + self.motion.displacement(t)


def box_walls(size_x: float, size_y: float, floor_z: float = 0.0, center=(0.0, 0.0),
              removed_at: float = np.inf) -> list[PlaneWall]:  # fmt: skip
    """Floor and four vertical walls of an open box (normals pointing inside); the vertical ones
    disappear at `removed_at`."""
    cx, cy = center
    hx, hy = 0.5 * size_x, 0.5 * size_y
    gone = Motion(removed_at=removed_at)
    return [
        PlaneWall(np.array([cx, cy, floor_z]), np.array([0.0, 0.0, 1.0]), name="floor"),
        PlaneWall(np.array([cx - hx, cy, floor_z]), np.array([1.0, 0.0, 0.0]), gone, "wall -x"),
        PlaneWall(np.array([cx + hx, cy, floor_z]), np.array([-1.0, 0.0, 0.0]), gone, "wall +x"),
        PlaneWall(np.array([cx, cy - hy, floor_z]), np.array([0.0, 1.0, 0.0]), gone, "wall -y"),
        PlaneWall(np.array([cx, cy + hy, floor_z]), np.array([0.0, -1.0, 0.0]), gone, "wall +y"),
    ]


def mirrored(walls: list, names: tuple[str, ...]) -> list:
    """`walls` with the ones named made frictionless: mirror planes, across which the grains move as
    if the mirror image of the scene were there."""
    return [replace(w, frictionless=True) if w.name in names else w for w in walls]


def corner_mirrors(size_x: float, size_y: float, floor_z: float = 0.0, center=(0.0, 0.0)) -> list[PlaneWall]:
    """The -x and -y walls of box_walls' box as mirror planes, so the grains in their corner move as
    if the mirrored quarters of a box four times as large were there."""
    _floor, back, _front, side_lo, _side_hi = box_walls(size_x, size_y, floor_z, center)
    return mirrored([back, side_lo], (back.name, side_lo.name))


def disc_wall(radius: float, z: float = 0.0, centre=(0.0, 0.0), segments: int = 64, name: str = "disc") -> MeshWall:
    """A horizontal disc of finite radius (a fan of `segments` triangles, facing up): the floor of a
    poured heap, which grains roll off at its rim."""
    angle = 2.0 * np.pi * np.arange(segments) / segments
    ring = np.column_stack([centre[0] + radius * np.cos(angle), centre[1] + radius * np.sin(angle), np.full(segments, z)])
    vertices = np.vstack([[centre[0], centre[1], z], ring])
    k = np.arange(segments)
    faces = np.column_stack([np.zeros(segments, int), 1 + k, 1 + (k + 1) % segments])  # counter-clockwise: +z
    return MeshWall(vertices, faces, name=name)


def box_sides(size_x: float, size_y: float, floor_z: float, height: float, center=(0.0, 0.0),
              motion: Motion = Motion()) -> list[MeshWall]:  # fmt: skip
    """The four vertical sides of a box as finite rectangles (two triangles each, facing inside),
    from floor_z to floor_z + height: walls that can rise off the floor, grains flowing out under
    their bottom edges (box_walls' planes are infinite and can only vanish)."""
    cx, cy = center
    hx, hy = 0.5 * size_x, 0.5 * size_y
    z0, z1 = floor_z, floor_z + height
    # (a, b): the bottom edge of each side; its two triangles are wound so that their normals point inside
    sides = {"side -x": ((cx - hx, cy + hy), (cx - hx, cy - hy)), "side +x": ((cx + hx, cy - hy), (cx + hx, cy + hy)),
             "side -y": ((cx - hx, cy - hy), (cx + hx, cy - hy)), "side +y": ((cx + hx, cy + hy), (cx - hx, cy + hy))}
    walls = []
    for name, (a, b) in sides.items():
        v = np.array([[a[0], a[1], z0], [b[0], b[1], z0], [b[0], b[1], z1], [a[0], a[1], z1]])
        walls.append(MeshWall(v, np.array([[0, 2, 1], [0, 3, 2]]), motion, name))
    return walls
