"""The rigid modes of every grain: the grain-block coarse space (grain_block.py) and the reference
modes of the Woodbury path (woodbury.py)."""

import numpy as np
from numba import njit, prange


@njit(cache=True, parallel=True)
def _rigid_modes(x, vertex_ptr, z):
    for g in prange(len(vertex_ptr) - 1):
        lo, hi = vertex_ptr[g], vertex_ptr[g + 1]
        c = np.zeros(3)
        for i in range(lo, hi):
            c += x[i]
        c /= hi - lo
        ss = 0.0
        for i in range(lo, hi):
            ss += np.sum((x[i] - c) ** 2)
        size = max(np.sqrt(ss / (hi - lo)), 1e-300)
        for i in range(lo, hi):
            r = (x[i] - c) / size
            for k in range(3):
                row = 3 * i + k
                for m in range(6):
                    z[row, m] = 0.0
                z[row, k] = 1.0
            # e_m x r for m = 0, 1, 2 in the columns 3 + m
            z[3 * i + 1, 3] = r[2]
            z[3 * i + 2, 3] = -r[1]
            z[3 * i + 0, 4] = -r[2]
            z[3 * i + 2, 4] = r[0]
            z[3 * i + 0, 5] = r[1]
            z[3 * i + 1, 5] = -r[0]


def rigid_modes(x: np.ndarray, vertex_ptr: np.ndarray) -> np.ndarray:
    """(3N, 6) rows of Z: translations and rotations (scaled by the grain's size) about each
    grain's vertex average, dof 3 v + i."""
    x = np.ascontiguousarray(x, float)
    z = np.empty((3 * len(x), 6))
    _rigid_modes(x, np.asarray(vertex_ptr, np.int64), z)
    return z
