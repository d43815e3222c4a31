"""Broad phase: candidate grain pairs in O(N) with a uniform grid (docs/contact.md).

Each grain's axis-aligned box, inflated by half the activation gap, goes into every grid cell
it overlaps. The cell size is the largest box extent, so a box touches at most 8 cells. Two
grains are a candidate when their boxes overlap; a pair is reported only by the cell that holds
the lower corner of the two boxes' intersection, so it is reported once.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange


@njit(parallel=True, cache=True)
def grain_boxes(x, vertex_ptr, inflate):
    G = len(vertex_ptr) - 1
    lo = np.empty((G, 3))
    hi = np.empty((G, 3))
    for g in prange(G):
        for a in range(3):
            mn = np.inf
            mx = -np.inf
            for v in range(vertex_ptr[g], vertex_ptr[g + 1]):
                mn = min(mn, x[v, a])
                mx = max(mx, x[v, a])
            lo[g, a] = mn - inflate
            hi[g, a] = mx + inflate
    return lo, hi


@njit(cache=True)
def _overlap(lo, hi, i, j):
    for a in range(3):
        if hi[i, a] < lo[j, a] or hi[j, a] < lo[i, a]:
            return False
    return True


@njit(cache=True)
def _cell_key(ix, iy, iz, dims):
    return (ix * dims[1] + iy) * dims[2] + iz


@njit(cache=True)
def _grid_entries(lo, hi, origin, cell, dims):
    G = len(lo)
    count = 0
    c0 = np.empty((G, 3), dtype=np.int64)
    c1 = np.empty((G, 3), dtype=np.int64)
    for g in range(G):
        n = 1
        for a in range(3):
            c0[g, a] = int((lo[g, a] - origin[a]) / cell)
            c1[g, a] = int((hi[g, a] - origin[a]) / cell)
            n *= c1[g, a] - c0[g, a] + 1
        count += n
    keys = np.empty(count, dtype=np.int64)
    owner = np.empty(count, dtype=np.int64)
    k = 0
    for g in range(G):
        for ix in range(c0[g, 0], c1[g, 0] + 1):
            for iy in range(c0[g, 1], c1[g, 1] + 1):
                for iz in range(c0[g, 2], c1[g, 2] + 1):
                    keys[k] = _cell_key(ix, iy, iz, dims)
                    owner[k] = g
                    k += 1
    return keys, owner


@njit(cache=True)
def _pairs_in_cells(keys, owner, lo, hi, origin, cell, dims, fill, out):
    """Count (fill=False) or write (fill=True) the candidate pairs; returns the count."""
    n = 0
    start = 0
    m = len(keys)
    while start < m:
        stop = start
        while stop < m and keys[stop] == keys[start]:
            stop += 1
        key = keys[start]
        for p in range(start, stop):
            i = owner[p]
            for q in range(p + 1, stop):
                j = owner[q]
                if not _overlap(lo, hi, i, j):
                    continue
                # report only from the cell holding the intersection's lower corner
                ix = int((max(lo[i, 0], lo[j, 0]) - origin[0]) / cell)
                iy = int((max(lo[i, 1], lo[j, 1]) - origin[1]) / cell)
                iz = int((max(lo[i, 2], lo[j, 2]) - origin[2]) / cell)
                if _cell_key(ix, iy, iz, dims) != key:
                    continue
                if fill:
                    out[n, 0] = min(i, j)
                    out[n, 1] = max(i, j)
                n += 1
        start = stop
    return n


def candidate_pairs(x: np.ndarray, vertex_ptr: np.ndarray, activation_gap: float) -> np.ndarray:
    """Sorted (k, 2) array of grain pairs whose boxes come within the activation gap."""
    lo, hi = grain_boxes(np.ascontiguousarray(x), vertex_ptr, 0.5 * activation_gap)
    if len(lo) < 2:
        return np.zeros((0, 2), dtype=np.int64)
    cell = float((hi - lo).max())
    origin = lo.min(axis=0)
    dims = np.floor((hi.max(axis=0) - origin) / cell).astype(np.int64) + 1
    keys, owner = _grid_entries(lo, hi, origin, cell, dims)
    order = np.argsort(keys, kind="stable")
    keys, owner = keys[order], owner[order]
    n = _pairs_in_cells(keys, owner, lo, hi, origin, cell, dims, False, np.empty((0, 2), dtype=np.int64))
    out = np.empty((n, 2), dtype=np.int64)
    _pairs_in_cells(keys, owner, lo, hi, origin, cell, dims, True, out)
    return out[np.lexsort((out[:, 1], out[:, 0]))]


def brute_force_pairs(x: np.ndarray, vertex_ptr: np.ndarray, activation_gap: float) -> np.ndarray:
    """All-pairs reference for tests (O(N^2))."""
    lo, hi = grain_boxes(np.ascontiguousarray(x), vertex_ptr, 0.5 * activation_gap)
    ok = np.all((hi[:, None, :] >= lo[None, :, :]) & (hi[None, :, :] >= lo[:, None, :]), axis=2)
    i, j = np.nonzero(np.triu(ok, k=1))
    return np.column_stack([i, j]).astype(np.int64)
