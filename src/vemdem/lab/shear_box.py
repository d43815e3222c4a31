"""The vessel of a direct shear test: a split box around a settled pack (docs/direct-shear.md).

The pack's box becomes a shear box split at `split` of the pack's height: the lower half (the
floor and its two x sides, finite rectangles up to the split) moves along x on one steered motion
(`drive`), the upper half's two x sides (from `opening` mean grain sizes above the split up, past
the lid) ride with the sample on another (`frame`), the two y sides are frictionless planes along
the shear, and a lid starts `gap` mean grain sizes above the pack. Where the halves' ends no
longer face each other, two horizontal plates close the box as a lab box's frames do: the lower
half's -x end carries a plate at the split that reaches outwards past the travel, and the upper
half's +x end a plate just above the split that reaches outwards past the travel.
"""

from __future__ import annotations

import numpy as np

from ..contact.walls import MeshWall, PlaneWall, ServoMotion
from ..model.bodies import equivalent_diameters
from .cell import cell_region

LOWER = ("floor", "lower -x", "lower +x", "lower -x plate")  # the walls that move with the lower half


class OpeningTooWide(ValueError):
    """The gap between the halves would let the smallest grain out: str(e) says by how much."""


def _quad(corners, normal) -> tuple[np.ndarray, np.ndarray]:
    """A planar rectangle through four corners in order, its two triangles wound so that their
    normals point along `normal` (a mesh wall pushes grains along its triangles' normals)."""
    v = np.asarray(corners, dtype=float)
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    if np.dot(np.cross(v[1] - v[0], v[2] - v[0]), normal) < 0:
        faces = faces[:, ::-1]
    return v, faces


def _side(x: float, y0: float, y1: float, z0: float, z1: float, inward: float) -> tuple[np.ndarray, np.ndarray]:
    """A rectangle in the plane x = const from (y0, z0) to (y1, z1), facing `inward` (+1 or -1) along x."""
    return _quad([[x, y0, z0], [x, y1, z0], [x, y1, z1], [x, y0, z1]], (inward, 0.0, 0.0))


def _plate(z: float, x0: float, x1: float, y0: float, y1: float, up: float) -> tuple[np.ndarray, np.ndarray]:
    """A rectangle in the plane z = const over [x0, x1] x [y0, y1], facing `up` (+1 or -1) along z."""
    return _quad([[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]], (0.0, 0.0, up))


