"""The microstructure of one frame: contact network, fabric, force network and stress (docs/microstructure.md).

Input is plain arrays, one row per contact record (contact.model.ContactRecords: a, b the bodies
on sides A and B, walls numbered from n_grains; kind 0..3 in KINDS' order; point; normal, unit,
from B to A; force on A from B). A record is one touching spot of the narrow phase; two grains
touching face to face give several. Everything here counts contacts per grain PAIR: the records
between two grains are one contact, whose

    force     f = sum over its records of the force on the pair's lower-numbered grain (lo) from
              the other (hi)
    normal    f_n = sum over its records of f_r . n_r (each record's normal part, on its own normal)
    direction n = the records' normals (oriented from hi to lo) weighted by their f_n, normalised:
              the force-weighted mean normal (the plain mean where the records carry no force)

The fabric, the strong/weak split and the force distribution are over grain-grain contacts; wall
contacts are counted apart. The Love-Weber stress takes every record, walls' included (the
boundary's forces are what loads the sample).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

KINDS = ("vertex-face", "edge-edge", "vertex-edge", "vertex-vertex")  # record kinds, in the narrow phase's numbering
KIND_COLUMNS = tuple(k.replace("-", "_") for k in KINDS)
_PAIRS = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))  # the six components of a symmetric tensor
FABRIC_COLUMNS = tuple(f"F_{'xyz'[i]}{'xyz'[j]}" for i, j in _PAIRS)
STRESS_COLUMNS = tuple(f"sigma_{'xyz'[i]}{'xyz'[j]}" for i, j in _PAIRS)
FABRIC_HEADER = ["time", "n_records", "n_pairs", "coordination", "mechanical_coordination", "rattlers",
                 "wall_contacts", *KIND_COLUMNS, *FABRIC_COLUMNS, "anisotropy", "strong_share", "strong_stress_share",
                 "fn_mean", "fn_max_over_mean", *STRESS_COLUMNS]  # fmt: skip

# f_n / <f_n> histogram: equal bins from 0 to the largest ratio
FORCE_BINS = 30
# A contact is strong above the mean normal force by more than this share of it: forces equal to the
# mean but for round-off (a regular packing's) are weak, not a coin toss in the last bit
STRONG_TOL = 1e-9


@dataclass(frozen=True)
class PairContacts:
    """Grain-grain contacts, one row per grain pair (lo < hi), in increasing (lo, hi)."""

    lo: np.ndarray  # (C,) the pair's lower grain index
    hi: np.ndarray  # (C,) its higher one
    n_records: np.ndarray  # (C,) records between the two
    force: np.ndarray  # (C, 3) force on lo from hi
    normal: np.ndarray  # (C, 3) unit force-weighted mean normal, from hi to lo
    fn: np.ndarray  # (C,) normal force (sum of the records' normal parts; > 0 pushes the grains apart)


def is_grain_grain(a: np.ndarray, b: np.ndarray, n_grains: int) -> np.ndarray:
    """(m,) bool: the record is between two grains (no wall on either side)."""
    return (np.asarray(a) < n_grains) & (np.asarray(b) < n_grains)


def _unique_pairs(lo: np.ndarray, hi: np.ndarray, n_bodies: int):
    """(lo, hi, inverse) of the distinct unordered pairs, sorted, and each record's pair."""
    keys, inverse = np.unique(lo.astype(np.int64) * n_bodies + hi, return_inverse=True)
    return keys // n_bodies, keys % n_bodies, inverse.ravel()


def pair_contacts(a, b, normal, force, n_grains: int) -> PairContacts:
    """The grain-grain records merged into one contact per grain pair (module docstring)."""
    a, b = np.asarray(a, np.int64), np.asarray(b, np.int64)
    mine = is_grain_grain(a, b, n_grains)
    a, b = a[mine], b[mine]
    normal, force = np.asarray(normal, float)[mine], np.asarray(force, float)[mine]
    # a record's force and normal both flip with its sides: fn_r is the same either way round
    fn_r = np.einsum("ri,ri->r", force, normal)
    sign = np.where(a < b, 1.0, -1.0)[:, None]
    lo, hi, inverse = _unique_pairs(np.minimum(a, b), np.maximum(a, b), max(n_grains, 1))
    C = len(lo)
    count = np.bincount(inverse, minlength=C)
    pair_force = _sum_rows(sign * force, inverse, C)
    fn = np.bincount(inverse, weights=fn_r, minlength=C).astype(float)  # (bincount of nothing is int)
    weighted = _sum_rows(fn_r[:, None] * sign * normal, inverse, C)
    plain = _sum_rows(sign * normal, inverse, C)
    length = np.linalg.norm(weighted, axis=1)
    # no force to weigh by (a record inside the layer at zero force, or forces that cancel): the plain mean
    use = np.where((length > 0.0)[:, None], weighted, plain)
    return PairContacts(lo, hi, count, pair_force, _unit(use), fn)


