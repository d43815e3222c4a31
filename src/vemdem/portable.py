"""One set of kernels on every x86-64 machine, so that a config and a seed give the same run on
any of them (docs/errors.md, "Reproducible across machines").

Two kinds of compiled code follow the CPU unless told otherwise, and both round differently in
the last bit from one CPU to another; every run of grains is chaotic, so a last-bit difference
ends in another heap of the same statistics:
- OpenBLAS, behind NumPy and SciPy, picks its kernels when it loads: AVX-512 ones on a recent
  Intel Xeon, AVX2 ones ("Haswell") on an AMD EPYC or an older Intel. The main job's 160 grains
  (the README) left 27.9 +- 7.7 deg with an AVX-512 Xeon's own kernels and 21.6 +- 3.2 deg with
  the Haswell ones, the run of the EPYC where the docs' figures were measured (its angle,
  uncertainty and 17,177 steps);
- numba compiles for the host CPU. Its kernels without fast-math gave the same bits for the
  host and a generic CPU, but the linear solvers' fast-math kernels (summed rows, reassociated
  to the vector width) did not: an implicit 40-grain pack parted at round-off.

`pin_kernels` runs when vemdem is imported, before NumPy loads OpenBLAS and numba reads its
configuration (the command line, and a local sweep's Dask workers, which inherit the variables).
On x86-64 Linux machines whose CPU has AVX2, FMA and the rest of Haswell's features
(HASWELL_FLAGS) it sets OPENBLAS_CORETYPE=Haswell and NUMBA_CPU_NAME=haswell with the features
that name implies (NUMBA_CPU_FEATURES empty), each only where the user set neither that variable
nor VEMDEM_NATIVE=1 (the machine's own kernels). Measured cost: none beyond the noise
(docs/errors.md). This module imports nothing that loads NumPy.
"""

from __future__ import annotations

import os
import platform
import sys

OPENBLAS_CORE = "Haswell"
NUMBA_CPU = "haswell"


def _cpu_flags() -> set[str]:
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as f:
            for line in f:
                if line.startswith("flags"):
                    return set(line.split(":", 1)[1].split())
    except OSError:
        pass
    return set()


# what code for the "haswell" target may use (LLVM's x86-64-v3 and Haswell's extras; Linux's flag
# names): a virtual machine that hides one of them gets the native kernels, never an illegal instruction
HASWELL_FLAGS = frozenset({"avx", "avx2", "fma", "f16c", "bmi1", "bmi2", "abm", "movbe", "popcnt", "sse4_1", "sse4_2",
                           "ssse3", "cx16", "lahf_lm", "pclmulqdq"})  # fmt: skip


def portable_machine() -> bool:
    """x86-64 Linux whose CPU has every feature of the Haswell kernels."""
    x86 = platform.machine().lower() in ("x86_64", "amd64") and sys.platform.startswith("linux")
    return x86 and HASWELL_FLAGS <= _cpu_flags()


_SENTINEL = "VEMDEM_PINNED"  # which of the variables vemdem itself set (children inherit it)


def _mark(library: str) -> None:
    marks = [m for m in os.environ.get(_SENTINEL, "").split(",") if m]
    os.environ[_SENTINEL] = ",".join(sorted({*marks, library}))


def _pin_one(library: str, settings: dict, label: str, user_vars: tuple, loaded: dict, inherited: list) -> str:
    """Pin one library's variables (`settings`) unless the user set one of `user_vars` or a module of
    `loaded` (module name -> the name said) was imported already; returns what was done."""
    if library in inherited and all(os.environ.get(k) == v for k, v in settings.items()):
        return f"{library} pinned ({label})"  # a child of a pinned process (a local sweep's Dask workers)
    if any(v in os.environ for v in user_vars):
        return f"{library} set by the user ({os.environ.get(user_vars[0], 'host')})"
    early = [shown for module, shown in loaded.items() if module in sys.modules]
    if early:
        return f"{library} native ({early[0]} was imported before vemdem)"
    os.environ.update(settings)
    _mark(library)
    return f"{library} pinned ({label})"


def pin_kernels() -> str:
    """Set the variables where that is safe and still in time; returns what was done, per library."""
    if os.environ.get("VEMDEM_NATIVE") == "1":
        return "native: VEMDEM_NATIVE=1"
    if not portable_machine():
        return "native: not x86-64 Linux with the Haswell features (AVX2, FMA, ...)"
    inherited = os.environ.get(_SENTINEL, "").split(",")
    openblas = _pin_one("openblas", {"OPENBLAS_CORETYPE": OPENBLAS_CORE}, OPENBLAS_CORE, ("OPENBLAS_CORETYPE",),
                        {"numpy": "NumPy", "scipy": "NumPy"}, inherited)  # fmt: skip
    # NUMBA_CPU_FEATURES empty: the named CPU's own features, not the host's
    numba = _pin_one("numba", {"NUMBA_CPU_NAME": NUMBA_CPU, "NUMBA_CPU_FEATURES": ""}, NUMBA_CPU,
                     ("NUMBA_CPU_NAME", "NUMBA_CPU_FEATURES"), {"numba": "numba"}, inherited)  # fmt: skip
    return f"{openblas}, {numba}"


PINNED = pin_kernels()


def kernels() -> dict:
    """What the run rounds with: OpenBLAS's kernels (threadpoolctl's "architecture" for NumPy's and
    SciPy's libraries), numba's target CPU, and why (PINNED). For summary.json, so that two runs
    that differ can be told apart by it."""
    import llvmlite.binding  # noqa: PLC0415
    import numba  # noqa: PLC0415 (loaded by any run before this is asked)
    import numpy  # noqa: F401, PLC0415 (the libraries must be loaded to be listed)
    import scipy.linalg  # noqa: F401, PLC0415 (SciPy's own OpenBLAS, which numba's kernels call too)
    from threadpoolctl import threadpool_info  # noqa: PLC0415

    cores = sorted({str(lib.get("architecture")) for lib in threadpool_info() if lib.get("internal_api") == "openblas"})
    target = numba.config.CPU_NAME or f"host ({llvmlite.binding.get_host_cpu_name()})"
    return {"openblas": ",".join(cores) or None, "numba_cpu": target, "choice": PINNED}
