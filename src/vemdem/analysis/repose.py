"""Angle of repose of a settled pile, measured on its free surface (docs/repose.md).

The pile was a column in a square box whose walls were removed, so it spreads around a
vertical axis into a heap between a cone and a square pyramid. Its angle of repose is the
slope of the flank; the measurement keeps only what describes the flank:

1. **Axis**: the horizontal centroid of all grains unless the caller gives it (the box
   centre). A symmetric heap has its axis at its centroid; a stray grain moves it by only
   1/G of its distance.
2. **Free surface**: rings one grain size d wide around the axis, each cut in azimuth into
   cells of about two grain footprints (2 d^2); the grain with the highest top in a cell
   (its highest surface vertex, or centroid + d/2 without vertices) is a surface grain, and
   its own (distance, top height) pair is a point of the profile h(r). Cells of one area
   everywhere, rather than a fixed number of sectors: the highest of n rough grains rises
   with n, and in a sector n grows with r, lifting the toe against the crest (8 sectors
   read the test heaps 1 to 1.6 degrees too low). Two footprints, not one: in a random
   packing a one-footprint cell often holds no surface grain's centroid and would report
   a buried grain.
3. **Flank only**: a first fit takes the surface points whose tops are between `toe`
   (1.5) grain sizes above the floor and `crest` (0.5) grain sizes below the highest top.
   A grain lying on the floor has its top at about d, so the single-grain layer that runs
   out beyond the heap stays below 1.5 d while any grain resting on another is above it;
   the crest plateau is flat to within the roughness of its top layer. Then the points
   whose *distance* lies where the fitted line is inside that height band are kept and the
   line refitted, until the set stops changing. Selecting on the noisy height itself would
   clip the surface roughness one-sidedly at both ends of the band (rough points above the
   band near the crest, below it near the toe), which flattens the line: 2 to 4.5 degrees
   too low on the test heaps; selecting on distance leaves the roughness symmetric.
   A low mound (under 3 grain sizes) has a band less than `MIN_BAND` (one grain size) tall,
   narrower than its surface roughness: the toe then comes down until the band is one grain
   size tall, but never below the measured top of the floor layer (95th percentile of the
   tops of the grains touching the floor). Such a mound reads 1 to 3.5 degrees low.
4. **Fit**: ordinary least squares h = h0 - tan(theta) r with the standard error of the
   slope. The angle is atan of the slope, in degrees.
5. **Uncertainty**: the same line fitted to each of `n_sectors` (8) azimuthal sectors with
   at least 3 flank points gives one angle per sector; their standard error (standard
   deviation / sqrt(number of sectors)) says how far the heap is from the shape assumed.
   The reported uncertainty combines it with the fit's standard error in quadrature; both
   are reported on their own too.

"Distance from the axis" is Euclidean for a round heap (a cone's height is linear in it)
and max(|dx|, |dy|) in the box axes for a square heap (a square pyramid's height is linear
in it; along a diagonal its Euclidean slope is only tan(theta)/sqrt(2)). `plan="auto"`
measures both and keeps the one whose line fits the flank with the smaller residual, so a
heap that kept its box's square plan is not read as a cone with gentle diagonals. The box
walls are taken parallel to x and y.

`plan="channel"` measures a wedge leaning on a back wall (a two-dimensional collapse: only the
box's +x wall was removed, the grains spread along x between the side walls): the distance is
x - centre[0] (centre[0] is the back wall), the surface cells are the ring's `width` cut into
pieces of about two footprints, and the sectors are those strips along the channel.

`plan="corner"` measures a quarter heap in the corner of two walls (only the box's +x and +y
walls were removed): the distance is Euclidean from the corner (centre), the rings are quarter
rings, and the quadrant is cut into n_sectors / 4 sectors (the full heap's sector width). With
frictionless walls it is a quarter of the heap four times the column would leave (the walls are
its mirror planes); with frictional ones the grains along them lean on the walls (docs/repose.md).

Pile height is the highest grain top above the floor. The heap's extent is the largest horizontal
(Euclidean) distance of a grain centroid from the axis; its runout (one definition everywhere,
`runout`) is that extent beyond the column's half width, 0 for a pile that did not spread.
"""