def _sum_rows(values: np.ndarray, index: np.ndarray, n: int) -> np.ndarray:
    """(n, 3): the rows of values summed by index."""
    out = np.zeros((n, 3))
    for k in range(3):
        out[:, k] = np.bincount(index, weights=values[:, k], minlength=n)
    return out


def _unit(v: np.ndarray) -> np.ndarray:
    length = np.linalg.norm(v, axis=1, keepdims=True)
    return np.divide(v, length, out=np.zeros_like(v), where=length > 0.0)


def coordination(a, b, n_grains: int) -> dict:
    """Coordination of the grain-grain contact network, counted per grain pair (C pairs, N grains):

        coordination             Z   = 2 C / N
        mechanical_coordination  Z_m = (2 C - N1) / (N - N0 - N1)   (Thornton 2000)

    N0, N1: grains with no and with one grain contact; they carry no stable load ("rattlers",
    their count N0 + N1). Wall contacts do not count here: a grain resting on the floor alone is a
    rattler, and grains along the walls lower Z (wall_contacts counts those contacts). Z_m is None
    where every grain is a rattler."""
    a, b = np.asarray(a, np.int64), np.asarray(b, np.int64)
    mine = is_grain_grain(a, b, n_grains)
    lo, hi, _ = _unique_pairs(np.minimum(a[mine], b[mine]), np.maximum(a[mine], b[mine]), max(n_grains, 1))
    degree = np.bincount(np.concatenate([lo, hi]), minlength=n_grains)
    n0, n1 = int(np.sum(degree == 0)), int(np.sum(degree == 1))
    C = len(lo)
    carrying = n_grains - n0 - n1
    return {"n_pairs": C, "coordination": 2.0 * C / n_grains if n_grains else None,
            "mechanical_coordination": (2.0 * C - n1) / carrying if carrying > 0 else None,
            "rattlers": n0 + n1, "no_contact": n0, "one_contact": n1}  # fmt: skip


def wall_contacts(a, b, n_grains: int) -> int:
    """Contacts between a grain and a wall, per (grain, wall) pair: the records one grain has with
    one wall are one contact."""
    a, b = np.asarray(a, np.int64), np.asarray(b, np.int64)
    wall = (a < n_grains) != (b < n_grains)
    grain, body = np.minimum(a[wall], b[wall]), np.maximum(a[wall], b[wall])
    n_bodies = int(body.max()) + 1 if len(body) else 1
    return len(_unique_pairs(grain, body, n_bodies)[0])


def kind_counts(kind, a, b, n_grains: int) -> dict:
    """Grain-grain records of each kind (KIND_COLUMNS: vertex_face, edge_edge, vertex_edge,
    vertex_vertex); walls' records left out (a plane's are all vertex-face)."""
    mine = is_grain_grain(a, b, n_grains)
    counts = np.bincount(np.asarray(kind, np.int64)[mine], minlength=len(KINDS))
    return {name: int(counts[k]) for k, name in enumerate(KIND_COLUMNS)}


def fabric_tensor(normals) -> np.ndarray:
    """F = <n (x) n>, the mean over the given unit normals (one per contact); trace 1. NaN without
    normals. A normal's sign does not enter."""
    n = np.asarray(normals, float).reshape(-1, 3)
    if not len(n):
        return np.full((3, 3), np.nan)
    return n.T @ n / len(n)


def fabric_deviator(F) -> np.ndarray:
    """F' = F - tr(F) I / 3: zero for an isotropic fabric."""
    F = np.asarray(F, float)
    return F - np.trace(F) / 3.0 * np.eye(3)


