"""The k = 1 VEM projection (paper eq. 4 and 6).

For a closed outward triangulation the gradient of the projection is a surface integral,

    grad u_Pi = (1/V) int_dOmega u_h (x) N dA = sum_v u_v (x) g_v,
    g_v = (1/V) sum_{faces f at v} A_f N_f / 3          (u_h linear on each triangle)

so F_Pi = I + grad u_Pi = sum_v x_v (x) g_v (because sum_v X_v (x) g_v = I). The constant
part comes from the vertex average (eq. 4 with the nodal-average integral):

    u_Pi(X) = sum_v [1/n + g_v . (X - Xbar)] u_v = sum_v N_v(X) u_v.
"""

from __future__ import annotations

import numpy as np

from ..geometry.polyhedron import face_area_vectors


def projection_gradients(vertices: np.ndarray, faces: np.ndarray, volume: float) -> np.ndarray:
    """g_v (n, 3) with grad u_Pi = sum_v u_v (x) g_v."""
    area_normal = face_area_vectors(vertices, faces) / (3.0 * volume)
    g = np.zeros_like(vertices)
    for corner in range(3):
        np.add.at(g, faces[:, corner], area_normal)
    return g


def projection_shape_functions(points: np.ndarray, vertices: np.ndarray, g: np.ndarray) -> np.ndarray:
    """N_v(P) (k, n): u_Pi(P) = sum_v N_v(P) u_v, and also x_Pi(P) = sum_v N_v(P) x_v."""
    points = np.atleast_2d(points)
    return 1.0 / len(vertices) + (points - vertices.mean(axis=0)) @ g.T
