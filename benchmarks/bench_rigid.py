"""Rigid grains, explicit: the cost of one step and of its pieces on a settled pack (docs/performance.md).

    python benchmarks/bench_rigid.py [--config CONFIG.toml] [--state STATE.npz] [--out DIR]
                                     [--steps 1000] [--threads N] [--json PATH]

CONFIG is a `pile_collapse` config with `[model] grains = "rigid"` and `integrator = "explicit"`
(default: the README's main job, `vemdem example pile`), STATE a settled pack it wrote
(`DIR/pack/state.npz`); without one the config's pack is settled into `--out`/pack (about a
minute; kept and reused by later runs). The walls are those of the collapse (the config's
`[collapse] open`); the run starts from the pack at rest, so the measured steps are the first
`--steps` of the collapse: a dense pack whose front starts to move. One warm-up step first (numba
compilation excluded).

Prints steps per second, grain-steps per second and per CPU-second (wall x numba threads), how many
grain pairs' feature lists (contact/feature_list.py) were rebuilt per step, and the pieces of a
step, each timed on its own at the end state: the contact search (broad phase), the narrow phase
(the full search `find_contacts`, and the feature list with every list kept), the contact
forces, the rigid kinematics (free rotation, vertex placement and velocities) and the step limits.
The reference point: rigid polyhedra in other DEM codes cost about 0.3 CPU-s per
step for a 515-grain dense pack (600-1,600 grain-steps per CPU-second). Nothing here asserts a
timing.
"""

from __future__ import annotations

import argparse
import json
import time
import tomllib
from pathlib import Path

import numba
import numpy as np

from vemdem.cli import checked_config, load_toml
from vemdem.config.build import scene_from, solver_options_from
from vemdem.contact.model import ContactHistory
from vemdem.contact.pairs import find_contacts
from vemdem.io.state import load_state
from vemdem.scenarios.pack import initial_state_from
from vemdem.scenarios.pile_collapse import standing_walls
from vemdem.scenarios.registry import example_text
from vemdem.solver.api import make_integrator
from vemdem.solver.explicit import advance_explicit
from vemdem.solver.rigid import free_rotation
from vemdem.solver.state import RunStats


def _per_call(fn, repeats: int) -> float:
    """Seconds per call of fn(), after one warm-up call."""
    fn()
    t = time.perf_counter()
    for _ in range(repeats):
        fn()
    return (time.perf_counter() - t) / repeats


