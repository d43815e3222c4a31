"""One implicit Newton iteration, split by piece, against the number of grains (docs/performance.md).

    python benchmarks/bench_newton.py [--grains 515,4096] [--dt 1e-4,1e-3] [--state PATH/state.npz]
                                      [--tile 1x1,2x4,4x8] [--step] [--quiet SECONDS]
                                      [--run CONFIG.toml:DIR/checkpoint.npz]
                                      [--solvers direct,grain-block] [--repeat 3] [--json PATH]

Packs: bench_dynamics.py's geometric deposits (loose stacks, every grain resting on a point of the
one below) of N grains of the paper's sand (E = 90 GPa, real density), after 2 ms of implicit
settling; with --state, also a settled pack written by `vemdem run` (a `pack` scenario's
state.npz: several contacts per grain), tiled --tile times side by side in a box as many times
wider and deeper (2x4: 8 copies of a 515-grain pack, 4,120 grains; 4x8: 16,480): settled packs of
any size in seconds, with fewer contacts per grain only along the seams where two copies meet
across a former wall (reported as c/grain). For each pack, Newmark shift and linear solver, the pieces
of one Newton iteration at the same state (best of --repeat, wall seconds on this machine):

    element     force + tangent blocks of every grain, a1 M added (vem kernel)
    contact     narrow phase (from the feature list, as in Newton), normal and friction terms with their tangents
    assembly    contact self-terms into the blocks, coupling matrix
    factor      the linear solver's set-up (block LU + coarse space, or SuperLU)
    solve       the solve to a relative residual 1e-8 (GMRES iterations reported)

and the exponent p of cost ~ N^p between the smallest and the largest pack of each kind. With
--step, also one whole implicit step from the pack's state (pair search, Newton to convergence
within 40 iterations, the update's CCD share), with its Newton and Krylov iterations; with
--quiet, each --state pack is first carried on with mass damping until its surface grains stop
rolling (a pack settled by the scenario's rule is not at rest). A GMRES solve that
does not reach 1e-8 in 200 iterations is reported as krylov -1 (solve nan). Nothing asserts a
timing; results and their reading: docs/linear-solvers.md.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

import bench_dynamics as bd
from vemdem.contact.defaults import default_contact_laws, material_contact_laws
from vemdem.contact.walls import box_walls
from vemdem.contact.model import ContactHistory
from vemdem.io.state import load_state
from vemdem.model.scene import Scene
from vemdem.scenarios.lid_compression import lid_wall
from vemdem.solver.explicit import FEATURE_SKIN_GAPS
from vemdem.solver.linear import LinearSolveDiverged, make_linear_solver, woodbury
from vemdem.solver.newmark import NewmarkParameters, advance, initial_state, newmark_step, newton_system
from vemdem.solver.state import RunStats, State, StepControl, StepRejected
from vemdem.vem.material import Material

BETA, GAMMA = 0.3025, 0.6


def deposit_case(n: int):
    pack = bd.make_pack(n)
    scene = bd.make_scene(pack)
    state = initial_state(scene)
    params = NewmarkParameters(BETA, GAMMA, linear=make_linear_solver("auto"))
    state, _ = advance(scene, state, 2e-3, StepControl(dt=1e-5, dt_max=1e-4), params, None, RunStats())
    return f"deposit {n}", scene, state


def tiled(grains, x, v, box, centre, nx: int, ny: int):
    """nx x ny copies of a pack side by side (reference shapes and state moved together), and the
    box around them: (grains, x, v, box, centre)."""
    width, depth = box
    offsets = [np.array([i * width, j * depth, 0.0]) for i in range(nx) for j in range(ny)]
    grains = [g.translated(o) for o in offsets for g in grains]
    x = np.vstack([x + o for o in offsets])
    v = np.vstack([v] * len(offsets))
    centre = (centre[0] + 0.5 * (nx - 1) * width, centre[1] + 0.5 * (ny - 1) * depth)
    return grains, x, v, (nx * width, ny * depth), centre


def state_case(path: Path, tile: tuple[int, int] = (1, 1)):
    """A state file's pack in its box. A lid run's state (benchmarks/jam_state.py: its record holds
    "lid" and "contact") also gets the lid, on its way down from where it stood, the run's friction
    and damping, and its contacts' friction history (untiled: the history's keys are the grains')."""
    s = load_state(path)
    meta = s.meta
    grains, x, v, box, centre = tiled(s.grains, s.x, s.v, meta["box"], meta["centre"], *tile)
    size = float(np.mean([np.cbrt(6 * g.volume / np.pi) for g in s.grains]))
    material = Material(bd.E, bd.NU, bd.DENSITY)
    contact = {"mu_s": bd.MU_S, "mu_d": bd.MU_D, **meta.get("contact", {})}
    if contact.pop("law", "weight") == "material" and "reference_force" not in contact:  # config.build's choice
        law, friction = material_contact_laws(size, material.E, material.nu, **contact)
    else:
        law, friction = default_contact_laws(size, material.E, material.density, bd.GRAVITY, **contact)
    walls = box_walls(*box, meta["floor"], tuple(centre))
    history = None
    if "lid" in meta:
        walls.append(lid_wall(meta["lid"], centre)[0])
        if tile == (1, 1) and s.friction is not None:
            f = s.friction
            history = ContactHistory(f["keys"], f["c_prev"], f["gt"], f["stick"].astype(bool))
    scene = Scene.build(grains, material, law, friction, planes=walls)
    kind = "lid" if "lid" in meta else "settled"
    name = f"{kind} {len(grains)}" if tile == (1, 1) else f"tiled {len(grains)}"
    return name, scene, State(0.0, x.copy(), v.copy(), np.zeros_like(x), history)


