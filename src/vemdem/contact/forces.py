"""Contact potential, forces and tangent of the active pairs (frictionless part).

Each pair contributes Phi(d) (law.py) of its gap d (narrow.py). With grad d and hess d from
`gap_derivatives` (which include the change of the contact point with the deformation):

    dPhi/dx   = -f_n(d) grad d
    d2Phi/dx2 =  k(d) grad d grad d^T - f_n(d) hess d

Pairs are evaluated in parallel into per-pair local arrays; the scatter onto shared vertices is
a serial compiled loop (no write races).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numba import njit, prange

from .law import normal_force, normal_potential
from .narrow import (
    EDGE_EDGE,
    N_NODES,
    VERTEX_FACE,
    gap_derivatives_into,
    gap_gradient_into,
    pair_weights,
    pair_weights_into,
)
from .pairs import C0, C1, KIND, NODE0, PAIR_CHUNKS, chunk_range, pair_nodes


@njit(cache=True)
def _normal_terms(c, nn, d, grad, law, energy, local_force):
    """Phi(d) and -f_n(d) grad d of pair c into energy[c] and local_force[c]; returns (f_n, k)."""
    fn, k = normal_force(d, law)
    energy[c] = normal_potential(d, law)
    for i in range(nn):
        for a in range(3):
            local_force[c, i, a] = -fn * grad[i, a]
    return fn, k


# Pairs in PAIR_CHUNKS ranges, each with its own scratch (pairs.chunk_range)
@njit(parallel=True, cache=True)
def _local_forces(x, ints, floats, law, energy, local_force):
    """_local_terms without the tangent (explicit steps): numba compiles every branch of a
    kernel, and the tangent's would cost a fresh install's first explicit run seconds."""
    n = len(ints)
    for k in prange(PAIR_CHUNKS):
        xs, grad = np.zeros((6, 3)), np.zeros((6, 3))
        w0, D, w, g = np.zeros(6), np.zeros((6, 2)), np.zeros(6), np.zeros(3)
        lo, hi = chunk_range(np.int64(k), PAIR_CHUNKS, n)  # np.int64: k is uint64 in the parallel body
        for c in range(lo, hi):
            kind = ints[c, KIND]
            nn = N_NODES[kind]
            pair_nodes(x, ints, c, nn, xs)
            d = gap_gradient_into(kind, xs, floats[c, C0], floats[c, C1], grad, w0, D, w, g)
            _normal_terms(c, nn, d, grad, law, energy, local_force)


@njit(parallel=True, cache=True)
def _local_terms(x, ints, floats, law, energy, local_force, local_tangent):
    """Energy, force and 18 x 18 tangent of every pair (implicit steps)."""
    n = len(ints)
    for k in prange(PAIR_CHUNKS):
        xs, grad, hess = np.zeros((6, 3)), np.zeros((6, 3)), np.zeros((18, 18))
        w0, D, w, g = np.zeros(6), np.zeros((6, 2)), np.zeros(6), np.zeros(3)
        J, B = np.zeros((3, 2)), np.zeros((3, 18))
        lo, hi = chunk_range(np.int64(k), PAIR_CHUNKS, n)
        for c in range(lo, hi):
            kind = ints[c, KIND]
            nn = N_NODES[kind]
            pair_nodes(x, ints, c, nn, xs)
            d = gap_derivatives_into(kind, xs, floats[c, C0], floats[c, C1], True, grad, hess, w0, D, w, g, J, B)
            fn, kd = _normal_terms(c, nn, d, grad, law, energy, local_force)
            for r in range(3 * nn):
                gr = grad[r // 3, r % 3]
                for s in range(3 * nn):
                    local_tangent[c, r, s] = kd * gr * grad[s // 3, s % 3] - fn * hess[r, s]


@njit(cache=True)
def scatter_local_forces(ints, local_force, out):
    """out[v] += local force of every pair at its node v (serial: pairs share vertices)."""
    for c in range(len(ints)):
        for i in range(N_NODES[ints[c, KIND]]):
            v = ints[c, NODE0 + i]
            for a in range(3):
                out[v, a] += local_force[c, i, a]


class ContactEvaluation:
    def __init__(self, energy, force, local_force, local_tangent, ints):
        self.energy = energy  # (n_pairs,) potential of each pair
        self.force = force  # (N, 3) dPhi/dx
        self.local_force = local_force  # (n_pairs, 6, 3) dPhi/dx of each pair at its nodes
        self.local_tangent = local_tangent  # (n_pairs, 18, 18) or None
        self.ints = ints

    @property
    def total_energy(self) -> float:
        return float(self.energy.sum())

    def tangent_matrix(self, n_vertices: int) -> sp.csr_matrix:
        return local_tangent_matrix(self.ints, self.local_tangent, n_vertices)


def local_tangent_matrix(ints, local_tangent, n_vertices: int) -> sp.csr_matrix:
    """Global sparse matrix (3 n_vertices square) from the pairs' local 18 x 18 blocks."""
    rows, cols, vals = [], [], []
    for kind in np.unique(ints[:, KIND]):
        sel = ints[:, KIND] == kind
        nn = N_NODES[kind]
        dofs = (3 * ints[sel, NODE0 : NODE0 + nn][:, :, None] + np.arange(3)).reshape(-1, 3 * nn)
        rows.append(np.repeat(dofs, 3 * nn, axis=1).ravel())
        cols.append(np.tile(dofs, (1, 3 * nn)).ravel())
        vals.append(local_tangent[sel, : 3 * nn, : 3 * nn].ravel())
    n = 3 * n_vertices
    if not rows:
        return sp.csr_matrix((n, n))
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n))


