"""A refined tetrahedral finite-element reference for single-grain compression.

The grain's surface is meshed with TetGen (constrained Delaunay with quality refinement, so
boundary triangles may be split) and every tetrahedron is a linear (constant-strain)
element with the same compressible Neo-Hookean energy as the virtual element
(`vemdem.vem.material.neo_hooke`):

    W(x) = sum_t V_t psi(F_t),    F_t = sum_a x_a (x) grad N_a

One compiled kernel evaluates energy, nodal forces and the 12 x 12 tangent of every
tetrahedron in parallel; the global residual and sparse tangent are assembled with a
scatter map computed once (the CSR pattern of the mesh), so no Python loop visits a tet.

`run_fem` and `compress_vem` run the plate compression of
`vemdem.scenarios.grain_compression` (same grain orientation, plates, pins and Newton
solver, `scenarios.plates.compress`) on the FE mesh and on the one-element VEM, so that
the two force-strain curves differ only by the discretisation. In the FE model the plates
hold every mesh node on the grain's flat caps.

The plates' roller condition makes the stress singular along the cap rims, so the FE force
converges slowly (about N^-0.6 in the number of nodes N); `reference_mesh` grades the mesh
towards the rims and `richardson` extrapolates a refinement sequence. Measurements:
benchmarks/fem_comparison.py and docs/fem_comparison.md.
"""

from __future__ import annotations

import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from numba import njit, prange

from ..geometry.polyhedron import Polyhedron
from ..geometry.submesh import signed_tet_volumes
from ..model.bodies import VemBodies
from ..scenarios.plates import PLATE_TOL, PlateSetup, compress, prepare_grain, body_assembler
from ..vem.element import InvertedElementError, VemOptions, tet_gradients
from ..vem.material import Material, neo_hooke


class FemMeshError(RuntimeError):
    """TetGen's mesh does not fill the grain or lost one of its vertices."""


# ----------------------------------------------------------------------------- meshing


def mesh_grain(
    grain: Polyhedron,
    max_volume: float,
    rim_size: float | None = None,
    rim_exponent: float = 0.5,
    rim_length: float | None = None,
    min_ratio: float = 1.5,
    min_dihedral: float = 10.0,
):
    """Quality tetrahedral mesh of the grain: nodes (n, 3), positively oriented tets (m, 4).

    max_volume is the largest tetrahedron volume allowed (absolute, in length^3). With
    rim_size the mesh is also graded towards the rims of the flat caps (`cap_rims`: where a
    plate's roller condition meets the free surface, the stress is singular): target edge
    length h(d) = clip(h_far (d / rim_length)^rim_exponent, rim_size, h_far), d the distance
    to the nearest rim, h_far the edge of a regular tet of volume max_volume, rim_length half
    the grain's height by default. TetGen gets h as a background sizing mesh (switch -m).
    The first grain.n_vertices nodes are the grain's vertices, in the grain's order; the
    other nodes are TetGen's Steiner points (on the surface, where it refines boundary
    triangles, and inside).
    """
    import tetgen

    if not (np.isfinite(max_volume) and max_volume > 0):
        raise ValueError(f"max_volume must be positive, got {max_volume}")
    gen = tetgen.TetGen(np.asarray(grain.vertices, float), grain.faces.astype(np.int32))
    # fixedvolume is TetGen's -a switch; without it maxvolume is silently ignored. nomergefacet
    # (-M): TetGen would otherwise merge nearly coplanar neighbouring triangles into one facet
    # and put Steiner points on its average plane, changing the grain (seen on seed 2).
    options = dict(
        plc=True, quality=True, minratio=min_ratio, mindihedral=min_dihedral,
        fixedvolume=True, maxvolume=float(max_volume), nomergefacet=True, quiet=True,
    )  # fmt: skip
    if rim_size is None:
        nodes, elems = gen.tetrahedralize(**options)[:2]
    else:
        h_far = regular_tet_edge(max_volume)
        if rim_length is None:
            rim_length = 0.5 * np.ptp(grain.vertices[:, 2])
        rims = cap_rims(grain)
        a, b = grain.vertices[rims[:, 0]], grain.vertices[rims[:, 1]]

        def size(points):
            d = distance_to_segments(points, a, b)
            return np.clip(h_far * (d / rim_length) ** rim_exponent, rim_size, h_far)

        with tempfile.TemporaryDirectory() as tmp:
            stem = str(Path(tmp) / "sizing.b")
            _write_sizing_mesh(stem, grain, size, rim_size, h_far)
            nodes, elems = gen.tetrahedralize(bgmeshfilename=stem, metric=True, **options)[:2]
    return _checked_mesh(grain, np.array(nodes, dtype=float), np.array(elems, dtype=np.int64))


