"""Do placed grains overlap? Checked before a run starts (docs/errors.md): two grains that interpenetrate
at t = 0 have no contact pair between them (the barrier only acts across a positive gap), and
the run would fail later with a message about something else.

Grain b overlaps grain a when a vertex of b lies inside a's closed surface: the generalized
winding number of a's triangles about the vertex (sum of their solid angles / 4 pi, Van Oosterom
and Strackee) is 1 inside and 0 outside, exact for any closed surface, convex or not. Pairs are
pruned by their bounding boxes first. (Two grains whose edges cross with no vertex inside the
other are not caught: it needs the grains to be placed through each other like a cross.)
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .polyhedron import Polyhedron


@njit(cache=True)
def winding_numbers(points, vertices, faces):
    """Generalized winding number of the closed triangle surface (vertices, faces) about each point."""
    out = np.zeros(len(points))
    for p in range(len(points)):
        total = 0.0
        for f in range(len(faces)):
            a = vertices[faces[f, 0]] - points[p]
            b = vertices[faces[f, 1]] - points[p]
            c = vertices[faces[f, 2]] - points[p]
            la, lb, lc = np.sqrt(np.sum(a * a)), np.sqrt(np.sum(b * b)), np.sqrt(np.sum(c * c))
            det = a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) + a[2] * (b[0] * c[1] - b[1] * c[0])
            den = la * lb * lc + np.sum(a * b) * lc + np.sum(b * c) * la + np.sum(c * a) * lb
            total += 2.0 * np.arctan2(det, den)
        out[p] = total / (4.0 * np.pi)
    return out


def first_overlap(grains: list[Polyhedron]) -> tuple[int, int] | None:
    """(a, b): the first pair of grains where a vertex of b is inside a (or None)."""
    lo = np.array([g.vertices.min(axis=0) for g in grains])
    hi = np.array([g.vertices.max(axis=0) for g in grains])
    for a in range(len(grains)):
        near = np.flatnonzero(np.all(lo <= hi[a], axis=1) & np.all(hi >= lo[a], axis=1))
        for b in near[near != a]:
            w = winding_numbers(grains[b].vertices, grains[a].vertices, grains[a].faces.astype(np.int64))
            if np.any(w > 0.5):
                return (min(a, b), max(a, b))
    return None