from __future__ import annotations

import math
import textwrap
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

Plan = Literal["round", "square", "auto", "channel", "corner"]

MIN_FIT_POINTS = 3
CELL_FOOTPRINTS = 2.0  # surface cell area in grain_size^2
MAX_REFITS = 10
MIN_BAND = 1.0  # flank band height in grain sizes below which the toe comes down (step 3)
MIN_FLANK = 0.25  # grain sizes: a heap with a lower band than this is flat (a grain on a layer)
FLOOR_CONTACT = 0.1  # a grain whose lowest point is this close to the floor (grain sizes) lies on it
LAYER_PERCENTILE = 95.0

# Perimeter of the level set at unit distance: the area of a ring is this times its mid-radius.
_LEVEL_SET_PERIMETER = {"round": 2 * math.pi, "square": 8.0, "corner": 0.5 * math.pi}
_ORIGIN = {"channel": "back wall", "corner": "corner"}  # what the side views measure distances from


# eq=False: the array fields make element-wise == ambiguous, so compare by identity.
@dataclass(frozen=True, eq=False)
class ReposeResult:
    """One angle of repose measurement; lengths in the units of the input (m in vemdem).

    profile_r, profile_h: distance from the axis and top height above the floor of each
    surface grain; used_mask marks the flank points of the fit. intercept is h0 in
    h = h0 - tan(angle) r. sector_std_deg is the standard error of the mean of the finite
    sector_angles_deg (nan with fewer than 2 sectors fitted; the uncertainty is then the
    fit's alone). plan says which distance the profile uses ("round" or "square").
    """

    angle_deg: float
    uncertainty_deg: float
    fit_stderr_deg: float
    sector_std_deg: float
    sector_angles_deg: np.ndarray
    intercept: float
    pile_height: float
    extent: float  # largest horizontal distance of a centroid from the axis
    profile_r: np.ndarray
    profile_h: np.ndarray
    used_mask: np.ndarray
    centre: tuple[float, float]
    plan: str
    floor: float

    def runout_from(self, initial_half_width: float) -> float:
        """How far the heap ran out beyond the column it started as (`runout`)."""
        return runout(self.extent, initial_half_width)


@dataclass(frozen=True)
class _Line:
    slope: float  # dh/dr: negative on a heap's flank
    intercept: float
    slope_stderr: float
    residual_std: float

    def distance_at(self, height: float) -> float:
        return (height - self.intercept) / self.slope


