"""Element evaluation cost: energy, energy+force, energy+force+tangent and sparse assembly, batched.

    python benchmarks/bench_elements.py [--grains 515] [--repeat 10] [--seed 0] [--skip-compile]

The scene: `--grains` random sand grains (1.45 mm, 20-40 vertices, E 90 GPa, nu 0.16, rho 2200,
beta_i 0.5, automatic sub-mesh = the fan on these convex grains) in a random deformed state:
a homogeneous stretch of a few per cent (random symmetric F, |F - I| <= 3 %) plus small random
vertex displacements (0.2 % of the grain size); every piece has J > 0.

Printed: set-up time (build_elements, build_mass), the one-off numba compilation time (measured
in a fresh process with an empty cache; skip it with --skip-compile), then for each kind of call
the best of `--repeat` wall times, calls per second and grain evaluations per second with one
numba thread and with the default number of threads (alternating within each repetition), and the
parallel speed-up. Timings on a shared machine are only as good as its quietest moment: the best
of several repetitions is reported, the load average is printed before and after, and a trivially
parallel compute loop is timed alongside: its speed-up is the most the machine gave at that moment
(on a virtual machine whose second core is shared it can be well below the core count). No figure is asserted anywhere: this is a measurement, not a test.
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import tempfile
import time

import numba
import numpy as np
from numba import njit, prange

from vemdem.geometry import sand_grain
from vemdem.vem.element import VemOptions, build_elements, evaluate, tangent_matrix
from vemdem.vem.mass import build_mass
from vemdem.vem.material import Material

MATERIAL = Material(90e9, 0.16, 2200.0)
SIZE = 1.45e-3


def make_grains(n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    counts = rng.integers(20, 41, size=n)
    return [sand_grain(size=SIZE, n_vertices=int(counts[i]), seed=i) for i in range(n)]


def deformed_state(elements, seed: int = 0, stretch: float = 0.03, noise: float = 2e-3) -> np.ndarray:
    """x = F X + small random displacements, F = I + symmetric random of entries <= `stretch`."""
    rng = np.random.default_rng(seed + 1)
    E = rng.uniform(-stretch, stretch, size=(3, 3))
    F = np.eye(3) + 0.5 * (E + E.T)
    X = elements.reference
    return X @ F.T + rng.normal(scale=noise * SIZE, size=X.shape)


COLD_COMPILE = """
import time
from vemdem.geometry import sand_grain
from vemdem.vem.element import VemOptions, build_elements, evaluate
from vemdem.vem.material import Material
el = build_elements([sand_grain(seed=1)], Material(90e9, 0.16, 2200.0), VemOptions(beta_internal=0.5))
t = time.perf_counter()
evaluate(el, el.reference, force=True, tangent=True)
print(time.perf_counter() - t)
"""


def cold_compile_time() -> float:
    """First call of the element kernels in a fresh process with an empty numba cache."""
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        out = subprocess.run([sys.executable, "-c", COLD_COMPILE], env=env, check=True, capture_output=True, text=True)
    return float(out.stdout.split()[-1])


def best_time(fn, repeat: int):
    best = np.inf
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return best


@njit(parallel=True, cache=True)
def _reference_loop(n):
    """Trivially parallel, compute-bound: its speed-up is what the machine gives right now."""
    out = np.zeros(64)
    for t in prange(64):
        s = 0.0
        for i in range(n):
            s += np.sin(i * 1e-3 + t)
        out[t] = s
    return out


def time_calls(elements, x, repeat: int, thread_counts) -> dict:
    """Best wall time of each call for each thread count. The thread counts alternate within every
    repetition, so a burst of load from elsewhere on the machine hits them alike."""
    blocks = evaluate(elements, x, force=True, tangent=True).blocks
    calls = {
        "energy": lambda: evaluate(elements, x, force=False, tangent=False),
        "energy+force": lambda: evaluate(elements, x, force=True, tangent=False),
        "energy+force+tangent": lambda: evaluate(elements, x, force=True, tangent=True),
        "sparse assembly (tangent_matrix)": lambda: tangent_matrix(elements, blocks),
        "reference: trivially parallel loop": lambda: _reference_loop(20000),
    }
    _reference_loop(10)
    best = {t: dict.fromkeys(calls, np.inf) for t in thread_counts}
    for _ in range(repeat):
        for threads in thread_counts:
            numba.set_num_threads(threads)
            for name, fn in calls.items():
                best[threads][name] = min(best[threads][name], best_time(fn, 1))
    return best


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--grains", type=int, default=515, help="number of grains (default 515)")
    p.add_argument("--repeat", type=int, default=10, help="timed repetitions, best is reported (default 10)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--skip-compile", action="store_true", help="do not measure compilation from an empty cache")
    args = p.parse_args(argv)

    default_threads = numba.get_num_threads()
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"element benchmark: {args.grains} grains, best of {args.repeat}, "
          f"{os.cpu_count()} cores, numba {numba.__version__} ({default_threads} threads by default), "
          f"{platform.processor() or platform.machine()}, load average {load:.2f}")  # fmt: skip

    t = time.perf_counter()
    grains = make_grains(args.grains, args.seed)
    t_shapes = time.perf_counter() - t
    t = time.perf_counter()
    elements = build_elements(grains, MATERIAL, VemOptions(beta_internal=0.5))
    t_elements = time.perf_counter() - t
    t = time.perf_counter()
    build_mass(grains, elements, MATERIAL.density)
    t_mass = time.perf_counter() - t
    n_v = elements.n_vertices
    n_pieces = len(elements.piece_weight)
    print(f"scene: {elements.n_grains} grains, {n_v} vertices ({3 * n_v} dofs), {n_pieces} pieces "
          f"(projection + sub-tetrahedra), {elements.block_ptr[-1]:,} tangent-block entries")  # fmt: skip
    print(f"set-up: shapes {t_shapes:.3f} s, build_elements {t_elements:.3f} s, build_mass {t_mass:.3f} s")

    x = deformed_state(elements, args.seed)
    # compilation (or loading numba's on-disk cache) of every kernel variant, excluded from the timings
    t = time.perf_counter()
    ev = evaluate(elements, x, force=True, tangent=True)
    evaluate(elements, x, force=False, tangent=False)
    t_compile = time.perf_counter() - t
    t = time.perf_counter()
    tangent_matrix(elements, ev.blocks)
    t_structure = time.perf_counter() - t
    print(f"warm-up in this process (numba cache load or compilation, excluded below): {t_compile:.3f} s")
    print(f"first tangent_matrix call (builds the cached CSR structure, excluded below): {t_structure:.3f} s")
    if not args.skip_compile:
        print(f"numba compilation of the element kernels from an empty cache (fresh process): {cold_compile_time():.1f} s")
    print(f"deformed state: total strain energy {ev.total_energy:.4e} J, all J > 0")

    results = time_calls(elements, x, args.repeat, sorted({1, default_threads}))
    numba.set_num_threads(default_threads)

    G = elements.n_grains
    print()
    print(f"{'call':34s} {'threads':>7s} {'ms/call':>9s} {'calls/s':>9s} {'grain-evals/s':>14s}")
    for threads, res in results.items():
        for name, sec in res.items():
            per_grain = "-" if name.startswith("reference") else f"{G / sec:,.0f}"
            print(f"{name:34s} {threads:7d} {sec * 1e3:9.2f} {1 / sec:9.1f} {per_grain:>14s}")
    if len(results) > 1:
        print()
        one, many = results[1], results[default_threads]
        for name in one:
            print(f"parallel speed-up {name:34s} {one[name] / many[name]:.2f}x on {default_threads} threads")
    if hasattr(os, "getloadavg"):
        print(f"load average after the timings: {os.getloadavg()[0]:.2f} (on {os.cpu_count()} cores)")
    res = results[default_threads]
    print(f"\nNewton-step element cost ({default_threads} threads): energy+force+tangent + assembly = "
          f"{(res['energy+force+tangent'] + res['sparse assembly (tangent_matrix)']) * 1e3:.1f} ms")  # fmt: skip


if __name__ == "__main__":
    main()
