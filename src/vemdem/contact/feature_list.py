"""A Verlet list of feature pairs: the narrow phase's records from a short list per grain pair.

The narrow phase (pairs.py) searches every candidate grain pair's features at every call: 1.7 ms
of a 4.5 ms explicit step of the main job's 160 rigid grains (benchmarks/bench_rigid.py). Between
two calls grains move a fraction of the activation gap gbar, so the feature pairs that can be
within gbar hardly change. This list keeps, for each candidate grain pair (A, B), the feature pairs
that were within reach = gbar + skin when it was built, in the order the search visits them
(vertex-face with A's vertices, then with B's, edge-edge, vertex-edge both ways, vertex-vertex;
each by ascending feature indices), and re-runs on them the search's own exact tests
(pairs.vf_record, ee_record, ve_record, vv_record). The records are therefore those of the search,
in its order, bit for bit (tests/test_feature_list.py), as long as the list holds every feature
pair now within gbar:

- every point of a feature is a convex combination of its nodes, and distances do not change
  when both bodies are shifted alike. So if every node of A moved by at most m_A and every node
  of B by at most m_B from a common translation u, the distance of any two of their features
  changed by at most m_A + m_B. Per call, with each body's shift (its nodes' mean displacement)
  and spread (the largest distance of a node's displacement from that shift), u the mean of the
  two shifts: m_A + m_B = spread_A + spread_B + |shift_A - shift_B|;
- these bounds add up over the calls since the grain pair's list was built (any sequence of
  positions: Newton iterates and rejected steps included); the list is rebuilt once the sum
  exceeds the skin. Grains that fall or flow together keep their lists;
- the build keeps a feature pair when a lower bound of its distance is within reach: the boxes
  and the slab of the search, then the distance to the face's plane (vertex-face), to the edge's
  line (vertex-edge), between the two edges (edge-edge) or between the vertices. Flat edges never
  make edge-edge records and are left out.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .broad import grain_boxes
from .pairs import (
    FLOAT_COLS,
    INT_COLS,
    _boxes_near,
    _compact,
    _point_near_box,
    ee_record,
    feature_box,
    near_features,
    ve_record,
    vf_record,
    vv_record,
)
from .topology import FLAT

# The build's filters compare with reach (1 + BUILD_MARGIN): far above their round-off (1e-10
# relative at the conditioning _segments_gap allows), far below the skin
BUILD_MARGIN = 1e-6
# entry codes, in the order the search visits the kinds
VF_A, VF_B, EE, VE_A, VE_B, VV = 0, 1, 2, 3, 4, 5


@njit(cache=True)
def _plane_gap(x, p, f, faces):
    """|distance from vertex p to the plane of face f|: at most its distance to the face (0 for a
    degenerate face: no bound). Scalars throughout: numba allocates every array difference."""
    i0, i1, i2 = faces[f, 0], faces[f, 1], faces[f, 2]
    e10, e11, e12 = x[i1, 0] - x[i0, 0], x[i1, 1] - x[i0, 1], x[i1, 2] - x[i0, 2]
    e20, e21, e22 = x[i2, 0] - x[i0, 0], x[i2, 1] - x[i0, 1], x[i2, 2] - x[i0, 2]
    n0 = e11 * e22 - e12 * e21
    n1 = e12 * e20 - e10 * e22
    n2 = e10 * e21 - e11 * e20
    nn = np.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
    if nn == 0.0:
        return 0.0
    return abs((x[p, 0] - x[i0, 0]) * n0 + (x[p, 1] - x[i0, 1]) * n1 + (x[p, 2] - x[i0, 2]) * n2) / nn


@njit(cache=True)
def _line_gap(x, p, e, edges):
    """Distance from vertex p to the line of edge e: at most its distance to the edge."""
    i0, i1 = edges[e, 0], edges[e, 1]
    d0, d1, d2 = x[i1, 0] - x[i0, 0], x[i1, 1] - x[i0, 1], x[i1, 2] - x[i0, 2]
    r0, r1, r2 = x[p, 0] - x[i0, 0], x[p, 1] - x[i0, 1], x[p, 2] - x[i0, 2]
    dd = d0 * d0 + d1 * d1 + d2 * d2
    if dd == 0.0:
        return 0.0
    c0, c1, c2 = r1 * d2 - r2 * d1, r2 * d0 - r0 * d2, r0 * d1 - r1 * d0
    return np.sqrt((c0 * c0 + c1 * c1 + c2 * c2) / dd)


@njit(cache=True)
def _point_segment(x, p, i0, i1):
    """Distance from node p to the segment (i0, i1)."""
    d0, d1, d2 = x[i1, 0] - x[i0, 0], x[i1, 1] - x[i0, 1], x[i1, 2] - x[i0, 2]
    r0, r1, r2 = x[p, 0] - x[i0, 0], x[p, 1] - x[i0, 1], x[p, 2] - x[i0, 2]
    dd = d0 * d0 + d1 * d1 + d2 * d2
    t = min(max((r0 * d0 + r1 * d1 + r2 * d2) / dd, 0.0), 1.0) if dd > 0.0 else 0.0
    g0, g1, g2 = r0 - t * d0, r1 - t * d1, r2 - t * d2
    return np.sqrt(g0 * g0 + g1 * g1 + g2 * g2)


@njit(cache=True)
def _segments_gap(x, ea, eb, edges):
    """A lower bound of the distance between edges ea and eb, within round-off of it: the clamped
    closest points of two segments (Ericson, Real-Time Collision Detection, 5.1.9), on scalars.
    Near parallel (sin^2 of the angle below 1e-6) those points are ill-conditioned and their
    distance may exceed the true one; there the closest endpoint-to-segment distance, less what
    turning one edge parallel to the other moves its points (2 L sin), bounds it from below."""
    p1, q1, p2, q2 = edges[ea, 0], edges[ea, 1], edges[eb, 0], edges[eb, 1]
    u0, u1, u2 = x[q1, 0] - x[p1, 0], x[q1, 1] - x[p1, 1], x[q1, 2] - x[p1, 2]
    v0, v1, v2 = x[q2, 0] - x[p2, 0], x[q2, 1] - x[p2, 1], x[q2, 2] - x[p2, 2]
    r0, r1, r2 = x[p1, 0] - x[p2, 0], x[p1, 1] - x[p2, 1], x[p1, 2] - x[p2, 2]
    a = u0 * u0 + u1 * u1 + u2 * u2
    e = v0 * v0 + v1 * v1 + v2 * v2
    if a == 0.0 or e == 0.0:
        return 0.0  # a degenerate edge: no bound
    b = u0 * v0 + u1 * v1 + u2 * v2
    denom = a * e - b * b
    if denom <= 1e-6 * a * e:
        ends = min(min(_point_segment(x, p1, p2, q2), _point_segment(x, q1, p2, q2)),
                   min(_point_segment(x, p2, p1, q1), _point_segment(x, q2, p1, q1)))  # fmt: skip
        turn = 2.0 * np.sqrt(max(denom, 0.0) / (a * e)) * (np.sqrt(a) + np.sqrt(e))
        return max(ends - turn, 0.0)
    f = v0 * r0 + v1 * r1 + v2 * r2
    c = u0 * r0 + u1 * r1 + u2 * r2
    s = min(max((b * f - c * e) / denom, 0.0), 1.0)
    t = (b * s + f) / e
    if t < 0.0:
        t, s = 0.0, min(max(-c / a, 0.0), 1.0)
    elif t > 1.0:
        t, s = 1.0, min(max((b - c) / a, 0.0), 1.0)
    g0, g1, g2 = r0 + s * u0 - t * v0, r1 + s * u1 - t * v1, r2 + s * u2 - t * v2
    return np.sqrt(g0 * g0 + g1 * g1 + g2 * g2)


@njit(cache=True)
def _entry(out, n, code, a, b):
    if n < len(out):
        out[n, 0] = code
        out[n, 1] = a
        out[n, 2] = b
    return n + 1


@njit(cache=True)
def pair_entries(x, A, B, reach, vptr, fptr, eptr, faces, edges, edge_type, v_face_ptr, v_faces, v_edge_ptr, v_edges,
                 glo, ghi, fbox, ebox, out):  # fmt: skip
    """Fill out (capacity = len(out)) with the feature pairs of grains A and B that may be within
    reach, in the search's order; returns their number (more than the capacity: the caller retries)."""
    n = np.int64(0)
    reach = reach * (1.0 + BUILD_MARGIN)
    vA, fA, eA, vB, fB, eB = near_features(x, A, B, reach, vptr, fptr, eptr, v_face_ptr, v_faces, v_edge_ptr,
                                           v_edges, glo, ghi, fbox, ebox)  # fmt: skip
    for side in range(2):
        verts, fcs = (vA, fB) if side == 0 else (vB, fA)
        for p in verts:
            for f in fcs:
                if _point_near_box(x, p, fbox, f, reach) and _plane_gap(x, p, f, faces) <= reach:
                    n = _entry(out, n, np.int64(VF_A + side), p, f)
    for ea in eA:
        if edge_type[ea] == FLAT:
            continue
        for eb in eB:
            if edge_type[eb] != FLAT and _boxes_near(ebox, ea, eb, reach) and _segments_gap(x, ea, eb, edges) <= reach:
                n = _entry(out, n, np.int64(EE), ea, eb)
    for side in range(2):
        verts, eds = (vA, eB) if side == 0 else (vB, eA)
        for p in verts:
            for e in eds:
                if _point_near_box(x, p, ebox, e, reach) and _line_gap(x, p, e, edges) <= reach:
                    n = _entry(out, n, np.int64(VE_A + side), p, e)
    for p in vA:
        for q in vB:
            d2 = (x[p, 0] - x[q, 0]) ** 2 + (x[p, 1] - x[q, 1]) ** 2 + (x[p, 2] - x[q, 2]) ** 2
            if d2 <= reach * reach:
                n = _entry(out, n, np.int64(VV), p, q)
    return n


