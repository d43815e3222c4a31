"""The tilting box's measures: the free surface's angle to the horizontal, and its picture.

The box stays put and gravity turns (scenarios.tilting_box): tilted by theta about the y axis, its
+x end down, gravity in the box's frame is

    g(theta) = |g| (sin theta, 0, -cos theta)

and the horizontal and the up direction of the tilted world, in the box's frame, are

    e_h = (cos theta, 0, sin theta),   e_u = (-sin theta, 0, cos theta).

The surface grains are those no other grain covers (none higher within half a grain size in the
box's floor plan), those within a grain size of the two end walls (x) left out: the wall bends
the surface there.
A plane u = a + s h + c y through their centroids, in tilted-world coordinates h = x.e_h,
u = x.e_u, gives the surface angle atan(-s) (positive: the surface falls towards +x, downhill) and
its standard error from the fit. Before the avalanche the surface is the flat top of the pack, at
the tilt angle; after it, at the angle of repose.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

MIN_SURFACE_GRAINS = 5  # a plane through fewer is noise, not a surface


def tilted_gravity(theta_deg: float, g: float) -> np.ndarray:
    th = math.radians(theta_deg)
    return np.array([g * math.sin(th), 0.0, -g * math.cos(th)])


def tilted_frame(theta_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """(e_h, e_u): the tilted world's horizontal (downhill) and up directions in the box's frame."""
    th = math.radians(theta_deg)
    return np.array([math.cos(th), 0.0, math.sin(th)]), np.array([-math.sin(th), 0.0, math.cos(th)])


@dataclass
class Surface:
    """A plane fitted to the surface grains, in the tilted world (h, u, y)."""

    angle_deg: float  # to the horizontal, positive falling towards +x
    stderr_deg: float
    intercept: float  # u at h = 0, y = mean y of the surface grains
    slope: float  # du/dh
    grains: np.ndarray  # indices of the surface grains


def surface_grains(centroids: np.ndarray, box: tuple[float, float], centre, grain_size: float) -> np.ndarray:
    """The grains no other grain covers (none higher by a quarter grain size, box z, within half a
    grain size in plan), those within one grain size of the end walls (x) left out."""
    from scipy.spatial import cKDTree

    xy, z = centroids[:, :2], centroids[:, 2]
    covered = np.zeros(len(z), bool)
    for i, near in enumerate(cKDTree(xy).query_ball_point(xy, 0.5 * grain_size)):
        covered[i] = np.any(z[near] > z[i] + 0.25 * grain_size)
    inner = np.abs(centroids[:, 0] - centre[0]) < box[0] / 2 - grain_size
    return np.flatnonzero(~covered & inner)


def fit_surface(centroids: np.ndarray, theta_deg: float, box, centre, grain_size: float) -> Surface:
    """The surface plane of the grains (module docstring); ValueError when too few cells hold one."""
    top = surface_grains(centroids, box, centre, grain_size)
    if len(top) < MIN_SURFACE_GRAINS:
        raise ValueError(f"only {len(top)} surface grains away from the end walls (need {MIN_SURFACE_GRAINS}): "
                         "the box is too short or too empty for a surface angle")  # fmt: skip
    e_h, e_u = tilted_frame(theta_deg)
    c = centroids[top]
    h, u, y = c @ e_h, c @ e_u, c[:, 1] - c[:, 1].mean()
    A = np.column_stack([np.ones(len(c)), h, y])
    coef, *_ = np.linalg.lstsq(A, u, rcond=None)
    dof = len(c) - 3
    residual = u - A @ coef
    if dof > 0 and np.ptp(h) > 0:
        cov = float(residual @ residual) / dof * np.linalg.pinv(A.T @ A)
        slope_err = math.sqrt(max(cov[1, 1], 0.0))
    else:
        slope_err = math.inf
    s = float(coef[1])
    return Surface(math.degrees(math.atan(-s)), math.degrees(slope_err / (1 + s * s)), float(coef[0]), s, top)


def plot_tilt(path: Path, centroids: np.ndarray, theta_deg: float, box, centre, floor: float, top: float,
              after: Surface | None, onset: dict | None, times, kinetic_ratio, tilts, threshold: float | None,
              title: str = "") -> None:  # fmt: skip
    """Left: the box seen along y in the tilted world, the grains at the end, the surface fits
    at the avalanche (dashed) and after it; right: the kinetic energy and the tilt against time
    (threshold: the kinetic mark's level, None with the surface mark)."""
    from .plots import plt

    mm = 1e3
    e_h, e_u = tilted_frame(theta_deg)
    fig, (ax, ak) = plt.subplots(1, 2, figsize=(11, 4.4), dpi=120, gridspec_kw={"width_ratios": [1.4, 1]})
    (w, _), (cx, _) = box, centre
    corners = np.array([[cx - w / 2, 0, top], [cx - w / 2, 0, floor], [cx + w / 2, 0, floor], [cx + w / 2, 0, top]])
    ax.plot(corners @ e_h * mm, corners @ e_u * mm, "k-", lw=1.5, label="box (floor and end walls)")
    ax.plot(centroids @ e_h * mm, centroids @ e_u * mm, "o", color="0.6", ms=4, label="grain centroids")
    h = corners @ e_h
    span = np.array([h.min(), h.max()])
    if onset is not None and onset.get("intercept") is not None:
        ax.plot(span * mm, (onset["intercept"] + onset["slope"] * span) * mm, "--", color="tab:orange",
                label=f"surface at the avalanche: {onset['angle_deg']:.1f} deg")  # fmt: skip
    if after is not None:
        c = centroids[after.grains]
        ax.plot(c @ e_h * mm, c @ e_u * mm, "o", color="tab:blue", ms=5, label="surface grains")
        ax.plot(span * mm, (after.intercept + after.slope * span) * mm, "-", color="tab:red",
                label=f"surface after it: {after.angle_deg:.1f} +- {after.stderr_deg:.1f} deg")  # fmt: skip
    ax.set_aspect("equal")
    ax.set_xlabel("horizontal (mm)")
    ax.set_ylabel("up (mm)")
    ax.set_title(f"box tilted {theta_deg:.1f} deg")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.18), ncol=2, frameon=False)
    ak.semilogy(times, np.maximum(kinetic_ratio, 1e-12), "-", color="tab:purple", label="kinetic energy / (N m g d)")
    if threshold is not None:  # the kinetic mark (scenarios.tilting_box)
        ak.axhline(threshold, color="tab:purple", ls=":", lw=1, label="avalanche threshold")
    if onset is not None:
        ak.axvline(onset["time"], color="tab:orange", ls="--", lw=1, label="avalanche")
    ak.set_xlabel("time (s)")
    ak.set_ylabel("kinetic energy / (N m g d)")
    ak.grid(alpha=0.3)
    at = ak.twinx()
    at.plot(times, tilts, "k-", lw=1, label="tilt")
    at.set_ylabel("tilt (degrees)")
    lines = ak.get_legend_handles_labels()[0] + at.get_legend_handles_labels()[0]
    ak.legend(lines, [ln.get_label() for ln in lines], fontsize=8, loc="lower right")
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, bbox_inches="tight")
    plt.close(fig)