@njit(cache=True)
def scatter_pair_tangents(ints, local_tangent, vertex_grain, vertex_ptr, block_ptr, n_vertices, blocks,
                          rows, cols, vals, touched):  # fmt: skip
    """Add the pairs' local tangents to the grains' dense blocks (both nodes on one grain) and
    return the count of coupling node blocks (nodes on two grains) written to rows, cols (node
    indices) and vals (3 x 3 each), which must hold 36 per pair. Wall nodes (index >= n_vertices)
    are prescribed: dropped. touched[v] is set for every vertex whose own block received a term
    (the grain-block solver's Woodbury path needs the dofs the contacts touch). Serial: pairs
    share grains."""
    m = 0
    for c in range(len(ints)):
        nn = N_NODES[ints[c, KIND]]
        for i in range(nn):
            vi = ints[c, NODE0 + i]
            if vi >= n_vertices:
                continue
            touched[vi] = True
            gi = vertex_grain[vi]
            for j in range(nn):
                vj = ints[c, NODE0 + j]
                if vj >= n_vertices:
                    continue
                gj = vertex_grain[vj]
                if gi == gj:
                    n3 = 3 * (vertex_ptr[gi + 1] - vertex_ptr[gi])
                    li, lj = 3 * (vi - vertex_ptr[gi]), 3 * (vj - vertex_ptr[gi])
                    b0 = block_ptr[gi]
                    for a in range(3):
                        for b in range(3):
                            blocks[b0 + (li + a) * n3 + lj + b] += local_tangent[c, 3 * i + a, 3 * j + b]
                else:
                    rows[m] = vi
                    cols[m] = vj
                    for a in range(3):
                        for b in range(3):
                            vals[m, a, b] = local_tangent[c, 3 * i + a, 3 * j + b]
                    m += 1
    return m


