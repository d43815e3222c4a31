"""One-element VEM against a refined tetrahedral FE model: single-grain plate compression.

    python benchmarks/fem_comparison.py            # full run (~15 min on 2 cores)
    python benchmarks/fem_comparison.py --quick    # one seed, coarser FE (~2 min)

Prints the FE refinement study and the table beta_i x strain -> VEM force, FE force,
relative error, and writes docs/fem_comparison.md and docs/img/fem_comparison.png
(--no-write to skip). Both models use the grain_compression scenario's boundary conditions
(vemdem.verification.fem_reference).
"""

from __future__ import annotations

import argparse
import os
import pickle
import platform
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

SIZE, N_VERTICES, TRUNCATE = 1.45e-3, 30, 0.7
E, NU = 90e9, 0.16
BETAS = (0.1, 0.25, 0.5)
STRAINS = np.round(np.arange(1, 9) * 0.025, 6)  # loaded steps 2.5 % ... 20 %
REPORTED = (0.05, 0.10, 0.20)
LEVELS = (3e-3, 1e-3, 3e-4, 1e-4)  # max tet volume / grain volume, graded family
UNIFORM_LEVELS = (1e-3, 3e-4, 1e-4)  # ungraded TetGen meshes, refinement study only


def grain_of(seed):
    from vemdem.geometry import sand_grain

    return sand_grain(size=SIZE, n_vertices=N_VERTICES, seed=seed, truncate=TRUNCATE)


def material():
    from vemdem.vem.material import Material

    return Material(E, NU, 2200.0)


def _init_worker():
    import numba

    numba.set_num_threads(1)  # one process per core; the sparse solve is serial anyway


def fem_task(args):
    """One FE compression; if Newton fails, retry with the load steps halved."""
    seed, mode, level, graded = args
    from vemdem.verification.fem_reference import run_fem
    from vemdem.solver.statics import NewtonDivergedError

    grain = grain_of(seed)
    strains = STRAINS
    for attempt in range(3):
        try:
            run = run_fem(grain, material(), strains, mode, level * grain.volume, graded=graded)
            keep = np.isin(np.round(strains, 6), STRAINS)
            return args, dict(forces=run.forces[keep], penetration=run.penetration[keep], nodes=run.n_nodes,
                              tets=run.n_elements, iterations=run.newton_iterations, seconds=run.seconds,
                              substeps=2**attempt, error=None)  # fmt: skip
        except NewtonDivergedError as exc:
            error = str(exc)
            strains = np.round(np.sort(np.concatenate([strains, 0.5 * (strains + np.r_[0.0, strains[:-1]])])), 6)
        except Exception as exc:  # a mesh or solver failure is reported, not fatal to the whole run
            return args, dict(error=f"{type(exc).__name__}: {exc}")
    return args, dict(error=error)


def vem_runs(seeds, modes):
    from vemdem.verification.fem_reference import run_vem

    out = {}
    for seed in seeds:
        for mode in modes:
            for beta in BETAS:
                run = run_vem(grain_of(seed), material(), beta, STRAINS, mode)
                out[seed, mode, beta] = dict(forces=run.forces, penetration=run.penetration, seconds=run.seconds)
    return out


def at(strain):
    return int(np.flatnonzero(np.isclose(STRAINS, strain))[0])


def run_all(seeds, modes, levels, uniform, study, jobs):
    t_start = time.perf_counter()
    tasks = [(s, m, lv, True) for s in seeds for m in modes for lv in levels]
    tasks += [(study[0], study[1], lv, False) for lv in uniform]
    tasks.sort(key=lambda t: t[2])  # the biggest meshes first, so the two workers finish together
    fem = {}
    with ProcessPoolExecutor(max_workers=jobs, initializer=_init_worker) as pool:
        for (seed, mode, level, graded), res in pool.map(fem_task, tasks):
            fem[seed, mode, level, graded] = res
            what = "graded " if graded else "uniform"
            if res["error"]:
                print(f"FE seed {seed} {mode:9s} {what} V/{1 / level:>6.0f}: FAILED {res['error']}", flush=True)
            else:
                print(f"FE seed {seed} {mode:9s} {what} V/{1 / level:>6.0f}: {res['nodes']:6d} nodes "
                      f"{res['tets']:7d} tets {res['seconds']:7.1f} s", flush=True)  # fmt: skip
    vem = vem_runs(seeds, modes)
    return fem, vem, time.perf_counter() - t_start


