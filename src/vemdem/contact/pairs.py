"""Narrow phase between two grains: eligible contact pairs and the hierarchy (docs/contact.md).

For a pair of grains (A, B) whose inflated boxes overlap, the features of each grain that reach
into the other's box (inflated by the activation gap) are tested pairwise:

    vertex-face   LCP in range, vertex on the outer side of the face, gap <= gbar
    edge-edge     LCP in range (never for parallel edges), gap <= gbar; flat edges (the
                  diagonals of planar regions) are skipped: a crossing there is already carried
                  by the vertex-face pairs of the planar region
    vertex-edge   LCP in range, gap <= gbar, and the hierarchy: a convex or flat edge yields to an
                  eligible vertex-face pair with either face at the edge, a concave edge only to
                  both. The paper's last clause (it also yields to two or more eligible edge-edge
                  pairs between the edge and edges at the vertex) is left out: it switches the
                  record on inside the layer as they leave (an energy jump); without it one spot
                  can count up to three times, which the angle of repose does not show beyond its
                  scatter (docs/contact.md)
    vertex-vertex gap <= gbar, unless an eligible pair links either vertex with a face or an edge
                  at the other one

so one physical touching point is counted once. Candidates are found by boxes and by a slab
along the line between the grains (below), not all pairs; the records are those of all pairs.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .narrow import (
    EDGE_EDGE,
    VERTEX_EDGE,
    VERTEX_FACE,
    VERTEX_VERTEX,
    PARALLEL_SIN2,
    RANGE_TOL,
)
from .broad import grain_boxes
from .topology import CONCAVE, FLAT

# columns of the integer contact record
KIND, GRAIN_A, GRAIN_B, FEATURE_A, FEATURE_B, NODE0 = 0, 1, 2, 3, 4, 5
INT_COLS = NODE0 + 6
# columns of the float contact record
C0, C1, GAP = 0, 1, 2
FLOAT_COLS = 3

# The pair kernels (forces._local_terms, friction.dissipative_terms, ...) split the records into
# PAIR_CHUNKS ranges, each one task of the parallel loop with its own scratch arrays: numba puts
# every array a kernel makes on the heap, and those allocations, a dozen to thirty per pair, were
# a third to a half of these kernels' time (docs/results.md, "Where the time goes"). A pair's
# result does not depend on its chunk.
PAIR_CHUNKS = 64


@njit(cache=True)
def chunk_range(k, chunks, n):
    """Records lo:hi of chunk k of n records in `chunks` ranges."""
    return k * n // chunks, (k + 1) * n // chunks


@njit(cache=True)
def pair_nodes(x, ints, c, nn, out):
    """Row c's nn node values of x (positions or velocities) into out (6, 3), zero-padded."""
    for i in range(6):
        for a in range(3):
            out[i, a] = x[ints[c, NODE0 + i], a] if i < nn else 0.0


# The three gap tests below are narrow.py's vertex_face_lcp, vertex_edge_lcp and edge_edge_lcp
# (same formulas, same tolerances) written on scalars: the array versions allocate a 3-vector per
# difference, and those allocations took most of the narrow phase (docs/contact.md, measured).
@njit(cache=True)
def _sub(x, i, j):
    return x[i, 0] - x[j, 0], x[i, 1] - x[j, 1], x[i, 2] - x[j, 2]


@njit(cache=True)
def _vf_gap(x, p, f, faces, gbar):
    """Gap of vertex p against face f if the pair is eligible, else -1 (with the coordinates u, v)."""
    i0, i1, i2 = faces[f, 0], faces[f, 1], faces[f, 2]
    e1x, e1y, e1z = _sub(x, i1, i0)
    e2x, e2y, e2z = _sub(x, i2, i0)
    a11 = e1x * e1x + e1y * e1y + e1z * e1z
    a12 = e1x * e2x + e1y * e2y + e1z * e2z
    a22 = e2x * e2x + e2y * e2y + e2z * e2z
    det = a11 * a22 - a12 * a12
    if det <= 0.0:
        return -1.0, 0.0, 0.0
    rx, ry, rz = _sub(x, p, i0)
    b1 = rx * e1x + ry * e1y + rz * e1z
    b2 = rx * e2x + ry * e2y + rz * e2z
    u = (b1 * a22 - b2 * a12) / det
    v = (b2 * a11 - b1 * a12) / det
    if not (u > RANGE_TOL and v > RANGE_TOL and u + v < 1.0 - RANGE_TOL):
        return -1.0, u, v
    side = rx * (e1y * e2z - e1z * e2y) + ry * (e1z * e2x - e1x * e2z) + rz * (e1x * e2y - e1y * e2x)
    if side <= 0.0:
        return -1.0, u, v
    w = 1.0 - u - v
    d2 = 0.0
    for a in range(3):
        g = x[p, a] - w * x[i0, a] - u * x[i1, a] - v * x[i2, a]
        d2 += g * g
    d = np.sqrt(d2)
    if d > gbar:
        return -1.0, u, v
    return d, u, v