def measure(cfg: dict, pack, steps: int) -> dict:
    if cfg["model"]["grains"] != "rigid" or cfg["solver"]["integrator"] != "explicit":
        raise SystemExit("bench_rigid: the config needs [model] grains = 'rigid' and [solver] integrator = 'explicit'")
    scene = scene_from(pack.grains, cfg, standing_walls(pack.meta, cfg["collapse"]["open"]))
    runner = make_integrator(solver_options_from(cfg), scene)
    integ = runner.integrator
    history = ContactHistory(**pack.friction) if pack.friction is not None else None
    state = runner.initial_state(pack.x, pack.v, history=history)
    control = runner.control

    state, _ = _advance_steps(integ, state, 1, control)  # compilation
    builds0 = scene.contact.feature_list.builds
    t0 = time.perf_counter()
    state, stats = _advance_steps(integ, state, steps, control)
    wall = time.perf_counter() - t0
    builds = scene.contact.feature_list.builds - builds0
    G, threads = scene.n_grains, numba.get_num_threads()
    x, t = state.x, state.t
    contact = scene.contact
    candidates = integ.candidates(x, t)
    x_all = contact.all_positions(x, t)
    gbar = contact.law.activation_gap
    _, ints, floats = contact.pairs(x, t, candidates)
    s = state.bodies
    b = integ.bodies
    repeats = max(20, steps // 10)
    pieces = {
        "search (broad phase, Verlet skin)": _per_call(lambda: contact.search(x, t, margin=integ.skin), repeats),
        "narrow phase, full search (find_contacts)": _per_call(
            lambda: find_contacts(x_all, candidates, contact.topology, gbar), repeats),
        "narrow phase, feature list kept (what a step at rest costs)": _per_call(
            lambda: contact.feature_list.find(x_all, candidates, contact.topology, gbar), repeats),
        "contact forces (evaluate, narrow phase included)": _per_call(
            lambda: contact.evaluate(x, t, candidates, state.history, v=state.v), repeats),
        "free rotation": _per_call(lambda: free_rotation(s["rotation"], s["momentum"], b.moments, 1e-6), repeats),
        "vertex placement and velocities": _per_call(
            lambda: integ.vertex_motion(s["centre"], s["rotation"], s["velocity"], s["momentum"]), repeats),
        "step limits (stable step, approach)": _per_call(lambda: integ.stable_step(state, ints, floats), repeats),
    }  # fmt: skip
    return {
        "grains": G,
        "vertices": scene.n_vertices,
        "threads": threads,
        "steps": stats.accepted,
        "rejected": stats.rejected,
        "wall_s": wall,
        "steps_per_s": stats.accepted / wall,
        "ms_per_step": 1e3 * wall / stats.accepted,
        "grain_steps_per_s": G * stats.accepted / wall,
        "grain_steps_per_cpu_s": G * stats.accepted / (wall * threads),
        "contact_pairs": int(len(ints)),
        "candidate_grain_pairs": int(len(candidates)),
        "feature_list_builds_per_step": builds / stats.accepted,
        "pieces_ms": {k: 1e3 * v for k, v in pieces.items()},
    }


def _advance_steps(integ, state, n, control):
    """(state, stats) after n explicit steps at the stable step: advance_explicit without an end
    time, stopped from its step callback."""
    stats = RunStats()

    def stop_after(s, info, h):
        if stats.accepted >= n:
            raise _Enough(s)

    try:
        state, stats = advance_explicit(integ, state, np.inf, control, stop_after, stats)
    except _Enough as e:
        state = e.state
    return state, stats


class _Enough(Exception):
    def __init__(self, state):
        self.state = state


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--config", type=Path, help="a pile_collapse config [the `pile` example]")
    p.add_argument("--state", type=Path, help="a settled pack [settle the config's pack into --out/pack]")
    p.add_argument("--out", type=Path, default=Path("bench_rigid_out"),
                   help="where a pack is settled [bench_rigid_out]")
    p.add_argument("--steps", type=int, default=1000, help="steps measured [1000]")
    p.add_argument("--threads", type=int, help="numba threads [numba's default]")
    p.add_argument("--json", type=Path, help="save the numbers here")
    a = p.parse_args(argv)
    if a.threads:
        numba.set_num_threads(a.threads)
    raw = load_toml(a.config) if a.config else tomllib.loads(example_text("pile"))
    cfg, _ = checked_config(raw)
    if a.state:
        pack = load_state(a.state)
    else:
        print(f"settling the config's pack into {a.out / 'pack'} (reused when there) ...", flush=True)
        pack, _ = initial_state_from(cfg, a.config.parent if a.config else Path.cwd(), a.out)
    r = measure(cfg, pack, a.steps)
    print(f"{r['grains']} rigid grains ({r['vertices']} vertices), {r['contact_pairs']} contact pairs at the end, "
          f"{r['threads']} numba thread(s)")  # fmt: skip
    print(f"  {r['steps']} steps ({r['rejected']} rejected) in {r['wall_s']:.2f} s: {r['steps_per_s']:.0f} steps/s, "
          f"{r['ms_per_step']:.2f} ms per step")  # fmt: skip
    print(f"  {r['grain_steps_per_s']:,.0f} grain-steps/s, {r['grain_steps_per_cpu_s']:,.0f} per CPU-second "
          f"({r['grain_steps_per_cpu_s'] / 1600:.0f}-{r['grain_steps_per_cpu_s'] / 600:.0f}x the 600-1,600 of "
          "rigid polyhedra in other DEM codes)")  # fmt: skip
    print(f"  feature list: {r['feature_list_builds_per_step']:.1f} grain-pair lists rebuilt per step of "
          f"{r['candidate_grain_pairs']} candidate grain pairs")  # fmt: skip
    print("  pieces, ms per call at the end state:")
    for k, v in r["pieces_ms"].items():
        print(f"    {v:7.3f}  {k}")
    if a.json:
        a.json.write_text(json.dumps(r, indent=2))


if __name__ == "__main__":
    main()