def solver_timing(study, level):
    """One Newton system of the finest study mesh (free dofs, at 1 % strain): vemdem.solver.linear
    (SciPy spsolve) and, if it happens to be installed, pypardiso (not a vemdem dependency)."""
    import scipy.sparse as sp

    from vemdem.verification.fem_reference import build_tet_model, reference_mesh
    from vemdem.scenarios.plates import PlateSetup, prepare_grain
    from vemdem.solver.linear import solve

    seed, mode = study
    turned, pins = prepare_grain(grain_of(seed), mode)
    nodes, tets = reference_mesh(turned, level * turned.volume)
    model = build_tet_model(nodes, tets, material())
    plates = PlateSetup(nodes, mode, pins)
    x = nodes.copy()
    x[:, 2] = plates.z0 + 0.99 * (x[:, 2] - plates.z0)  # 1 % homogeneous strain: a representative tangent
    x = x.ravel()
    _, f, K = model.evaluate(x, tangent=True)
    Kff, b = K[plates.free][:, plates.free], f[plates.free]
    out = dict(dofs=Kff.shape[0], nnz=Kff.nnz)

    def best(fn):
        times = []
        for _ in range(2):
            t = time.perf_counter()
            y = fn()
            times.append(time.perf_counter() - t)
        return min(times), y

    out["spsolve"], y = best(lambda: solve(Kff, b))
    try:
        import pypardiso
    except ImportError:
        return out
    # a fresh solver each time: pypardiso reuses a factorisation when it sees the same matrix again
    out["pardiso"], y2 = best(lambda: pypardiso.PyPardisoSolver().solve(sp.csr_matrix(Kff), b))
    out["pardiso_diff"] = float(np.abs(y - y2).max() / np.abs(y).max())
    return out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="seed 0 only, FE levels up to V/3333")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--modes", nargs="+", default=["uniaxial", "confined"], choices=["uniaxial", "confined"])
    parser.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1))
    parser.add_argument("--no-write", action="store_true", help="print only")
    parser.add_argument("--save", type=Path, help="also pickle the raw results to this file")
    parser.add_argument("--load", type=Path, help="rebuild the report from results saved with --save")
    args = parser.parse_args(argv)
    levels = LEVELS[:-1] if args.quick else LEVELS
    seeds = [args.seeds[0]] if args.quick else args.seeds
    uniform = () if args.quick else UNIFORM_LEVELS
    study = (seeds[0], args.modes[0])

    if args.load:
        with open(args.load, "rb") as fh:
            saved = pickle.load(fh)
        fem, vem, wall, solver = saved["fem"], saved["vem"], saved["wall"], saved["solver"]
    else:
        fem, vem, wall = run_all(seeds, args.modes, levels, uniform, study, args.jobs)
        solver = solver_timing(study, levels[-1])
        if args.save:
            with open(args.save, "wb") as fh:
                pickle.dump(dict(fem=fem, vem=vem, wall=wall, solver=solver), fh)

    from vemdem.verification.fem_reference import richardson

    reference = {}
    for seed in seeds:
        for mode in args.modes:
            runs = [fem[seed, mode, lv, True] for lv in levels]
            ok = [r for r in runs if not r["error"]]
            if not ok:
                nan = np.full(len(STRAINS), np.nan)
                reference[seed, mode] = dict(finest=nan, limit=nan, rho=nan, nodes=0, tets=0, penetration=nan)
                continue
            finest = ok[-1]["forces"]
            if len(ok) >= 3:
                limit, rho = richardson(*(r["forces"] for r in ok[-3:]))
            else:
                limit, rho = np.full_like(finest, np.nan), np.full_like(finest, np.nan)
            reference[seed, mode] = dict(finest=finest, limit=limit, rho=rho, nodes=ok[-1]["nodes"],
                                         tets=ok[-1]["tets"], penetration=ok[-1]["penetration"])  # fmt: skip

    text = report(seeds, args.modes, levels, uniform, study, fem, vem, reference, wall, solver, args)
    print(text)
    if not args.no_write:
        (ROOT / "docs").mkdir(exist_ok=True)
        (ROOT / "docs/img").mkdir(exist_ok=True)
        (ROOT / "docs/fem_comparison.md").write_text(text)
        plot(ROOT / "docs/img/fem_comparison.png", seeds[0], args.modes, vem, reference)
        print(f"wrote {ROOT / 'docs/fem_comparison.md'} and {ROOT / 'docs/img/fem_comparison.png'}")


def pct(x):
    return "n/a" if not np.isfinite(x) else f"{100 * x:+.1f} %"