def quieted(case, seconds: float):
    """The case carried on implicitly for `seconds` with the pack stage's mass damping (20 1/s):
    a pack settled by the scenario's rule still has surface grains rolling at cm/s, so a long step
    from it is a step of colliding grains; 0.09 s of this leaves the fastest vertex of the
    515-grain pack at 9e-6 m/s (docs/dynamics.md)."""
    name, scene, state = case
    if seconds <= 0.0:
        return case
    params = NewmarkParameters(BETA, GAMMA, linear=make_linear_solver("auto"), mass_damping=20.0)
    state, _ = advance(scene, state, state.t + seconds, StepControl(dt=1e-5, dt_max=1e-4), params, None, RunStats())
    print(f"{name}: {seconds:g} s quieted, fastest vertex {np.linalg.norm(state.v, axis=1).max():.2g} m/s")
    return f"{name} quiet", scene, state


def run_case(config: Path, checkpoint: Path):
    """A `vemdem run` in progress (or done): its config and DIR/checkpoint.npz, e.g. the falling,
    contact-rich 515-grain paper-pack-implicit (several contacts per grain, friction history on)."""
    import tomllib

    from vemdem.config.build import scene_from
    from vemdem.scenarios import pack as pack_scenario
    from vemdem.scenarios.registry import checked_config

    cfg, _ = checked_config(tomllib.loads(config.read_text()))
    packing = pack_scenario.place(cfg)
    scene = scene_from(packing.grains, cfg, box_walls(*packing.box))
    with np.load(checkpoint) as d:
        history = ContactHistory(d["keys"], d["c_prev"], d["gt"], d["stick"].astype(bool))
        state = State(float(d["t"]), d["x"].copy(), d["v"].copy(), d["a"].copy(), history)
    return f"run {scene.n_grains} t={state.t:.3g}", scene, state


# Untimed calls before the timed ones: the first calls of a piece fault in fresh memory (the 33 MB
# of tangent blocks at 515 grains, from mmap until glibc's threshold has grown), and two threads
# faulting pages at once are slow: the element kernel took 52-57 ms in its 2nd-4th calls and 6 ms
# from the 5th on, on 2 threads (1 thread: 15 -> 11 ms). A run pays it in its first steps only: 13
# of 371 element calls over 40 steps of the lid jam took about 53 ms, one of them in the last 20
# (docs/performance.md)
WARMUP = 4


