"""Grain shapes: cube, tetrahedron, an L-shaped (non-convex) prism and sand-like random grains."""

from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull, HalfspaceIntersection

from .polyhedron import GeometryError, Polyhedron


def cube(edge: float = 1.0, center=(0.0, 0.0, 0.0)) -> Polyhedron:
    h = 0.5 * edge
    v = np.array(
        [[-h, -h, -h], [h, -h, -h], [h, h, -h], [-h, h, -h], [-h, -h, h], [h, -h, h], [h, h, h], [-h, h, h]]
    )
    f = np.array(
        [
            [0, 2, 1], [0, 3, 2],  # z = -h
            [4, 5, 6], [4, 6, 7],  # z = +h
            [0, 1, 5], [0, 5, 4],  # y = -h
            [2, 3, 7], [2, 7, 6],  # y = +h
            [1, 2, 6], [1, 6, 5],  # x = +h
            [3, 0, 4], [3, 4, 7],  # x = -h
        ]
    )
    return Polyhedron(v + np.asarray(center, float), f, "cube")


def tetrahedron(vertices=None) -> Polyhedron:
    if vertices is None:
        vertices = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    vertices = np.asarray(vertices, float)
    f = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])
    if np.dot(np.cross(vertices[1] - vertices[0], vertices[2] - vertices[0]), vertices[3] - vertices[0]) < 0:
        f = f[:, ::-1]
    return Polyhedron(vertices, f, "tetrahedron")


def _ear_clip(outline: np.ndarray) -> np.ndarray:
    """Triangles of a simple counter-clockwise polygon (ear clipping, O(n^2): caps are small)."""
    idx = list(range(len(outline)))
    tris = []

    def cross(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    while len(idx) > 3:
        for k in range(len(idx)):
            i, j, m = idx[k - 1], idx[k], idx[(k + 1) % len(idx)]
            a, b, c = outline[i], outline[j], outline[m]
            if cross(a, b, c) <= 0:
                continue  # reflex or flat corner
            others = [outline[q] for q in idx if q not in (i, j, m)]
            if any(cross(a, b, p) >= 0 and cross(b, c, p) >= 0 and cross(c, a, p) >= 0 for p in others):
                continue
            tris.append((i, j, m))
            idx.pop(k)
            break
        else:
            raise GeometryError("polygon outline is not simple or not counter-clockwise")
    tris.append(tuple(idx))
    return np.array(tris)


def extruded_polygon(outline, height: float, name: str = "prism") -> Polyhedron:
    """A prism over a simple counter-clockwise polygon (convex or not), centred on its vertex average."""
    outline = np.asarray(outline, float)
    n = len(outline)
    caps = _ear_clip(outline)
    faces = [caps[:, ::-1], caps + n]  # bottom faces down, top faces up
    for i in range(n):
        j = (i + 1) % n
        faces.append([[i, j, j + n], [i, j + n, i + n]])
    vertices = np.vstack([np.column_stack([outline, np.zeros(n)]), np.column_stack([outline, np.full(n, height)])])
    return Polyhedron(vertices - vertices.mean(axis=0), np.vstack(faces), name)


def l_prism(size: float = 1.0, height: float = 0.5) -> Polyhedron:
    """An L-shaped prism: non-convex (one concave edge), star-shaped about its inner corner square."""
    outline = size * 0.5 * np.array([[0.0, 0], [2, 0], [2, 1], [1, 1], [1, 2], [0, 2]])
    return extruded_polygon(outline, height, "L-prism")


def u_prism(size: float = 1.0, height: float = 0.5) -> Polyhedron:
    """A U-shaped prism: non-convex and not star-shaped (its kernel is empty)."""
    outline = size / 3.0 * np.array([[0.0, 0], [3, 0], [3, 3], [2, 3], [2, 1], [1, 1], [1, 3], [0, 3]])
    return extruded_polygon(outline, height, "U-prism")


def hull_polyhedron(points: np.ndarray, name: str = "hull") -> Polyhedron:
    """Convex hull with outward triangles; points strictly inside the hull are dropped."""
    hull = ConvexHull(points)
    used = np.unique(hull.simplices)
    remap = -np.ones(len(points), dtype=np.int64)
    remap[used] = np.arange(len(used))
    faces = remap[hull.simplices]
    vertices = points[used]
    # Qhull does not orient simplices; its facet normals (hull.equations) point outward.
    normals = np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]], vertices[faces[:, 2]] - vertices[faces[:, 0]])
    flip = np.einsum("ij,ij->i", normals, hull.equations[:, :3]) < 0
    faces[flip] = faces[flip][:, ::-1]
    return Polyhedron(vertices, faces, name)


