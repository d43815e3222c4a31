"""One implicit Newton iteration, split by piece, against the number of grains (issue 14).

    python benchmarks/bench_newton.py [--grains 515,4096] [--dt 1e-4,1e-3] [--state PATH/state.npz]
                                      [--run CONFIG.toml:DIR/checkpoint.npz]
                                      [--solvers direct,grain-block] [--repeat 3] [--json PATH]

Packs: bench_dynamics.py's geometric deposits (loose stacks, every grain resting on a point of the
one below) of N grains of the paper's sand (E = 90 GPa, real density), after 2 ms of implicit
settling; with --state, also a settled pack written by `vemdem run` (a `pack` scenario's
state.npz: several contacts per grain). For each pack, Newmark shift and linear solver, the pieces
of one Newton iteration at the same state (best of --repeat, wall seconds on this machine):

    element     force + tangent blocks of every grain (vem kernel)
    contact     narrow phase, normal and friction terms with their tangents
    assembly    mass into the blocks, contact self-terms into the blocks, coupling matrix
    factor      the linear solver's set-up (block LU + coarse space, or SuperLU)
    solve       the solve to a relative residual 1e-8 (GMRES iterations reported)

and the exponent p of cost ~ N^p between the smallest and the largest pack. A GMRES solve that
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
from vemdem.contact.defaults import default_contact_laws
from vemdem.contact.walls import box_walls
from vemdem.io.state import load_state
from vemdem.model.scene import Scene
from vemdem.solver.linear import LinearSolveDiverged, NewtonSystem, make_linear_solver
from vemdem.solver.newmark import NewmarkParameters, advance, initial_state, newton_blocks
from vemdem.solver.state import RunStats, State, StepControl
from vemdem.vem.material import Material

BETA, GAMMA = 0.3025, 0.6


def deposit_case(n: int):
    pack = bd.make_pack(n)
    scene = bd.make_scene(pack)
    state = initial_state(scene)
    params = NewmarkParameters(BETA, GAMMA, linear=make_linear_solver("auto"))
    state, _ = advance(scene, state, 2e-3, StepControl(dt=1e-5, dt_max=1e-4), params, None, RunStats())
    return f"deposit {n}", scene, state


def state_case(path: Path):
    s = load_state(path)
    meta = s.meta
    size = float(np.mean([np.cbrt(6 * g.volume / np.pi) for g in s.grains]))
    material = Material(bd.E, bd.NU, bd.DENSITY)
    law, friction = default_contact_laws(size, material.E, material.density, bd.GRAVITY, bd.MU_S, bd.MU_D)
    walls = box_walls(*meta["box"], meta["floor"], tuple(meta["centre"]))
    scene = Scene.build(s.grains, material, law, friction, planes=walls)
    a = np.zeros_like(s.x)
    return f"settled {len(s.grains)}", scene, State(0.0, s.x.copy(), s.v.copy(), a)


def run_case(config: Path, checkpoint: Path):
    """A `vemdem run` in progress (or done): its config and DIR/checkpoint.npz, e.g. the falling,
    contact-rich 515-grain paper-pack-implicit (several contacts per grain, friction history on)."""
    import tomllib

    from vemdem.config.build import scene_from
    from vemdem.contact.model import ContactHistory
    from vemdem.scenarios import pack as pack_scenario
    from vemdem.scenarios.registry import checked_config

    cfg, _ = checked_config(tomllib.loads(config.read_text()))
    packing = pack_scenario.place(cfg)
    scene = scene_from(packing.grains, cfg, box_walls(*packing.box))
    with np.load(checkpoint) as d:
        history = ContactHistory(d["keys"], d["c_prev"], d["gt"], d["stick"].astype(bool))
        state = State(float(d["t"]), d["x"].copy(), d["v"].copy(), d["a"].copy(), history)
    return f"run {scene.n_grains} t={state.t:.3g}", scene, state


def best(f, repeat):
    times, out = [], None
    for _ in range(repeat):
        t = time.perf_counter()
        out = f()
        times.append(time.perf_counter() - t)
    return min(times), out


def measure(scene, state, dt, solver_name, repeat):
    a1, a4 = 1 / (BETA * dt * dt), GAMMA / (BETA * dt)
    contact = scene.contact
    cand = contact.search(state.x, state.t)
    t_el, el = best(lambda: scene.bodies.evaluate(state.x, tangent=True), repeat)
    t_c, cr = best(lambda: contact.evaluate(state.x, state.t, cand, state.history, v=state.v, a4=a4, tangent=True),
                   repeat)  # fmt: skip

    def assemble():
        ev = scene.bodies.evaluate(state.x, tangent=True)
        t0 = time.perf_counter()
        blocks, coupling = newton_blocks(scene, ev, cr, a1)
        return time.perf_counter() - t0, NewtonSystem(blocks, scene.bodies.block_ptr, scene.bodies.dof_ptr, coupling,
                                                      state.x)  # fmt: skip

    t_asm = min(assemble()[0] for _ in range(repeat))
    _, system = assemble()
    solver = make_linear_solver(solver_name)
    rhs = np.random.default_rng(0).normal(size=system.n)
    t_f, _ = best(lambda: solver.factor(system), repeat)
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
    p.add_argument("--run", action="append", default=[], metavar="CONFIG.toml:DIR/checkpoint.npz",
                   help="a pack run's config and checkpoint (its state at that time)")
    p.add_argument("--solvers", default="direct,grain-block")
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--json", type=Path)
    args = p.parse_args()
    cases = [deposit_case(int(n)) for n in args.grains.split(",") if n]
    cases += [state_case(path) for path in args.state]
    cases += [run_case(*(Path(part) for part in spec.split(":", 1))) for spec in args.run]
    rows = []
    print(f"{'pack':>14} {'dt':>7} {'solver':>11} {'c/grain':>7} {'element':>8} {'contact':>8} {'assembly':>8} "
          f"{'factor':>8} {'solve':>8} {'total ms':>9} {'krylov':>6}")  # fmt: skip
    for name, scene, state in cases:
        for dt in (float(d) for d in args.dt.split(",")):
            for solver in args.solvers.split(","):
                m = measure(scene, state, dt, solver, args.repeat)
                rows.append({"pack": name, "n_grains": scene.n_grains, "dt": dt, "solver": solver, **m})
                print(f"{name:>14} {dt:7.0e} {solver:>11} {m['contacts_per_grain']:7.2f} "
                      + " ".join(f"{1e3 * m[k]:8.1f}" for k in ("element", "contact", "assembly", "factor", "solve"))
                      + f" {1e3 * m['total']:9.1f} {m['krylov']:6d}", flush=True)  # fmt: skip
    deposits = [r for r in rows if r["pack"].startswith("deposit")]
    for solver in args.solvers.split(","):
        for dt in {r["dt"] for r in deposits}:
            sel = sorted((r for r in deposits if r["solver"] == solver and r["dt"] == dt), key=lambda r: r["n_grains"])
            if len(sel) >= 2:
                lo, hi = sel[0], sel[-1]
                exponent = np.log(hi["total"] / lo["total"]) / np.log(hi["n_grains"] / lo["n_grains"])
                print(f"cost exponent, {solver}, dt {dt:g}: N^{exponent:.2f} ({lo['n_grains']} -> {hi['n_grains']} grains)")
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