@njit(parallel=True, cache=True)
def _build(x, grain_pairs, which, reach, vptr, fptr, eptr, faces, edges, edge_type, v_face_ptr, v_faces, v_edge_ptr,
           v_edges, glo, ghi, fbox, ebox, cap, out, counts):  # fmt: skip
    for j in prange(len(which)):
        k = which[j]
        counts[j] = pair_entries(x, grain_pairs[k, 0], grain_pairs[k, 1], reach, vptr, fptr, eptr, faces, edges,
                                 edge_type, v_face_ptr, v_faces, v_edge_ptr, v_edges, glo, ghi, fbox, ebox,
                                 out[j * cap : (j + 1) * cap])  # fmt: skip


@njit(cache=True)
def entry_records(x, A, B, entries, start, stop, gbar, faces, edges, edge_faces, edge_type, v_face_ptr, v_faces,
                  v_edge_ptr, v_edges, ints, floats):  # fmt: skip
    """The records of the entries start..stop of grain pair (A, B): the search's exact tests."""
    cap = len(ints)
    n = np.int64(0)
    for k in range(start, stop):
        code, a, b = entries[k, 0], entries[k, 1], entries[k, 2]
        if code == VF_A:
            n = vf_record(x, a, b, A, B, faces, gbar, ints, floats, n, cap)
        elif code == VF_B:
            n = vf_record(x, a, b, B, A, faces, gbar, ints, floats, n, cap)
        elif code == EE:
            n = ee_record(x, a, b, A, B, edges, edge_type, gbar, ints, floats, n, cap)
        elif code == VE_A:
            n = ve_record(x, a, b, A, B, faces, edges, edge_faces, edge_type, gbar, ints, floats, n, cap)
        elif code == VE_B:
            n = ve_record(x, a, b, B, A, faces, edges, edge_faces, edge_type, gbar, ints, floats, n, cap)
        else:
            n = vv_record(x, a, b, A, B, faces, edges, v_face_ptr, v_faces, v_edge_ptr, v_edges, gbar, ints, floats, n,
                          cap)  # fmt: skip
    return n


