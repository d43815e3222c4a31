"""One virtual element per grain: blended energy, internal forces and tangent (paper eq. 8).

    W_i = (1 - beta_i) V psi(F_Pi) + beta_i sum_t V_t psi(F_t)

Both terms are sums of *pieces* with a constant deformation gradient F = I + sum_a u_a (x) b_a:
the projection (nodes = all vertices, b_a = g_v, weight (1 - beta_i) V) and every sub-mesh
tetrahedron (4 nodes, b_a = grad N_a, weight beta_i V_t). One compiled kernel evaluates any
piece, so the projection and the stabilisation share the same, tested code.

Sub-mesh nodes may be virtual interior points (the fan's apex, TetGen's Steiner points) with
x_k = sum_v T_kv x_v, T_kv = N_v(P_k) the projection shape functions (projection.py). Forces
and tangents on those nodes are condensed onto the vertices with T; no unknown is added.

All grains of a scene live in flat arrays with per-grain offsets; the kernels loop over
grains in parallel (numba prange), each grain writing only its own slice.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numba import njit, prange

from ..geometry.polyhedron import Polyhedron
from ..geometry.submesh import SubMesh, augmented_points, build_submesh
from .material import Material, det3, inv3, neo_hooke
from .projection import projection_gradients, projection_shape_functions


class InvertedElementError(FloatingPointError):
    """A grain's projection or one of its sub-tetrahedra has J <= 0."""


@dataclass(frozen=True)
class VemOptions:
    """The `[vem]` table, typed: the blending betas of paper eq. 8 and the stabilisation sub-mesh method."""
    beta_internal: float = 0.5  # beta_i of eq. 8
    beta_mass: float = 1.0  # beta_d
    beta_load: float = 1.0  # beta_e
    submesh: str = "auto"

    def __post_init__(self):
        for key in ("beta_internal", "beta_mass", "beta_load"):
            value = getattr(self, key)
            if not (0.0 <= value <= 1.0):
                raise ValueError(f"vem.{key} must be in [0, 1], got {value}")


@dataclass
class GrainElements:
    """Flat, kernel-ready description of the elements of every grain in a scene."""

    reference: np.ndarray  # (N, 3) reference vertex coordinates X of all grains
    vertex_ptr: np.ndarray  # (G+1,) vertices of grain g: vertex_ptr[g]:vertex_ptr[g+1]
    virtual_ptr: np.ndarray  # (G+1,) virtual sub-mesh nodes per grain (offsets)
    virtual_weight_ptr: np.ndarray  # (G+1,) offsets into virtual_weights (n_virtual * n_vertices each)
    virtual_weights: np.ndarray  # flat T_kv
    piece_ptr: np.ndarray  # (G+1,) pieces of grain g
    piece_weight: np.ndarray  # (P,) blend weight times volume
    piece_node_ptr: np.ndarray  # (P+1,)
    piece_nodes: np.ndarray  # local augmented node index of each piece node
    piece_grads: np.ndarray  # (., 3) b_a of each piece node
    mu: np.ndarray  # (G,)
    kappa: np.ndarray  # (G,)
    block_ptr: np.ndarray  # (G+1,) offsets of the dense (3n x 3n) tangent block of each grain
    volume: np.ndarray  # (G,)
    projection_grads: np.ndarray  # (N, 3) g_v of every vertex: F_Pi = sum_v x_v (x) g_v
    submeshes: list
    options: VemOptions

    @property
    def n_grains(self) -> int:
        return len(self.vertex_ptr) - 1

    @property
    def n_vertices(self) -> int:
        return len(self.reference)


def tet_gradients(points: np.ndarray, tets: np.ndarray):
    """Volumes (m,) and shape-function gradients (m, 4, 3) of linear tetrahedra."""
    p = points[tets]
    D = np.stack([p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]], axis=2)  # columns
    vol = np.linalg.det(D) / 6.0
    Dinv = np.linalg.inv(D)  # rows are grad N_1..3
    grads = np.concatenate([-Dinv.sum(axis=1, keepdims=True), Dinv], axis=1)
    return vol, grads


