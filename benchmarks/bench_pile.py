"""The small pile both ways: implicit at the real density against explicit with mass scaling 1e6.

    python benchmarks/bench_pile.py                  # both runs, warm kernels (about 2 minutes)
    python benchmarks/bench_pile.py --dt-max 1e-3    # the implicit run with a larger step cap too
    python benchmarks/bench_pile.py --out runs/ --keep

The target: a small pile run implicitly at the real density in at most twice the wall time of
the mass-scaled explicit run (goal: no slower). The pile is 24 sand grains of 16 vertices, 1.45 mm,
settled in a 5.2 mm box at mu 0.9/0.8, then its walls removed (the README's main job is the
160-grain corner collapse of rigid grains).
Both runs go through the library as `vemdem run` would, pack stage and collapse, after a short
warm-up that compiles every kernel they use, so the wall times compare integrators, not
compilers. Prints one row per run and the ratio of each run's wall time to the explicit one. The
collapse is chaotic: a change at the round-off (a sum in another order) gives another trajectory
and another step count, so the ratio moves by 10-30 % between versions that cost the same per
step; the milliseconds per step are the steadier figure.
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import platform
import shutil
import tempfile
import time
import warnings
from pathlib import Path

from vemdem.config.build import MassScalingWarning
from vemdem.scenarios.registry import checked_config

PILE = {  # a 24-grain pile (docs/performance.md, "The small pile")
    "scenario": "pile_collapse",
    "pack": {"n_grains": 24, "seed": 1, "mu_s": 0.9, "mu_d": 0.8, "grains": {"size": 1.45e-3, "vertices": 16},
             "box": {"width": 5.2e-3, "depth": 5.2e-3}},  # fmt: skip
    "material": {"E": 90e9, "nu": 0.16, "density": 2200.0},
    "contact": {"mu_s": 0.9, "mu_d": 0.8},
    "solver": {"integrator": "explicit", "mass_scaling": 1e6},
    "settle": {"kinetic_threshold": 1e-3, "max_time": 0.4},
    "output": {"every": 5e-3, "vtk": False},
}


def pile(integrator: str, mass_scaling: float, dt_max: float | None = None, max_time: float | None = None) -> dict:
    raw = copy.deepcopy(PILE)  # the nested [pack] tables too: a config check may fill them in
    raw["solver"] = {"integrator": integrator, "mass_scaling": mass_scaling}
    if dt_max is not None:
        raw["solver"]["dt_max"] = dt_max
    if max_time is not None:  # the warm-up: a few steps of each stage
        # one frame, at rest or not at its end (output.every and settle.min_time may not exceed max_time)
        raw["settle"] = dict(raw["settle"], max_time=max_time, min_time=max_time)
        raw["output"] = dict(raw["output"], every=min(raw["output"]["every"], max_time))
    return raw


def run(raw: dict, folder: Path) -> tuple[dict, float]:
    """(summary of the collapse, wall seconds of pack + collapse)."""
    cfg, module = checked_config(raw)
    shutil.rmtree(folder, ignore_errors=True)
    t0 = time.perf_counter()
    summary = module.run(cfg, folder)
    return summary, time.perf_counter() - t0


def pack_summary(folder: Path) -> dict:
    return json.loads((folder / "pack" / "summary.json").read_text())


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--dt-max", type=float, action="append", default=[],
                   help="also run the implicit pile with this solver.dt_max (repeatable)")  # fmt: skip
    p.add_argument("--out", type=Path, help="folder for the runs [a temporary one]")
    p.add_argument("--keep", action="store_true", help="keep the runs' outputs (with --out)")
    args = p.parse_args(argv)
    warnings.simplefilter("ignore", MassScalingWarning)  # 1e6 is not neutral: the explicit run is the old reference
    out = args.out or Path(tempfile.mkdtemp(prefix="bench_pile_"))
    runs = [("explicit, mass scaling 1e6", pile("explicit", 1e6)), ("implicit, real density", pile("implicit", 1.0))]
    runs += [(f"implicit, real density, dt_max {d:g} s", pile("implicit", 1.0, d)) for d in args.dt_max]
    print(f"pile of 24 grains, {time.strftime('%Y-%m-%d %H:%M')}, {platform.processor() or platform.machine()}, "
          f"{os.cpu_count()} cores, NUMBA_NUM_THREADS={os.environ.get('NUMBA_NUM_THREADS', 'default')}")  # fmt: skip
    for _, raw in runs[:2]:  # compile every kernel both integrators use
        run(pile(raw["solver"]["integrator"], raw["solver"]["mass_scaling"], max_time=2e-3), out / "warm-up")
    print("| run | pack steps (rejected) | collapse steps (rejected) | Newton it./step | pile height mm | runout mm | "
          "wall s | ms per step | / explicit |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|")
    reference = None
    for k, (name, raw) in enumerate(runs):
        folder = out / f"run{k}"
        s, wall = run(raw, folder)
        pack = pack_summary(folder)
        reference = reference or wall
        newton = "-" if raw["solver"]["integrator"] == "explicit" else (
            f"{pack['newton_iterations_per_step']:.1f}, {s['newton_iterations_per_step']:.1f}")  # fmt: skip
        height, runout = s.get("pile_height"), s.get("runout")
        per_step = 1e3 * wall / (pack["n_steps"] + s["n_steps"])
        print(f"| {name} | {pack['n_steps']:,} ({pack['n_rejected_steps']}) | {s['n_steps']:,} "
              f"({s['n_rejected_steps']}) | {newton} | {height * 1e3:.2f} | {runout * 1e3:.2f} | {wall:.1f} | "
              f"{per_step:.2f} | {wall / reference:.2f} |", flush=True)  # fmt: skip
    if not (args.keep and args.out):
        shutil.rmtree(out / "warm-up", ignore_errors=True)
        for k in range(len(runs)):
            shutil.rmtree(out / f"run{k}", ignore_errors=True)
        if args.out is None:
            shutil.rmtree(out, ignore_errors=True)


if __name__ == "__main__":
    main()
