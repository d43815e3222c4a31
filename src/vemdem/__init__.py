"""vemdem: granular media of flexible polyhedral grains (one virtual element per grain)."""

# first, before anything loads NumPy or numba: one set of kernels on every x86-64 machine (portable.py)
from . import portable  # noqa: F401