@njit(cache=True)
def _ve_gap(x, p, e, edges, gbar):
    i0, i1 = edges[e, 0], edges[e, 1]
    dx, dy, dz = _sub(x, i1, i0)
    dd = dx * dx + dy * dy + dz * dz
    if dd <= 0.0:
        return -1.0, 0.0
    rx, ry, rz = _sub(x, p, i0)
    t = (rx * dx + ry * dy + rz * dz) / dd
    if not (RANGE_TOL < t < 1.0 - RANGE_TOL):
        return -1.0, t
    d2 = 0.0
    for a in range(3):
        g = x[p, a] - (1.0 - t) * x[i0, a] - t * x[i1, a]
        d2 += g * g
    d = np.sqrt(d2)
    return (d if d <= gbar else -1.0), t


@njit(cache=True)
def _ee_gap(x, ea, eb, edges, edge_type, gbar):
    if edge_type[ea] == FLAT or edge_type[eb] == FLAT:
        return -1.0, 0.0, 0.0
    a0, a1, b0, b1 = edges[ea, 0], edges[ea, 1], edges[eb, 0], edges[eb, 1]
    dax, day, daz = _sub(x, a1, a0)
    dbx, dby, dbz = _sub(x, b1, b0)
    aa = dax * dax + day * day + daz * daz
    bb = dbx * dbx + dby * dby + dbz * dbz
    ab = dax * dbx + day * dby + daz * dbz
    if aa * bb - ab * ab <= PARALLEL_SIN2 * aa * bb:
        return -1.0, 0.0, 0.0
    rx, ry, rz = _sub(x, a0, b0)
    ra = rx * dax + ry * day + rz * daz
    rb = rx * dbx + ry * dby + rz * dbz
    det = aa * bb - ab * ab
    s = (ab * rb - bb * ra) / det
    t = (aa * rb - ab * ra) / det
    if not (RANGE_TOL < s < 1.0 - RANGE_TOL and RANGE_TOL < t < 1.0 - RANGE_TOL):
        return -1.0, s, t
    d2 = 0.0
    for a in range(3):
        g = (1.0 - s) * x[a0, a] + s * x[a1, a] - (1.0 - t) * x[b0, a] - t * x[b1, a]
        d2 += g * g
    d = np.sqrt(d2)
    return (d if d <= gbar else -1.0), s, t


@njit(cache=True)
def _vertex_edge_survives(x, p, e, faces, edge_faces, edge_type, gbar):
    """The vertex-edge hierarchy (module docstring)."""
    fa = edge_faces[e, 0]
    fb = edge_faces[e, 1]
    ca = _vf_gap(x, p, fa, faces, gbar)[0] >= 0.0
    cb = fb >= 0 and _vf_gap(x, p, fb, faces, gbar)[0] >= 0.0  # fb < 0: rim of an open wall
    if edge_type[e] == CONCAVE:
        if ca and cb:
            return False
    elif ca or cb:
        return False
    return True


@njit(cache=True)
def _vertex_vertex_survives(x, p, q, faces, edges, v_face_ptr, v_faces, v_edge_ptr, v_edges, gbar):
    for a, b in ((p, q), (q, p)):
        for k in range(v_face_ptr[b], v_face_ptr[b + 1]):
            if _vf_gap(x, a, v_faces[k], faces, gbar)[0] >= 0.0:
                return False
        for k in range(v_edge_ptr[b], v_edge_ptr[b + 1]):
            if _ve_gap(x, a, v_edges[k], edges, gbar)[0] >= 0.0:
                return False
    return True