def _fibonacci_directions(n: int) -> np.ndarray:
    k = np.arange(n) + 0.5
    z = 1.0 - 2.0 * k / n
    phi = np.pi * (1.0 + 5**0.5) * k
    r = np.sqrt(1.0 - z * z)
    return np.column_stack([r * np.cos(phi), r * np.sin(phi), z])


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 2] *= -1
    return q


def _outside_hull_radius(points: np.ndarray, hull: ConvexHull, idx: np.ndarray) -> np.ndarray:
    """Distance along each ray from the origin to the hull boundary (origin inside the hull)."""
    normals, offsets = hull.equations[:, :3], -hull.equations[:, 3]
    d = points[idx] / np.linalg.norm(points[idx], axis=1, keepdims=True)
    proj = d @ normals.T
    with np.errstate(divide="ignore"):
        t = np.where(proj > 1e-12, offsets[None, :] / proj, np.inf)
    return t.min(axis=1)


def sand_grain(
    size: float = 1.45e-3,
    n_vertices: int = 30,
    elongation: float = 0.8,
    flatness: float = 0.8,
    roughness: float = 0.15,
    seed: int = 0,
    truncate: float | None = None,
) -> Polyhedron:
    """A sand-like grain: convex hull of randomly perturbed points on an ellipsoid.

    size        equivalent diameter d (the grain's volume is pi d^3 / 6)
    elongation  intermediate / long axis (Zingg's I/L), in (0, 1]
    flatness    short / intermediate axis (Zingg's S/I), in (0, 1]
    roughness   relative radial perturbation of the points, in [0, 0.5)
    truncate    if given (0 < t < 1), points are clamped to |z| <= t * c so that the grain
                has two flat, parallel ends (plates in a compression test touch them)
    Every perturbed point is kept on the hull (points that fall inside are pushed out),
    so an untruncated grain has exactly n_vertices vertices. Same arguments, same grain.
    """
    _check_sand_parameters(size, n_vertices, elongation, flatness, roughness, truncate)
    rng = np.random.default_rng(seed)
    axes = np.array([1.0, elongation, elongation * flatness])
    directions = _fibonacci_directions(n_vertices) @ _random_rotation(rng).T
    directions += rng.normal(scale=0.25 / np.sqrt(n_vertices), size=directions.shape)
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    radii = 1.0 + roughness * rng.uniform(-1.0, 1.0, size=n_vertices)
    points = directions * radii[:, None] * axes
    if truncate is not None:
        points[:, 2] = np.clip(points[:, 2], -truncate * axes[2], truncate * axes[2])
    else:
        points = _push_onto_hull(points)
    grain = hull_polyhedron(points, "sand grain")
    scale = (np.pi * size**3 / 6.0 / grain.volume) ** (1.0 / 3.0)
    return Polyhedron((grain.vertices - grain.centroid) * scale, grain.faces, f"sand grain (seed {seed})")