@njit(cache=True)
def csr_from_block_triplets(rows, cols, vals, n_block_rows):
    """(indptr, indices, data) of the matrix sum_k vals[k] at block (rows[k], cols[k]), vals (m, b, b),
    as a CSR matrix of b n_block_rows rows: duplicates summed in input order, columns increasing.
    SciPy's COO -> CSR gives the same matrix (1 x 1 blocks), but its Python layers cost 0.3 ms for
    5,000 triplets (docs/linear-solvers.md), and its std::sort need not keep equal columns in order,
    so its sums of duplicates may differ from these in the last bits: these are deterministic.

    The contact coupling arrives as 3 x 3 node blocks: sorting the blocks' columns within each
    node row (a stable insertion sort: the rows hold tens of blocks) is a ninth of the work of
    sorting scalar triplets, whose rows in the 515-grain lid jam held hundreds of entries (with the
    scatter, ContactEvaluation.add_to_blocks there 21.3 -> 7.4 ms, docs/linear-solvers.md). Every
    scalar entry sums its duplicates in the order the scalar triplets gave them: the same matrix to
    the bit."""
    m = len(rows)
    bs = vals.shape[1]
    n = n_block_rows
    start = np.zeros(n + 1, np.int64)
    for k in range(m):
        start[rows[k] + 1] += 1
    for i in range(n):
        start[i + 1] += start[i]
    fill = start[:-1].copy()
    c = np.empty(m, np.int64)
    order = np.empty(m, np.int64)
    for k in range(m):
        p = fill[rows[k]]
        c[p] = cols[k]
        order[p] = k
        fill[rows[k]] = p + 1
    ucol = np.empty(m, np.int64)  # the distinct columns of each row, in order
    first = np.empty(m + 1, np.int64)  # where each distinct column's run of duplicates starts
    row_ptr = np.zeros(n + 1, np.int64)
    nu = 0
    for i in range(n):
        a, b = start[i], start[i + 1]
        for p in range(a + 1, b):  # stable insertion sort of the row by column
            cp, kp = c[p], order[p]
            q = p - 1
            while q >= a and c[q] > cp:
                c[q + 1] = c[q]
                order[q + 1] = order[q]
                q -= 1
            c[q + 1] = cp
            order[q + 1] = kp
        for p in range(a, b):
            if p == a or c[p] != c[p - 1]:
                ucol[nu] = c[p]
                first[nu] = p
                nu += 1
        row_ptr[i + 1] = nu
    first[nu] = m
    indptr = np.zeros(n * bs + 1, np.int64)
    indices = np.empty(nu * bs * bs, np.int64)
    data = np.empty(nu * bs * bs)
    q = 0
    for i in range(n):
        for a in range(bs):
            for u in range(row_ptr[i], row_ptr[i + 1]):
                for b in range(bs):
                    s = vals[order[first[u]], a, b]
                    for p in range(first[u] + 1, first[u + 1]):
                        s += vals[order[p], a, b]
                    indices[q] = ucol[u] * bs + b
                    data[q] = s
                    q += 1
            indptr[i * bs + a + 1] = q
    return indptr, indices, data


def evaluate_contacts(x, ints, floats, law_params, n_vertices: int, tangent: bool = False) -> ContactEvaluation:
    m = len(ints)
    energy = np.zeros(m)
    local_force = np.zeros((m, 6, 3))
    local_tangent = np.zeros((m, 18, 18)) if tangent else np.zeros((1, 18, 18))
    if tangent:
        _local_terms(np.ascontiguousarray(x), ints, floats, law_params, energy, local_force, local_tangent)
    else:
        _local_forces(np.ascontiguousarray(x), ints, floats, law_params, energy, local_force)
    force = np.zeros((n_vertices, 3))
    scatter_local_forces(ints, local_force, force)
    return ContactEvaluation(energy, force, local_force, local_tangent if tangent else None, ints)


def force_on_side_a(ints, local_force) -> np.ndarray:
    """Physical contact force on side A of every pair (m, 3): minus dPhi/dx summed over A's nodes
    (the nodes with positive weight: the vertex, or the first edge)."""
    kinds = ints[:, KIND]
    n_a = np.where(kinds == EDGE_EDGE, 2, 1)  # edge-edge: two nodes on side A; otherwise the vertex
    mask = np.arange(6)[None, :] < n_a[:, None]
    return -(local_force * mask[:, :, None]).sum(axis=1)


