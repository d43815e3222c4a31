"""Plots people would rather look at than read (matplotlib, no screen needed)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def plot_compression_curve(path: Path, strain, force, closed_form=None, mode: str = "", title: str = "") -> None:
    """One grain squeezed between plates: the VEM force against strain, and the closed form
    (docs/vem.md) when there is one. (The lid cycle has its own plot: force_strain.plot_force_strain.)"""
    fig, ax = plt.subplots(figsize=(6, 4.2), dpi=120)
    ax.plot(np.asarray(strain) * 100, force, "o-", ms=3, label="VEM, one element")
    if closed_form is not None:
        ax.plot(np.asarray(strain) * 100, closed_form, "k--", lw=1, label=f"closed form ({mode})")
    ax.set_xlabel("compressive strain 1 - h/h0 (%)")
    ax.set_ylabel("compressive force on the top plate (N)")
    ax.set_title(f"{title}: {mode} compression" if title else f"{mode} compression")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def plot_grains_3d(path: Path, x: np.ndarray, faces: np.ndarray, face_grain: np.ndarray, title: str = "",
                   floor_z: float | None = None) -> None:  # fmt: skip
    """A 3D view of the grains' surfaces (triangles `faces` into the vertex positions x, m),
    each grain coloured by the height of its centroid, drawn back to front; mm on the axes."""
    from matplotlib import cm
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    mm = 1e3
    tris = x[faces] * mm
    n_grains = int(face_grain.max()) + 1 if len(face_grain) else 0
    height = np.zeros(n_grains)
    np.maximum.at(height, face_grain, tris[:, :, 2].mean(axis=1))  # a grain's highest face: its colour
    lo, hi = height.min(), max(height.max(), height.min() + 1e-9)
    colours = cm.viridis((height[face_grain] - lo) / (hi - lo))
    # shade each face by its normal against a light from above, so that shapes read in print
    normal = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-30)
    shade = 0.55 + 0.45 * np.clip(normal @ np.array([0.3, -0.4, 0.87]), 0.0, 1.0)
    colours[:, :3] *= shade[:, None]
    fig = plt.figure(figsize=(6.4, 5.2), dpi=130)
    ax = fig.add_subplot(projection="3d")
    ax.add_collection3d(Poly3DCollection(tris, facecolors=colours, edgecolors=(0, 0, 0, 0.15), linewidths=0.2))
    lo_xyz, hi_xyz = tris.reshape(-1, 3).min(axis=0), tris.reshape(-1, 3).max(axis=0)
    if floor_z is not None:
        lo_xyz[2] = floor_z * mm
    for setter, a, b in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), lo_xyz, hi_xyz):
        setter(a, b)
    ax.set_box_aspect(np.maximum(hi_xyz - lo_xyz, 1e-9))  # one scale on all three axes
    ax.view_init(elev=22, azim=-60)
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_zlabel("z (mm)")
    if title:
        ax.set_title(title)
    fig.colorbar(cm.ScalarMappable(cmap="viridis", norm=plt.Normalize(lo, hi)), ax=ax, shrink=0.6, pad=0.12,
                 label="height of the grain's top (mm)")  # fmt: skip
    fig.savefig(path)
    plt.close(fig)