@njit(cache=True)
def _region(glo, ghi, A, B, gbar, lo, hi):
    """Fill [lo, hi] with the part of grain A's box that lies within gbar of grain B's box."""
    for a in range(3):
        lo[a] = max(glo[A, a], glo[B, a] - gbar)
        hi[a] = min(ghi[A, a], ghi[B, a] + gbar)


@njit(parallel=True, cache=True)
def feature_boxes(x, nodes):
    """Box (lo, hi) of every feature: row k spans x[nodes[k]] (faces: 3 nodes, edges: 2). Computed
    once per search, as the grains' boxes: the pre-tests compare boxes instead of re-reading nodes."""
    out = np.empty((len(nodes), 6))
    for k in prange(len(nodes)):
        feature_box(x, nodes, k, out)
    return out


@njit(cache=True)
def feature_box(x, nodes, k, out):
    """Row k of out: the box (lo, hi) of the nodes nodes[k]."""
    for a in range(3):
        lo = hi = x[nodes[k, 0], a]
        for j in range(1, nodes.shape[1]):
            lo = min(lo, x[nodes[k, j], a])
            hi = max(hi, x[nodes[k, j], a])
        out[k, a] = lo
        out[k, 3 + a] = hi


@njit(cache=True)
def _box_meets(box, k, lo, hi):
    """Does feature k's box meet [lo, hi]?"""
    for a in range(3):
        if box[k, 3 + a] < lo[a] or box[k, a] > hi[a]:
            return False
    return True


@njit(cache=True)
def _point_near_box(x, p, box, k, gbar):
    """Is vertex p within gbar of feature k's box? (the pre-test before an exact gap)"""
    for a in range(3):
        if x[p, a] < box[k, a] - gbar or x[p, a] > box[k, 3 + a] + gbar:
            return False
    return True


@njit(cache=True)
def _boxes_near(box, i, j, gbar):
    """Do the boxes of features i and j come within gbar?"""
    for a in range(3):
        if box[i, 3 + a] + gbar < box[j, a] or box[j, 3 + a] + gbar < box[i, a]:
            return False
    return True


# A slab test along the line between the two grains' box centres, n (unit): every point of a
# feature of A projects on n at most the largest projection of its nodes, every point of B at
# least min over B's vertices, so a feature of A whose nodes all project below min_B - gbar lies
# farther than gbar from all of B (for any polyhedra: a feature is the convex hull of its nodes);
# the same for B with the roles swapped. Its margin is far above the round-off of a projection,
# so the exact tests below see the same candidates in the same order: the same records.
SLAB_MARGIN = 1e-9


@njit(cache=True)
def _slab_axis(glo, ghi, A, B):
    n = np.empty(3)
    for a in range(3):
        n[a] = 0.5 * (glo[B, a] + ghi[B, a] - glo[A, a] - ghi[A, a])
    norm = np.sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2])
    if norm > 0.0:
        n /= norm
    return n, norm > 0.0


@njit(cache=True)
def _project(x, start, stop, n, out):
    """out[k] = x[start + k] . n; returns (min, max)."""
    lo, hi = np.inf, -np.inf
    for k in range(stop - start):
        d = x[start + k, 0] * n[0] + x[start + k, 1] * n[1] + x[start + k, 2] * n[2]
        out[k] = d
        lo = min(lo, d)
        hi = max(hi, d)
    return lo, hi