def _checked_mesh(grain: Polyhedron, nodes: np.ndarray, tets: np.ndarray):
    """TetGen's mesh with the grain's vertices first and every tet positively oriented; refused
    if a tet is flat or the volumes do not add up to the grain's."""
    nodes, tets = _vertices_first(grain, nodes, tets)
    vol = signed_tet_volumes(nodes, tets)
    flip = vol < 0
    tets[flip] = tets[flip][:, [0, 2, 1, 3]]
    vol = np.abs(vol)
    if vol.min() <= 1e-12 * grain.volume:
        raise FemMeshError(f"{grain.name}: TetGen produced a flat tetrahedron (volume {vol.min():.3g})")
    if abs(vol.sum() - grain.volume) > 1e-9 * grain.volume:
        raise FemMeshError(f"{grain.name}: tet volumes sum to {vol.sum():.9g}, the grain's volume is {grain.volume:.9g}")
    return nodes, tets


def regular_tet_edge(volume: float) -> float:
    """Edge length of the regular tetrahedron of the given volume (V = a^3 / (6 sqrt 2))."""
    return (6.0 * np.sqrt(2.0) * volume) ** (1.0 / 3.0)


def cap_rims(grain: Polyhedron) -> np.ndarray:
    """Edges (k, 2) between a flat cap (a face on a plate, see grain_compression.PlateSetup)
    and a face that is not on that plate."""
    z = grain.vertices[:, 2]
    tol = PLATE_TOL * np.ptp(z)
    side = np.where(z <= z.min() + tol, 1, np.where(z >= z.max() - tol, 2, 0))
    fs = side[grain.faces]
    cap = (fs[:, 0] > 0) & (fs[:, 0] == fs[:, 1]) & (fs[:, 1] == fs[:, 2])
    f = grain.faces
    edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    keys, inverse = np.unique(edges, axis=0, return_inverse=True)
    n_cap = np.bincount(inverse.ravel(), weights=np.tile(cap, 3).astype(float), minlength=len(keys))
    return keys[n_cap == 1]


def distance_to_segments(points: np.ndarray, a: np.ndarray, b: np.ndarray, chunk: int = 4096) -> np.ndarray:
    """Distance of each point to the nearest of the segments a_k b_k (+inf without segments)."""
    out = np.full(len(points), np.inf)
    if len(a) == 0:
        return out
    ab = b - a
    ab2 = np.einsum("ij,ij->i", ab, ab)
    for s in range(0, len(points), chunk):
        p = points[s : s + chunk, None, :]
        t = np.clip(np.einsum("pkj,kj->pk", p - a[None], ab) / ab2[None], 0.0, 1.0)
        out[s : s + chunk] = np.linalg.norm(p - (a[None] + t[..., None] * ab[None]), axis=2).min(axis=1)
    return out


_CUBE_CORNERS = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], dtype=float) - 0.5


def _write_sizing_mesh(stem: str, grain: Polyhedron, size, h_min: float, h_max: float) -> None:
    """TetGen background mesh (stem.node, .ele, .mtr) carrying the target edge length size(x):
    the Delaunay tetrahedralisation of the corners of an octree around the grain whose cells
    are split until they are no larger than the size asked at their centre."""
    from scipy.spatial import Delaunay

    lo, hi = grain.vertices.min(axis=0), grain.vertices.max(axis=0)
    margin = 0.05 * np.ptp(grain.vertices, axis=0).max()
    lo, hi = lo - margin, hi + margin
    cell = 0.5 * h_max
    counts = np.maximum(np.ceil((hi - lo) / cell).astype(int), 1)
    centres = lo + (np.stack(np.meshgrid(*[np.arange(c) for c in counts], indexing="ij"), -1).reshape(-1, 3) + 0.5) * cell
    points = []
    while len(centres):
        points.append((centres[:, None, :] + cell * _CUBE_CORNERS[None]).reshape(-1, 3))
        too_big = size(centres) < cell
        if cell <= 0.5 * h_min:
            break
        cell *= 0.5
        centres = (centres[too_big][:, None, :] + cell * _CUBE_CORNERS[None]).reshape(-1, 3)
    points = np.vstack(points)
    key = np.round((points - lo) / (0.25 * cell)).astype(np.int64)
    points = points[np.unique(key, axis=0, return_index=True)[1]]
    # A small deterministic jitter keeps qhull away from cospherical (flat-tet) configurations.
    points = points + 1e-3 * h_min * np.random.default_rng(0).uniform(-1, 1, points.shape)
    tets = Delaunay(points).simplices.astype(np.int64)
    vol = signed_tet_volumes(points, tets)
    tets[vol < 0] = tets[vol < 0][:, [0, 2, 1, 3]]
    ids = np.arange(len(points))
    np.savetxt(stem + ".node", np.column_stack([ids, points]), fmt=["%d", "%.17g", "%.17g", "%.17g"],
               header=f"{len(points)} 3 0 0", comments="")  # fmt: skip
    np.savetxt(stem + ".ele", np.column_stack([np.arange(len(tets)), tets]), fmt="%d",
               header=f"{len(tets)} 4 0", comments="")  # fmt: skip
    np.savetxt(stem + ".mtr", size(points), fmt="%.17g", header=f"{len(points)} 1", comments="")


