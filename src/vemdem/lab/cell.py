"""The vessel of a laboratory test: a cuboid cell of six plane walls around a settled pack.

The pack stays where it settled (in the box its `[pack]` stage built); the cell's floor is that
box's floor, its four sides the box's sides, and its top wall starts `gap` mean grain sizes above
the pack's highest point. Each wall either stays or moves along its inward normal on a steered
motion (contact.walls.ServoMotion), which a servo or a drive steers (lab/path.py); the sample's
dimensions are the box's less the walls' travel, and each wall's loaded area is the sample's face
it closes.
"""

from __future__ import annotations

import numpy as np

from ..contact.walls import PlaneWall, ServoMotion
from ..model.bodies import equivalent_diameters

SIDES = ("wall -x", "wall +x", "wall -y", "wall +y")
# the axis each wall closes the sample along (0: x, 1: y, 2: z), and its inward normal
_FLOOR = (2, (0.0, 0.0, 1.0))
_SIDES = ((0, (1.0, 0.0, 0.0)), (0, (-1.0, 0.0, 0.0)), (1, (0.0, 1.0, 0.0)), (1, (0.0, -1.0, 0.0)))
_TOP = (2, (0.0, 0.0, -1.0))


def cell_region(centre, box, floor: float, height: float) -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper) corners a sample's vertices never leave while its cell holds it: the cell
    as built, widened on every side by its largest dimension (room for a wall's travel outwards,
    a lid backing off, a shear box's lower half). A vertex beyond them has flown out of the cell."""
    margin = max(box[0], box[1], height)
    lower = np.array([centre[0] - 0.5 * box[0], centre[1] - 0.5 * box[1], floor]) - margin
    upper = np.array([centre[0] + 0.5 * box[0], centre[1] + 0.5 * box[1], floor + height]) + margin
    return lower, upper


def mean_grain_size(grains) -> float:
    """The grains' mean equivalent diameter (m): the length a test's rates and gaps are given in."""
    return float(np.mean(equivalent_diameters(np.array([g.volume for g in grains]))))


class BoxCell:
    """Six plane walls around a settled pack (`initial`: a hand-over state with the pack's box in
    its meta): the floor, the four sides (SIDES) and the top wall named `top`. `moving`: the names
    of the walls that move (steered); `frictionless`: those without friction (mirror planes).
    `top_area`: the top wall's loaded area where the test fixes it (m^2); the sample's section
    otherwise."""

    meshes = ()  # plane walls only

    def __init__(self, initial, gap: float, *, top: str = "top", moving=(), frictionless=(), top_area=None):
        meta = initial.meta
        self.box, self.floor = tuple(float(v) for v in meta["box"]), float(meta["floor"])
        cx, cy = (float(v) for v in meta["centre"])
        self.grain_size = mean_grain_size(initial.grains)
        self.height0 = float(initial.x[:, 2].max()) - self.floor + gap * self.grain_size
        self.top_area = top_area
        hx, hy = 0.5 * self.box[0], 0.5 * self.box[1]
        z0, z1 = self.floor, self.floor + self.height0
        points = [(cx, cy, z0), (cx - hx, cy, z0), (cx + hx, cy, z0), (cx, cy - hy, z0), (cx, cy + hy, z0),
                  (cx, cy, z1)]
        self.names = ("floor", *SIDES, top)
        self.axes = tuple(axis for axis, _ in (_FLOOR, *_SIDES, _TOP))
        self.walls = [_wall(point, normal, name, name in moving, name in frictionless)
                      for point, (_, normal), name in zip(points, (_FLOOR, *_SIDES, _TOP), self.names)]  # fmt: skip
        self.wall = dict(zip(self.names, self.walls))
        self.region = cell_region((cx, cy), self.box, self.floor, self.height0)

    def travel(self, name: str, t: float) -> float:
        """How far a wall has moved into the sample by time t (m); 0 for a wall that stays."""
        motion = self.wall[name].motion
        return motion.travel(t) if isinstance(motion, ServoMotion) else 0.0

    # ------------------------------------------------------------------ dimensions
    def widths(self, t: float) -> tuple[float, float]:
        return (self.box[0] - self.travel("wall -x", t) - self.travel("wall +x", t),
                self.box[1] - self.travel("wall -y", t) - self.travel("wall +y", t))  # fmt: skip

    def height(self, t: float) -> float:
        return self.height0 - self.travel(self.names[-1], t) - self.travel("floor", t)

    def section(self, t: float) -> float:
        """The top wall's loaded area (m^2)."""
        if self.top_area is not None:
            return self.top_area
        wx, wy = self.widths(t)
        return wx * wy

    def volume(self, t: float) -> float:
        return self.section(t) * self.height(t)

    def area(self, name: str, t: float) -> float:
        """The loaded area of a wall: the sample's face it closes (m^2)."""
        wx, wy = self.widths(t)
        axis = self.axes[self.names.index(name)]
        return (wy * self.height(t), wx * self.height(t), self.section(t))[axis]

    def stresses(self, reactions: np.ndarray, indices: list[int], names: tuple, t: float) -> np.ndarray:
        """The walls' normal stresses (Pa, compressive positive), `indices` their places in the
        contact model's walls."""
        normals = np.array([self.wall[n].normal for n in names])
        force = -np.einsum("ij,ij->i", reactions[indices], normals)
        return force / np.array([self.area(n, t) for n in names])


def _wall(point, normal, name: str, moving: bool, frictionless: bool) -> PlaneWall:
    kwargs = {"frictionless": True} if frictionless else {}
    if moving:
        return PlaneWall(np.array(point), np.array(normal), ServoMotion(normal), name, **kwargs)
    return PlaneWall(np.array(point), np.array(normal), name=name, **kwargs)
