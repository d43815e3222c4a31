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


def mean_deformation_gradients(x: np.ndarray, X: np.ndarray, faces: np.ndarray, face_body: np.ndarray,
                               n_bodies: int) -> np.ndarray:  # fmt: skip
    """(n_bodies, 3, 3) every body's volume-averaged deformation gradient from reference positions X
    to x, by the divergence theorem over its closed surface: F = (1 / V0) sum over faces of
    mean(x on the face) (x) (A N)_0, exact for surfaces of flat triangles (x is linear on each), so
    F is the linear virtual element's own (its constant projected gradient); I for a rigid motion
    up to its rotation."""
    area_normal = 0.5 * np.cross(X[faces[:, 1]] - X[faces[:, 0]], X[faces[:, 2]] - X[faces[:, 0]])
    centre = (x[faces[:, 0]] + x[faces[:, 1]] + x[faces[:, 2]]) / 3.0
    terms = np.einsum("fi,fj->fij", centre, area_normal).reshape(len(faces), 9)
    F = np.zeros((n_bodies, 9))
    for k in range(9):  # nine bincounts: one pass over the faces each, no loop over bodies
        F[:, k] = np.bincount(face_body, weights=terms[:, k], minlength=n_bodies)
    volume0 = body_volumes(X, faces, face_body, n_bodies)
    return F.reshape(n_bodies, 3, 3) / volume0[:, None, None]


def largest_strains(F: np.ndarray) -> np.ndarray:
    """(n,) each body's largest principal strain |lambda - 1| (Biot: stretch minus one) of its
    deformation gradient F (n, 3, 3): 0 for a rigid motion, 0.2 for a fifth shorter or longer."""
    stretches = np.linalg.svd(F, compute_uv=False)
    return np.abs(stretches - 1.0).max(axis=1)