@njit(cache=True)
def _features_near(x, A, lo, hi, vptr, fptr, eptr, fbox, ebox, proj, sign, bound, v_face_ptr, v_faces,
                   v_edge_ptr, v_edges, buf, mark):  # fmt: skip
    """Vertices, faces and edges of grain A whose boxes meet [lo, hi] and that reach the slab
    sign * proj >= sign * bound (proj: A's vertices projected on the slab axis), as three views
    into buf (one allocation per grain pair: allocations dominated this kernel, docs/contact.md).
    A face or an edge reaches the slab iff one of its nodes does: they are marked from the
    vertices in the slab (mark: zeros, one per face then one per edge of A) and read in order."""
    v0, f0, e0 = vptr[A], fptr[A], eptr[A]
    nfa = fptr[A + 1] - f0
    nv = nf = ne = 0
    for v in range(v0, vptr[A + 1]):
        if sign * proj[v - v0] < sign * bound:
            continue
        for k in range(v_face_ptr[v], v_face_ptr[v + 1]):
            mark[v_faces[k] - f0] = 1
        for k in range(v_edge_ptr[v], v_edge_ptr[v + 1]):
            mark[nfa + v_edges[k] - e0] = 1
        if lo[0] <= x[v, 0] <= hi[0] and lo[1] <= x[v, 1] <= hi[1] and lo[2] <= x[v, 2] <= hi[2]:
            buf[nv] = v
            nv += 1
    fs = buf[nv:]
    for f in range(f0, fptr[A + 1]):
        if mark[f - f0] and _box_meets(fbox, f, lo, hi):
            fs[nf] = f
            nf += 1
    es = fs[nf:]
    for e in range(e0, eptr[A + 1]):
        if mark[nfa + e - e0] and _box_meets(ebox, e, lo, hi):
            es[ne] = e
            ne += 1
    return buf[:nv], fs[:nf], es[:ne]


@njit(cache=True)
def _record(ints, floats, n, cap, kind, A, B, fa, fb, n0, n1, n2, n3, c0, c1, gap):
    """Row n of the records (nodes n0..n3, -1 where the kind has fewer; passed as scalars: an
    array of them per record was an allocation per record)."""
    if n < cap:
        ints[n, KIND] = kind
        ints[n, GRAIN_A] = A
        ints[n, GRAIN_B] = B
        ints[n, FEATURE_A] = fa
        ints[n, FEATURE_B] = fb
        ints[n, NODE0] = n0
        ints[n, NODE0 + 1] = n1
        ints[n, NODE0 + 2] = n2
        ints[n, NODE0 + 3] = n3
        ints[n, NODE0 + 4] = -1
        ints[n, NODE0 + 5] = -1
        floats[n, C0] = c0
        floats[n, C1] = c1
        floats[n, GAP] = gap
    return n + 1


@njit(cache=True)
def near_features(x, A, B, reach, vptr, fptr, eptr, v_face_ptr, v_faces, v_edge_ptr, v_edges, glo, ghi, fbox,
                  ebox):  # fmt: skip
    """(vA, fA, eA, vB, fB, eB): the vertices, faces and edges of grains A and B that may lie within
    `reach` of the other grain (boxes and the slab); empty when the grains are farther apart."""
    box = np.empty((4, 3))
    _region(glo, ghi, A, B, reach, box[0], box[1])
    _region(glo, ghi, B, A, reach, box[2], box[3])
    none = np.empty(0, dtype=np.int64)
    for a in range(3):
        if box[0, a] > box[1, a] or box[2, a] > box[3, a]:
            return none, none, none, none, none, none  # the boxes are more than reach apart
    nA, nB = vptr[A + 1] - vptr[A], vptr[B + 1] - vptr[B]
    sizeA = nA + fptr[A + 1] - fptr[A] + eptr[A + 1] - eptr[A]
    sizeB = nB + fptr[B + 1] - fptr[B] + eptr[B + 1] - eptr[B]
    buf = np.empty(2 * (sizeA + sizeB) - nA - nB, dtype=np.int64)  # features, then marks (faces, edges)
    proj = np.empty(nA + nB)
    axis, has_axis = _slab_axis(glo, ghi, A, B)
    minA, maxA = _project(x, vptr[A], vptr[A + 1], axis, proj[:nA])
    minB, maxB = _project(x, vptr[B], vptr[B + 1], axis, proj[nA:])
    slab = reach * (1.0 + SLAB_MARGIN)
    if not has_axis:  # coinciding box centres: no slab
        maxA, minB = np.inf, -np.inf
    elif maxA + slab < minB:
        return none, none, none, none, none, none  # a plane between the grains, more than reach from each
    marks = buf[sizeA + sizeB :]
    marks[:] = 0
    vA, fA, eA = _features_near(x, A, box[0], box[1], vptr, fptr, eptr, fbox, ebox, proj[:nA], 1.0, minB - slab,
                                v_face_ptr, v_faces, v_edge_ptr, v_edges, buf[:sizeA], marks[: sizeA - nA])  # fmt: skip
    vB, fB, eB = _features_near(x, B, box[2], box[3], vptr, fptr, eptr, fbox, ebox, proj[nA:], -1.0, maxA + slab,
                                v_face_ptr, v_faces, v_edge_ptr, v_edges, buf[sizeA : sizeA + sizeB],
                                marks[sizeA - nA :])  # fmt: skip
    return vA, fA, eA, vB, fB, eB


