"""Surface features of all grains in flat arrays: faces, edges, their neighbours and edge type.

Built once per scene (reference configuration) for the narrow phase and its hierarchy
(docs/contact.md): which faces meet at an edge, which edges and faces meet at a vertex,
and whether an edge is convex, flat or concave.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

CONVEX, FLAT, CONCAVE = 1, 0, -1


@dataclass
class SurfaceTopology:
    faces: np.ndarray  # (F, 3) global vertex indices, outward
    face_grain: np.ndarray  # (F,)
    edges: np.ndarray  # (E, 2) global vertex indices, sorted
    edge_faces: np.ndarray  # (E, 2) the two faces at each edge (-1: open boundary of a wall)
    edge_type: np.ndarray  # (E,) CONVEX, FLAT or CONCAVE
    edge_grain: np.ndarray  # (E,)
    vertex_grain: np.ndarray  # (N,)
    vertex_edge_ptr: np.ndarray  # CSR: edges at vertex v are vertex_edges[ptr[v]:ptr[v+1]]
    vertex_edges: np.ndarray
    vertex_face_ptr: np.ndarray  # CSR: faces at vertex v
    vertex_faces: np.ndarray
    grain_face_ptr: np.ndarray  # (G+1,) faces of grain g are contiguous
    grain_edge_ptr: np.ndarray  # (G+1,)
    grain_vertex_ptr: np.ndarray  # (G+1,)


def _csr(keys: np.ndarray, values: np.ndarray, n: int):
    order = np.argsort(keys, kind="stable")
    ptr = np.zeros(n + 1, dtype=np.int64)
    np.add.at(ptr, keys + 1, 1)
    return np.cumsum(ptr), values[order].astype(np.int64)


def edge_types(vertices: np.ndarray, faces: np.ndarray, edges: np.ndarray, edge_faces: np.ndarray,
               rel_tol: float = 1e-6) -> np.ndarray:  # fmt: skip
    """Convex when the second face's far vertex lies below the first face's plane. The boundary
    edge of an open wall surface counts as convex (it is a rim)."""
    open_edge = edge_faces[:, 1] < 0
    f1, f2 = faces[edge_faces[:, 0]], faces[np.where(open_edge, edge_faces[:, 0], edge_faces[:, 1])]
    a, b, c = (vertices[f1[:, i]] for i in range(3))
    n1 = np.cross(b - a, c - a)
    n1 /= np.linalg.norm(n1, axis=1, keepdims=True)
    far = np.where((f2 != edges[:, [0]]) & (f2 != edges[:, [1]]), f2, -1).max(axis=1)
    height = np.einsum("ij,ij->i", vertices[far] - vertices[edges[:, 0]], n1)
    length = np.linalg.norm(vertices[edges[:, 1]] - vertices[edges[:, 0]], axis=1)
    out = np.full(len(edges), FLAT, dtype=np.int64)
    out[height < -rel_tol * length] = CONVEX
    out[height > rel_tol * length] = CONCAVE
    out[open_edge] = CONVEX
    return out


def build_topology(vertices: np.ndarray, faces_per_grain: list[np.ndarray], vertex_ptr: np.ndarray) -> SurfaceTopology:
    """vertices: (N, 3) reference positions of all surfaces (grains, then triangulated walls);
    faces_per_grain: local triangles of each surface."""
    faces = np.vstack([f + vertex_ptr[g] for g, f in enumerate(faces_per_grain)]).astype(np.int64)
    n_faces = np.array([len(f) for f in faces_per_grain])
    face_grain = np.repeat(np.arange(len(faces_per_grain)), n_faces)
    directed = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    owner = np.tile(np.arange(len(faces)), 3)
    key = np.sort(directed, axis=1)
    edges, inverse = np.unique(key, axis=0, return_inverse=True)
    inverse = inverse.ravel()
    edge_faces = np.full((len(edges), 2), -1, dtype=np.int64)
    order = np.argsort(inverse, kind="stable")
    starts = np.searchsorted(inverse[order], np.arange(len(edges)))
    counts = np.bincount(inverse, minlength=len(edges))
    edge_faces[:, 0] = owner[order][starts]
    two = counts == 2
    edge_faces[two, 1] = owner[order][starts[two] + 1]
    n = len(vertices)
    vertex_grain = np.repeat(np.arange(len(vertex_ptr) - 1), np.diff(vertex_ptr))
    edge_grain = vertex_grain[edges[:, 0]]
    e_ptr, e_list = _csr(edges.ravel(), np.repeat(np.arange(len(edges)), 2), n)
    f_ptr, f_list = _csr(faces.ravel(), np.repeat(np.arange(len(faces)), 3), n)
    G = len(faces_per_grain)
    return SurfaceTopology(
        faces=faces,
        face_grain=face_grain,
        edges=edges.astype(np.int64),
        edge_faces=edge_faces.astype(np.int64),
        edge_type=edge_types(vertices, faces, edges, edge_faces),
        edge_grain=edge_grain,
        vertex_grain=vertex_grain,
        vertex_edge_ptr=e_ptr,
        vertex_edges=e_list,
        vertex_face_ptr=f_ptr,
        vertex_faces=f_list,
        grain_face_ptr=np.concatenate([[0], np.cumsum(n_faces)]).astype(np.int64),
        grain_edge_ptr=np.searchsorted(edge_grain, np.arange(G + 1)).astype(np.int64),
        grain_vertex_ptr=np.asarray(vertex_ptr, dtype=np.int64),
    )