def _vertices_first(grain: Polyhedron, nodes: np.ndarray, tets: np.ndarray):
    """Put the grain's vertices first (in the grain's order) and drop nodes no tet uses."""
    n = grain.n_vertices
    tol = 1e-10 * np.ptp(grain.vertices)
    if len(nodes) >= n and np.abs(nodes[:n] - grain.vertices).max() <= tol:
        order = np.arange(n)
    else:
        from scipy.spatial import cKDTree

        dist, order = cKDTree(nodes).query(grain.vertices)
        if dist.max() > tol or len(np.unique(order)) != n:
            raise FemMeshError(f"{grain.name}: TetGen moved or merged a vertex of the grain")
    used = np.zeros(len(nodes), dtype=bool)
    used[tets.ravel()] = True
    if not used[order].all():
        raise FemMeshError(f"{grain.name}: a vertex of the grain is in no tetrahedron")
    rest = np.setdiff1d(np.flatnonzero(used), order)
    perm = np.concatenate([order, rest])  # new index -> old index
    new_of_old = -np.ones(len(nodes), dtype=np.int64)
    new_of_old[perm] = np.arange(len(perm))
    nodes = nodes[perm]
    nodes[:n] = grain.vertices  # bit-identical, so plates and pins see the same coordinates
    return nodes, new_of_old[tets]


# ----------------------------------------------------------------------------- element kernel


@njit(parallel=True, cache=True)
def _tet_kernel(x, tets, vol, grads, mu, kappa, want_force, want_tangent, energy, force, Ke, inverted):
    """Per tet: energy V psi(F), forces f_a = V P grad N_a, tangent K_ab[i, j] = V b_a[I] A[iI, jK] b_b[K]."""
    for e in prange(tets.shape[0]):
        F = np.zeros((3, 3))
        P = np.empty((3, 3))
        A = np.empty((9, 9))
        for a in range(4):
            node = tets[e, a]
            for i in range(3):
                for I in range(3):
                    F[i, I] += x[node, i] * grads[e, a, I]
        psi = neo_hooke(F, mu, kappa, want_tangent, P, A)
        if psi == np.inf:
            inverted[e] = True
            energy[e] = np.inf
            continue
        c = vol[e]
        energy[e] = c * psi
        if want_force:
            for a in range(4):
                for i in range(3):
                    s = 0.0
                    for I in range(3):
                        s += P[i, I] * grads[e, a, I]
                    force[e, 3 * a + i] = c * s
        if want_tangent:
            AG = np.empty((4, 9, 3))
            for b in range(4):
                for row in range(9):
                    for j in range(3):
                        s = 0.0
                        for K in range(3):
                            s += A[row, 3 * j + K] * grads[e, b, K]
                        AG[b, row, j] = s
            for a in range(4):
                for i in range(3):
                    for b in range(4):
                        for j in range(3):
                            s = 0.0
                            for I in range(3):
                                s += grads[e, a, I] * AG[b, 3 * i + I, j]
                            Ke[e, 3 * a + i, 3 * b + j] = c * s