def build_elements(
    grains: list[Polyhedron],
    material: Material,
    options: VemOptions = VemOptions(),
    submeshes: list[SubMesh] | None = None,
) -> GrainElements:
    """Set-up (once per scene): projection vectors, sub-meshes and flat offsets."""
    if submeshes is None:
        submeshes = [build_submesh(g, options.submesh) for g in grains]
    beta = options.beta_internal
    refs, vptr, kptr, wptr, weights, proj = [], [0], [0], [0], [], []
    pptr, pweight, nptr, nodes, grads, bptr = [0], [], [0], [], [], [0]
    for grain, mesh in zip(grains, submeshes):
        n = grain.n_vertices
        g = projection_gradients(grain.vertices, grain.faces, grain.volume)
        T = projection_shape_functions(mesh.virtual_points, grain.vertices, g) if mesh.n_virtual else np.zeros((0, n))
        refs.append(grain.vertices)
        proj.append(g)
        vptr.append(vptr[-1] + n)
        kptr.append(kptr[-1] + mesh.n_virtual)
        weights.append(T.ravel())
        wptr.append(wptr[-1] + T.size)
        pieces = 0
        if beta < 1.0:
            pweight.append((1.0 - beta) * grain.volume)
            nodes.append(np.arange(n))
            grads.append(g)
            nptr.append(nptr[-1] + n)
            pieces += 1
        if beta > 0.0:
            vol, dN = tet_gradients(augmented_points(grain, mesh), mesh.tets)
            pweight.extend((beta * vol).tolist())
            nodes.append(mesh.tets.ravel())
            grads.append(dN.reshape(-1, 3))
            nptr.extend((nptr[-1] + 4 * np.arange(1, len(vol) + 1)).tolist())
            pieces += len(vol)
        pptr.append(pptr[-1] + pieces)
        bptr.append(bptr[-1] + (3 * n) ** 2)
    G = len(grains)
    i64 = lambda a: np.asarray(a, dtype=np.int64)  # noqa: E731
    return GrainElements(
        reference=np.ascontiguousarray(np.vstack(refs)),
        vertex_ptr=i64(vptr),
        virtual_ptr=i64(kptr),
        virtual_weight_ptr=i64(wptr),
        virtual_weights=np.concatenate(weights) if weights else np.zeros(0),
        piece_ptr=i64(pptr),
        piece_weight=np.asarray(pweight, float),
        piece_node_ptr=i64(nptr),
        piece_nodes=i64(np.concatenate(nodes)),
        piece_grads=np.ascontiguousarray(np.vstack(grads)),
        mu=np.full(G, material.mu),
        kappa=np.full(G, material.kappa),
        block_ptr=i64(bptr),
        volume=np.array([g.volume for g in grains]),
        projection_grads=np.vstack(proj),
        submeshes=list(submeshes),
        options=options,
    )


@njit(cache=True)
def _polar_rotation(ua, v0, nv, projection_grads, R):
    """R of the polar decomposition F_Pi = R U (F_Pi = I + sum_v u_v (x) g_v), by Higham's iteration
    R <- (R + R^-T) / 2, quadratic from F_Pi: two or three sweeps for the strains of stiff grains.
    False where F_Pi is inverted or the iteration does not settle."""
    for i in range(3):
        for j in range(3):
            R[i, j] = 1.0 if i == j else 0.0
    for v in range(nv):
        for i in range(3):
            for j in range(3):
                R[i, j] += ua[v, i] * projection_grads[v0 + v, j]
    for _ in range(30):
        J = det3(R)
        if not (J > 0.0):
            return False
        Ri = inv3(R, J)
        change = 0.0
        for i in range(3):
            for j in range(3):
                r = 0.5 * (R[i, j] + Ri[j, i])
                change = max(change, abs(r - R[i, j]))
                R[i, j] = r
        if change <= 1e-15:
            return True
    return False


