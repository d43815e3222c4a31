"""Initial placement of a sand pack: grains on a grid of cells, layer above layer.

The paper's sand pack starts from grains that touch nothing, stacked in a column
above the box, and lets gravity settle them. Separation holds by construction, so
no overlap search is needed: within a layer each grain's circumscribed sphere stays
inside its own cell, and successive layers occupy disjoint horizontal slabs.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from .polyhedron import Polyhedron
from .shapes import angular_grain, sand_grain

# grain makers by name (the config's grains.shape): rounded sand, or cut, angular grains
GRAIN_SHAPES = {"sand": sand_grain, "angular": angular_grain}

SHAPE_KEYS = ("n_vertices", "elongation", "flatness", "roughness")


class SurfaceShapes:
    """A grain maker over given surfaces (a user's STL grains): each grain is one of `surfaces`,
    drawn with the number shares `fractions` (equal where None) from the grain's own seed, centred
    on its centroid and scaled to the drawn equivalent diameter `size` (pi size^3 / 6 its volume).
    The shape keys of the built-in makers do not apply and are ignored."""

    def __init__(self, surfaces: Sequence[Polyhedron], fractions: Sequence[float] | None = None):
        if not surfaces:
            raise ValueError("no surface to make grains of")
        shares = np.ones(len(surfaces)) if not fractions else np.asarray(fractions, dtype=float)
        if len(shares) != len(surfaces) or not np.all(np.isfinite(shares) & (shares > 0)):
            raise ValueError(f"fractions: one positive share per surface ({len(surfaces)}), got {list(shares)}")
        self.surfaces = [g.translated(-g.centroid) for g in surfaces]
        self.diameters = np.array([(6.0 * g.volume / np.pi) ** (1.0 / 3.0) for g in self.surfaces])
        self.cumulative = np.cumsum(shares / shares.sum())

    def __call__(self, size: float, seed: int, **_shape_keys) -> Polyhedron:
        u = np.random.default_rng(seed).uniform()
        k = min(int(np.searchsorted(self.cumulative, u, side="right")), len(self.surfaces) - 1)
        return self.surfaces[k].scaled(size / self.diameters[k])


@dataclass(frozen=True)
class Packing:
    """Grains placed without contact above `floor`, inside the walls of `box`.

    sizes          equivalent diameter of each grain (its volume is pi d^3 / 6)
    box, centre    footprint (x, y sides) and its centre: the walls are the planes
                   x = centre[0] +- box[0] / 2 and y = centre[1] +- box[1] / 2
    column_height  distance from the floor to the highest vertex
    """

    grains: list[Polyhedron]
    sizes: np.ndarray
    seed: int
    box: tuple[float, float]
    column_height: float
    centre: tuple[float, float] = (0.0, 0.0)
    floor: float = 0.0

    @property
    def top(self) -> float:
        """Height of the highest vertex of the column."""
        return _top(self.grains)


def column_packing(
    n: int,
    size: float = 1.45e-3,
    size_spread: float = 0.1,
    box: tuple[float, float] = (8e-3, 8e-3),
    centre: tuple[float, float] = (0.0, 0.0),
    floor: float = 0.0,
    clearance: float = 0.1,
    seed: int = 0,
    shape_params: dict | None = None,
    shape: str | Callable[..., Polyhedron] = "sand",
) -> Packing:
    """`n` sand grains in a column above the box, none touching another or a wall.

    Sizes are uniform in size * (1 +- size_spread); orientations are uniform on SO(3).
    With D the largest circumscribed diameter, the cells have pitch D (1 + clearance)
    and every grain keeps a gap of at least clearance * D / 2 to every other grain and
    to the walls; the other half of the clearance is room for a random horizontal
    jitter, so the grains do not stand in exact columns. A layer's grains rest their
    lowest vertex on the layer's base; the first base is clearance * size above the
    floor and each next one a gap above the previous layer's highest vertex (slabs
    rather than spheres, which keeps the column shorter). `shape` picks the grain maker
    (GRAIN_SHAPES: "sand" rounded, "angular" cut) or is one (SurfaceShapes: a user's
    surfaces), `shape_params` (keys n_vertices, elongation, flatness, roughness) go to it. Everything random
    comes from one generator seeded with `seed`: same arguments, bitwise same packing.
    """
    footprint = _check_arguments(n, size, size_spread, box, clearance, shape_params)
    if not callable(shape) and shape not in GRAIN_SHAPES:
        raise ValueError(f"shape must be one of {sorted(GRAIN_SHAPES)}, got {shape!r}")
    rng = np.random.default_rng(seed)
    make = shape if callable(shape) else GRAIN_SHAPES[shape]
    sizes, shapes, local = _oriented_grains(rng, n, size, size_spread, make, shape_params)
    radii = np.array([np.linalg.norm(v, axis=1).max() for v in local])
    pitch = 2.0 * radii.max() * (1.0 + clearance)
    gap = clearance * radii.max()
    cells = _cell_centres(footprint, centre, pitch, gap)
    if len(cells) == 0:
        raise ValueError(
            f"sizes: a grain of size {size:g} needs a cell of {pitch:.3g} m plus "
            f"{gap:.3g} m from the walls (circumscribed diameter {2 * radii.max():.3g}"
            f" m), more than the box {footprint[0]:g} x {footprint[1]:g} m; "
            "lower size or clearance, or enlarge the box"
        )
    # each circumscribed sphere stays gap / 2 inside its cell
    jitter_room = 0.5 * (pitch - gap) - radii
    jitter = jitter_room[:, None] * rng.uniform(-1.0, 1.0, (n, 2))
    xy = cells[np.arange(n) % len(cells)] + jitter
    lows = np.array([v[:, 2].min() for v in local])
    heights = np.array([v[:, 2].max() for v in local]) - lows
    bases = _layer_bases(heights, len(cells), floor + clearance * size, gap)
    offsets = np.column_stack([xy, bases - lows])
    grains = [
        Polyhedron(v + d, g.faces, g.name) for v, d, g in zip(local, offsets, shapes)
    ]
    sizes.setflags(write=False)
    height = _top(grains) - floor
    return Packing(grains, sizes, seed, footprint, height, tuple(centre), floor)


def _oriented_grains(rng, n, size, size_spread, make, shape_params):
    """(sizes, shapes, vertices about each centroid turned by a random rotation) of n grains,
    drawn from rng in this order: sizes, the grains' own seeds, the rotations."""
    sizes = rng.uniform(size * (1.0 - size_spread), size * (1.0 + size_spread), n)
    grain_seeds = rng.integers(0, 2**62, n)
    rotations = random_rotations(rng, n)
    shapes = [make(size=s, seed=int(k), **(shape_params or {})) for s, k in zip(sizes, grain_seeds)]
    # vertices about the centroid, so the circumscribed sphere is centred on it
    return sizes, shapes, [(g.vertices - g.centroid) @ r.T for g, r in zip(shapes, rotations)]