def best(f, repeat):
    for _ in range(WARMUP):
        f()
    times, out = [], None
    for _ in range(repeat):
        t = time.perf_counter()
        out = f()
        times.append(time.perf_counter() - t)
    return min(times), out


STEP_ITERATIONS = 40  # the lid cycle's budget: a long step that converges in 16-40 iterations is reported


def one_step(scene, state, dt, solver_name, repeat, rotated=NewmarkParameters.rotated_tangent):
    """Wall seconds (best of `repeat`), Newton and Krylov iterations of one implicit step from
    `state` (nan, -1, -1 when the step is rejected: reported, not fatal)."""
    params = NewmarkParameters(BETA, GAMMA, linear=make_linear_solver(solver_name), max_iterations=STEP_ITERATIONS,
                               rotated_tangent=rotated)
    try:
        wall, (_, info) = best(lambda: newmark_step(scene, state, dt, params), repeat)
    except StepRejected:
        return np.nan, -1, -1
    return wall, info.iterations, info.krylov_iterations


def measure(scene, state, dt, solver_name, repeat, rotated=NewmarkParameters.rotated_tangent):
    a1, a4 = 1 / (BETA * dt * dt), GAMMA / (BETA * dt)
    contact = scene.contact
    # as the implicit integrator does (solver/api.py): Newton's iterations reuse the feature pairs,
    # so the best of `repeat` calls is an iteration's narrow phase with every list kept
    contact.keep_feature_list(FEATURE_SKIN_GAPS * contact.law.activation_gap)
    cand = contact.search(state.x, state.t)
    t_el, el = best(lambda: scene.bodies.evaluate(state.x, tangent=True, mass_shift=a1, rotated_strain=rotated), repeat)
    t_c, cr = best(lambda: contact.evaluate(state.x, state.t, cand, state.history, v=state.v, a4=a4, tangent=True),
                   repeat)  # fmt: skip

    def assemble():
        ev = scene.bodies.evaluate(state.x, tangent=True, mass_shift=a1, rotated_strain=rotated)
        t0 = time.perf_counter()
        system = newton_system(scene, ev, cr, state.x, a1)
        return time.perf_counter() - t0, system

    t_asm = min(assemble()[0] for _ in range(repeat))
    _, system = assemble()
    solver = make_linear_solver(solver_name)
    rhs = np.random.default_rng(0).normal(size=system.n)
    # each factor() its own coarse LU, as at a step's first Newton iteration: the pieces of one
    # iteration, not the best case of a coarse LU kept for the same matrix (the --step column has those)
    t_f, _ = best(lambda: (solver.forget(), solver.factor(system)), repeat)
    try:
        t_s, _ = best(lambda: solver.solve(rhs, 1e-8), repeat)
        krylov = solver.stats.last_iterations
    except LinearSolveDiverged:  # reported, not fatal: GMRES's limit is part of the measurement
        t_s, krylov = np.nan, -1
    grain_pairs = {(min(a, b), max(a, b)) for a, b in cr.ints[:, 1:3].tolist()}
    return {
        "element": t_el, "contact": t_c, "assembly": t_asm, "factor": t_f, "solve": t_s,
        "total": t_el + t_c + t_asm + t_f + t_s, "krylov": krylov,
        "contacts_per_grain": 2 * len(grain_pairs) / scene.n_grains, "pairs": cr.n_contacts,
    }  # fmt: skip


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--grains", default="515,4096")
    p.add_argument("--dt", default="1e-4,1e-3")
    p.add_argument("--state", type=Path, action="append", default=[])
    p.add_argument("--tile", default="1x1", help="copies of each --state pack side by side, e.g. 1x1,2x4,4x8")
    p.add_argument("--step", action="store_true", help="also time one whole implicit step")
    p.add_argument("--quiet", type=float, default=0.0, metavar="SECONDS",
                   help="carry each --state pack on for SECONDS with mass damping 20 1/s first (0.09: at rest)")
    p.add_argument("--run", action="append", default=[], metavar="CONFIG.toml:DIR/checkpoint.npz",
                   help="a pack run's config and checkpoint (its state at that time)")
    p.add_argument("--solvers", default="direct,grain-block")
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--json", type=Path)
    p.add_argument("--rotated-tangent", type=float, default=NewmarkParameters.rotated_tangent, metavar="STRAIN",
                   help="the solver's rotated_tangent (0: every grain's exact element tangent)")
    p.add_argument("--woodbury-max-dofs", type=int, default=woodbury.WOODBURY_MAX_DOFS, metavar="K",
                   help="rotated blocks touched on at most K dofs take the Woodbury path (0: every block its LU)")
    args = p.parse_args()
    woodbury.WOODBURY_MAX_DOFS = args.woodbury_max_dofs
    cases = [deposit_case(int(n)) for n in args.grains.split(",") if n]
    tiles = [tuple(int(k) for k in t.split("x")) for t in args.tile.split(",") if t]
    cases += [quieted(state_case(path, tile), args.quiet) for path in args.state for tile in tiles]
    cases += [run_case(*(Path(part) for part in spec.split(":", 1))) for spec in args.run]
    rows = []
    print(f"{'pack':>14} {'dt':>7} {'solver':>11} {'c/grain':>7} {'element':>8} {'contact':>8} {'assembly':>8} "
          f"{'factor':>8} {'solve':>8} {'total ms':>9} {'krylov':>6}" + (f" {'step ms':>9} {'newton':>6} {'krylov':>6}"
          if args.step else ""))  # fmt: skip
    for name, scene, state in cases:
        for dt in (float(d) for d in args.dt.split(",")):
            for solver in args.solvers.split(","):
                m = measure(scene, state, dt, solver, args.repeat, args.rotated_tangent)
                if args.step:
                    m["step"], m["newton"], m["step_krylov"] = one_step(scene, state, dt, solver, args.repeat,
                                                                        args.rotated_tangent)
                rows.append({"pack": name, "n_grains": scene.n_grains, "dt": dt, "solver": solver, **m})
                print(f"{name:>14} {dt:7.0e} {solver:>11} {m['contacts_per_grain']:7.2f} "
                      + " ".join(f"{1e3 * m[k]:8.1f}" for k in ("element", "contact", "assembly", "factor", "solve"))
                      + f" {1e3 * m['total']:9.1f} {m['krylov']:6d}"
                      + (f" {1e3 * m['step']:9.1f} {m['newton']:6d} {m['step_krylov']:6d}" if args.step else ""),
                      flush=True)  # fmt: skip
    for kind, prefixes in (("deposits", ("deposit",)), ("settled packs", ("settled", "tiled"))):
        packs = [r for r in rows if r["pack"].startswith(prefixes)]
        for solver in args.solvers.split(","):
            for dt in sorted({r["dt"] for r in packs}):
                sel = sorted((r for r in packs if r["solver"] == solver and r["dt"] == dt), key=lambda r: r["n_grains"])
                if len(sel) >= 2:
                    lo, hi = sel[0], sel[-1]
                    ratio = np.log(hi["n_grains"] / lo["n_grains"])
                    text = f"N^{np.log(hi['total'] / lo['total']) / ratio:.2f} per Newton iteration"
                    if args.step and lo["newton"] > 0 and hi["newton"] > 0:
                        text += f", N^{np.log(hi['step'] / lo['step']) / ratio:.2f} per step"
                    print(f"cost exponent, {kind}, {solver}, dt {dt:g}: {text} ({lo['n_grains']} -> {hi['n_grains']} grains)")
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