@njit(cache=True)
def pair_points(x, ints, floats):
    """The two closest points of every pair (m, 2, 3): [:, 0] on side A, sum of w_i x_i over A's
    nodes (the vertex, or the first edge), [:, 1] on side B, sum of -w_i x_i over the others. By
    role, not by the sign of w: a wall plane's triangle is finite, and the projection of a vertex
    may lie outside it (weights of any sign)."""
    out = np.zeros((len(ints), 2, 3))
    w0 = np.empty(6)
    D = np.empty((6, 2))
    for c in range(len(ints)):
        kind = ints[c, KIND]
        w = pair_weights(kind, floats[c, C0], floats[c, C1], w0, D)
        n_a = 2 if kind == EDGE_EDGE else 1
        for i in range(N_NODES[kind]):
            side = 0 if i < n_a else 1
            sign = 1.0 if i < n_a else -1.0
            for a in range(3):
                out[c, side, a] += sign * w[i] * x[ints[c, NODE0 + i], a]
    return out


def contact_points(x, ints, floats):
    """Contact point on side B of every pair (m, 3) (pair_points)."""
    return np.ascontiguousarray(pair_points(x, ints, floats)[:, 1])


@njit(cache=True)
def _cross_of(x, i0, i1, j0, j1):
    """(x[i1] - x[i0]) x (x[j1] - x[j0])."""
    a0, a1, a2 = x[i1, 0] - x[i0, 0], x[i1, 1] - x[i0, 1], x[i1, 2] - x[i0, 2]
    b0, b1, b2 = x[j1, 0] - x[j0, 0], x[j1, 1] - x[j0, 1], x[j1, 2] - x[j0, 2]
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


@njit(cache=True)
def pair_normals(x, ints, floats):
    """Unit normal of every pair (m, 3), from side B to side A: the direction of the normal force on
    A (force_on_side_a: f_n g / |g|, g = p_A - p_B). Where the features give it without the gap
    vector, it comes from them: a gap near the touching floor is a difference of nearly equal
    positions, its direction round-off, while a face's normal or two edges' cross product is not.

        vertex-face   the face's normal (t1 - t0) x (t2 - t0): the narrow phase keeps a vertex on the
                      face's outer side only, so it points to A; a wall plane's too (its triangle is
                      counter-clockwise seen from its normal's side)
        edge-edge     (a1 - a0) x (b1 - b0), turned along g
        vertex-edge,  g / |g|: nothing else fixes the direction (zero where g is)
        vertex-vertex
    """
    m = len(ints)
    out = np.zeros((m, 3))
    w0 = np.empty(6)
    D = np.empty((6, 2))
    w = np.empty(6)
    for c in range(m):
        kind = ints[c, KIND]
        pair_weights_into(kind, floats[c, C0], floats[c, C1], w0, D, w)
        g0 = g1 = g2 = 0.0
        for i in range(N_NODES[kind]):
            node = ints[c, NODE0 + i]
            g0 += w[i] * x[node, 0]
            g1 += w[i] * x[node, 1]
            g2 += w[i] * x[node, 2]
        n0, n1, n2 = g0, g1, g2
        if kind == VERTEX_FACE:
            t0, t1, t2 = ints[c, NODE0 + 1], ints[c, NODE0 + 2], ints[c, NODE0 + 3]
            n0, n1, n2 = _cross_of(x, t0, t1, t0, t2)
        elif kind == EDGE_EDGE:
            n0, n1, n2 = _cross_of(x, ints[c, NODE0], ints[c, NODE0 + 1], ints[c, NODE0 + 2], ints[c, NODE0 + 3])
            if n0 * g0 + n1 * g1 + n2 * g2 < 0.0:
                n0, n1, n2 = -n0, -n1, -n2
        norm = np.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
        if norm > 0.0:
            out[c, 0], out[c, 1], out[c, 2] = n0 / norm, n1 / norm, n2 / norm
    return out