@njit(parallel=True, cache=True)
def _records(x, grain_pairs, ptr, entries, gbar, faces, edges, edge_faces, edge_type, v_face_ptr, v_faces, v_edge_ptr,
             v_edges, cap, ints, floats, counts):  # fmt: skip
    for k in prange(len(grain_pairs)):
        counts[k] = entry_records(x, grain_pairs[k, 0], grain_pairs[k, 1], entries, ptr[k], ptr[k + 1], gbar, faces,
                                  edges, edge_faces, edge_type, v_face_ptr, v_faces, v_edge_ptr, v_edges,
                                  ints[k * cap : (k + 1) * cap], floats[k * cap : (k + 1) * cap])  # fmt: skip


@njit(cache=True)
def _body_moves(x, x_last, vptr, shift, spread):
    """Each body's move since x_last: shift[g] its nodes' mean displacement, spread[g] the largest
    distance of a node's displacement from it (turning, deforming); x_last <- x."""
    for g in range(len(vptr) - 1):
        n = vptr[g + 1] - vptr[g]
        for a in range(3):
            shift[g, a] = 0.0
        for i in range(vptr[g], vptr[g + 1]):
            for a in range(3):
                shift[g, a] += (x[i, a] - x_last[i, a]) / n
        most = 0.0
        for i in range(vptr[g], vptr[g + 1]):
            d = 0.0
            for a in range(3):
                r = x[i, a] - x_last[i, a] - shift[g, a]
                d += r * r
                x_last[i, a] = x[i, a]
            most = max(most, d)
        spread[g] = np.sqrt(most)


