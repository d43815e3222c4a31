"""Exact volume moments of a closed triangulated surface (unit density).

Each outward triangle (a, b, c) and a reference point o span a signed tetrahedron;
summing them integrates 1, X and X (x) X over the enclosed volume exactly (the
divergence theorem in discrete form). The moments also give the VEM projection
mass matrix in closed form (`vemdem.vem.mass`), so no quadrature rule is needed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class MassProperties:
    volume: float
    centroid: np.ndarray  # (3,)
    second_moment: np.ndarray  # (3, 3): integral of (X - c)(X - c)^T dV, unit density
    inertia: np.ndarray  # (3, 3): inertia tensor about the centroid, unit density

    def scaled(self, density: float) -> "MassProperties":
        return MassProperties(self.volume, self.centroid, density * self.second_moment, density * self.inertia)


def signed_tet_moments(o, a, b, c):
    """Volume, first and second moments of the signed tetrahedra (o, a, b, c), batched.

    Uses  int_T X X^T dV = V/20 (sum_i X_i X_i^T + s s^T),  s = sum_i X_i.
    """
    vol = np.einsum("ij,ij->i", a - o, np.cross(b - o, c - o)) / 6.0
    pts = np.stack([np.broadcast_to(o, a.shape), a, b, c], axis=1)  # (m, 4, 3)
    s = pts.sum(axis=1)
    first = vol[:, None] * s / 4.0
    second = vol[:, None, None] / 20.0 * (np.einsum("mki,mkj->mij", pts, pts) + np.einsum("mi,mj->mij", s, s))
    return vol, first, second


def mass_properties(vertices: np.ndarray, faces: np.ndarray) -> MassProperties:
    # A reference point near the surface keeps the signed sums well conditioned.
    origin = vertices.mean(axis=0)
    x = vertices - origin
    vol, first, second = signed_tet_moments(np.zeros(3), x[faces[:, 0]], x[faces[:, 1]], x[faces[:, 2]])
    volume = float(vol.sum())
    if volume == 0.0:
        return MassProperties(0.0, origin.copy(), np.zeros((3, 3)), np.zeros((3, 3)))
    c = first.sum(axis=0) / volume
    second_central = second.sum(axis=0) - volume * np.outer(c, c)
    inertia = np.trace(second_central) * np.eye(3) - second_central
    return MassProperties(volume, origin + c, second_central, inertia)


def body_volumes(x: np.ndarray, faces: np.ndarray, face_body: np.ndarray, n_bodies: int) -> np.ndarray:
    """The enclosed volume of every body of a set of closed surfaces at positions x (its faces'
    signed tetrahedra about the body's first face vertex summed per body): the grains' current
    volumes, which a soft grain changes under load."""
    ref = np.zeros((n_bodies, 3))
    ref[face_body[::-1]] = x[faces[::-1, 0]]  # any point of the body keeps the sum exact; a near one keeps it accurate
    o = ref[face_body]
    a, b, c = x[faces[:, 0]] - o, x[faces[:, 1]] - o, x[faces[:, 2]] - o
    vol = np.einsum("ij,ij->i", a, np.cross(b, c)) / 6.0
    return np.bincount(face_body, weights=vol, minlength=n_bodies)
