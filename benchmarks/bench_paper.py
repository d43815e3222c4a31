"""Wall time of the paper's runs: the 515-grain pack, the three collapses and the lid cycle.

    python benchmarks/bench_paper.py                 # the paper's configs (hours on 2 cores)
    python benchmarks/bench_paper.py --grains 16     # the same configs with fewer grains (minutes)
    python benchmarks/bench_paper.py --only pack,high --out runs/
    python benchmarks/bench_paper.py --implicit --no-vtk --out real/     # the real-density runs
    python benchmarks/bench_paper.py --implicit --only mid --pack-state rpack/state.npz
    python benchmarks/bench_paper.py --implicit --only compression-pack --lid-turn 0.22 --pack-state rpack/state.npz
    python benchmarks/bench_paper.py --implicit --only compression-pack --set solver.max_iterations=30 ...

Each run is the `paper-*` example run through the library as `vemdem run` would, in OUT/<name>;
`compression-pack` is `paper-compression` started from the pack (the paper's own setup: the lid
cycle on the 515-grain, 6 mm pack). The collapses and `compression-pack` start from OUT/pack/state.npz,
or from `--pack-state` (docs/validation.md times the real-density collapses from a rigid-grain pack
settled at the real density: `paper-pack` with `[model] grains = "rigid"` and `mass_scaling = 1`).
`--implicit` runs the `paper-*-implicit` examples instead: the paper's own method, implicit Newmark
at the real density, with no mass scaling. `--no-vtk` leaves the frames out (the docs' wall times).
`--lid-turn E` turns the lids at compressive strain E of their start height instead of the paper's
4.9 mm (docs/validation.md, "Cycles turned before the jam"). `--set KEY=VALUE` changes one config value of
every run (the step control's budget of docs/design-notes.md: `--set solver.max_iterations=30
--set solver.easy_iterations=16`).
A run whose summary.json already exists is read, not rerun (so an interrupted sweep goes on
where it stopped; an interrupted run itself resumes from its checkpoint). Prints one row per run:
grains, simulated time, accepted steps, wall seconds, steps/s, grain-steps/s and the run's
headline figures, and the ratio of each wall time to its target: 2 hours for the mass-scaled runs
and 1 hour at the real density (the goal there: 10 minutes).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
import tomllib
from pathlib import Path

from vemdem.analysis.spring_back import spring_back_shares
from vemdem.config import ConfigError
from vemdem.scenarios.registry import checked_config, example_text
from vemdem.sweep import parse_sets, with_values

RUNS = {
    "pack": "paper-pack",
    "high": "paper-collapse-high",
    "mid": "paper-collapse-mid",
    "low": "paper-collapse-low",
    "compression": "paper-compression",
    # the paper's own setup: the lid cycle on the 515-grain paper-pack (6 mm) instead of its own 110-grain pack
    "compression-pack": "paper-compression",
}
TARGET_S = {False: 2 * 3600.0, True: 3600.0}  # by --implicit
HEADLINES = ("pack_height", "packing_fraction", "angle_of_repose_deg", "angle_of_repose_uncertainty_deg",
             "pile_height", "runout", "peak_force", "hysteresis_energy", "residual_strain",
             "residual_strain_absolute")  # fmt: skip

def config_for(name: str, out: Path, grains: int | None, implicit: bool = False, pack_state: Path | None = None,
               vtk: bool = True, lid_turn: float | None = None, overrides: dict | None = None) -> tuple:  # fmt: skip
    """The checked config of one run and its scenario module (registry.checked_config)."""
    raw = tomllib.loads(example_text(RUNS[name] + ("-implicit" if implicit else "")))
    if name in ("high", "mid", "low", "compression-pack"):
        raw["initial_state"] = str(Path(pack_state).resolve() if pack_state else out / "pack" / "state.npz")
        raw.pop("pack", None)
    if not vtk:
        raw.setdefault("output", {})["vtk"] = False
    if grains is not None:
        if name == "pack":
            raw["n_grains"] = grains
        elif name == "compression":
            raw["pack"]["n_grains"] = grains
            raw["pack"]["box"] = {"width": 5.5e-3, "depth": 5.5e-3}
            raw["lid"]["start"], raw["lid"]["end"] = 3.5e-3, 2.4e-3  # a few grains stand lower
    if lid_turn is not None and "lid" in raw:
        raw["lid"]["end"] = round(raw["lid"]["start"] * (1.0 - lid_turn), 9)  # to the nm: 5.6 mm as one types it
    return checked_config(with_values(raw, overrides or {}))


def run_one(name: str, out: Path, grains: int | None, **options) -> dict:
    cfg, module = config_for(name, out, grains, **options)
    folder = out / name
    done = folder / "summary.json"
    if done.is_file():
        return json.loads(done.read_text())
    return module.run(cfg, folder, resume=(folder / "checkpoint.npz").is_file())


def row(name: str, s: dict, target: float) -> str:
    wall = s.get("wall_seconds_total") or s["wall_seconds"]  # a resumed run: every part
    steps = s["n_steps"]
    figures = ", ".join(f"{k} {s[k]:.4g}" for k in HEADLINES if isinstance(s.get(k), int | float))
    back = s.get("spring_back", {})
    share = spring_back_shares(back)
    if share is not None:
        figures += (f", spring-back {back['branch_strain']:.4g} (grains {share['deformation']:.0%}, "
                    f"gaps {share['contact_gap']:.0%})")  # fmt: skip
    return (f"| {name} | {s['n_grains']} | {s['simulated_time']:.3g} | {steps:,} | {wall:,.0f} | "
            f"{steps / wall:.1f} | {steps * s['n_grains'] / wall:,.0f} | {wall / target:.2f} | {figures} |")  # fmt: skip


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--grains", type=int, help="grains of the pack (and of the compression's pack) [the paper's]")
    p.add_argument("--only", default=",".join(RUNS), help=f"runs, comma-separated [{','.join(RUNS)}]")
    p.add_argument("--out", type=Path, default=Path("paper-runs"), help="folder of the runs [paper-runs]")
    p.add_argument("--implicit", action="store_true",
                   help="the paper-*-implicit examples: implicit Newmark at the real density, no mass scaling")
    p.add_argument("--pack-state", type=Path,
                   help="start the collapses and compression-pack from this state.npz [OUT/pack/state.npz]")
    p.add_argument("--no-vtk", action="store_true", help="write no VTK frames (the wall times of docs/validation.md)")
    p.add_argument("--lid-turn", type=float, metavar="E",
                   help="turn the lids at compressive strain E (0 < E < 1) of their start height [the paper's 4.9 mm]")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="one config value for every run, as `vemdem sweep --set` spells it (solver.max_iterations=30)")
    args = p.parse_args(argv)
    if args.lid_turn is not None and not 0.0 < args.lid_turn < 1.0:
        p.error(f"--lid-turn: a strain between 0 and 1, got {args.lid_turn}")
    try:
        sets = parse_sets(args.set)
    except ConfigError as exc:
        p.error(str(exc))
    for key, values in sets.items():
        if len(values) != 1:
            p.error(f"--set {key}: one value per key (a sweep of values is `vemdem sweep`)")
    overrides = {key: values[0] for key, values in sets.items()}
    names = [n.strip() for n in args.only.split(",") if n.strip()]
    unknown = set(names) - set(RUNS)
    if unknown:
        p.error(f"--only: unknown runs {sorted(unknown)} (known: {', '.join(RUNS)})")
    if args.grains is not None and "compression-pack" in names:
        p.error("compression-pack presses the paper's 6 mm pack: it has no few-grain version (leave out --grains)")
    print(f"paper runs, {time.strftime('%Y-%m-%d %H:%M')}, {platform.processor() or platform.machine()}, "
          f"{os.cpu_count()} cores, NUMBA_NUM_THREADS={os.environ.get('NUMBA_NUM_THREADS', 'default')}")  # fmt: skip
    if args.pack_state is not None and not args.pack_state.is_file():
        p.error(f"--pack-state: no file {args.pack_state}")
    target = TARGET_S[args.implicit]
    print(f"{'implicit, real density' if args.implicit else 'explicit, mass-scaled'} (the paper-*"
          f"{'-implicit' if args.implicit else ''} examples)")  # fmt: skip
    print(f"| run | grains | simulated s | steps | wall s | steps/s | grain-steps/s | wall / {target / 3600:.0f} h | figures |")
    print("|---|---|---|---|---|---|---|---|---|")
    options = dict(implicit=args.implicit, pack_state=args.pack_state, vtk=not args.no_vtk, lid_turn=args.lid_turn,
                   overrides=overrides)  # fmt: skip
    for name in names:
        try:
            summary = run_one(name, args.out, args.grains, **options)
        except ConfigError as exc:  # a --set value the config check refuses
            p.error(f"{name}: {exc}")
        print(row(name, summary, target), flush=True)


if __name__ == "__main__":
    main()
