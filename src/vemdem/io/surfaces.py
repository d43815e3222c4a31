"""Surfaces from files (STL, OBJ, PLY, ... through meshio): grains and rigid mesh walls.

The only place vemdem reads a surface file. Surface formats such as STL repeat every vertex once
per triangle; coincident vertices (within 1e-9 of the surface's size) are merged. Quads are split
into triangles. Non-convex grains are accepted; the checks of `Polyhedron` apply. Every failure is
a `GeometryError` naming the file.
"""

from __future__ import annotations

from pathlib import Path

import meshio
import numpy as np

import warnings

from ..contact.walls import MeshWall, Motion
from ..geometry.polyhedron import GeometryError, Polyhedron

# m: a surface's coordinates lie within a kilometre of the origin, as a config's positions do
# (config/checks.py MAX_COORDINATE); one of 1e300 overflowed in the surface's checks, an
# OverflowError that named no file
MAX_COORDINATE = 1e3


def merge_vertices(points: np.ndarray, faces: np.ndarray, rel_tol: float = 1e-9):
    tol = rel_tol * float(np.ptp(points, axis=0).max())
    keys = np.round(points / max(tol, np.finfo(float).tiny)).astype(np.int64)
    _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    return points[first], inverse.ravel()[faces]


def _read(path: Path, what: str):
    if not path.is_file():
        raise GeometryError(f"{path}: {what} file not found")
    try:
        with warnings.catch_warnings():
            # meshio's STL reader probes the binary layout with int32 arithmetic and warns on text files
            warnings.simplefilter("ignore", RuntimeWarning)
            return meshio.read(path)
    except Exception as exc:  # meshio raises many types (unknown extension, truncated file, ...)
        raise GeometryError(f"{path}: cannot read the surface ({type(exc).__name__}: {exc})") from None


def _triangles(mesh, path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Triangles (quads split) over the used points only."""
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
    if not np.all(np.isfinite(points)):
        # before merge_vertices, whose rounding would fold every non-finite point into one
        bad = int(np.flatnonzero(~np.all(np.isfinite(points), axis=1))[0])
        raise GeometryError(f"{path}: non-finite coordinates (vertex {int(used[bad])} of the file)")
    far = np.abs(points).max(axis=1) > MAX_COORDINATE
    if far.any():
        bad = int(np.flatnonzero(far)[0])
        raise GeometryError(f"{path}: coordinates beyond {MAX_COORDINATE:g} m (vertex {int(used[bad])} of the file, "
                            f"at {np.abs(points[bad]).max():.3g} m); the file's unit must be the metre")  # fmt: skip
    return points, remap[faces]


def load_surface(path: str | Path) -> Polyhedron:
    """A grain from a closed surface file."""
    path = Path(path)
    points, faces = _triangles(_read(path, "grain"), path)
    vertices, faces = merge_vertices(points, faces)
    return Polyhedron(vertices, faces, name=str(path))


def load_mesh_wall(path: str | Path, motion: Motion | None = None, flip: bool = False) -> MeshWall:
    """A rigid wall from a surface file (open surfaces allowed). `flip` reverses the faces when the
    file's normals point away from the grains."""
    path = Path(path)
    points, faces = _triangles(_read(path, "wall"), path)
    vertices, faces = merge_vertices(points, faces)
    used = np.unique(faces)
    remap = np.full(len(vertices), -1)
    remap[used] = np.arange(len(used))
    faces = remap[faces]
    return MeshWall(vertices[used], faces[:, ::-1] if flip else faces, motion or Motion(), name=str(path))


def save_surface(grain: Polyhedron, path: str | Path) -> None:
    meshio.write(path, meshio.Mesh(grain.vertices, [("triangle", grain.faces)]))