# The exact test of one feature pair and its record if eligible (returns the new count): the
# search below and the feature list (contact/feature_list.py) call the same four, so that both
# find the same records.
@njit(cache=True)
def vf_record(x, p, f, ga, gb, faces, gbar, ints, floats, n, cap):
    d, u, v = _vf_gap(x, p, f, faces, gbar)
    if d >= 0.0:
        n = _record(ints, floats, n, cap, np.int64(VERTEX_FACE), ga, gb, p, f, p, faces[f, 0], faces[f, 1], faces[f, 2],
                    u, v, d)  # fmt: skip
    return n


@njit(cache=True)
def ee_record(x, ea, eb, A, B, edges, edge_type, gbar, ints, floats, n, cap):
    d, s, t = _ee_gap(x, ea, eb, edges, edge_type, gbar)
    if d >= 0.0:
        n = _record(ints, floats, n, cap, np.int64(EDGE_EDGE), A, B, ea, eb, edges[ea, 0], edges[ea, 1], edges[eb, 0],
                    edges[eb, 1], s, t, d)  # fmt: skip
    return n


@njit(cache=True)
def ve_record(x, p, e, ga, gb, faces, edges, edge_faces, edge_type, gbar, ints, floats, n, cap):
    d, t = _ve_gap(x, p, e, edges, gbar)
    if d >= 0.0 and _vertex_edge_survives(x, p, e, faces, edge_faces, edge_type, gbar):
        n = _record(ints, floats, n, cap, np.int64(VERTEX_EDGE), ga, gb, p, e, p, edges[e, 0], edges[e, 1],
                    np.int64(-1), t, 0.0, d)  # fmt: skip
    return n


@njit(cache=True)
def vv_record(x, p, q, A, B, faces, edges, v_face_ptr, v_faces, v_edge_ptr, v_edges, gbar, ints, floats, n, cap):
    d = np.sqrt((x[p, 0] - x[q, 0]) ** 2 + (x[p, 1] - x[q, 1]) ** 2 + (x[p, 2] - x[q, 2]) ** 2)
    if d <= gbar and _vertex_vertex_survives(x, p, q, faces, edges, v_face_ptr, v_faces, v_edge_ptr, v_edges, gbar):
        n = _record(ints, floats, n, cap, np.int64(VERTEX_VERTEX), A, B, p, q, p, q, np.int64(-1), np.int64(-1), 0.0,
                    0.0, d)  # fmt: skip
    return n