def anisotropy(F) -> float:
    """Scalar fabric anisotropy a = sqrt(3/2 a_ij a_ij), a_ij = 15/2 F'_ij: the second-order
    coefficients of the normals' density E(n) = (1 + a_ij n_i n_j) / (4 pi) (Ouadfel and Rothenburg
    2001). Axisymmetric about z, a_ij = a diag(-1/3, -1/3, 2/3). 0 for an isotropic fabric, 7.5
    for all normals along one axis. The second-order density turns negative in some direction from
    a = 1.5 on (a_ij = a diag(1/3, 1/3, -2/3)), in every fabric from a = 3: large values still rank
    fabrics but no longer describe a density."""
    a_ij = 7.5 * fabric_deviator(F)
    return float(np.sqrt(1.5 * np.sum(a_ij * a_ij)))


def is_strong(fn: np.ndarray) -> np.ndarray:
    """(C,) bool: f_n > <f_n> (1 + STRONG_TOL)."""
    return fn > fn.mean() * (1.0 + STRONG_TOL)


def strong_network(fn, force=None, branch=None) -> dict:
    """The strong/weak split at the mean normal force <f_n> (Radjai et al. 1998): a contact is
    strong where f_n > <f_n> (is_strong: beyond round-off).

        strong_share         strong contacts / contacts
        strong_stress_share  p_strong / p, p = tr(sigma) / 3 of the grain-grain contacts alone,
                             each contributing f . l (force on lo, branch l = x_lo - x_hi between
                             the grains' centroids); needs force and branch, else None

    Both None without contacts."""
    fn = np.asarray(fn, float)
    if not len(fn):
        return {"strong_share": None, "strong_stress_share": None}
    strong = is_strong(fn)
    share = None
    if force is not None and branch is not None:
        trace = np.einsum("ci,ci->c", np.asarray(force, float), np.asarray(branch, float))
        total = trace.sum()
        share = float(trace[strong].sum() / total) if total != 0.0 else None
    return {"strong_share": float(strong.mean()), "strong_stress_share": share}


def force_distribution(fn, bins: int = FORCE_BINS) -> dict:
    """The distribution of f_n / <f_n> over the contacts: a histogram (edges, counts, density: the
    probability density, integrating to 1) on [0, max], and max_over_mean, share_above_1 (the
    strong contacts' share, is_strong), share_above_2, share_below_half, cv (standard deviation
    over mean). Empty (None values, no bins) without contacts or where <f_n> is not a positive
    number (mean: None, or what it is)."""
    fn = np.asarray(fn, float)
    mean = fn.mean() if len(fn) else 0.0
    if not (mean > 0.0 and np.isfinite(mean)):
        return {"mean": float(mean) if len(fn) else None, "edges": np.zeros(0), "counts": np.zeros(0, np.int64),
                "density": np.zeros(0), "max_over_mean": None, "share_above_1": None, "share_above_2": None,
                "share_below_half": None, "cv": None}  # fmt: skip
    ratio = fn / mean
    counts, edges = np.histogram(ratio, bins=bins, range=(0.0, max(float(ratio.max()), 1.0)))
    density = counts / (len(ratio) * np.diff(edges))
    return {"mean": float(mean), "edges": edges, "counts": counts, "density": density,
            "max_over_mean": float(ratio.max()), "share_above_1": float(np.mean(is_strong(fn))),
            "share_above_2": float(np.mean(ratio > 2.0)), "share_below_half": float(np.mean(ratio < 0.5)),
            "cv": float(ratio.std())}  # fmt: skip


def love_weber_stress(a, b, point, force, centroids, volume: float) -> np.ndarray:
    """The Love-Weber mean stress of the grains in a volume V, compression positive:

        sigma = -(1/V) sum over grains g, over g's records c:  f_g^c (x) (x^c - x_g)

    f_g^c the force on grain g at record c (side A gets the record's force, side B minus it),
    x^c the contact point and x_g the grain's centroid. A wall's side adds nothing (it is no
    grain), so a wall record counts once, on its grain: the boundary forces load the sample. For a
    grain-grain record the two sides add f (x) (x_A - x_B), the branch vector. Returns the
    symmetric part (the grains' moments balance only at rest)."""
    a, b = np.asarray(a, np.int64), np.asarray(b, np.int64)
    point, force = np.asarray(point, float), np.asarray(force, float)
    centroids = np.asarray(centroids, float)
    n_grains = len(centroids)
    total = np.zeros((3, 3))
    for side, sign in ((a, 1.0), (b, -1.0)):
        mine = side < n_grains
        lever = point[mine] - centroids[side[mine]]
        total += sign * force[mine].T @ lever
    sigma = (0.0 - total) / volume  # not -total: no -0.0 in fabric.csv
    return 0.5 * (sigma + sigma.T)