def random_rotations(rng: np.random.Generator, n: int) -> np.ndarray:
    """`n` rotation matrices (n, 3, 3), uniform (Haar) on SO(3).

    A normalised 4-d Gaussian is a uniform unit quaternion, and unit quaternions
    cover SO(3) twice with equal weight (Shoemake, Graphics Gems III, 1992).
    """
    q = rng.normal(size=(n, 4))
    w, x, y, z = (q / np.linalg.norm(q, axis=1, keepdims=True)).T
    rows = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ]
    return np.moveaxis(np.array(rows), -1, 0)


def _cell_centres(footprint, centre, pitch: float, gap: float) -> np.ndarray:
    """Centres (m, 2) of the grid cells, centred in the footprint, gap/2 off the walls."""
    counts = [int(np.floor((side - gap) / pitch)) for side in footprint]
    if min(counts) < 1:
        return np.empty((0, 2))
    x, y = (c + pitch * (np.arange(k) - 0.5 * (k - 1)) for c, k in zip(centre, counts))
    gx, gy = np.meshgrid(x, y, indexing="ij")
    return np.column_stack([gx.ravel(), gy.ravel()])


def _layer_bases(
    heights: np.ndarray, per_layer: int, base: float, gap: float
) -> np.ndarray:
    """Height of each grain's lowest vertex, filling layers of `per_layer` grains."""
    bases = np.empty(len(heights))
    for start in range(0, len(heights), per_layer):
        layer = slice(start, start + per_layer)
        bases[layer] = base
        base += heights[layer].max() + gap
    return bases


def _top(grains: Sequence[Polyhedron]) -> float:
    return max(float(g.vertices[:, 2].max()) for g in grains)


def pack_height(grains: Sequence[Polyhedron], floor: float = 0.0) -> float:
    """Height of a settled pack above the floor: twice that of its centre of volume.

    A pack of uniform packing fraction filling floor <= z <= floor + H has its centre
    of volume at H / 2. Unlike the highest vertices this uses every grain and needs no
    cell size or percentile, and a loose top layer of thickness t biases the packing
    fraction by only O((t / H)^2) (volume is conserved: grains above H balance the
    voids below it), whereas a surface through the top grains biases it by O(t / H).
    """
    if len(grains) == 0:
        raise ValueError("grains: need at least one grain")
    volumes = np.array([g.volume for g in grains])
    return centre_of_volume_height(volumes, np.array([g.centroid[2] for g in grains]) - floor)


def centre_of_volume_height(volumes: np.ndarray, heights: np.ndarray) -> float:
    """Twice the volume-weighted mean height (`pack_height` from arrays: grain volumes and
    centroid heights above the floor)."""
    return 2.0 * float(volumes @ heights) / float(volumes.sum())


def packing_fraction(
    grains: Sequence[Polyhedron], box: tuple[float, float], height: float
) -> float:
    """Total grain volume over the volume box[0] x box[1] x height (see `pack_height`)."""
    if not height > 0:
        raise ValueError(f"height must be > 0, got {height}")
    return sum(g.volume for g in grains) / (box[0] * box[1] * height)


def _check_arguments(n, size, size_spread, box, clearance, shape_params):
    """Raise a ValueError naming the first bad argument; return the box as floats."""
    if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 1:
        raise ValueError(f"n must be an integer >= 1, got {n}")
    if not (np.isfinite(size) and size > 0):
        raise ValueError(f"size must be a positive length, got {size}")
    if not 0 <= size_spread < 1:
        raise ValueError(f"size_spread must be in [0, 1), got {size_spread}")
    footprint = tuple(float(side) for side in box)
    if len(footprint) != 2 or not all(np.isfinite(s) and s > 0 for s in footprint):
        raise ValueError(f"box must be two positive side lengths, got {box}")
    if not (np.isfinite(clearance) and clearance >= 0):
        raise ValueError(f"clearance must be >= 0, got {clearance}")
    unknown = set(shape_params or {}) - set(SHAPE_KEYS)
    if unknown:
        raise ValueError(
            f"shape_params: unknown keys {sorted(unknown)}; allowed {SHAPE_KEYS}"
        )
    return footprint