@njit(cache=True)
def _add_relative_moves(keys, n_bodies, shift, spread, used):
    """used[k] += a bound on how much any distance between the two bodies of pair k changed: with u
    the mean of their shifts, every node of A moved by at most spread_A + |shift_A - shift_B| / 2
    from u, and the same for B (distances do not change under the common translation u)."""
    for k in range(len(keys)):
        A, B = keys[k] // n_bodies, keys[k] % n_bodies
        d = 0.0
        for a in range(3):
            d += (shift[A, a] - shift[B, a]) ** 2
        used[k] += spread[A] + spread[B] + np.sqrt(d)


@njit(parallel=True, cache=True)
def _feature_boxes_of(x, nodes, body_ptr, bodies):
    """pairs.feature_boxes for the features of the given bodies only (the other rows are left
    unset): a build touches a few grains, and all boxes were a third of its time."""
    out = np.empty((len(nodes), 6))
    for j in prange(len(bodies)):
        for k in range(body_ptr[bodies[j]], body_ptr[bodies[j] + 1]):
            feature_box(x, nodes, k, out)
    return out


@njit(cache=True)
def _merge(old_ptr, old_entries, slot, built, built_counts, cap, stale_rank):
    """(ptr, entries) for the current grain pairs: a kept pair's entries from the old list, a
    rebuilt one's (stale_rank[k] = j >= 0) from slot j of the build (rows j cap onwards)."""
    m = len(slot)
    ptr = np.zeros(m + 1, dtype=np.int64)
    for k in range(m):
        j = stale_rank[k]
        size = built_counts[j] if j >= 0 else old_ptr[slot[k] + 1] - old_ptr[slot[k]]
        ptr[k + 1] = ptr[k] + size
    entries = np.empty((ptr[m], 3), dtype=np.int64)
    for k in range(m):
        j = stale_rank[k]
        src, start = (built, j * cap) if j >= 0 else (old_entries, old_ptr[slot[k]])
        for r in range(ptr[k + 1] - ptr[k]):
            for c in range(3):
                entries[ptr[k] + r, c] = src[start + r, c]
    return ptr, entries