def fabric_row(t: float, records, n_grains: int, centroids=None, volume: float | None = None,
               pairs: PairContacts | None = None) -> dict:  # fmt: skip
    """One frame's fabric.csv row (FABRIC_HEADER): records holds the arrays a, b, kind, point,
    normal, force (contact.model.ContactRecords); centroids (n_grains, 3) the grains' centroids
    (the strong network's share of the stress, and the Love-Weber stress), volume the sample's
    (the stress); pairs: pair_contacts of the records, where the caller has them already. A value
    that is not defined (no contacts, no centroids, no volume) is None, an empty cell."""
    a, b = np.asarray(records.a, np.int64), np.asarray(records.b, np.int64)
    if pairs is None:
        pairs = pair_contacts(a, b, records.normal, records.force, n_grains)
    branch = None
    if centroids is not None:
        centroids = np.asarray(centroids, float)
        branch = centroids[pairs.lo] - centroids[pairs.hi]
    F = fabric_tensor(pairs.normal)
    has_fabric = len(pairs.lo) > 0
    dist = force_distribution(pairs.fn)
    row = {"time": float(t), "n_records": int(np.sum(is_grain_grain(a, b, n_grains)))}
    net = coordination(a, b, n_grains)
    row.update({k: net[k] for k in ("n_pairs", "coordination", "mechanical_coordination", "rattlers")})
    row["wall_contacts"] = wall_contacts(a, b, n_grains)
    row.update(kind_counts(records.kind, a, b, n_grains))
    row.update({name: float(F[i, j]) if has_fabric else None for name, (i, j) in zip(FABRIC_COLUMNS, _PAIRS)})
    row["anisotropy"] = anisotropy(F) if has_fabric else None
    row.update(strong_network(pairs.fn, pairs.force, branch))
    row["fn_mean"] = dist["mean"]
    row["fn_max_over_mean"] = dist["max_over_mean"]
    sigma = None
    if volume is not None and centroids is not None:
        sigma = love_weber_stress(a, b, records.point, records.force, centroids, volume)
    row.update({name: None if sigma is None else float(sigma[i, j]) for name, (i, j) in zip(STRESS_COLUMNS, _PAIRS)})
    return row


def normal_angles(normals) -> tuple[np.ndarray, np.ndarray]:
    """(azimuth, elevation) of unit normals in radians: azimuth atan2(n_y, n_x) in the xy plane,
    elevation asin(n_z) above it."""
    n = np.asarray(normals, float).reshape(-1, 3)
    return np.arctan2(n[:, 1], n[:, 0]), np.arcsin(np.clip(n[:, 2], -1.0, 1.0))


ROSE_BINS = 24