@dataclass
class TetModel:
    """Linear-tetrahedron Neo-Hookean model of one body; dof 3 * node + i."""

    nodes: np.ndarray  # (n, 3) reference coordinates
    tets: np.ndarray  # (m, 4) positively oriented
    volumes: np.ndarray  # (m,)
    grads: np.ndarray  # (m, 4, 3) reference shape-function gradients
    mu: float
    kappa: float
    element_dofs: np.ndarray = field(repr=False)  # (m * 12,) global dof of each element force entry
    entry_map: np.ndarray = field(repr=False)  # (m * 144,) CSR data index of each element tangent entry
    indptr: np.ndarray = field(repr=False)
    indices: np.ndarray = field(repr=False)

    @property
    def n_nodes(self) -> int:
        return len(self.nodes)

    @property
    def n_tets(self) -> int:
        return len(self.tets)

    @property
    def n_dofs(self) -> int:
        return 3 * len(self.nodes)

    def element_terms(self, x: np.ndarray, force: bool = True, tangent: bool = False):
        """Per-tet energy (m,), forces (m, 12) and tangents (m, 12, 12); raises on inversion."""
        x = np.ascontiguousarray(np.asarray(x, dtype=float).reshape(-1, 3))
        m = self.n_tets
        energy = np.zeros(m)
        fe = np.zeros((m, 12)) if force else np.zeros((1, 12))
        Ke = np.zeros((m, 12, 12)) if tangent else np.zeros((1, 12, 12))
        inverted = np.zeros(m, dtype=np.bool_)
        _tet_kernel(x, self.tets, self.volumes, self.grads, self.mu, self.kappa, force, tangent, energy, fe, Ke, inverted)
        if inverted.any():
            raise InvertedElementError(f"{int(inverted.sum())} inverted tetrahedra (J <= 0)")
        return energy, (fe if force else None), (Ke if tangent else None)

    def evaluate(self, x: np.ndarray, tangent: bool = False):
        """Total energy, global internal force (3n,) and, if asked, the sparse tangent (CSR)."""
        energy, fe, Ke = self.element_terms(x, True, tangent)
        f = np.bincount(self.element_dofs, weights=fe.ravel(), minlength=self.n_dofs)
        K = None
        if tangent:
            data = np.bincount(self.entry_map, weights=Ke.ravel(), minlength=len(self.indices))
            K = sp.csr_matrix((data, self.indices, self.indptr), shape=(self.n_dofs, self.n_dofs))
        return float(energy.sum()), f, K

    def assembler(self):
        """`assemble(xflat, want_tangent) -> (energy, residual, K)` for solve_static / compress."""

        def assemble(xflat, want_tangent):
            return self.evaluate(xflat, want_tangent)

        return assemble


