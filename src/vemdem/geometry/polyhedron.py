"""A closed, manifold, outward-oriented triangulated polyhedron: the shape of one grain.

Every grain in vemdem is one virtual element whose boundary is this surface, so the
projection of paper eq. 6 (a surface integral) is only right when the surface is
closed and outward oriented. `Polyhedron` therefore validates on construction and
raises a `GeometryError` subclass that names the defect.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .mass import MassProperties, mass_properties


class GeometryError(ValueError):
    """Base class of every defect found in a grain's surface."""


class NonFiniteCoordinatesError(GeometryError):
    pass


class BadFaceIndexError(GeometryError):
    pass


class DuplicateVerticesError(GeometryError):
    pass


class UnusedVertexError(GeometryError):
    pass


class DegenerateFaceError(GeometryError):
    pass


class OpenSurfaceError(GeometryError):
    pass


class NonManifoldEdgeError(GeometryError):
    pass


class NonManifoldVertexError(GeometryError):
    pass


class InconsistentOrientationError(GeometryError):
    pass


class InwardOrientationError(GeometryError):
    pass


class NonPositiveVolumeError(GeometryError):
    pass


@dataclass(frozen=True)
class Polyhedron:
    """Vertices (n, 3) and triangles (m, 3), validated on construction.

    `name` only serves error messages (e.g. the file a grain came from).
    """

    vertices: np.ndarray
    faces: np.ndarray
    name: str = "grain"
    mass: MassProperties = field(init=False, repr=False)

    def __post_init__(self):
        vertices = np.ascontiguousarray(self.vertices, dtype=np.float64)
        faces = np.ascontiguousarray(self.faces, dtype=np.int64)
        object.__setattr__(self, "vertices", vertices)
        object.__setattr__(self, "faces", faces)
        validate_surface(vertices, faces, self.name)
        props = mass_properties(vertices, faces)
        _check_volume(props.volume, vertices, self.name)
        object.__setattr__(self, "mass", props)
        vertices.setflags(write=False)
        faces.setflags(write=False)

    @property
    def n_vertices(self) -> int:
        return len(self.vertices)

    @property
    def volume(self) -> float:
        return self.mass.volume

    @property
    def centroid(self) -> np.ndarray:
        return self.mass.centroid

    def edges(self) -> np.ndarray:
        """Unique undirected edges (k, 2), sorted vertex indices."""
        return unique_edges(self.faces)

    def translated(self, offset) -> "Polyhedron":
        return Polyhedron(self.vertices + np.asarray(offset, float), self.faces, self.name)

    def scaled(self, factor: float) -> "Polyhedron":
        return Polyhedron(self.vertices * float(factor), self.faces, self.name)

    def rotated(self, rotation_matrix) -> "Polyhedron":
        return Polyhedron(self.vertices @ np.asarray(rotation_matrix, float).T, self.faces, self.name)


def unique_edges(faces: np.ndarray) -> np.ndarray:
    directed = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    return np.unique(np.sort(directed, axis=1), axis=0)


def face_area_vectors(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """A_f N_f for every triangle: half the cross product of two edges."""
    a, b, c = (vertices[faces[:, i]] for i in range(3))
    return 0.5 * np.cross(b - a, c - a)


def validate_surface(vertices: np.ndarray, faces: np.ndarray, name: str = "grain") -> None:
    """Raise a GeometryError naming the first defect; checks run from cheap to costly."""
    if vertices.ndim != 2 or vertices.shape[1] != 3 or len(vertices) < 4:
        raise GeometryError(f"{name}: vertices must be an (n>=4, 3) array, got shape {vertices.shape}")
    if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) < 4:
        raise GeometryError(f"{name}: faces must be an (m>=4, 3) array of triangles, got shape {faces.shape}")
    bad = ~np.isfinite(vertices).all(axis=1)
    if bad.any():
        raise NonFiniteCoordinatesError(
            f"{name}: non-finite coordinates at vertex {np.flatnonzero(bad)[:5].tolist()}"
        )
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise BadFaceIndexError(f"{name}: face index out of range [0, {len(vertices) - 1}]")
    _check_duplicate_vertices(vertices, name)
    unused = np.setdiff1d(np.arange(len(vertices)), faces.ravel())
    if unused.size:
        raise UnusedVertexError(f"{name}: vertex {unused[:5].tolist()} belongs to no face")
    _check_degenerate_faces(vertices, faces, name)
    _check_edges(faces, name)
    _check_vertex_manifold(faces, len(vertices), name)


