"""Shape descriptors of a grain, as sedimentology and soil mechanics report them.

    elongation  I / L, flatness  S / I   (Zingg's ratios; L >= I >= S the grain's extents along
                                          the principal axes of its inertia)
    sphericity  pi^(1/3) (6 V)^(2/3) / A  (Wadell's true sphericity: the area of the sphere of
                                          the same volume over the grain's area; 1 for a sphere)
    convexity   V / V_hull
    faces       planar faces (coplanar triangles merged)
    edge_angle_deg  length-weighted mean of the exterior dihedral angle over the edges between
                faces that are not coplanar: how sharp the edges are (a cube: 90; a fine
                polyhedral sphere: a few degrees). Wadell's roundness needs corner curvature,
                which a polyhedron does not have; this is its angular counterpart.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull

from .mass import mass_properties
from .polyhedron import Polyhedron

COPLANAR_DEG = 1.0  # triangles meeting at less than this are one planar face


def shape_descriptors(grain: Polyhedron) -> dict[str, float]:
    v, f = grain.vertices, grain.faces
    props = mass_properties(v, f)
    _, axes = np.linalg.eigh(props.second_moment)
    extents = np.sort(np.ptp((v - props.centroid) @ axes, axis=0))[::-1]  # L, I, S
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    cross = np.cross(b - a, c - a)
    area = 0.5 * float(np.linalg.norm(cross, axis=1).sum())
    normals = cross / np.linalg.norm(cross, axis=1, keepdims=True)
    angle, length, pairs = _edge_angles(v, f, normals)
    sharp = angle > np.radians(COPLANAR_DEG)
    return {
        "n_vertices": int(len(v)),
        "faces": _planar_faces(len(f), pairs[~sharp]),
        "elongation": float(extents[1] / extents[0]),
        "flatness": float(extents[2] / extents[1]),
        "sphericity": float(np.pi ** (1 / 3) * (6.0 * props.volume) ** (2 / 3) / area),
        "convexity": float(props.volume / ConvexHull(v).volume),
        "edge_angle_deg": float(np.degrees(np.sum(angle[sharp] * length[sharp]) / np.sum(length[sharp]))),
    }


def _edge_angles(v, f, normals):
    """(exterior dihedral angle, length, the two triangles) of every edge of a closed surface."""
    half = np.stack([f, np.roll(f, -1, axis=1)], axis=2).reshape(-1, 2)
    tri = np.repeat(np.arange(len(f)), 3)
    key = np.sort(half, axis=1)
    order = np.lexsort((key[:, 1], key[:, 0]))
    first, second = order[0::2], order[1::2]  # a closed manifold surface: each edge twice
    t1, t2 = tri[first], tri[second]
    cosine = np.clip(np.einsum("ij,ij->i", normals[t1], normals[t2]), -1.0, 1.0)
    e = key[first]
    return np.arccos(cosine), np.linalg.norm(v[e[:, 0]] - v[e[:, 1]], axis=1), np.column_stack([t1, t2])


def _planar_faces(n_triangles: int, coplanar_pairs: np.ndarray) -> int:
    """Connected groups of triangles joined across coplanar edges (union-find)."""
    parent = np.arange(n_triangles)

    def root(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for a, b in coplanar_pairs:
        parent[root(a)] = root(b)
    return len({root(i) for i in range(n_triangles)})
