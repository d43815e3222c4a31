"""One set of BLAS kernels on every x86-64 machine, so that a config and a seed give the same
run on any of them (docs/errors.md, "Reproducible across machines").

OpenBLAS, behind NumPy and SciPy, picks its kernels when it loads: AVX-512 ones on a recent Intel
Xeon, AVX2 ones ("Haswell") on an AMD EPYC or an older Intel. They round differently in the last
bit, and every run of grains is chaotic: the main job's 160 grains (the README) left 27.9 +- 7.7
deg on an AVX-512 Xeon and 21.6 +- 3.2 deg on the EPYC where the docs' figures were measured;
with the Haswell kernels the Xeon gives the EPYC's run to the bit (grains.csv byte for byte), as
fast (docs/errors.md). Numba's own kernels are compiled without fast-math contractions and gave
the same bits for the host CPU and a generic one, so BLAS is the part to pin.

`pin_blas_kernels` runs when vemdem is imported, before NumPy loads OpenBLAS (the command line,
and the sweep's Dask workers, which inherit the variable). It sets OPENBLAS_CORETYPE=Haswell only
on x86-64 Linux machines whose CPU has AVX2 and FMA (the kernels need them) and only where the
user set neither OPENBLAS_CORETYPE nor VEMDEM_NATIVE_BLAS=1 (the machine's own kernels).
This module imports nothing that loads NumPy.
"""

from __future__ import annotations

import os
import platform
import sys

PORTABLE_CORE = "Haswell"


def _cpu_flags() -> set[str]:
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as f:
            for line in f:
                if line.startswith("flags"):
                    return set(line.split(":", 1)[1].split())
    except OSError:
        pass
    return set()


def pin_blas_kernels() -> str:
    """Set OPENBLAS_CORETYPE where that is safe and still in time; returns what was done."""
    if os.environ.get("VEMDEM_NATIVE_BLAS") == "1":
        return "native: VEMDEM_NATIVE_BLAS=1"
    if "OPENBLAS_CORETYPE" in os.environ:
        return f"set by the user: {os.environ['OPENBLAS_CORETYPE']}"
    if platform.machine().lower() not in ("x86_64", "amd64") or not sys.platform.startswith("linux"):
        return "native: not x86-64 Linux"
    if not {"avx2", "fma"} <= _cpu_flags():
        return "native: the CPU lacks AVX2 or FMA"
    if "numpy" in sys.modules:
        return "native: NumPy was imported before vemdem"
    os.environ["OPENBLAS_CORETYPE"] = PORTABLE_CORE
    return f"pinned: {PORTABLE_CORE}"


PINNED = pin_blas_kernels()


def blas_kernels() -> dict:
    """What the run's OpenBLAS libraries use ("architecture" per library, from threadpoolctl) and
    why (PINNED): for summary.json, so that two runs that differ can be told apart by it."""
    import numpy  # noqa: F401, PLC0415 (the libraries must be loaded to be listed)
    import scipy.linalg  # noqa: F401, PLC0415 (SciPy's own OpenBLAS, which numba's kernels call too)
    from threadpoolctl import threadpool_info  # noqa: PLC0415

    cores = sorted({str(lib.get("architecture")) for lib in threadpool_info() if lib.get("internal_api") == "openblas"})
    return {"architecture": ",".join(cores) or None, "choice": PINNED}