def rose_histograms(normals, bins: int = ROSE_BINS) -> dict:
    """The rose of contact normals, each normal counted with its opposite (a contact's normal is a
    direction, not an orientation), as densities that are 1 for an isotropic fabric:

        azimuth    share per bin over [-pi, pi) times the number of bins, each normal weighted by
                   n_x^2 + n_y^2 (a vertical normal has no azimuth: it adds nothing)
        elevation  share per band over [-pi/2, pi/2] over the band's share of the sphere's area
                   (an isotropic fabric has few normals near the poles)

    All zero without normals (or, the azimuth, without a normal off the vertical)."""
    n = np.asarray(normals, float).reshape(-1, 3)
    both = np.vstack([n, -n])
    azimuth, elevation = normal_angles(both)
    weight = both[:, 0] ** 2 + both[:, 1] ** 2
    a_sums, a_edges = np.histogram(azimuth, bins=bins, range=(-np.pi, np.pi), weights=weight)
    e_counts, e_edges = np.histogram(elevation, bins=bins // 2, range=(-0.5 * np.pi, 0.5 * np.pi))
    band = 0.5 * np.diff(np.sin(e_edges))  # a band's share of the sphere's area
    a_total = weight.sum()
    return {"azimuth_edges": a_edges, "azimuth_density": a_sums * bins / a_total if a_total > 0 else a_sums,
            "elevation_edges": e_edges, "elevation_density": e_counts / max(len(both), 1) / band}  # fmt: skip


# what the marks mean, under the figure: a rose read without it looks like a plain histogram
ROSE_CAPTION = ("Roses: the density of contact normals per direction (each normal counted with its opposite), "
                "1 for an isotropic fabric (dashed circle);\nazimuth weighted by the normal's horizontal part, "
                "elevation per band of the sphere's area. Right: the normal forces over their mean "
                "(dashed line: the mean).")


def plot_fabric_rose(path: Path, frames) -> None:
    """fabric_rose.png: one row per frame (label, normals (C, 3), fn (C,)), each with the rose of
    the normals' azimuth (xy plane) and elevation (rose_histograms; the dashed circle: isotropic)
    and the distribution of f_n / <f_n> (log scale); the row's label above it, and a caption that
    says what the marks are. Agg, no pyplot: no global backend for the driver to set."""
    from matplotlib.figure import Figure  # here: a run that draws nothing does not load matplotlib

    frames = list(frames)
    rows = max(len(frames), 1)
    row_height, head, foot = 3.6, 1.0, 0.75  # inches: a row, above the first (its label, titles), the caption
    height = rows * row_height + head + foot
    fig = Figure(figsize=(10, height), dpi=100)
    labels = []
    for row, (label, normals, fn) in enumerate(frames):
        rose = rose_histograms(normals)
        for col, key, title, colour in ((0, "azimuth", "azimuth of the normals (xy plane)", "tab:blue"),
                                        (1, "elevation", "elevation above the xy plane", "tab:orange")):  # fmt: skip
            ax = fig.add_subplot(rows, 3, 3 * row + col + 1, projection="polar")
            edges = rose[f"{key}_edges"]
            ax.bar(edges[:-1], rose[f"{key}_density"], width=np.diff(edges), align="edge", color=colour,
                   edgecolor="k", lw=0.3)  # fmt: skip
            ax.plot(np.linspace(edges[0], edges[-1], 73), np.ones(73), "k--", lw=0.8)
            ax.set_ylim(0.0, max(1.2, 1.05 * float(rose[f"{key}_density"].max())))
            ax.set_yticks([1.0], ["1"])
            ax.tick_params(labelsize=8)
            if key == "elevation":
                ax.set_thetamin(-90)
                ax.set_thetamax(90)
            ax.set_title(title, fontsize=9, pad=14)  # clear of the 90 degree label
            labels.append((row, ax, label))
        ax = fig.add_subplot(rows, 3, 3 * row + 3)
        dist = force_distribution(fn)
        if len(dist["counts"]):
            ax.stairs(np.where(dist["density"] > 0, dist["density"], np.nan), dist["edges"], fill=True, alpha=0.6)
            ax.set_yscale("log")
            ax.axvline(1.0, color="k", lw=0.8, ls="--")
        ax.set_xlabel("f_n / <f_n>")
        ax.set_ylabel("probability density")
        ax.tick_params(labelsize=8)
        ax.set_title(f"{len(np.atleast_1d(fn))} contacts, max {dist['max_over_mean'] or 0:.2f} <f_n>", fontsize=9,
                     pad=14)  # fmt: skip
    fig.text(0.5, 0.12 / height, ROSE_CAPTION, ha="center", va="bottom", fontsize=8, wrap=True)
    # fixed margins: tight_layout measured every tick label of the polar axes, most of the drawing time
    fig.subplots_adjust(left=0.06, right=0.97, bottom=(foot + 0.45) / height, top=1.0 - head / height,
                        wspace=0.35, hspace=0.75)  # fmt: skip
    tops: dict[int, tuple[float, str]] = {}
    for row, ax, label in labels:  # a polar axes draws inside its box: its circle's top, not the box's
        ax.apply_aspect()
        top = ax.get_position(original=False).y1
        tops[row] = (max(top, tops.get(row, (0.0, ""))[0]), label)
    for top, label in tops.values():  # each row's label above its titles (pad, tick labels, the title)
        fig.text(0.5, top + 0.62 / height, label, ha="center", va="bottom", fontsize=10, fontweight="bold")
    fig.savefig(path)