def report(seeds, modes, levels, uniform, study, fem, vem, reference, wall, solver, args) -> str:
    import numba
    import scipy

    lines = []
    w = lines.append
    w("# One-element VEM vs refined tetrahedral FE: single-grain plate compression\n")
    w("Generated by `python benchmarks/fem_comparison.py" + (" --quick" if args.quick else "") + "` "
      f"(total wall time {wall / 60:.1f} min on {os.cpu_count()} cores, {args.jobs} worker processes; "
      f"Python {platform.python_version()}, NumPy {np.__version__}, SciPy {scipy.__version__}, "
      f"Numba {numba.__version__}).\n")  # fmt: skip
    w("## Set-up\n")
    w(f"- Grain: `sand_grain(size={SIZE}, n_vertices={N_VERTICES}, seed=s, truncate={TRUNCATE})`, seeds "
      f"{', '.join(map(str, seeds))}: flat caps at both ends. Material: compressible Neo-Hookean (paper eq. 2), "
      f"E = {E / 1e9:g} GPa, nu = {NU}.")  # fmt: skip
    w("- Boundary conditions: those of the `grain_compression` scenario, shared code "
      "(`scenarios.plates.compress`, `PlateSetup`, `prepare_grain`): frictionless plates acting on the nodes "
      "initially on the caps (within 1e-6 h0 of min/max z): bottom u_z = 0, top u_z = -strain h0; `uniaxial` "
      "pins x, y of one plate vertex and y of another (rigid modes only); `confined` holds the lateral "
      "displacement of every node. In the FE model the plates hold *every* mesh node on the caps.")  # fmt: skip
    w(f"- Load: {len(STRAINS)} steps of {100 * STRAINS[0]:g} % up to {100 * STRAINS[-1]:g} %, one Newton solve "
      "(`solver.statics.solve_static`, rtol 1e-9, SciPy `spsolve` for the linear systems) per step.")
    w("- VEM: one element per grain, `VemOptions(beta_internal=beta_i)`, sub-mesh `auto` (the scenario's model).")
    w("- FE: TetGen quality mesh (`-pq1.5/10a`) of the same polyhedron, boundary triangles split, linear "
      "tetrahedra with the same `neo_hooke` energy (`verification/fem_reference.py`). Graded family: target edge "
      "h(d) = clip(h_far (d / (h0/2))^(1/2), h_far / 8, h_far) with d the distance to the cap rims (the edges "
      "where a plate meets the free surface: the stress is singular there) and h_far the edge of a regular tet "
      "of volume max_volume; one parameter, max_volume = V / k, refines the whole family.\n")  # fmt: skip

    seed, mode = study
    w(f"## FE mesh convergence (seed {seed}, {mode})\n")
    w("| mesh | max tet volume | nodes | tets | F(5 %) N | F(10 %) N | F(20 %) N | change vs previous (5/10/20 %) | wall s |")
    w("|---|---|---|---|---|---|---|---|---|")
    for graded, lvls in ((True, levels), (False, uniform)):
        prev = None
        for lv in lvls:
            r = fem[seed, mode, lv, graded]
            name = "graded" if graded else "uniform"
            if r["error"]:
                w(f"| {name} | V/{1 / lv:.0f} | | | failed: {r['error']} | | | | |")
                continue
            f = [r["forces"][at(s)] for s in REPORTED]
            change = " / ".join(pct(a / b - 1) for a, b in zip(f, prev)) if prev else ""
            w(f"| {name} | V/{1 / lv:.0f} | {r['nodes']} | {r['tets']} | {f[0]:.1f} | {f[1]:.1f} | {f[2]:.1f} | "
              f"{change} | {r['seconds']:.0f} |")  # fmt: skip
            prev = f
    ref = reference[seed, mode]
    w("")
    w("Richardson extrapolation from the three finest graded meshes (constant refinement factor): "
      + ", ".join(f"{100 * s:g} %: limit {ref['limit'][at(s)]:.1f} N, contraction {ref['rho'][at(s)]:.2f}, "
                  f"finest mesh {pct(ref['finest'][at(s)] / ref['limit'][at(s)] - 1)} above it"
                  for s in REPORTED) + ".\n")  # fmt: skip
    ok = [fem[seed, mode, lv, True] for lv in levels if not fem[seed, mode, lv, True]["error"]]
    if len(ok) >= 3:
        node_ratio = ok[-1]["nodes"] / ok[-2]["nodes"]
        rate = np.log(ref["rho"][[at(s) for s in REPORTED]]) / np.log(node_ratio)
        w(f"The FE force falls monotonically under refinement (a conforming displacement model is too stiff), "
          f"but slowly: a refinement step (max volume / 3.3, nodes x {node_ratio:.1f}) divides the change by "
          f"{', '.join(f'{r:.2f}' for r in ref['rho'][[at(s) for s in REPORTED]])} at 5/10/20 %, i.e. a force "
          f"error ~ N^-{np.nanmean(rate):.2f} (N nodes): the stress is singular at the cap rims. Grading "
          "towards the rims helps (compare the uniform meshes of the same max volume), but two meshes 1 % apart "
          "would need of the order of 10^5 nodes, beyond the serial sparse solver in a few minutes. The FE "
          "reference below is therefore the **Richardson limit** of the three finest graded meshes; the error "
          "against the finest mesh itself (stiffer, unconverged) is given in brackets. The two bracket the "
          "discretisation uncertainty of the reference.\n")  # fmt: skip

    w("## Relative force error of the VEM, (F_VEM - F_FE) / F_FE\n")
    w("Errors against the extrapolated FE force (in brackets: against the finest FE mesh).\n")
    for mode in modes:
        w(f"### {mode}\n")
        w("| seed | strain | FE finest N | FE extrapolated N (contraction) | "
          + " | ".join(f"VEM beta_i={b} N | error beta_i={b}" for b in BETAS) + " |")  # fmt: skip
        w("|---|---|---|---|" + "---|---|" * len(BETAS))
        for seed in seeds:
            ref = reference[seed, mode]
            for s in REPORTED:
                k = at(s)
                cells = []
                for b in BETAS:
                    fv = vem[seed, mode, b]["forces"][k]
                    cells.append(f"{fv:.1f} | {pct(fv / ref['limit'][k] - 1)} ({pct(fv / ref['finest'][k] - 1)})")
                w(f"| {seed} | {100 * s:g} % | {ref['finest'][k]:.1f} | {ref['limit'][k]:.1f} ({ref['rho'][k]:.2f}) | "
                  + " | ".join(cells) + " |")  # fmt: skip
        w("")
        w(f"Finest FE meshes ({mode}): " + ", ".join(f"seed {s}: {reference[s, mode]['nodes']} nodes, "
                                                    f"{reference[s, mode]['tets']} tets" for s in seeds) + ".\n")  # fmt: skip
        w("Mean error over the seeds (against the extrapolated FE force):\n")
        w("| beta_i | " + " | ".join(f"{100 * s:g} %" for s in REPORTED) + " |")
        w("|---|" + "---|" * len(REPORTED))
        for b in BETAS:
            errs = [np.mean([vem[sd, mode, b]["forces"][at(s)] / reference[sd, mode]["limit"][at(s)] - 1 for sd in seeds])
                    for s in REPORTED]  # fmt: skip
            w(f"| {b} | " + " | ".join(pct(e) for e in errs) + " |")
        w("")

    w("## Nodes passing through the plates\n")
    w("The plates act on the nodes that touch them at the start (bilateral rollers on a fixed contact set, as "
      "in the scenario). Deepest penetration of any other node through a plate, as a fraction of h0 "
      "(seed-wise maximum):\n")
    w("| mode | model | " + " | ".join(f"{100 * s:g} %" for s in REPORTED) + " |")
    w("|---|---|" + "---|" * len(REPORTED))
    for mode in modes:
        rows = [("FE finest", [reference[sd, mode]["penetration"] for sd in seeds])]
        rows += [(f"VEM beta_i={b}", [vem[sd, mode, b]["penetration"] for sd in seeds]) for b in BETAS]
        for name, pens in rows:
            w(f"| {mode} | {name} | " + " | ".join(f"{max(p[at(s)] for p in pens):.3f}" for s in REPORTED) + " |")
    w("")
    w("![force vs strain](img/fem_comparison.png)\n")
    w("## Cost\n")
    w("FE wall time per compression run (8 load steps, all Newton iterations), graded meshes:\n")
    w("| max tet volume | " + " | ".join(f"{m}, seeds {', '.join(map(str, seeds))}" for m in modes) + " |")
    w("|---|" + "---|" * len(modes))
    for lv in levels:
        cells = []
        for m in modes:
            rs = [fem[sd, m, lv, True] for sd in seeds if not fem[sd, m, lv, True]["error"]]
            cells.append("; ".join(f"{r['nodes']} nodes {r['seconds']:.0f} s" for r in rs))
        w(f"| V/{1 / lv:.0f} | " + " | ".join(cells) + " |")
    w("")
    w("The sparse direct solve dominates (the element kernel and assembly take well under a second per "
      "iteration even on the finest mesh). In confined mode only the z dofs are free, hence the much cheaper "
      "runs. A VEM run takes a few hundredths of a second.\n")
    if solver:
        line = (f"One Newton system of the finest seed-{study[0]} {study[1]} mesh ({solver['dofs']} free dofs, "
                f"{solver['nnz']} non-zeros): `solver.linear.solve` (SciPy spsolve, SuperLU) {solver['spsolve']:.2f} s")
        if "pardiso" in solver:
            line += (f"; pypardiso (MKL PARDISO, measured only, not a vemdem dependency) {solver['pardiso']:.2f} s "
                     f"(same solution to {solver['pardiso_diff']:.0e})")
        w(line + ".\n")
    w("## Findings\n")
    for mode in modes:
        err = {b: np.array([[vem[sd, mode, b]["forces"][at(s)] / reference[sd, mode]["limit"][at(s)] - 1
                             for s in REPORTED] for sd in seeds]) for b in BETAS}  # fmt: skip
        ranges = "; ".join(f"beta_i = {b}: {pct(np.nanmin(e))} to {pct(np.nanmax(e))}" for b, e in err.items())
        w(f"- {mode}: over seeds and 5/10/20 % strain the VEM error is {ranges}. "
          + zero_crossing(err) + "")
    for mode in modes:
        gap = [max(abs(reference[sd, mode]["finest"][at(s)] / reference[sd, mode]["limit"][at(s)] - 1) for sd in seeds)
               for s in REPORTED]  # fmt: skip
        w(f"- FE reference uncertainty ({mode}): the finest mesh is up to "
          + ", ".join(f"{100 * g:.0f} % ({100 * s:g} %)" for g, s in zip(gap, REPORTED))
          + " above the extrapolated force (the extrapolation's own error is a fraction of that): VEM errors "
          "of this size are within the uncertainty of the reference.")  # fmt: skip
    pen = max(reference[sd, m]["penetration"][at(0.2)] for sd in seeds for m in modes)
    pen_v = max(vem[sd, m, b]["penetration"][at(0.2)] for sd in seeds for m in modes for b in BETAS)
    w(f"- The scenario's plates hold only the nodes that touch them at the start. From a few % strain on, other "
      f"nodes pass through the plates (at 20 %: up to {pen:.2f} h0 in the FE model, {pen_v:.2f} h0 in the "
      "VEM), partly because the grain, loaded through small, offset caps, tilts. Both models solve the same "
      "boundary-value problem, so the comparison stands, but at 10-20 % it is not the physical plate test: "
      "that needs unilateral plate contact (an active set) in the scenario.")  # fmt: skip
    w("")
    return "\n".join(lines) + "\n"