def build_tet_model(nodes: np.ndarray, tets: np.ndarray, material: Material) -> TetModel:
    nodes = np.ascontiguousarray(nodes, dtype=float)
    tets = np.ascontiguousarray(tets, dtype=np.int64)
    vol, grads = tet_gradients(nodes, tets)
    if vol.min() <= 0:
        raise FemMeshError("tetrahedra must be positively oriented")
    n_dofs = 3 * len(nodes)
    dofs = (3 * tets[:, :, None] + np.arange(3)).reshape(-1, 12)  # (m, 12)
    rows = np.repeat(dofs, 12, axis=1).ravel()
    cols = np.tile(dofs, (1, 12)).ravel()
    keys, entry_map = np.unique(rows * n_dofs + cols, return_inverse=True)  # row-major = CSR order
    indptr = np.zeros(n_dofs + 1, dtype=np.int64)
    np.cumsum(np.bincount(keys // n_dofs, minlength=n_dofs), out=indptr[1:])
    return TetModel(
        nodes=nodes,
        tets=tets,
        volumes=vol,
        grads=np.ascontiguousarray(grads),
        mu=float(material.mu),
        kappa=float(material.kappa),
        element_dofs=dofs.ravel(),
        entry_map=entry_map.ravel(),
        indptr=indptr,
        indices=(keys % n_dofs).astype(np.int32 if n_dofs < 2**31 else np.int64),
    )


# ----------------------------------------------------------------------------- compression drivers


RIM_RATIO = 0.125  # graded meshes: rim_size = RIM_RATIO * h_far (see mesh_grain)


def reference_mesh(grain: Polyhedron, max_volume: float, graded: bool = True):
    """The FE mesh family of the comparison: graded towards the cap rims (exponent 1/2, rim
    edge h_far / 8) or, with graded=False, TetGen's quality mesh with a volume bound only.
    One parameter, max_volume, refines the whole family."""
    if not graded:
        return mesh_grain(grain, max_volume)
    return mesh_grain(grain, max_volume, rim_size=RIM_RATIO * regular_tet_edge(max_volume), rim_exponent=0.5)


@dataclass
class CompressionRun:
    strains: np.ndarray
    forces: np.ndarray  # compressive force on the top plate at each strain (N)
    n_nodes: int
    n_elements: int  # tetrahedra (FE) or 1 (VEM)
    newton_iterations: int
    seconds: float
    penetration: np.ndarray | None = None  # at each strain: deepest a node off the plates went through one, / h0


def _tracker(nodes: np.ndarray, plates: PlateSetup, log: list):
    """on_step callback recording how far nodes that are not held by a plate pass through one
    (the plates are bilateral rollers on their initial contact set; this checks that a
    unilateral contact would not have picked up more nodes)."""
    off = np.setdiff1d(np.arange(len(nodes)), np.concatenate([plates.top, plates.bottom]))
    z_top = nodes[:, 2].max()

    def on_step(k, strain, x, force, result):
        z = x.reshape(-1, 3)[off, 2]
        top = z_top - strain * plates.height
        log.append(max(0.0, float((z - top).max(initial=-np.inf)), float((plates.z0 - z).max(initial=-np.inf))) / plates.height)

    return on_step


def run_fem(grain: Polyhedron, material: Material, strains, mode: str = "uniaxial", max_volume: float | None = None,
            rtol: float = 1e-9, max_iter: int = 40, graded: bool = True) -> CompressionRun:  # fmt: skip
    """Plate compression of the FE model of the grain: the forces on the top plate at each strain
    for a TetGen mesh of it. strains are the loaded steps (increasing; steps of a few % at most);
    max_volume bounds the tetrahedra (default V / 1000) and, for the graded family
    (`reference_mesh`), sets every size. Same plates, pins and orientation as the
    grain_compression scenario; the plates hold every mesh node on the grain's flat caps."""
    t0 = time.perf_counter()
    if max_volume is None:
        max_volume = 1e-3 * grain.volume
    material = ensure_material(material)
    turned, pins = prepare_grain(grain, mode)
    nodes, tets = reference_mesh(turned, max_volume, graded)
    model = build_tet_model(nodes, tets, material)
    plates = PlateSetup(nodes, mode, pins)  # every node on the flat caps is a plate node
    force_scale = material.E * turned.volume ** (2 / 3)
    pen = []
    forces, its = compress(model.assembler(), nodes, plates, strains, force_scale, rtol=rtol, max_iter=max_iter,
                           on_step=_tracker(nodes, plates, pen))  # fmt: skip
    return CompressionRun(np.asarray(strains, float), forces, model.n_nodes, model.n_tets, its,
                          time.perf_counter() - t0, np.array(pen))  # fmt: skip


def run_vem(grain: Polyhedron, material: Material, beta_internal: float, strains, mode: str = "uniaxial",
            rtol: float = 1e-9, max_iter: int = 40, submesh: str = "auto") -> CompressionRun:  # fmt: skip
    """Plate compression of the one-element VEM of the grain, exactly as the grain_compression
    scenario does it (same orientation, plates, pins, Newton solver and tolerances)."""
    t0 = time.perf_counter()
    material = ensure_material(material)
    turned, pins = prepare_grain(grain, mode)
    bodies = VemBodies([turned], material, VemOptions(beta_internal=beta_internal, submesh=submesh))
    X = bodies.reference
    plates = PlateSetup(X, mode, pins)
    force_scale = material.E * turned.volume ** (2 / 3)
    pen = []
    forces, its = compress(body_assembler(bodies), X, plates, strains, force_scale, rtol=rtol, max_iter=max_iter,
                           on_step=_tracker(X, plates, pen))  # fmt: skip
    return CompressionRun(np.asarray(strains, float), forces, len(X), 1, its, time.perf_counter() - t0, np.array(pen))


def compress_vem(grain: Polyhedron, material: Material, beta_internal: float, strains,
                 mode: str = "uniaxial") -> np.ndarray:  # fmt: skip
    """Forces on the top plate at each strain for the one-element VEM (the scenario's model)."""
    return run_vem(grain, material, beta_internal, strains, mode).forces


def ensure_material(material) -> Material:
    """A Material, or one from (E, nu) (the density plays no part in a static test)."""
    if isinstance(material, Material):
        return material
    E, nu = material
    return Material(E, nu, 2200.0)


def richardson(coarse, medium, fine):
    """Extrapolate a sequence refined by a constant factor: with d1 = coarse - medium and
    d2 = medium - fine (arrays), the contraction rho = d1 / d2 and the limit
    fine - d2 / (rho - 1). Returns (limit, rho); where the sequence is not monotone and
    contracting (rho <= 1 or of the wrong sign) the limit is nan."""
    coarse, medium, fine = (np.asarray(a, float) for a in (coarse, medium, fine))
    d1, d2 = coarse - medium, medium - fine
    with np.errstate(divide="ignore", invalid="ignore"):
        rho = d1 / d2
        limit = np.where(rho > 1.0, fine - d2 / (rho - 1.0), np.nan)
    return limit, rho
