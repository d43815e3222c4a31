"""Flexible grains against rigid ones on the same settled pack: the explicit step with selective
mass scaling (docs/selective-mass-scaling.md).

    python benchmarks/bench_flexible.py                         # the main job's collapse (pile)
    python benchmarks/bench_flexible.py --examples pile,oedometer,triaxial --out runs/flex
    python benchmarks/bench_flexible.py --lambdas auto,0 --max-time 0.05
    python benchmarks/bench_flexible.py --examples pile24 --lambdas 1e4,3e6 --set contact.mu_s=0 \
        --set contact.mu_d=0 --max-time 0.1          # the energy books' table (docs/selective-mass-scaling.md)
    python benchmarks/bench_flexible.py --auto-table  # what "auto" gives under the weight's and the lab laws
    python benchmarks/bench_flexible.py --examples triaxial --seeds 1,2,3   # the lab, three packs
    python benchmarks/bench_flexible.py --examples oedometer --seeds 1,2,3 --stage-time 0.02

For each example: its pack is settled once with rigid grains (the example as shipped, into
OUT/NAME/pack-run/pack), then the test runs from that pack (`initial_state`) with rigid grains and with
flexible grains on the explicit step under each selective mass scaling of `--lambdas` ("auto" or
numbers; 0 is the unscaled lumped mass, bound by the grains' own vibration: give it a short
`--max-time`). A short warm-up compiles the kernels first, so the wall times compare models, not
compilers. Prints one row per run: steps, simulated time, wall time, grain-steps per second,
the headline figures, and the flexible/rigid wall-time ratio on the same pack. Nothing asserts a
timing. `pile24` is `bench_pile.py`'s 24-grain pile at the real density (minutes, not the main job's tens of
minutes); `--set TABLE.KEY=VALUE` changes a key of every run (e.g. `solver.safety=0.1`,
`contact.damping_ratio=0`); each run's energy books are printed (`balance_error`). `--seeds` runs
each example on the packs of those `[pack] seed`s and prints, per run kind, the mean and spread of
the headline figures and of the wall-time ratio over the seeds.
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import tomllib
import warnings
from pathlib import Path

import numpy as np

from vemdem.scenarios.pack import initial_state_from
from vemdem.scenarios.registry import checked_config, example_text
from vemdem.verification.impact import head_on

HEADLINES = {  # summary keys worth printing, by scenario
    "pile_collapse": ("angle_of_repose_deg", "angle_uncertainty_deg", "pile_height"),
    "oedometer": ("K0", "max_stress_Pa"),
    "triaxial": ("phi_peak_deg", "phi_cs_deg", "E50_Pa"),
    "direct_shear": ("phi_peak_deg", "phi_residual_deg"),
}


def _example(name: str) -> dict:
    if name == "pile24":
        from bench_pile import PILE  # noqa: PLC0415 - a sibling script, found from this folder

        raw = copy.deepcopy(PILE)
        raw["solver"] = {"integrator": "explicit", "mass_scaling": 1.0}  # the real density (PILE's is 1e6)
        return raw
    return tomllib.loads(example_text(name))


def _apply(raw: dict, settings: list[str], stage_time: float | None = None) -> dict:
    if stage_time is not None:
        for stage in raw.get("stages", []):
            stage["max_time"] = stage_time
    for item in settings:
        key, value = item.split("=", 1)
        table, name = key.split(".")
        raw.setdefault(table, {})[name] = tomllib.loads(f"v = {value}")["v"]
    return raw


def _run(raw: dict, out: Path) -> dict:
    cfg, module = checked_config(copy.deepcopy(raw))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return module.run(cfg, out, base_dir=None, progress=None)


def _settle(raw: dict, out: Path) -> Path:
    """The example's pack, settled with rigid grains into OUT/pack (its scenario's own pack stage),
    and its state file."""
    cfg, module = checked_config(copy.deepcopy(raw))
    pack_cfg = module.pack_config_for(cfg) if hasattr(module, "pack_config_for") else None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return initial_state_from(cfg, None, out, None, False, pack_cfg)[1]


def _variant(raw: dict, pack_state: Path | None, grains: str, lam, max_time: float | None) -> dict:
    raw = copy.deepcopy(raw)
    if pack_state is not None:
        raw.pop("pack", None)
        raw["initial_state"] = str(pack_state)
    raw.setdefault("model", {})["grains"] = grains
    raw.setdefault("solver", {}).update(integrator="explicit")
    if grains == "flexible":
        raw["solver"]["selective_mass_scaling"] = lam
    if max_time is not None and raw["scenario"] == "pile_collapse":
        settle = raw.setdefault("settle", {})
        settle["max_time"] = max_time
        settle["min_time"] = min(settle.get("min_time", max_time), max_time)
    return raw


def _row(name: str, label: str, summary: dict) -> dict:
    headline = {k: summary.get(k) for k in HEADLINES.get(summary.get("scenario"), ()) if k in summary}
    steps, wall = summary.get("n_steps", 0), summary.get("wall_seconds", float("nan"))
    return {"example": name, "run": label, "steps": steps, "wall_s": wall,
            "grain_steps_per_s": steps * summary.get("n_grains", 0) / wall if wall else float("nan"),
            "selective_mass_scaling": summary.get("selective_mass_scaling"),
            "balance_error": (summary.get("energy") or {}).get("balance_error"), **headline}  # fmt: skip


def bench(name: str, out: Path, lambdas: list, max_time: float | None, settings: list[str],
          seed: int | None = None, stage_time: float | None = None, pack_settings: tuple = ()) -> list[dict]:  # fmt: skip
    raw = _apply(_example(name), list(pack_settings))
    raw.pop("initial_state", None)
    if seed is not None:
        raw["pack"]["seed"] = seed
        out = out / f"seed{seed}"
    pack = _settle(_variant(raw, None, "rigid", 0.0, None), out / "pack-run")
    rigid = _apply(_variant(raw, pack, "rigid", 0.0, max_time), settings, stage_time)
    rows = [_row(name, "rigid", _run(rigid, out / "rigid"))]
    for lam in lambdas:
        flexible = _apply(_variant(raw, pack, "flexible", lam, max_time), settings, stage_time)
        summary = _run(flexible, out / f"flexible-{lam}")
        rows.append(_row(name, f"flexible, SMS {lam}", summary))
    rigid_wall = rows[0]["wall_s"]
    for r in rows:
        r["seed"] = seed
        r["wall_ratio_to_rigid"] = r["wall_s"] / rigid_wall
    return rows


def over_seeds(rows: list[dict]) -> list[dict]:
    """Per example and run kind: the mean and standard deviation over the seeds of every number a
    row carries (headline figures, steps, the wall-time ratio), and the flexible runs' differences
    from the rigid run on the same pack (seed by seed, then averaged)."""
    out = []
    for name in dict.fromkeys(r["example"] for r in rows):
        mine = [r for r in rows if r["example"] == name]
        rigid = {r["seed"]: r for r in mine if r["run"] == "rigid"}
        for label in dict.fromkeys(r["run"] for r in mine):
            runs = [r for r in mine if r["run"] == label]
            entry = {"example": name, "run": label, "seeds": [r["seed"] for r in runs]}
            for key, value in runs[0].items():
                values = [r.get(key) for r in runs]
                if isinstance(value, (int, float)) and key != "seed" and None not in values:
                    entry[key] = [float(np.mean(values)), float(np.std(values))]
                    if label != "rigid" and key in _headline_keys():
                        diffs = [r[key] - rigid[r["seed"]][key] for r in runs if rigid[r["seed"]].get(key) is not None]
                        entry[f"{key}_minus_rigid"] = [float(np.mean(diffs)), float(np.std(diffs))]
            out.append(entry)
    return out


def _headline_keys() -> set:
    return {k for keys in HEADLINES.values() for k in keys}


def auto_table(size: float = 0.9e-3, E: float = 90e9, density: float = 2200.0) -> None:
    """What "auto" chooses for 0.9 mm sand grains under the weight's law and the laws a laboratory
    test sets for its stress (reference force 2 sigma d^2): no run, the grains' spectra only."""
    from vemdem.contact.defaults import default_contact_laws, material_contact_laws  # noqa: PLC0415
    from vemdem.geometry import sand_grain  # noqa: PLC0415
    from vemdem.model.scene import Scene  # noqa: PLC0415
    from vemdem.model.selective import auto_selective_scaling  # noqa: PLC0415
    from vemdem.vem.material import Material  # noqa: PLC0415

    grains = [sand_grain(size, 30, seed=s) for s in range(6)]
    for label, stress in (("the weight's", None), ("25 kPa", 25e3), ("100 kPa", 100e3), ("1 MPa", 1e6)):
        force = {} if stress is None else {"reference_force": 2.0 * stress * size**2}
        law, friction = default_contact_laws(size, E, density, 9.81, **force)
        scene = Scene.build(grains, Material(E, 0.16, density), law, friction)
        print(json.dumps({"law": label, "run": "collision", **auto_selective_scaling(scene)}))
        if stress is not None:  # the lab test at that stress, driven at I = 5e-4
            print(json.dumps({"law": label, "run": "lab test, I = 5e-4", **auto_selective_scaling(scene, (5e-4, stress))}))
    law, friction = material_contact_laws(size, E, 0.16)
    scene = Scene.build(grains, Material(E, 0.16, density), law, friction)
    for label, stress in (("the material's, 25 kPa", 25e3), ("the material's, 100 kPa", 100e3),
                          ("the material's, 1 MPa", 1e6)):  # fmt: skip
        print(json.dumps({"law": label, "run": "lab test, I = 5e-4", **auto_selective_scaling(scene, (5e-4, stress))}))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--examples", default="pile", help="comma-separated example names")
    parser.add_argument("--lambdas", default="auto", help='selective mass scalings: "auto" or numbers, comma-separated')
    parser.add_argument("--max-time", type=float, default=None, help="cap on a collapse's [settle] max_time (s)")
    parser.add_argument("--out", type=Path, default=Path("bench-flexible"))
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--set", action="append", default=[], metavar="TABLE.KEY=VALUE",
                        help="a config key of every run after the pack (repeatable)")
    parser.add_argument("--pack-set", action="append", default=[], metavar="TABLE.KEY=VALUE",
                        help="a config key of the example before its pack settles, and so of every run "
                             "(pack.mu_s=0.15; contact.reference_force=0.162: the law the pack settles under)")
    parser.add_argument("--stage-time", type=float, default=None,
                        help="every [[stages]] max_time (s): an oedometer's stages end there if not at rest before")
    parser.add_argument("--seeds", default=None, help="comma-separated [pack] seeds: each example on each seed's pack")
    parser.add_argument("--auto-table", action="store_true", help='print what "auto" chooses under four laws, and stop')
    args = parser.parse_args()
    if args.auto_table:
        auto_table()
        return
    lambdas = [x if x == "auto" else float(x) for x in args.lambdas.split(",")]
    print(f"threads {os.environ.get('NUMBA_NUM_THREADS', 'all')}, load average {os.getloadavg()[0]:.1f}")
    head_on(1.0, selective_mass_scaling=1e6)  # warm-up: the flexible explicit step's kernels compile here
    seeds = [int(s) for s in args.seeds.split(",")] if args.seeds else [None]
    rows = []
    for name in args.examples.split(","):
        for seed in seeds:
            new = bench(name, args.out / name, lambdas, args.max_time, args.set, seed, args.stage_time, args.pack_set)
            for r in new:
                print(json.dumps(r), flush=True)
            rows += new
    if args.seeds:
        rows += [{"over_seeds": True, **entry} for entry in over_seeds(rows)]
        for entry in rows:
            if entry.get("over_seeds"):
                print(json.dumps(entry))
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
