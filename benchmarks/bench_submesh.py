"""Sub-mesh choice: critical explicit step, sliver ratio and implicit conditioning, fan vs Delaunay.

    python benchmarks/bench_submesh.py [--vertices 11 19 27 38] [--seeds 6] [--betas 0.1 0.5]

For sand grains (1.45 mm, E 90 GPa, nu 0.16, rho 2200 kg/m^3) of each vertex count and several
seeds, with the stabilisation sub-mesh built either as the fan from the vertex average ("fan",
one virtual apex slaved to u_Pi) or as the Delaunay tetrahedralisation of the hull vertices
("delaunay"), and the blend beta_i of eq. 8:

- critical explicit step dt_c = 2 / omega_max of the generalised eigenproblem K u = omega^2 M u
  at the undeformed state: K = the element tangent (`evaluate(..., tangent=True)` +
  `tangent_matrix`), M = the row-sum lumped mass (`build_mass(...).lumped`, repeated for x, y, z,
  beta_d = 1: sub-mesh mass), dense `scipy.linalg.eigh`;
- sliver measure: smallest / mean sub-tetrahedron volume;
- for one grain, the 2-norm condition number of the implicit Newmark matrix K + a1 M,
  a1 = 1 / (0.3 dt^2), dt = 1e-4 s, with the consistent and with the lumped mass.

The tables are printed as Markdown (docs/submesh.md holds a copy). Medians over the seeds, with
the range [min, max] where it matters; a seed whose Delaunay sub-mesh has a flat tetrahedron
(rejected by `check_submesh`) is counted and skipped.
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import time

import numpy as np
import scipy
import scipy.linalg

from vemdem.geometry import SubMeshError, build_submesh, sand_grain
from vemdem.geometry.submesh import augmented_points, signed_tet_volumes
from vemdem.vem.element import VemOptions, build_elements, evaluate, tangent_matrix
from vemdem.vem.mass import build_mass
from vemdem.vem.material import Material

MATERIAL = Material(90e9, 0.16, 2200.0)
SIZE = 1.45e-3
METHODS = ("delaunay", "fan")


def grain_matrices(grain, mesh, beta: float):
    """Dense tangent K (3n x 3n), lumped mass (3n,) and consistent mass (3n x 3n) at X."""
    el = build_elements([grain], MATERIAL, VemOptions(beta_internal=beta), submeshes=[mesh])
    ev = evaluate(el, el.reference, force=False, tangent=True)
    K = tangent_matrix(el, ev.blocks).toarray()
    mass = build_mass([grain], el, MATERIAL.density)
    return 0.5 * (K + K.T), np.repeat(mass.lumped, 3), mass.matrix().toarray()


def critical_step(K: np.ndarray, m_lumped: np.ndarray) -> float:
    """2 / omega_max of K u = omega^2 M u with diagonal M (eigenvalues of M^-1/2 K M^-1/2)."""
    s = 1.0 / np.sqrt(m_lumped)
    lam = scipy.linalg.eigh(s[:, None] * K * s[None, :], eigvals_only=True)
    return 2.0 / np.sqrt(lam[-1])


def sliver_ratio(grain, mesh) -> float:
    vol = signed_tet_volumes(augmented_points(grain, mesh), mesh.tets)
    return float(vol.min() / vol.mean())


def measure(vertex_counts, seeds: int, betas):
    """rows[(n, beta)][method] = list of (dt, sliver ratio) over the seeds; failures counted."""
    rows, failures = {}, {}
    for n in vertex_counts:
        for seed in range(seeds):
            grain = sand_grain(size=SIZE, n_vertices=n, seed=seed)
            meshes = {}
            for method in METHODS:
                try:
                    meshes[method] = build_submesh(grain, method)
                except SubMeshError:
                    failures[(n, method)] = failures.get((n, method), 0) + 1
            for beta in betas:
                for method, mesh in meshes.items():
                    K, m, _ = grain_matrices(grain, mesh, beta)
                    rows.setdefault((n, beta), {}).setdefault(method, []).append(
                        (critical_step(K, m), sliver_ratio(grain, mesh), len(mesh.tets), seed)
                    )
    return rows, failures


def print_tables(rows, failures, vertex_counts, betas):
    print("\n### Critical explicit step 2/omega_max (median over seeds, [min, max])\n")
    print("| vertices | beta_i | Delaunay dt_c (s) | fan dt_c (s) | fan / Delaunay, per seed: median [min, max] |")
    print("|---|---|---|---|---|")
    for n in vertex_counts:
        for beta in betas:
            r = rows[(n, beta)]
            d = {s: dt for dt, _, _, s in r.get("delaunay", [])}
            f = {s: dt for dt, _, _, s in r["fan"]}
            common = sorted(set(d) & set(f))
            ratio = np.array([f[s] / d[s] for s in common])
            dd, ff = np.array(list(d.values())), np.array(list(f.values()))
            print(f"| {n} | {beta} | {np.median(dd):.2g} [{dd.min():.2g}, {dd.max():.2g}] "
                  f"| {np.median(ff):.2g} [{ff.min():.2g}, {ff.max():.2g}] "
                  f"| {np.median(ratio):.1f} [{ratio.min():.1f}, {ratio.max():.1f}] |")  # fmt: skip
    print("\n### Slivers: smallest / mean sub-tetrahedron volume (median over seeds, [min, max])\n")
    print("| vertices | Delaunay tets | Delaunay min/mean | fan tets | fan min/mean |")
    print("|---|---|---|---|---|")
    beta = betas[0]
    for n in vertex_counts:
        r = rows[(n, beta)]
        cells = []
        for method in METHODS:
            vr = np.array([v for _, v, _, _ in r.get(method, [])])
            nt = np.array([t for _, _, t, _ in r.get(method, [])])
            cells.append(f"{int(np.median(nt))} | {np.median(vr):.1e} [{vr.min():.1e}, {vr.max():.1e}]")
        print(f"| {n} | " + " | ".join(cells) + " |")
    if failures:
        print("\nrejected sub-meshes (flat tetrahedron, check_submesh): "
              + ", ".join(f"{m} n={n}: {c}" for (n, m), c in sorted(failures.items())))  # fmt: skip


def print_conditioning(n: int, seed: int, beta: float, dt: float = 1e-4, newmark_beta: float = 0.3):
    grain = sand_grain(size=SIZE, n_vertices=n, seed=seed)
    a1 = 1.0 / (newmark_beta * dt**2)
    print(f"\n### Conditioning of K + a1 M (grain of {n} vertices, seed {seed}, beta_i {beta}, "
          f"a1 = 1/(0.3 dt^2) = {a1:.3g} s^-2 at dt = {dt:g} s)\n")  # fmt: skip
    print("| sub-mesh | cond(K + a1 M), consistent M | cond(K + a1 M), lumped M | cond(K) on the 3n - 6 elastic modes |")
    print("|---|---|---|---|")
    for method in METHODS:
        mesh = build_submesh(grain, method)
        K, m, Mc = grain_matrices(grain, mesh, beta)
        lam = np.linalg.eigvalsh(K)
        elastic = lam[6:]
        print(f"| {method} | {np.linalg.cond(K + a1 * Mc):.3g} | {np.linalg.cond(K + a1 * np.diag(m)):.3g} "
              f"| {elastic[-1] / elastic[0]:.3g} |")  # fmt: skip


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--vertices", type=int, nargs="+", default=[11, 19, 27, 38])
    p.add_argument("--seeds", type=int, default=8, help="grains (seeds 0..S-1) per vertex count")
    p.add_argument("--betas", type=float, nargs="+", default=[0.1, 0.5])
    p.add_argument("--cond-grain", type=int, nargs=2, default=[27, 0], metavar=("VERTICES", "SEED"))
    args = p.parse_args(argv)
    t0 = time.perf_counter()
    print(f"sub-mesh benchmark, {datetime.date.today()}, {os.cpu_count()} cores, "
          f"{platform.processor() or platform.machine()}, numpy {np.__version__}, scipy {scipy.__version__}")  # fmt: skip
    print(f"sand grains {SIZE * 1e3:g} mm, E {MATERIAL.E:.3g} Pa, nu {MATERIAL.nu}, rho {MATERIAL.density:g} kg/m^3, "
          f"{args.seeds} seeds per vertex count, lumped sub-mesh mass (beta_d = 1)")  # fmt: skip
    rows, failures = measure(args.vertices, args.seeds, args.betas)
    print_tables(rows, failures, args.vertices, args.betas)
    print_conditioning(*args.cond_grain, beta=args.betas[-1])
    print(f"\n({time.perf_counter() - t0:.1f} s)")


if __name__ == "__main__":
    main()