@njit(cache=True)
def pair_inverse_masses(inv_mass, ints, floats):
    """sum_i w_i^2 / m_i of every pair: k times it is the one nonzero eigenvalue omega^2 of the
    pair's spring k (w (x) n)(w (x) n)^T on the lumped masses (a wall node has 1/m = 0)."""
    out = np.zeros(len(ints))
    w0 = np.empty(6)
    D = np.empty((6, 2))
    for c in range(len(ints)):
        w = pair_weights(ints[c, KIND], floats[c, C0], floats[c, C1], w0, D)
        for i in range(N_NODES[ints[c, KIND]]):
            out[c] += w[i] * w[i] * inv_mass[ints[c, NODE0 + i]]
    return out


@njit(cache=True)
def gap_rates(x, v, ints, floats):
    """d(gap)/dt of every pair: n . sum_i w_i v_i, n the unit gap vector sum_i w_i x_i / |.|
    (negative: the two sides approach)."""
    out = np.zeros(len(ints))
    w0 = np.empty(6)
    D = np.empty((6, 2))
    for c in range(len(ints)):
        w = pair_weights(ints[c, KIND], floats[c, C0], floats[c, C1], w0, D)
        d = np.zeros(3)
        r = np.zeros(3)
        for i in range(N_NODES[ints[c, KIND]]):
            node = ints[c, NODE0 + i]
            for a in range(3):
                d[a] += w[i] * x[node, a]
                r[a] += w[i] * v[node, a]
        norm = np.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
        if norm > 0.0:
            out[c] = (d[0] * r[0] + d[1] * r[1] + d[2] * r[2]) / norm
    return out


@njit(cache=True)
def rigid_pair_blocks(ints, pair_tangent, x_all, centre, vertex_grain, n_vertices):
    """Z^T K_pair Z of every pair as up to four 6 x 6 grain blocks, for the rigid-grain Newton
    matrix (solver/rigid_implicit.py); Z_i = [I, -[r_i]x], the rigid modes of vertex i about its
    grain's centre. Returns rows, cols (grain indices, -1 where a node is a wall's) and blocks (4
    per pair: AA, AB, BA, BB in the order the pair's grains appear)."""
    m = len(ints)
    rows = np.full(4 * m, -1, np.int64)
    cols = np.full(4 * m, -1, np.int64)
    blocks = np.zeros((4 * m, 6, 6))
    Z = np.zeros((6, 3, 6))
    for c in range(m):
        nn = N_NODES[ints[c, KIND]]
        body = np.full(6, -1, np.int64)
        first, second = -1, -1
        for i in range(nn):
            node = ints[c, NODE0 + i]
            if node < n_vertices:
                g = vertex_grain[node]
                body[i] = g
                if first < 0:
                    first = g
                elif g != first and second < 0:
                    second = g
                r0 = x_all[node, 0] - centre[g, 0]
                r1 = x_all[node, 1] - centre[g, 1]
                r2 = x_all[node, 2] - centre[g, 2]
                for a in range(3):
                    for k in range(6):
                        Z[i, a, k] = 0.0
                    Z[i, a, a] = 1.0
                # -[r]x: dx = dphi x r
                Z[i, 0, 4], Z[i, 0, 5] = r2, -r1
                Z[i, 1, 3], Z[i, 1, 5] = -r2, r0
                Z[i, 2, 3], Z[i, 2, 4] = r1, -r0
        for i in range(nn):
            if body[i] < 0:
                continue
            for j in range(nn):
                if body[j] < 0:
                    continue
                slot = 4 * c + (0 if body[i] == first else 2) + (0 if body[j] == first else 1)
                rows[slot] = body[i]
                cols[slot] = body[j]
                for p in range(6):
                    for q in range(6):
                        s = 0.0
                        for a in range(3):
                            za = Z[i, a, p]
                            if za != 0.0:
                                for b in range(3):
                                    s += za * pair_tangent[c, 3 * i + a, 3 * j + b] * Z[j, b, q]
                        blocks[slot, p, q] += s
    return rows, cols, blocks
