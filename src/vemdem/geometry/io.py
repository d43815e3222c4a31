"""Grains from surface files (STL, OBJ, PLY, ... through meshio).

Surface formats such as STL repeat every vertex once per triangle; coincident vertices
(within 1e-9 of the grain's size) are merged before the surface is validated. Quads are
split into triangles. Non-convex grains are accepted; the checks of `Polyhedron` apply.
"""

from __future__ import annotations

from pathlib import Path

import meshio
import numpy as np

from .polyhedron import GeometryError, Polyhedron


def merge_vertices(points: np.ndarray, faces: np.ndarray, rel_tol: float = 1e-9):
    tol = rel_tol * float(np.ptp(points, axis=0).max())
    keys = np.round(points / max(tol, np.finfo(float).tiny)).astype(np.int64)
    _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    return points[first], inverse.ravel()[faces]


def load_surface(path: str | Path) -> Polyhedron:
    path = Path(path)
    if not path.is_file():
        raise GeometryError(f"{path}: grain file not found")
    try:
        mesh = meshio.read(path)
    except Exception as exc:  # meshio raises many types for unreadable files
        raise GeometryError(f"{path}: cannot read surface ({exc})") from None
    tris = []
    for block in mesh.cells:
        if block.type == "triangle":
            tris.append(block.data)
        elif block.type == "quad":
            q = block.data
            tris += [q[:, [0, 1, 2]], q[:, [0, 2, 3]]]
    if not tris:
        raise GeometryError(f"{path}: no triangles or quads in the file")
    faces = np.vstack(tris).astype(np.int64)
    used = np.unique(faces)
    remap = np.full(len(mesh.points), -1)
    remap[used] = np.arange(len(used))
    points = np.asarray(mesh.points, float)[used]
    if points.shape[1] == 2:
        raise GeometryError(f"{path}: the surface is 2D; a grain needs 3D coordinates")
    vertices, faces = merge_vertices(points, remap[faces])
    return Polyhedron(vertices, faces, name=str(path))


def save_surface(grain: Polyhedron, path: str | Path) -> None:
    meshio.write(path, meshio.Mesh(grain.vertices, [("triangle", grain.faces)]))