class ShearBox:
    """The walls of a split box around a settled pack (`initial`: a hand-over state with the pack's
    box in its meta), and its measures. `gap` and `opening` in mean grain sizes, `split` a share of
    the pack's height, `travel` the lower half's largest travel as a share of the box's length;
    `layer(size)` the contact layer's thickness for grains of mean size `size` (m)."""

    def __init__(self, initial, *, gap: float, split: float, opening: float, travel: float, layer):
        meta = initial.meta
        self.box, self.floor = tuple(float(v) for v in meta["box"]), float(meta["floor"])
        self.centre = tuple(float(v) for v in meta["centre"])
        sizes = equivalent_diameters(np.array([g.volume for g in initial.grains]))
        self.grain_size, smallest = float(np.mean(sizes)), float(np.min(sizes))
        self.travel_max = travel * self.box[0]
        self.opening = opening * self.grain_size
        if self.opening >= smallest:
            raise OpeningTooWide(f"{self.opening * 1e3:.3g} mm between the halves would let the smallest grain "
                                 f"({smallest * 1e3:.3g} mm) out; take less than {smallest / self.grain_size:.3g}")
        top = float(initial.x[:, 2].max())
        self.height0 = top - self.floor + gap * self.grain_size
        self.split = self.floor + split * (top - self.floor)
        self.drive = ServoMotion((1.0, 0.0, 0.0))  # the lower half's motion, shared by its walls
        self.frame = ServoMotion((0.0, 0.0, 1.0))  # the upper half's rise with the sample, shared by its walls
        self.meshes = self._halves(layer(self.grain_size))
        self.walls = self._planes()
        self.lid = self.walls[-1]
        self.area = self.box[0] * self.box[1]
        self.region = cell_region(self.centre, self.box, self.floor, self.height0)

    def _halves(self, layer: float) -> list[MeshWall]:
        """The halves' x sides and the frames' plates: the lower half's walls, then the upper's."""
        (cx, cy), hx, hy = self.centre, 0.5 * self.box[0], 0.5 * self.box[1]
        above = self.floor + self.height0 + 2.0 * self.grain_size  # the upper sides reach past the lid
        below = self.floor - self.grain_size
        lower, upper = [], []
        for name, x, inward in (("-x", cx - hx, 1.0), ("+x", cx + hx, -1.0)):
            v, f = _side(x, cy - hy, cy + hy, below, self.split, inward)
            lower.append(MeshWall(v, f, self.drive, f"lower {name}"))
            v, f = _side(x, cy - hy, cy + hy, self.split + self.opening, above, inward)
            upper.append(MeshWall(v, f, self.frame, f"upper {name}"))
        # the frames' plates, reaching a grain past the travel outwards from the halves' ends; their
        # inner edges stand back from the sides' edges by twice the contact layer, so that a grain
        # pressed on a side near the split is not pushed by the plate's edge too
        reach, back = self.travel_max + self.grain_size, 2.0 * layer
        v, f = _plate(self.split, cx - hx - reach, cx - hx - back, cy - hy, cy + hy, 1.0)
        lower.append(MeshWall(v, f, self.drive, "lower -x plate"))
        v, f = _plate(self.split + self.opening, cx + hx + back, cx + hx + reach, cy - hy, cy + hy, -1.0)
        upper.append(MeshWall(v, f, self.frame, "upper +x plate"))
        return lower + upper

    def _planes(self) -> list[PlaneWall]:
        """The floor (moving with the lower half), the frictionless y sides and the steered lid."""
        (cx, cy), hy = self.centre, 0.5 * self.box[1]
        floor = PlaneWall(np.array([cx, cy, self.floor]), np.array([0.0, 0.0, 1.0]), self.drive, "floor")
        sides = [PlaneWall(np.array([cx, cy - hy, self.floor]), np.array([0.0, 1.0, 0.0]), name="wall -y",
                           frictionless=True),
                 PlaneWall(np.array([cx, cy + hy, self.floor]), np.array([0.0, -1.0, 0.0]), name="wall +y",
                           frictionless=True)]  # fmt: skip
        lid = PlaneWall(np.array([cx, cy, self.floor + self.height0]), np.array([0.0, 0.0, -1.0]),
                        ServoMotion((0.0, 0.0, -1.0)), "lid")  # fmt: skip
        return [floor, *sides, lid]

    def height(self, t: float) -> float:
        return self.height0 - self.lid.motion.travel(t)

    def volume(self, t: float) -> float:
        return self.area * self.height(t)

    def stresses(self, reactions: np.ndarray, lid: int, lower: list[int]) -> tuple[float, float]:
        """(sigma_n, tau): the lid's normal stress and the shear stress the lower half carries (Pa)."""
        sigma_n = float(reactions[lid, 2]) / self.area  # the grains push the lid up
        tau = -float(np.sum(reactions[lower, 0])) / self.area  # the half pushes the grains along +x
        return sigma_n, tau

    def mark(self, t: float) -> tuple:
        """What a stage's displacements are measured from: (its start time, the lower half's
        travel, the lid's travel)."""
        return t, self.drive.travel(t), self.lid.motion.travel(t)

    def displacements(self, start: tuple | None, t: float) -> tuple[float, float]:
        """(shear, vertical) displacement from where the current stage began: the lower half's
        travel and the lid's rise."""
        _, x0, z0 = start if start is not None else (0.0, 0.0, 0.0)
        return self.drive.travel(t) - x0, -(self.lid.motion.travel(t) - z0)

    def frame_speed(self, start: tuple | None, t: float) -> float:
        """The upper frame rides with the lid's rise from the shear's start, never below where it
        stood (a lab box's upper frame lifts with a dilating sample, so that a grain caught at its
        edge lifts it instead of being crushed; it does not sink into the lower one)."""
        up = -self.lid.motion.speed
        rise, lifted = self.displacements(start, t)[1], self.frame.travel(t)
        if up > 0.0:
            return up if rise >= lifted else 0.0
        return up if lifted > 0.0 else 0.0


class FrameRide:
    """The upper frame as a drive of the load path (lab/path.py): in a stage that gives it a rate
    of 1 it rides with the lid (ShearBox.frame_speed), held otherwise."""

    def __init__(self, box: ShearBox):
        self.box, self.motion = box, box.frame

    def speed(self, t: float, rate: float, start: tuple) -> float:
        return rate * self.box.frame_speed(start, t)