def _length_scale(vertices: np.ndarray) -> float:
    return float(np.ptp(vertices, axis=0).max())


def _check_duplicate_vertices(vertices: np.ndarray, name: str) -> None:
    tol = 1e-9 * _length_scale(vertices)
    keys = np.round(vertices / max(tol, np.finfo(float).tiny)).astype(np.int64)
    _, first, counts = np.unique(keys, axis=0, return_index=True, return_counts=True)
    if (counts > 1).any():
        dup = first[counts > 1][:5].tolist()
        raise DuplicateVerticesError(
            f"{name}: duplicate vertices (coincident within {tol:.3g}) at vertex {dup}; merge them first"
        )


def _check_degenerate_faces(vertices: np.ndarray, faces: np.ndarray, name: str) -> None:
    repeated = (faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2]) | (faces[:, 0] == faces[:, 2])
    area = np.linalg.norm(face_area_vectors(vertices, faces), axis=1)
    tiny = area <= 1e-12 * _length_scale(vertices) ** 2
    bad = np.flatnonzero(repeated | tiny)
    if bad.size:
        raise DegenerateFaceError(f"{name}: zero-area (degenerate) triangle at face {bad[:5].tolist()}")


def _check_edges(faces: np.ndarray, name: str) -> None:
    directed = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    undirected, counts = np.unique(np.sort(directed, axis=1), axis=0, return_counts=True)
    if (counts == 1).any():
        e = undirected[counts == 1][0].tolist()
        raise OpenSurfaceError(
            f"{name}: open surface: edge {e} belongs to one face only ({(counts == 1).sum()} boundary edges)"
        )
    if (counts > 2).any():
        e = undirected[counts > 2][0].tolist()
        raise NonManifoldEdgeError(f"{name}: non-manifold edge {e} is shared by {counts[counts > 2][0]} faces")
    _, dcounts = np.unique(directed, axis=0, return_counts=True)
    if (dcounts > 1).any():
        d = np.unique(directed, axis=0)[dcounts > 1][0].tolist()
        raise InconsistentOrientationError(
            f"{name}: inconsistent orientation: directed edge {d} appears in two faces "
            "(neighbouring triangles must traverse a shared edge in opposite directions)"
        )


def _check_vertex_manifold(faces: np.ndarray, n_vertices: int, name: str) -> None:
    """The faces around each vertex must form one fan (one cycle of 'next' edges)."""
    # For face (a, b, c) at vertex a the fan links b -> c; a closed single fan is one cycle.
    incident = np.concatenate([faces[:, [0, 1, 2]], faces[:, [1, 2, 0]], faces[:, [2, 0, 1]]])
    order = np.argsort(incident[:, 0], kind="stable")
    incident = incident[order]
    starts = np.searchsorted(incident[:, 0], np.arange(n_vertices + 1))
    for v in range(n_vertices):
        ring = incident[starts[v] : starts[v + 1]]
        nxt = dict(zip(ring[:, 1].tolist(), ring[:, 2].tolist()))
        first = ring[0, 1]
        cur, steps = nxt[first], 1
        while cur != first and steps <= len(ring):
            cur = nxt.get(cur, first)
            steps += 1
        if steps != len(ring):
            raise NonManifoldVertexError(
                f"{name}: non-manifold vertex {v}: its faces form more than one fan (surfaces touch at a point)"
            )


def _check_volume(volume: float, vertices: np.ndarray, name: str) -> None:
    scale = _length_scale(vertices) ** 3
    if abs(volume) <= 1e-9 * scale:
        raise NonPositiveVolumeError(f"{name}: zero volume ({volume:.3g}); the surface encloses nothing")
    if volume < 0:
        raise InwardOrientationError(
            f"{name}: inward orientation: enclosed volume is negative ({volume:.3g}); "
            "reverse every face (normals must point out of the grain)"
        )