def grain_heights(
    centroids: np.ndarray,
    grain_size: float,
    vertices: np.ndarray | None = None,
    vertex_grain: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Lowest and highest point of each grain: its lowest and highest vertex, or centroid -+ d/2
    without vertices."""
    if vertices is None:
        return centroids[:, 2] - 0.5 * grain_size, centroids[:, 2] + 0.5 * grain_size
    vertices = np.asarray(vertices, dtype=float)
    vertex_grain = np.asarray(vertex_grain)
    n_grains = len(centroids)
    if vertices.ndim != 2 or vertices.shape[1] != 3 or vertex_grain.shape != vertices.shape[:1]:
        raise ValueError("vertices must be (N, 3) with one owner grain id each in vertex_grain (N,)")
    if vertex_grain.min() < 0 or vertex_grain.max() >= n_grains:
        raise ValueError(f"vertex_grain ids must lie in [0, {n_grains})")
    bottoms, tops = np.full(n_grains, np.inf), np.full(n_grains, -np.inf)
    np.minimum.at(bottoms, vertex_grain, vertices[:, 2])
    np.maximum.at(tops, vertex_grain, vertices[:, 2])
    if not np.isfinite(tops).all():
        raise ValueError(f"{int((~np.isfinite(tops)).sum())} grains have no vertex in vertex_grain")
    return bottoms, tops


def floor_layer_top(bottoms: np.ndarray, tops: np.ndarray, grain_size: float, floor: float) -> float:
    """Height above the floor of the top of the one-grain layer lying on it: the 95th percentile
    of the tops of the grains whose lowest point touches the floor (within FLOOR_CONTACT grain
    sizes). A percentile, not the maximum: one grain standing on its narrow end would set that."""
    on_floor = bottoms - floor <= FLOOR_CONTACT * grain_size
    if not on_floor.any():
        return grain_size  # a grain of size d lying on the floor
    return float(np.percentile(tops[on_floor] - floor, LAYER_PERCENTILE))


def plan_distance(xy: np.ndarray, centre: tuple[float, float], plan: str) -> np.ndarray:
    """Horizontal distance from the axis (a channel: from its back wall) in which the heap's flank
    is a straight line."""
    if plan == "channel":
        return xy[:, 0] - centre[0]
    dx = np.abs(xy[:, 0] - centre[0])
    dy = np.abs(xy[:, 1] - centre[1])
    return np.maximum(dx, dy) if plan == "square" else np.hypot(dx, dy)


def _turns(xy: np.ndarray, centre: tuple[float, float], plan: str, width: float) -> np.ndarray:
    """Where each point lies around its ring, as a fraction in [0, 1): the azimuth over a full turn,
    or in a channel the position across its width."""
    if plan == "channel":
        return np.clip((xy[:, 1] - centre[1]) / width + 0.5, 0.0, np.nextafter(1.0, 0.0))
    azimuth = np.arctan2(xy[:, 1] - centre[1], xy[:, 0] - centre[0])
    if plan == "corner":  # the quadrant x, y > centre
        return np.clip(azimuth / (0.5 * math.pi), 0.0, np.nextafter(1.0, 0.0))
    return np.mod(azimuth, 2 * math.pi) / (2 * math.pi)


def _ring_areas(ring: np.ndarray, plan: str, width: float) -> np.ndarray:
    """Area of each ring one grain size wide, in grain_size^2 (width: the channel's, in grain sizes)."""
    if plan == "channel":
        return np.full(ring.shape, width)
    return _LEVEL_SET_PERIMETER[plan] * (ring + 0.5)


def _cells(ring_area: np.ndarray) -> np.ndarray:
    return np.maximum(1, np.rint(ring_area / CELL_FOOTPRINTS)).astype(np.int64)


def surface_grains(
    distance: np.ndarray,
    turn: np.ndarray,
    tops: np.ndarray,
    grain_size: float,
    plan: str,
    width: float = 0.0,
) -> np.ndarray:
    """Indices of the highest grain in each surface cell (module docstring, step 2). turn: where
    each grain lies around its ring, in [0, 1) (`_turns`); width: a channel's, in grain sizes."""
    ring = np.floor(distance / grain_size).astype(np.int64)
    n_cells = _cells(_ring_areas(ring, plan, width))
    cell_in_ring = np.minimum(np.floor(turn * n_cells), n_cells - 1)
    cell = ring * (n_cells.max() + 1) + cell_in_ring.astype(np.int64)
    order = np.lexsort((tops, cell))
    last_of_cell = np.r_[cell[order][1:] != cell[order][:-1], True]
    return order[last_of_cell]


def _fit_line(r: np.ndarray, h: np.ndarray) -> _Line:
    r_mean = r.mean()
    sxx = float(((r - r_mean) ** 2).sum())
    slope = float(((r - r_mean) * (h - h.mean())).sum() / sxx)
    intercept = float(h.mean() - slope * r_mean)
    residual = h - (intercept + slope * r)
    residual_var = float((residual**2).sum()) / (len(r) - 2)
    return _Line(slope, intercept, math.sqrt(residual_var / sxx), math.sqrt(residual_var))


def _enough_points(r: np.ndarray) -> bool:
    return len(np.unique(r)) >= MIN_FIT_POINTS


def _slope_angle_deg(slope: float) -> float:
    return math.degrees(math.atan(-slope))


def _angle_stderr_deg(slope: float, slope_stderr: float) -> float:
    # d(atan s)/ds = 1 / (1 + s^2)
    return math.degrees(slope_stderr / (1.0 + slope * slope))


def _flank_fit(r: np.ndarray, h: np.ndarray, low: float, high: float, grain_size: float) -> _Line:
    if not _enough_points(r):
        raise ValueError(
            f"pile is flat: only {len(np.unique(r))} surface points between "
            f"{low / grain_size:.2f} and {high / grain_size:.2f} grain sizes above the "
            f"floor (need {MIN_FIT_POINTS} to fit a slope)"
        )
    line = _fit_line(r, h)
    if line.slope >= 0:
        raise ValueError(
            f"the surface does not descend away from the axis (slope {line.slope:+.3f}): is the centre right?"
        )
    return line


def _band(h_top: float, grain_size: float, toe: float, crest: float, layer_top: float) -> tuple[float, float]:
    """Heights (above the floor) between which the flank is fitted (module docstring, step 3)."""
    high = h_top - crest * grain_size
    # On a low mound a band narrower than the surface roughness holds too few points to fit a
    # slope, so the toe comes down until the band is MIN_BAND tall; never below the measured top
    # of the floor layer, so that the single layer running out beyond the heap stays out.
    low = max(min(toe * grain_size, high - MIN_BAND * grain_size), layer_top)
    if high - low < MIN_FLANK * grain_size:
        raise ValueError(
            f"pile is flat: its highest grain top is {h_top / grain_size:.2f} grain "
            f"sizes above the floor, leaving less than {MIN_FLANK} grain sizes of flank between "
            f"the top of the floor layer ({layer_top / grain_size:.2f} grain sizes) and {crest} "
            f"grain sizes below the top"
        )
    return low, high


def _flank(
    r: np.ndarray, h: np.ndarray, grain_size: float, toe: float, crest: float, layer_top: float
) -> tuple[np.ndarray, _Line]:
    """The flank points (module docstring, step 3) and the line fitted to them."""
    low, high = _band(float(h.max()), grain_size, toe, crest, layer_top)
    used = (h >= low) & (h <= high)
    line = _flank_fit(r[used], h[used], low, high, grain_size)
    for _ in range(MAX_REFITS):
        within = (r >= line.distance_at(high)) & (r <= line.distance_at(low))
        if np.array_equal(within, used):
            break
        used = within
        line = _flank_fit(r[used], h[used], low, high, grain_size)
    return used, line


def _sector_angles(r: np.ndarray, h: np.ndarray, sector: np.ndarray, n_sectors: int) -> np.ndarray:
    angles = np.full(n_sectors, np.nan)
    for k in range(n_sectors):
        mine = sector == k
        if _enough_points(r[mine]):
            angles[k] = _slope_angle_deg(_fit_line(r[mine], h[mine]).slope)
    return angles


def _standard_error(values: np.ndarray) -> float:
    finite = values[np.isfinite(values)]
    if len(finite) < 2:
        return math.nan
    return float(finite.std(ddof=1) / math.sqrt(len(finite)))


def _measure(
    centroids: np.ndarray,
    tops: np.ndarray,
    layer_top: float,
    grain_size: float,
    floor: float,
    centre: tuple[float, float],
    plan: str,
    n_sectors: int,
    toe: float,
    crest: float,
    width: float,
) -> tuple[ReposeResult, float]:
    """The measurement with one distance, and the residual std of its flank fit."""
    xy = centroids[:, :2]
    distance = plan_distance(xy, centre, plan)
    turn = _turns(xy, centre, plan, width)
    chosen = surface_grains(distance, turn, tops, grain_size, plan, width / grain_size)
    r, h = distance[chosen], tops[chosen] - floor
    used, line = _flank(r, h, grain_size, toe, crest, layer_top)
    if plan == "channel":  # the strips along the channel: one per surface cell across it
        n_sectors = int(_cells(np.array([width / grain_size]))[0])
    elif plan == "corner":  # sectors as wide as the full heap's
        n_sectors = max(2, n_sectors // 4)
    sector = np.floor(turn[chosen] * n_sectors).astype(np.int64)
    sector_angles = _sector_angles(r[used], h[used], sector[used], n_sectors)
    sector_se = _standard_error(sector_angles)
    fit_se = _angle_stderr_deg(line.slope, line.slope_stderr)
    combined = fit_se if math.isnan(sector_se) else math.hypot(fit_se, sector_se)
    result = ReposeResult(
        angle_deg=_slope_angle_deg(line.slope),
        uncertainty_deg=combined,
        fit_stderr_deg=fit_se,
        sector_std_deg=sector_se,
        sector_angles_deg=sector_angles,
        intercept=line.intercept,
        pile_height=float(tops.max() - floor),
        extent=_extent(xy, centre, plan),
        profile_r=r,
        profile_h=h,
        used_mask=used,
        centre=centre,
        plan=plan,
        floor=floor,
    )
    return result, line.residual_std


def _extent(xy: np.ndarray, centre: tuple[float, float], plan: str) -> float:
    """Largest horizontal distance of a centroid from the axis (Euclidean), or from a channel's back wall."""
    if plan == "channel":
        return float(plan_distance(xy, centre, plan).max())
    return float(np.hypot(xy[:, 0] - centre[0], xy[:, 1] - centre[1]).max())


def angle_of_repose(
    centroids: np.ndarray,
    grain_size: float,
    *,
    vertices: np.ndarray | None = None,
    vertex_grain: np.ndarray | None = None,
    floor: float = 0.0,
    centre: tuple[float, float] | None = None,
    plan: Plan = "auto",
    n_sectors: int = 8,
    toe: float = 1.5,
    crest: float = 0.5,
    width: float | None = None,
) -> ReposeResult:
    """Angle of repose of a settled heap from its grain centroids (G, 3).

    vertices (N, 3) with vertex_grain (N,) give the grains' tops; without them a grain's
    top is its centroid + grain_size / 2. centre defaults to the grains' horizontal
    centroid. toe and crest bound the flank in grain sizes (above the floor, below the
    highest top). plan="channel" needs centre = (x of the back wall, y of the channel's axis)
    and the channel's width; plan="corner" the corner (the heap lies at x, y > centre). Raises
    ValueError when the heap has no flank to fit.
    """
    centroids = np.asarray(centroids, dtype=float)
    if centroids.ndim != 2 or centroids.shape[1] != 3 or len(centroids) == 0:
        raise ValueError(f"centroids must be a non-empty (G, 3) array, got shape {centroids.shape}")
    if not grain_size > 0:
        raise ValueError(f"grain_size must be > 0, got {grain_size}")
    if plan not in ("round", "square", "auto", "channel", "corner"):
        raise ValueError(f"plan must be 'round', 'square', 'auto', 'channel' or 'corner', got {plan!r}")
    if plan == "channel" and (centre is None or width is None or not width > 0):
        raise ValueError("plan 'channel' needs the back wall and axis as centre and the channel's width > 0")
    if plan == "corner" and centre is None:
        raise ValueError("plan 'corner' needs the corner as centre")
    bottoms, tops = grain_heights(centroids, grain_size, vertices, vertex_grain)
    layer_top = floor_layer_top(bottoms, tops, grain_size, floor)
    cx, cy = centroids[:, :2].mean(axis=0) if centre is None else centre
    centre = (float(cx), float(cy))
    args = (centroids, tops, layer_top, grain_size, floor, centre)
    options = (n_sectors, toe, crest, width or 0.0)
    if plan != "auto":
        return _measure(*args, plan, *options)[0]
    measured, errors = [], []
    for candidate in ("round", "square"):
        try:
            measured.append(_measure(*args, candidate, *options))
        except ValueError as exc:
            errors.append(exc)
    if not measured:
        raise errors[0]
    return min(measured, key=lambda pair: pair[1])[0]


def runout(extent: float, half_width: float) -> float:
    """THE runout: how far the heap's extent reaches beyond the column's half width."""
    return extent - half_width


def pile_axis(meta: dict, opened: str = "all"):
    """(centre, plan, column, across) of a pile from its pack's box and the walls removed (`opened`,
    `[collapse] open`): all four, the box axis and "auto" with the column's half width; "front",
    the channel's back wall ("channel") with the box's width as the column and its depth across;
    "corner", the corner of the two standing walls ("corner") with the box's width as the column
    (the half width of the column four times as large that the walls mirror). Distances in the
    plots and figures are taken from `centre`."""
    width, depth = meta["box"]
    cx, cy = meta.get("centre", (0.0, 0.0))
    if opened == "front":
        return (cx - 0.5 * width, cy), "channel", width, depth
    if opened == "corner":
        return (cx - 0.5 * width, cy - 0.5 * depth), "corner", min(width, depth), None
    return (cx, cy), "auto", 0.5 * min(width, depth), None


def measure_pile(centroids: np.ndarray, x: np.ndarray, vertex_grain: np.ndarray, grain_size: float, meta: dict,
                 opened: str = "all"):  # fmt: skip
    """(ReposeResult or None, summary figures) of a settled pile at vertex positions x.
    pile_height: highest grain top above the floor; runout: largest horizontal distance of a grain
    centroid from the box axis minus the box's half width (0 for a pile that did not spread); both
    also for a heap too flat for an angle, which gets angle_of_repose_deg = None and the reason.
    opened: the walls removed (pile_axis): "front" (`plan="channel"`) measures distances from the
    back wall and the runout beyond the box's width, "corner" from the corner of the standing walls
    and the runout beyond the box's width."""
    floor = meta.get("floor", 0.0)
    centre, plan, column, across = pile_axis(meta, opened)
    extent = _extent(centroids[:, :2], centre, plan)
    figures = {"pile_height": float(x[:, 2].max() - floor), "runout": runout(extent, column)}
    try:
        result = angle_of_repose(centroids, grain_size, vertices=x, vertex_grain=vertex_grain, floor=floor,
                                 centre=centre, plan=plan, width=across)  # fmt: skip
    except ValueError as exc:
        return None, {"angle_of_repose_deg": None, "angle_of_repose_error": str(exc), **figures}
    return result, {
        "angle_of_repose_deg": result.angle_deg,
        "angle_of_repose_uncertainty_deg": result.uncertainty_deg,
        **figures,
        "surface_plan": result.plan,
    }


def repose_headline(summary: dict) -> str:
    """The one line a heap's run ends with: the angle with its uncertainty and the heap's height,
    or why there is no angle."""
    height = f"pile height {summary['pile_height'] * 1e3:.2f} mm"
    angle = summary.get("angle_of_repose_deg")
    if angle is None:
        return f"no angle of repose ({summary.get('angle_of_repose_error')}); {height}"
    return f"angle of repose {angle:.1f} +- {summary['angle_of_repose_uncertainty_deg']:.1f} deg; {height}"


def plot_pile(result: ReposeResult, centroids: np.ndarray, path: Path, title: str = "") -> None:
    """Side view: every centroid at (distance from the axis, height), the surface profile,
    and the fitted flank. Input lengths in m, plotted in mm."""
    from .plots import plt  # the package's Agg backend

    mm = 1e3
    centroids = np.asarray(centroids, dtype=float)
    distance = plan_distance(centroids[:, :2], result.centre, result.plan)
    used = result.used_mask
    fit_r = np.array([result.profile_r[used].min(), result.profile_r[used].max()])
    fit_h = result.intercept - math.tan(math.radians(result.angle_deg)) * fit_r

    fig, ax = plt.subplots(figsize=(7, 4.2), dpi=120)
    ax.axhline(0.0, color="k", lw=0.8)
    ax.scatter(
        distance * mm,
        (centroids[:, 2] - result.floor) * mm,
        s=6,
        c="0.7",
        label="grain centroids",
    )
    ax.scatter(
        result.profile_r[~used] * mm,
        result.profile_h[~used] * mm,
        s=14,
        facecolors="none",
        edgecolors="tab:blue",
        label="surface grain tops (not fitted)",
    )
    ax.scatter(
        result.profile_r[used] * mm,
        result.profile_h[used] * mm,
        s=14,
        c="tab:blue",
        label="surface grain tops (flank)",
    )
    ax.plot(
        fit_r * mm,
        fit_h * mm,
        "r-",
        lw=2,
        label=f"fit: {result.angle_deg:.1f}° ± {result.uncertainty_deg:.1f}°",
    )
    distance_name = {"round": "distance from the axis", "square": "max(|dx|, |dy|) from the axis",
                     "channel": "distance from the back wall", "corner": "distance from the corner"}[result.plan]  # fmt: skip
    ax.set_xlabel(f"{distance_name} (mm)")
    ax.set_ylabel("height above the floor (mm)")
    ax.set_title(f"{title}: angle of repose" if title else "angle of repose")
    _save_side_view(fig, ax, path)


def plot_heap(centroids: np.ndarray, centre: tuple[float, float], path: Path, title: str = "", note: str = "",
              plan: str = "round") -> None:  # fmt: skip
    """Side view of a heap without a fitted flank (too flat or too small to measure): every
    centroid at (distance from the axis, from a channel's back wall or from the corner, height),
    with `note` saying why there is no fit."""
    from .plots import plt  # the package's Agg backend

    mm = 1e3
    centroids = np.asarray(centroids, dtype=float)
    distance = plan_distance(centroids[:, :2], centre, plan if plan in ("channel", "corner") else "round")
    fig, ax = plt.subplots(figsize=(7, 4.2), dpi=120)
    ax.axhline(0.0, color="k", lw=0.8)
    ax.scatter(distance * mm, centroids[:, 2] * mm, s=10, c="0.4", label="grain centroids")
    ax.set_xlabel(f"distance from the {_ORIGIN.get(plan, 'axis')} (mm)")
    ax.set_ylabel("height above the floor (mm)")
    # the note goes under the title: inside the axes it covered a flat heap's thin plot
    ax.set_title((title or "heap") + ("\n" + textwrap.fill(note, 90) if note else ""), fontsize=9 if note else None)
    _save_side_view(fig, ax, path)


def vertical_exaggeration(width: float, height: float, target: float = 3.0) -> int:
    """Whole-number vertical scale that shows a heap `width` wide and `height` high in a box about
    `target` times wider than high (1 when it already is): a collapse's deposit can be 15 times
    wider than high, a thin strip at true scale."""
    if height <= 0 or width <= target * height:
        return 1
    return max(1, round(width / (target * height)))


def _save_side_view(fig, ax, path: Path) -> None:
    from .plots import plt

    ax.relim()
    (x0, y0), (x1, y1) = ax.dataLim.get_points()
    k = vertical_exaggeration(x1 - min(x0, 0.0), y1 - min(y0, 0.0))
    ax.set_aspect(k)  # one mm of height drawn k times as long as one of distance
    if k > 1:
        ax.set_ylabel(f"{ax.get_ylabel()}, vertical scale x{k}")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.22), ncol=2, frameon=False)
    fig.tight_layout()
    fig.savefig(path, bbox_inches="tight")
    plt.close(fig)