@njit(cache=True)
def grain_pair_contacts(x, A, B, gbar, vptr, fptr, eptr, faces, edges, edge_faces, edge_type,
                        v_face_ptr, v_faces, v_edge_ptr, v_edges, glo, ghi, fbox, ebox, ints, floats):  # fmt: skip
    """Fill ints/floats (capacity = len(ints)) with the eligible pairs of grains A and B.
    Returns the number found (which may exceed the capacity: then the caller retries)."""
    cap = len(ints)
    n = np.int64(0)  # typed, as the kinds below: numba compiles _record once per literal argument value
    vA, fA, eA, vB, fB, eB = near_features(x, A, B, gbar, vptr, fptr, eptr, v_face_ptr, v_faces, v_edge_ptr, v_edges,
                                           glo, ghi, fbox, ebox)  # fmt: skip
    # vertex-face, both ways: the vertex's grain is side "A" of the record
    for side in range(2):
        verts, fcs, ga, gb = (vA, fB, A, B) if side == 0 else (vB, fA, B, A)
        for p in verts:
            for f in fcs:
                if _point_near_box(x, p, fbox, f, gbar):
                    n = vf_record(x, p, f, ga, gb, faces, gbar, ints, floats, n, cap)
    for ea in eA:
        for eb in eB:
            if _boxes_near(ebox, ea, eb, gbar):
                n = ee_record(x, ea, eb, A, B, edges, edge_type, gbar, ints, floats, n, cap)
    for side in range(2):
        verts, eds, ga, gb = (vA, eB, A, B) if side == 0 else (vB, eA, B, A)
        for p in verts:
            for e in eds:
                if _point_near_box(x, p, ebox, e, gbar):
                    n = ve_record(x, p, e, ga, gb, faces, edges, edge_faces, edge_type, gbar, ints, floats, n, cap)
    for p in vA:
        for q in vB:
            n = vv_record(x, p, q, A, B, faces, edges, v_face_ptr, v_faces, v_edge_ptr, v_edges, gbar, ints, floats, n,
                          cap)  # fmt: skip
    return n


@njit(parallel=True, cache=True)
def _all_pairs(x, grain_pairs, gbar, vptr, fptr, eptr, faces, edges, edge_faces, edge_type,
               v_face_ptr, v_faces, v_edge_ptr, v_edges, glo, ghi, fbox, ebox, cap, ints, floats, counts):  # fmt: skip
    for k in prange(len(grain_pairs)):
        counts[k] = grain_pair_contacts(
            x, grain_pairs[k, 0], grain_pairs[k, 1], gbar, vptr, fptr, eptr, faces, edges, edge_faces,
            edge_type, v_face_ptr, v_faces, v_edge_ptr, v_edges, glo, ghi, fbox, ebox,
            ints[k * cap : (k + 1) * cap], floats[k * cap : (k + 1) * cap],
        )  # fmt: skip


def find_contacts(x: np.ndarray, grain_pairs: np.ndarray, topo, gbar: float, capacity: int = 32):
    """Eligible contact pairs of the candidate grain pairs, as (ints, floats) record arrays.

    Each grain pair gets `capacity` slots; when one overflows, the search is rerun with room
    for the largest count (fixed-capacity buffers keep the compiled kernel free of Python lists).
    """
    grain_pairs = np.ascontiguousarray(grain_pairs, dtype=np.int64).reshape(-1, 2)
    x = np.ascontiguousarray(x, dtype=np.float64)
    glo, ghi = grain_boxes(x, topo.grain_vertex_ptr, 0.0)
    fbox = feature_boxes(x, topo.faces)
    ebox = feature_boxes(x, topo.edges)
    while True:
        m = len(grain_pairs)
        ints = np.empty((m * capacity, INT_COLS), dtype=np.int64)
        floats = np.empty((m * capacity, FLOAT_COLS))
        counts = np.zeros(m, dtype=np.int64)
        _all_pairs(
            x, grain_pairs, gbar, topo.grain_vertex_ptr, topo.grain_face_ptr, topo.grain_edge_ptr, topo.faces,
            topo.edges, topo.edge_faces, topo.edge_type, topo.vertex_face_ptr, topo.vertex_faces,
            topo.vertex_edge_ptr, topo.vertex_edges, glo, ghi, fbox, ebox, capacity, ints, floats, counts,
        )  # fmt: skip
        if m == 0 or counts.max() <= capacity:
            break
        capacity = int(counts.max())
    return _compact(ints, floats, counts, capacity)


@njit(cache=True)
def _compact(ints, floats, counts, capacity):
    """The first counts[k] rows of every grain pair's slot k, in order."""
    n = 0
    for c in counts:
        n += c
    out_i = np.empty((n, ints.shape[1]), dtype=ints.dtype)
    out_f = np.empty((n, floats.shape[1]))
    row = 0
    for k in range(len(counts)):
        for j in range(k * capacity, k * capacity + counts[k]):
            for c in range(ints.shape[1]):  # element copies: a row assignment compiles a shape-error path
                out_i[row, c] = ints[j, c]
            for c in range(floats.shape[1]):
                out_f[row, c] = floats[j, c]
            row += 1
    return out_i, out_f