def zero_crossing(err) -> str:
    """Where the error changes sign in beta_i (linear interpolation of the seed-mean error)."""
    betas = np.array(BETAS)
    mean = np.array([np.nanmean(err[b], axis=0) for b in BETAS])  # (beta, strain)
    out = []
    for k, s in enumerate(REPORTED):
        e = mean[:, k]
        i = np.flatnonzero((e[:-1] < 0) & (e[1:] >= 0))
        if len(i):
            j = i[0]
            out.append(f"{100 * s:g} %: {betas[j] - e[j] * (betas[j + 1] - betas[j]) / (e[j + 1] - e[j]):.2f}")
    if not out:
        return "The error does not change sign between the beta_i tested."
    return "The seed-mean error vanishes near beta_i = " + ", ".join(out) + " (linear interpolation in beta_i)."


def plot(path, seed, modes, vem, reference):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(modes), figsize=(5.5 * len(modes), 4.2), dpi=120, squeeze=False)
    eps = np.r_[0.0, STRAINS] * 100
    for ax, mode in zip(axes[0], modes):
        ref = reference[seed, mode]
        ax.plot(eps, np.r_[0.0, ref["limit"]], "k-", lw=2, label="FE, extrapolated")
        ax.plot(eps, np.r_[0.0, ref["finest"]], "k--", lw=1, label=f"FE, {ref['nodes']} nodes")
        for b, c in zip(BETAS, ("tab:blue", "tab:orange", "tab:red")):
            ax.plot(eps, np.r_[0.0, vem[seed, mode, b]["forces"]], "o-", ms=3, color=c, label=f"VEM, beta_i = {b}")
        ax.set_xlabel("compressive strain 1 - h/h0 (%)")
        ax.set_ylabel("force on the top plate (N)")
        ax.set_title(f"sand grain seed {seed}, {mode}")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