@njit(cache=True)
def _piece_sum(ua, p0, p1, piece_weight, piece_node_ptr, piece_nodes, piece_grads, mu, kappa,
               want_force, want_tangent, R, fa, Ka, AG):  # fmt: skip
    """Energy of pieces p0:p1 of one grain, their forces added to fa and (want_tangent) their tangent
    to Ka. Returns (energy, deviation): +inf energy where a piece is inverted; deviation = the largest
    |F - R|_ij over the pieces when R is given (R.shape[0] == 3), how far they are from R's rotation."""
    F = np.empty((3, 3))
    P = np.empty((3, 3))
    A = np.empty((9, 9))
    kab = np.empty((3, 3))
    e = 0.0
    deviation = 0.0
    for p in range(p0, p1):
        q0 = piece_node_ptr[p]
        q1 = piece_node_ptr[p + 1]
        F[:, :] = 0.0
        for i in range(3):
            F[i, i] = 1.0
        for q in range(q0, q1):
            a = piece_nodes[q]
            for i in range(3):
                for I in range(3):
                    F[i, I] += ua[a, i] * piece_grads[q, I]
        if R.shape[0] == 3:
            for i in range(3):
                for I in range(3):
                    deviation = max(deviation, abs(F[i, I] - R[i, I]))
        psi = neo_hooke(F, mu, kappa, want_tangent, P, A)
        if psi == np.inf:
            return np.inf, deviation
        c = piece_weight[p]
        e += c * psi
        if want_force:
            for q in range(q0, q1):
                a = piece_nodes[q]
                for i in range(3):
                    s = 0.0
                    for I in range(3):
                        s += P[i, I] * piece_grads[q, I]
                    fa[a, i] += c * s
        if want_tangent:
            # AG_b[iI, j] = sum_K A[iI, jK] b_b[K], then K_ab[i, j] = c sum_I b_a[I] AG_b[iI, j]
            for qb in range(q0, q1):
                r = qb - q0
                for row in range(9):
                    for j in range(3):
                        s = 0.0
                        for K in range(3):
                            s += A[row, 3 * j + K] * piece_grads[qb, K]
                        AG[r, row, j] = s
            # A has major symmetry, so K_ba = K_ab^T: compute the pairs qb >= qa only and mirror
            # (half the multiplications of the plain double loop).
            for qa in range(q0, q1):
                a = piece_nodes[qa]
                ba0 = c * piece_grads[qa, 0]
                ba1 = c * piece_grads[qa, 1]
                ba2 = c * piece_grads[qa, 2]
                for qb in range(qa, q1):
                    b = piece_nodes[qb]
                    r = qb - q0
                    for i in range(3):
                        for j in range(3):
                            kab[i, j] = ba0 * AG[r, 3 * i, j] + ba1 * AG[r, 3 * i + 1, j] + ba2 * AG[r, 3 * i + 2, j]
                    for i in range(3):
                        for j in range(3):
                            Ka[3 * a + i, 3 * b + j] += kab[i, j]
                    if qb != qa:
                        for i in range(3):
                            for j in range(3):
                                Ka[3 * b + j, 3 * a + i] += kab[i, j]
    return e, deviation