def angular_grain(
    size: float = 1.45e-3,
    n_vertices: int = 16,
    elongation: float = 0.8,
    flatness: float = 0.8,
    roughness: float = 0.15,
    seed: int = 0,
) -> Polyhedron:
    """A crushed-rock-like grain: a cut polyhedron, flat faces and sharp edges.

    n_vertices / 2 + 2 planes (a simple polytope with F faces has 2F - 4 vertices) touch the unit
    sphere at directions spread evenly and then jittered, each pushed in or out by up to
    `roughness` of its distance (deeper and shallower cuts); their intersection, with corners
    closer than 4 % of the size merged (no sliver edges), is stretched to the axes 1, elongation,
    elongation * flatness (an affine map keeps faces flat). size, elongation, flatness as in
    `sand_grain`; same arguments, same grain.
    """
    _check_sand_parameters(size, n_vertices, elongation, flatness, roughness, None)
    n_planes = max(n_vertices // 2 + 2, 4)
    rng = np.random.default_rng(seed)
    axes = np.array([1.0, elongation, elongation * flatness])
    normals = _fibonacci_directions(n_planes) @ _random_rotation(rng).T
    normals += rng.normal(scale=0.35 / np.sqrt(n_planes), size=normals.shape)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    offsets = 1.0 + roughness * rng.uniform(-1.0, 0.5, n_planes)
    # a cube of six more planes keeps the intersection bounded whatever the directions
    box = np.vstack([np.eye(3), -np.eye(3)])
    halfspaces = np.column_stack([np.vstack([normals, box]), -np.concatenate([offsets, np.full(6, 2.0)])])
    corners = HalfspaceIntersection(halfspaces, np.zeros(3)).intersections
    grain = hull_polyhedron(_merge_close(corners, 0.08) * axes, "angular grain")
    scale = (np.pi * size**3 / 6.0 / grain.volume) ** (1.0 / 3.0)
    return Polyhedron((grain.vertices - grain.centroid) * scale, grain.faces, f"angular grain (seed {seed})")


def _merge_close(points: np.ndarray, tol: float) -> np.ndarray:
    """Points closer than tol replaced by their mean (greedy, in order): no sliver edges."""
    left = list(range(len(points)))
    merged = []
    while left:
        near = [j for j in left if np.linalg.norm(points[j] - points[left[0]]) < tol]
        merged.append(points[near].mean(axis=0))
        left = [j for j in left if j not in near]
    return np.array(merged)


def _push_onto_hull(points: np.ndarray, max_rounds: int = 50) -> np.ndarray:
    """Move points that lie inside the hull of the others radially onto it (plus 2 %)."""
    points = points.copy()
    for _ in range(max_rounds):
        hull = ConvexHull(points)
        inside = np.setdiff1d(np.arange(len(points)), hull.vertices)
        if inside.size == 0:
            return points
        r_hull = _outside_hull_radius(points, hull, inside)
        r = np.linalg.norm(points[inside], axis=1)
        points[inside] *= (1.02 * r_hull / r)[:, None]
    raise GeometryError("sand grain: could not place every point on the convex hull; lower roughness")


def _check_sand_parameters(size, n_vertices, elongation, flatness, roughness, truncate):
    if not (np.isfinite(size) and size > 0):
        raise ValueError(f"size must be a positive length, got {size}")
    if int(n_vertices) != n_vertices or n_vertices < 4:
        raise ValueError(f"vertices must be an integer >= 4, got {n_vertices}")
    for key, value in (("elongation", elongation), ("flatness", flatness)):
        if not (0.0 < value <= 1.0):
            raise ValueError(f"{key} must be in (0, 1], got {value}")
    if not (0.0 <= roughness < 0.5):
        raise ValueError(f"roughness must be in [0, 0.5), got {roughness}")
    if truncate is not None and not (0.0 < truncate < 1.0):
        raise ValueError(f"truncate must be in (0, 1), got {truncate}")


def rotation_matrix(rotation_vector) -> np.ndarray:
    """Rodrigues' formula: rotation by |r| about r / |r|."""
    r = np.asarray(rotation_vector, float)
    theta = np.linalg.norm(r)
    if theta < 1e-300:
        return np.eye(3)
    k = r / theta
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(theta) * kx + (1 - np.cos(theta)) * kx @ kx
