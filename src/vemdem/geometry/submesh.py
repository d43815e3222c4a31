"""The tetrahedral sub-mesh that stabilises each virtual element (paper eq. 7-8).

Nodes of the sub-mesh are the grain's own vertices plus, where needed, *virtual* interior
points whose displacement is the projection u_Pi at that point (docs/vem.md, "sub-mesh").
They add no unknowns: u_Pi is linear in the vertex displacements.

Choice (measured, ../shared/docs/performance.md section 1, and benchmarks/bench_submesh.py):
the fan from the vertex average (one tetrahedron per boundary triangle) has no slivers on
star-shaped grains and gives a 10-20x larger critical step than a Delaunay tetrahedralisation
of hull vertices, so it is the default. For grains that are not star-shaped about the vertex
average we fan from the centre of the largest ball in the kernel of the polyhedron; if the
kernel is empty (the grain is not star-shaped at all) TetGen builds a constrained
tetrahedralisation that keeps every boundary triangle, and any Steiner point it needs is a
virtual node like the fan's apex.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import linprog
from scipy.spatial import Delaunay

from .polyhedron import GeometryError, Polyhedron, face_area_vectors

METHODS = ("auto", "fan", "kernel-fan", "delaunay", "constrained")


class SubMeshError(GeometryError):
    pass


@dataclass(frozen=True)
class SubMesh:
    """tets index the augmented node list: [0, n_vertices) are the grain's vertices,
    [n_vertices, n_vertices + len(virtual_points)) the virtual interior points."""

    tets: np.ndarray  # (m, 4) int, positively oriented
    virtual_points: np.ndarray  # (k, 3) reference coordinates
    method: str

    @property
    def n_virtual(self) -> int:
        return len(self.virtual_points)


def signed_tet_volumes(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    p0, p1, p2, p3 = (points[tets[:, i]] for i in range(4))
    return np.einsum("ij,ij->i", np.cross(p1 - p0, p2 - p0), p3 - p0) / 6.0


def build_submesh(grain: Polyhedron, method: str = "auto") -> SubMesh:
    if method not in METHODS:
        raise ValueError(f"unknown sub-mesh method {method!r}; choose one of {METHODS}")
    if method == "fan":
        mesh = _fan(grain, grain.vertices.mean(axis=0), "fan")
    elif method == "kernel-fan":
        mesh = _kernel_fan(grain)
    elif method == "delaunay":
        mesh = _delaunay(grain)
    elif method == "constrained":
        mesh = _constrained(grain)
    else:
        mesh = _auto(grain)
    check_submesh(grain, mesh)
    return mesh


def _auto(grain: Polyhedron) -> SubMesh:
    fan = _fan(grain, grain.vertices.mean(axis=0), "fan")
    if _fills(grain, fan):
        return fan
    kernel = _kernel_fan(grain, required=False)
    if kernel is not None and _fills(grain, kernel):
        return kernel
    return _constrained(grain)


def _fan(grain: Polyhedron, apex: np.ndarray, method: str) -> SubMesh:
    n = grain.n_vertices
    f = grain.faces
    # (a, c, b, apex) is positive when the face is outward and the apex is inside.
    tets = np.column_stack([f[:, 0], f[:, 2], f[:, 1], np.full(len(f), n)])
    return SubMesh(tets, np.asarray(apex, float)[None, :], method)


def _kernel_fan(grain: Polyhedron, required: bool = True) -> SubMesh | None:
    """Fan from the Chebyshev centre of the kernel (intersection of the faces' inner half-spaces)."""
    an = face_area_vectors(grain.vertices, grain.faces)
    normals = an / np.linalg.norm(an, axis=1, keepdims=True)
    offsets = np.einsum("ij,ij->i", normals, grain.vertices[grain.faces[:, 0]])
    # maximise r subject to n_f . x + r <= d_f
    a_ub = np.column_stack([normals, np.ones(len(normals))])
    res = linprog(c=[0, 0, 0, -1], A_ub=a_ub, b_ub=offsets, bounds=[(None, None)] * 3 + [(0, None)])
    scale = np.ptp(grain.vertices, axis=0).max()
    if not res.success or res.x[3] <= 1e-6 * scale:
        if required:
            raise SubMeshError(f"{grain.name}: not star-shaped (empty kernel); use the constrained sub-mesh")
        return None
    return _fan(grain, res.x[:3], "kernel-fan")


def _delaunay(grain: Polyhedron) -> SubMesh:
    tri = Delaunay(grain.vertices)
    tets = tri.simplices.astype(np.int64)
    vol = signed_tet_volumes(grain.vertices, tets)
    tets[vol < 0] = tets[vol < 0][:, [0, 2, 1, 3]]
    keep = np.abs(vol) > 1e-14 * grain.volume
    return SubMesh(tets[keep], np.zeros((0, 3)), "delaunay")


def _constrained(grain: Polyhedron) -> SubMesh:
    import tetgen

    gen = tetgen.TetGen(grain.vertices, grain.faces.astype(np.int32))
    # plc: the surface is a constraint; nobisect: keep every boundary triangle; no quality refinement.
    nodes, elems = gen.tetrahedralize(plc=True, nobisect=True, quality=False, quiet=True)[:2]
    n = grain.n_vertices
    if not np.allclose(nodes[:n], grain.vertices, rtol=0, atol=1e-12 * np.ptp(grain.vertices)):
        raise SubMeshError(f"{grain.name}: TetGen moved or reordered the grain's vertices")
    tets = np.asarray(elems, dtype=np.int64)
    vol = signed_tet_volumes(nodes, tets)
    tets[vol < 0] = tets[vol < 0][:, [0, 2, 1, 3]]
    return SubMesh(tets, np.asarray(nodes[n:], float).reshape(-1, 3), "constrained")


def augmented_points(grain: Polyhedron, mesh: SubMesh) -> np.ndarray:
    return np.vstack([grain.vertices, mesh.virtual_points])


def _boundary_faces(tets: np.ndarray) -> np.ndarray:
    faces = np.concatenate([tets[:, [1, 2, 3]], tets[:, [0, 3, 2]], tets[:, [0, 1, 3]], tets[:, [0, 2, 1]]])
    key = np.sort(faces, axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    return key[counts[inverse.ravel()] == 1]


def _fill_defect(grain: Polyhedron, mesh: SubMesh) -> str | None:
    points = augmented_points(grain, mesh)
    vol = signed_tet_volumes(points, mesh.tets)
    if vol.min() <= 1e-10 * grain.volume:
        return f"tetrahedron {int(vol.argmin())} is inverted or flat (volume {vol.min():.3g})"
    if abs(vol.sum() - grain.volume) > 1e-9 * grain.volume:
        return f"tetrahedra volumes sum to {vol.sum():.6g}, the grain's volume is {grain.volume:.6g}"
    boundary = np.unique(_boundary_faces(mesh.tets), axis=0)
    surface = np.unique(np.sort(grain.faces, axis=1), axis=0)
    if boundary.shape != surface.shape or not np.array_equal(boundary, surface):
        return "the boundary of the tetrahedra is not the grain's surface"
    return None


def _fills(grain: Polyhedron, mesh: SubMesh) -> bool:
    return _fill_defect(grain, mesh) is None


def check_submesh(grain: Polyhedron, mesh: SubMesh) -> None:
    """The tetrahedra must fill the grain exactly: positive volumes that sum to the grain's
    volume and a boundary equal to the grain's triangles."""
    defect = _fill_defect(grain, mesh)
    if defect is not None:
        raise SubMeshError(f"{grain.name}: {mesh.method} sub-mesh does not fill the grain: {defect}")