class FeatureList:
    """The feature pairs of every candidate grain pair within gbar + skin, kept across calls
    (module docstring). One per contact model; `find` answers as pairs.find_contacts does."""

    def __init__(self, skin: float):
        if not skin > 0:
            raise ValueError(f"feature list skin must be > 0, got {skin}")
        self.skin = float(skin)
        self.builds = 0  # grain-pair lists built so far (benchmarks read it)
        self._last = None  # node positions at the last call

    def find(self, x: np.ndarray, grain_pairs: np.ndarray, topo, gbar: float, capacity: int = 32):
        """(ints, floats): the records find_contacts(x, grain_pairs, topo, gbar) returns."""
        grain_pairs = np.ascontiguousarray(grain_pairs, dtype=np.int64).reshape(-1, 2)
        x = np.ascontiguousarray(x, dtype=np.float64)
        vptr = topo.grain_vertex_ptr
        n_bodies = len(vptr) - 1
        if self._last is None or self._last.shape != x.shape or self._gbar != gbar:
            self._reset(x, n_bodies, gbar)
        else:
            _body_moves(x, self._last, vptr, self._shift, self._spread)
            _add_relative_moves(self._keys, n_bodies, self._shift, self._spread, self._used)
        keys = grain_pairs[:, 0] * n_bodies + grain_pairs[:, 1]
        slot = self._slots(keys)
        stale = np.flatnonzero((slot < 0) | (self._used[np.maximum(slot, 0)] > self.skin))
        if len(stale) or not np.array_equal(keys, self._keys):
            self._update(x, grain_pairs, keys, slot, stale, topo, gbar + self.skin)
        return self._records(x, grain_pairs, topo, gbar, capacity)

    def _reset(self, x, n_bodies, gbar):
        self._last = x.copy()
        self._gbar = gbar
        self._shift = np.zeros((n_bodies, 3))
        self._spread = np.zeros(n_bodies)
        self._keys = np.zeros(0, np.int64)  # grain pairs of the list (A n_bodies + B), in their order
        self._sorted = np.zeros(0, np.int64)  # argsort of _keys
        self._used = np.zeros(1)  # each pair's bound on its bodies' relative move since its list was built
        self._ptr = np.zeros(1, np.int64)
        self._entries = np.zeros((0, 3), np.int64)

    def _slots(self, keys):
        """Row of each key in the current list, -1 where it has none."""
        if len(self._keys) == 0:
            return np.full(len(keys), -1, np.int64)
        ordered = self._keys[self._sorted]
        pos = np.minimum(np.searchsorted(ordered, keys), len(ordered) - 1)
        return np.where(ordered[pos] == keys, self._sorted[pos], -1)

    def _update(self, x, grain_pairs, keys, slot, stale, topo, reach):
        built, built_counts, cap = self._build(x, grain_pairs, stale, topo, reach)
        stale_rank = np.full(len(keys), -1, np.int64)
        stale_rank[stale] = np.arange(len(stale))
        self._ptr, self._entries = _merge(self._ptr, self._entries, slot, built, built_counts, cap, stale_rank)
        used = self._used[np.maximum(slot, 0)]
        used[stale] = 0.0
        self._used = used if len(used) else np.zeros(1)
        self._keys = keys.copy()
        self._sorted = np.argsort(keys, kind="stable")
        self.builds += len(stale)

    def _build(self, x, grain_pairs, stale, topo, reach, capacity=64):
        """(out, counts, capacity): the entries of stale pair j in rows j capacity onwards of out."""
        if len(stale) == 0:
            return np.zeros((0, 3), np.int64), np.zeros(0, np.int64), capacity
        glo, ghi = grain_boxes(x, topo.grain_vertex_ptr, 0.0)
        bodies = np.unique(grain_pairs[stale])  # only their features' boxes are read
        fbox = _feature_boxes_of(x, topo.faces, topo.grain_face_ptr, bodies)
        ebox = _feature_boxes_of(x, topo.edges, topo.grain_edge_ptr, bodies)
        while True:
            out = np.empty((len(stale) * capacity, 3), np.int64)
            counts = np.zeros(len(stale), np.int64)
            _build(x, grain_pairs, stale, reach, topo.grain_vertex_ptr, topo.grain_face_ptr, topo.grain_edge_ptr,
                   topo.faces, topo.edges, topo.edge_type, topo.vertex_face_ptr, topo.vertex_faces,
                   topo.vertex_edge_ptr, topo.vertex_edges, glo, ghi, fbox, ebox, capacity, out, counts)  # fmt: skip
            if counts.max() <= capacity:
                break
            capacity = int(counts.max())
        return out, counts, capacity

    def _records(self, x, grain_pairs, topo, gbar, capacity):
        while True:
            m = len(grain_pairs)
            ints = np.empty((m * capacity, INT_COLS), dtype=np.int64)
            floats = np.empty((m * capacity, FLOAT_COLS))
            counts = np.zeros(m, dtype=np.int64)
            _records(x, grain_pairs, self._ptr, self._entries, gbar, topo.faces, topo.edges, topo.edge_faces,
                     topo.edge_type, topo.vertex_face_ptr, topo.vertex_faces, topo.vertex_edge_ptr, topo.vertex_edges,
                     capacity, ints, floats, counts)  # fmt: skip
            if m == 0 or counts.max() <= capacity:
                break
            capacity = int(counts.max())
        return _compact(ints, floats, counts, capacity)
