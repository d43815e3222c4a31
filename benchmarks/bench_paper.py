"""Wall time of the paper's runs: the 515-grain pack, the three collapses and the lid cycle.

    python benchmarks/bench_paper.py                 # the paper's configs (hours on 2 cores)
    python benchmarks/bench_paper.py --grains 16     # the same configs with fewer grains (minutes)
    python benchmarks/bench_paper.py --only pack,high --out runs/

Each run is the `paper-*` example run through the library as `vemdem run` would, in OUT/<name>;
`compression-pack` is `paper-compression` started from OUT/pack/state.npz (the paper's own setup:
the lid cycle on the 515-grain, 6 mm pack).
a run whose summary.json already exists is read, not rerun (so an interrupted sweep goes on
where it stopped; an interrupted run itself resumes from its checkpoint). Prints one row per run:
grains, simulated time, accepted steps, wall seconds, steps/s, grain-steps/s and the run's
headline figures, and the ratio of each wall time to the 2-hour target of issue 5.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
import tomllib
from pathlib import Path

from vemdem.scenarios.registry import checked_config, example_text

RUNS = {
    "pack": "paper-pack",
    "high": "paper-collapse-high",
    "mid": "paper-collapse-mid",
    "low": "paper-collapse-low",
    "compression": "paper-compression",
    # the paper's own setup: the lid cycle on the 515-grain paper-pack (6 mm) instead of its own 110-grain pack
    "compression-pack": "paper-compression",
}
TARGET_S = 2 * 3600.0
HEADLINES = ("pack_height", "packing_fraction", "angle_of_repose_deg", "angle_of_repose_uncertainty_deg",
             "pile_height", "runout", "peak_force", "hysteresis_energy", "residual_strain")  # fmt: skip


def config_for(name: str, out: Path, grains: int | None) -> dict:
    raw = tomllib.loads(example_text(RUNS[name]))
    if name in ("high", "mid", "low", "compression-pack"):
        raw["initial_state"] = str(out / "pack" / "state.npz")
        raw.pop("pack", None)
    if grains is not None:
        if name == "pack":
            raw["n_grains"] = grains
        elif name == "compression":
            raw["pack"]["n_grains"] = grains
            raw["pack"]["box"] = {"width": 5.5e-3, "depth": 5.5e-3}
            raw["lid"]["start"], raw["lid"]["end"] = 3.5e-3, 2.4e-3  # a few grains stand lower
    return checked_config(raw)


def run_one(name: str, out: Path, grains: int | None) -> dict:
    cfg, module = config_for(name, out, grains)
    folder = out / name
    done = folder / "summary.json"
    if done.is_file():
        return json.loads(done.read_text())
    return module.run(cfg, folder, resume=(folder / "checkpoint.npz").is_file())


def row(name: str, s: dict) -> str:
    wall = s["wall_seconds"]
    steps = s["n_steps"]
    figures = ", ".join(f"{k} {s[k]:.4g}" for k in HEADLINES if isinstance(s.get(k), int | float))
    return (f"| {name} | {s['n_grains']} | {s['simulated_time']:.3g} | {steps:,} | {wall:,.0f} | "
            f"{steps / wall:.1f} | {steps * s['n_grains'] / wall:,.0f} | {wall / TARGET_S:.2f} | {figures} |")  # fmt: skip


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--grains", type=int, help="grains of the pack (and of the compression's pack) [the paper's]")
    p.add_argument("--only", default=",".join(RUNS), help=f"runs, comma-separated [{','.join(RUNS)}]")
    p.add_argument("--out", type=Path, default=Path("paper-runs"), help="folder of the runs [paper-runs]")
    args = p.parse_args(argv)
    names = [n.strip() for n in args.only.split(",") if n.strip()]
    unknown = set(names) - set(RUNS)
    if unknown:
        p.error(f"--only: unknown runs {sorted(unknown)} (known: {', '.join(RUNS)})")
    if args.grains is not None and "compression-pack" in names:
        p.error("compression-pack presses the paper's 6 mm pack: it has no few-grain version (leave out --grains)")
    print(f"paper runs, {time.strftime('%Y-%m-%d %H:%M')}, {platform.processor() or platform.machine()}, "
          f"{os.cpu_count()} cores, NUMBA_NUM_THREADS={os.environ.get('NUMBA_NUM_THREADS', 'default')}")  # fmt: skip
    print("| run | grains | simulated s | steps | wall s | steps/s | grain-steps/s | wall / 2 h | figures |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name in names:
        print(row(name, run_one(name, args.out, args.grains)), flush=True)


if __name__ == "__main__":
    main()
