"""LAPACK's dgetrf for compiled kernels (the grain blocks' LU and the Woodbury path's S)."""

from numba import types

# LAPACK's dgetrf, through numba's own wrapper (the one behind np.linalg.inv in compiled code):
# a C symbol resolved by name, so the kernels that call it stay cacheable (a ctypes pointer would
# not be). The wrapper fetches the LAPACK routine under the GIL on its first call, so the kernel
# makes one call on the calling thread before its parallel loop (a worker thread asking for the
# GIL the caller holds would wait for ever).
_GETRF = types.ExternalFunction(
    "numba_xxgetrf",
    types.intc(types.char, types.intp, types.intp, types.CPointer(types.float64), types.intp,
               types.CPointer(types.int32)),
)  # fmt: skip
_DOUBLE = ord("d")