@njit(cache=True)
def _rotate_block(K0, R, out):
    """out = (I (x) R) K0 (I (x) R)^T, 3 x 3 sub-block by sub-block: R K0_ab R^T. The rows are
    combined first with unit-stride inner loops, then each row's triples."""
    n3 = K0.shape[0]
    W = np.empty((3, n3))
    for a in range(n3 // 3):
        for i in range(3):
            r0, r1, r2 = R[i, 0], R[i, 1], R[i, 2]
            for c in range(n3):
                W[i, c] = r0 * K0[3 * a, c] + r1 * K0[3 * a + 1, c] + r2 * K0[3 * a + 2, c]
        for i in range(3):
            row = out[3 * a + i]
            for b in range(n3 // 3):
                w0, w1, w2 = W[i, 3 * b], W[i, 3 * b + 1], W[i, 3 * b + 2]
                row[3 * b] = w0 * R[0, 0] + w1 * R[0, 1] + w2 * R[0, 2]
                row[3 * b + 1] = w0 * R[1, 0] + w1 * R[1, 1] + w2 * R[1, 2]
                row[3 * b + 2] = w0 * R[2, 0] + w1 * R[2, 1] + w2 * R[2, 2]


@njit(parallel=True, cache=True)
def _evaluate_grains(
    x, X, vertex_ptr, virtual_ptr, virtual_weight_ptr, virtual_weights,
    piece_ptr, piece_weight, piece_node_ptr, piece_nodes, piece_grads,
    mu, kappa, block_ptr, want_force, want_tangent, energy, force, blocks, inverted,
    mass_blocks, mass_ptr, mass_shift, projection_grads, reference_blocks, rotated_strain, rotated, rotations,
):  # fmt: skip
    n_grains = len(vertex_ptr) - 1
    for g in prange(n_grains):
        v0 = vertex_ptr[g]
        nv = vertex_ptr[g + 1] - v0
        nk = virtual_ptr[g + 1] - virtual_ptr[g]
        na = nv + nk
        T = virtual_weights[virtual_weight_ptr[g] : virtual_weight_ptr[g + 1]].reshape(nk, nv)
        # Displacements, not positions: F = I + sum_a u_a (x) b_a is exactly I at rest, whereas
        # sum_a x_a (x) b_a = I only to round-off, which for E ~ 1e11 Pa is a stress above gravity's.
        ua = np.zeros((na, 3))
        for v in range(nv):
            for i in range(3):
                ua[v, i] = x[v0 + v, i] - X[v0 + v, i]
        for k in range(nk):
            for v in range(nv):
                for i in range(3):
                    ua[nv + k, i] += T[k, v] * ua[v, i]
        fa = np.zeros((na, 3))
        p0, p1 = piece_ptr[g], piece_ptr[g + 1]
        # A grain whose every piece stays within rotated_strain of its projection's rotation R takes
        # its tangent as the reference one rotated by R (docs/vem.md, "The rotated tangent"). Each
        # array is assigned once: numba's parallel loop lowering mixed up a block reassigned in a branch.
        R = np.empty((3, 3))
        checked = near_rigid = False
        e = 0.0
        if want_tangent and rotated_strain > 0.0 and _polar_rotation(ua, v0, nv, projection_grads, R):
            checked = True
            # `not want_tangent`: False typed bool; a literal False compiles _piece_sum and
            # neo_hooke a second time (tests/test_compile_once.py on a cold cache)
            e, deviation = _piece_sum(ua, p0, p1, piece_weight, piece_node_ptr, piece_nodes, piece_grads, mu[g],
                                      kappa[g], want_force, not want_tangent, R, fa, np.zeros((1, 1)),
                                      np.zeros((1, 9, 3)))  # fmt: skip
            near_rigid = e < np.inf and deviation <= rotated_strain
        exact = want_tangent and not near_rigid
        Ka = np.zeros((3 * na, 3 * na)) if exact else np.zeros((1, 1))
        if not near_rigid:  # strained (or inverted) grains too: the forces of the check's pass stand
            AG = np.zeros((na, 9, 3)) if exact else np.zeros((1, 9, 3))
            e, _ = _piece_sum(ua, p0, p1, piece_weight, piece_node_ptr, piece_nodes, piece_grads, mu[g], kappa[g],
                              want_force and not checked, exact, np.empty((0, 0)), fa, Ka, AG)  # fmt: skip
        rotated[g] = near_rigid
        if near_rigid:
            rotations[g] = R
        energy[g] = e
        if e == np.inf:
            inverted[g] = True
            if want_tangent:  # not left as np.empty's garbage (an element loop: numba compiles a
                for k in range(block_ptr[g], block_ptr[g + 1]):  # slice assignment's error path for seconds)
                    blocks[k] = 0.0
            continue
        if want_force:
            for v in range(nv):
                for i in range(3):
                    s = fa[v, i]
                    for k in range(nk):
                        s += T[k, v] * fa[nv + k, i]
                    force[v0 + v, i] = s
        if want_tangent:
            out = blocks[block_ptr[g] : block_ptr[g + 1]].reshape(3 * nv, 3 * nv)
            if near_rigid:
                _rotate_block(reference_blocks[block_ptr[g] : block_ptr[g + 1]].reshape(3 * nv, 3 * nv), R, out)
            else:
                _condense_tangent(Ka, T, nv, nk, out)
            if mass_shift != 0.0:
                _add_mass(out, mass_blocks[mass_ptr[g] : mass_ptr[g + 1]], nv, mass_shift)


@njit(cache=True)
def _add_mass(out, mass, n, shift):
    """out += shift (M_g (x) I_3): the scalar n x n mass block on the tangent block's three
    diagonal sub-lattices (dof 3 v + i), while the block is still in cache."""
    for v in range(n):
        for w in range(n):
            m = shift * mass[v * n + w]
            for i in range(3):
                out[3 * v + i, 3 * w + i] += m


@njit(cache=True)
def _fold_virtual_columns(Ka, r, T, nv, nk, dst):
    """dst[3w+j] += sum_k Ka[r, 3(nv+k)+j] T[k, w]: row r of Ka T, virtual columns only."""
    n3 = 3 * nv
    for k in range(nk):
        a0 = Ka[r, n3 + 3 * k]
        a1 = Ka[r, n3 + 3 * k + 1]
        a2 = Ka[r, n3 + 3 * k + 2]
        for w in range(nv):
            t = T[k, w]
            dst[3 * w] += a0 * t
            dst[3 * w + 1] += a1 * t
            dst[3 * w + 2] += a2 * t


@njit(cache=True)
def _condense_tangent(Ka, T, nv, nk, out):
    """out = T^T Ka T with T = [I; T_virtual] acting on each of x, y, z.

    Written as a copy of the vertex block plus rank updates with unit-stride inner loops
    (the plain triple loop with its length-nk inner sum cost more than the whole assembly)."""
    n3 = 3 * nv
    for r in range(n3):
        for col in range(n3):
            out[r, col] = Ka[r, col]
    if nk == 0:
        return
    # vertex rows, virtual columns: out[r, 3w+j] += sum_k Ka[r, n3+3k+j] T[k, w]
    for r in range(n3):
        _fold_virtual_columns(Ka, r, T, nv, nk, out[r])
    # virtual rows condensed on the columns: C = Ka[virtual, vertex] + Ka[virtual, virtual] T
    C = np.empty((3 * nk, n3))
    for kr in range(3 * nk):
        r = n3 + kr
        for col in range(n3):
            C[kr, col] = Ka[r, col]
        _fold_virtual_columns(Ka, r, T, nv, nk, C[kr])
    # out[3v+i, :] += sum_k T[k, v] C[3k+i, :]
    for k in range(nk):
        for v in range(nv):
            t = T[k, v]
            for i in range(3):
                for col in range(n3):
                    out[3 * v + i, col] += t * C[3 * k + i, col]


@dataclass
class Evaluation:
    """The element kernel's result for every grain: strain energies, internal forces and tangent blocks."""
    energy: np.ndarray  # (G,) strain energy of each grain
    force: np.ndarray | None  # (N, 3) internal force dW/dx
    blocks: np.ndarray | None  # flat dense tangent blocks (see GrainElements.block_ptr)
    rotated: np.ndarray | None = None  # (G,) bool: the grain's block is its reference block rotated
    rotations: np.ndarray | None = None  # (G, 3, 3): that rotation R where rotated (else undefined)

    @property
    def total_energy(self) -> float:
        return float(self.energy.sum())


def evaluate(elements: GrainElements, x: np.ndarray, force: bool = True, tangent: bool = False,
             raise_on_inversion: bool = True, mass=None, mass_shift: float = 0.0,
             rotated_strain: float = 0.0) -> Evaluation:  # fmt: skip
    """Strain energy, internal forces and tangent blocks at current vertex positions x (N, 3).

    With `mass` (a vem.mass.GrainMass) and mass_shift, the blocks are those of K_int + mass_shift M,
    the Newmark matrix's grain part: each grain's mass is added while its block is in cache (a
    separate pass over the 33 MB of the 515-grain blocks cost 5-6 ms per Newton iteration).

    rotated_strain > 0: a grain whose pieces' deformation gradients all lie within rotated_strain
    (entrywise) of R, the rotation of its projection's F_Pi = R U, gets the tangent block of its
    reference configuration rotated by R, (I (x) R) K(X) (I (x) R)^T: exact for a rigid motion, off by
    O(rotated_strain) relative otherwise, a third of the cost (docs/vem.md, "The rotated tangent").
    Energy and forces are always exact; only Newton's matrix is approximated."""
    x = np.ascontiguousarray(x, dtype=np.float64)
    G = elements.n_grains
    energy = np.zeros(G)
    f = np.zeros((elements.n_vertices, 3)) if force else np.zeros((1, 3))
    blocks = np.empty(elements.block_ptr[-1]) if tangent else np.zeros(1)  # every entry written
    inverted = np.zeros(G, dtype=np.bool_)
    if mass is None or not tangent:
        mass_blocks, mass_ptr, mass_shift = np.zeros(1), np.zeros(G + 1, np.int64), 0.0
    else:
        mass_blocks, mass_ptr = mass.blocks, mass.block_ptr
    rotated = np.zeros(G, dtype=np.bool_)
    rotations = np.empty((G if tangent else 0, 3, 3))
    rotated_strain = float(rotated_strain) if tangent else 0.0
    reference_blocks = reference_tangent(elements) if rotated_strain > 0.0 else np.zeros(1)
    _evaluate_grains(
        x, elements.reference, elements.vertex_ptr, elements.virtual_ptr, elements.virtual_weight_ptr, elements.virtual_weights,
        elements.piece_ptr, elements.piece_weight, elements.piece_node_ptr, elements.piece_nodes,
        elements.piece_grads, elements.mu, elements.kappa, elements.block_ptr, force, tangent,
        energy, f, blocks, inverted, mass_blocks, mass_ptr, float(mass_shift),
        elements.projection_grads, reference_blocks, rotated_strain, rotated, rotations,
    )  # fmt: skip
    if raise_on_inversion and inverted.any():
        bad = np.flatnonzero(inverted)
        raise InvertedElementError(
            f"inverted element (J <= 0) in grain {bad[:10].tolist()}: the deformation is not admissible"
        )
    return Evaluation(energy, f if force else None, blocks if tangent else None, rotated if tangent else None,
                      rotations if tangent else None)  # fmt: skip


def reference_tangent(elements: GrainElements) -> np.ndarray:
    """The flat tangent blocks K(X) at the reference configuration, made once (cached on the object)."""
    cached = getattr(elements, "_reference_tangent", None)
    if cached is None:
        cached = evaluate(elements, elements.reference, force=False, tangent=True).blocks
        object.__setattr__(elements, "_reference_tangent", cached)
    return cached


def tangent_matrix(elements: GrainElements, blocks: np.ndarray) -> sp.csr_matrix:
    """Global sparse tangent (3N x 3N, dof 3 v + i) from the per-grain dense blocks.

    A grain's dofs are contiguous and its block is stored row by row, so the flat blocks are
    already the CSR data array (sorted, no duplicates): no COO sort, only a copy of the data."""
    indptr, indices = _csr_structure(elements)
    n = 3 * elements.n_vertices
    K = sp.csr_matrix((np.array(blocks, dtype=np.float64), indices, indptr), shape=(n, n))
    K.has_sorted_indices = True
    return K


def _csr_structure(elements: GrainElements):
    """CSR (indptr, indices) of the block-diagonal tangent (cached on the object)."""
    cached = getattr(elements, "_csr_structure", None)
    if cached is not None:
        return cached
    ndof = 3 * np.diff(elements.vertex_ptr)
    nnz = int((ndof**2).sum())
    dtype = np.int32 if max(nnz, 3 * elements.n_vertices) < np.iinfo(np.int32).max else np.int64
    indptr = np.zeros(ndof.sum() + 1, dtype=dtype)
    np.cumsum(np.repeat(ndof, ndof), out=indptr[1:])
    first = 3 * elements.vertex_ptr[:-1]
    tiles = [np.tile(np.arange(d0, d0 + nd, dtype=dtype), nd) for d0, nd in zip(first, ndof)]
    indices = np.concatenate(tiles) if tiles else np.zeros(0, dtype=dtype)
    result = (indptr, indices)
    object.__setattr__(elements, "_csr_structure", result)
    return result


def projected_deformation_gradients(elements: GrainElements, x: np.ndarray) -> np.ndarray:
    """F_Pi = I + sum_v u_v (x) g_v (G, 3, 3) of every grain at vertex positions x (N, 3)."""
    outer = np.einsum("vi,vj->vij", x - elements.reference, elements.projection_grads)
    return np.eye(3) + np.add.reduceat(outer, elements.vertex_ptr[:-1], axis=0)


@njit(cache=True)
def _cauchy(Fs, mu, kappa, out):
    P = np.empty((3, 3))
    A = np.empty((9, 9))
    for g in range(len(Fs)):
        F = Fs[g]
        psi = neo_hooke(F, mu[g], kappa[g], False, P, A)
        # loops, not out[g] = P @ F.T / J: numba compiles an array slice assignment with a
        # string-formatting error path (about 5 s of a fresh install's first run, measured)
        J = det3(F)
        for i in range(3):
            for j in range(3):
                if psi == np.inf:
                    out[g, i, j] = np.nan
                else:
                    out[g, i, j] = (P[i, 0] * F[j, 0] + P[i, 1] * F[j, 1] + P[i, 2] * F[j, 2]) / J


def projected_cauchy_stress(elements: GrainElements, x: np.ndarray) -> np.ndarray:
    """Cauchy stress sigma = P F^T / J at F_Pi, one constant tensor per grain (G, 3, 3)."""
    Fs = np.ascontiguousarray(projected_deformation_gradients(elements, x))
    out = np.empty_like(Fs)
    _cauchy(Fs, elements.mu, elements.kappa, out)
    return out
