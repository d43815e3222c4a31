"""Flexible grains against rigid ones on the same settled pack: the explicit step with selective
mass scaling (docs/selective-mass-scaling.md).

    python benchmarks/bench_flexible.py                         # the main job's collapse (pile)
    python benchmarks/bench_flexible.py --examples pile,oedometer,triaxial --out runs/flex
    python benchmarks/bench_flexible.py --lambdas auto,0 --max-time 0.05
    python benchmarks/bench_flexible.py --examples pile24 --lambdas 1e4,3e6 --set contact.mu_s=0 \
        --set contact.mu_d=0 --max-time 0.1          # the energy books' table (docs/selective-mass-scaling.md)
    python benchmarks/bench_flexible.py --auto-table  # what "auto" gives under the weight's and the lab laws

For each example: its pack is settled once with rigid grains (the example as shipped, into
OUT/NAME/pack-run), then the test runs from that pack (`initial_state`) with rigid grains and with
flexible grains on the explicit step under each selective mass scaling of `--lambdas` ("auto" or
numbers; 0 is the unscaled lumped mass, bound by the grains' own vibration: give it a short
`--max-time`). A short warm-up compiles the kernels first, so the wall times compare models, not
compilers. Prints one row per run: steps, simulated time, wall time, grain-steps per second,
the headline figures, and the flexible/rigid wall-time ratio on the same pack. Nothing asserts a
timing. `pile24` is `bench_pile.py`'s 24-grain pile at the real density (minutes, not the main job's tens of
minutes); `--set TABLE.KEY=VALUE` changes a key of every run (e.g. `solver.safety=0.1`,
`contact.damping_ratio=0`); each run's energy books are printed (`balance_error`).
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import tomllib
import warnings
from pathlib import Path

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


def _apply(raw: dict, settings: list[str]) -> dict:
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


def bench(name: str, out: Path, lambdas: list, max_time: float | None, settings: list[str]) -> list[dict]:
    raw = _example(name)
    raw.pop("initial_state", None)
    rigid = _variant(raw, None, "rigid", 0.0, None)
    _run(rigid, out / "pack-run")  # settles the pack (the example's own, with rigid grains)
    pack = out / "pack-run" / "pack" / "state.npz"
    rows = [_row(name, "rigid", _run(_apply(_variant(raw, pack, "rigid", 0.0, max_time), settings), out / "rigid"))]
    for lam in lambdas:
        summary = _run(_apply(_variant(raw, pack, "flexible", lam, max_time), settings), out / f"flexible-{lam}")
        rows.append(_row(name, f"flexible, SMS {lam}", summary))
    return rows


def auto_table(size: float = 0.9e-3, E: float = 90e9, density: float = 2200.0) -> None:
    """What "auto" chooses for 0.9 mm sand grains under the weight's law and the laws a laboratory
    test sets for its stress (reference force 2 sigma d^2): no run, the grains' spectra only."""
    from vemdem.contact.defaults import default_contact_laws  # noqa: PLC0415
    from vemdem.geometry import sand_grain  # noqa: PLC0415
    from vemdem.model.scene import Scene  # noqa: PLC0415
    from vemdem.model.selective import auto_selective_scaling  # noqa: PLC0415
    from vemdem.vem.material import Material  # noqa: PLC0415

    grains = [sand_grain(size, 30, seed=s) for s in range(6)]
    for label, stress in (("the weight's", None), ("25 kPa", 25e3), ("100 kPa", 100e3), ("1 MPa", 1e6)):
        force = {} if stress is None else {"reference_force": 2.0 * stress * size**2}
        law, friction = default_contact_laws(size, E, density, 9.81, **force)
        auto = auto_selective_scaling(Scene.build(grains, Material(E, 0.16, density), law, friction))
        print(json.dumps({"law": label, **auto}))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--examples", default="pile", help="comma-separated example names")
    parser.add_argument("--lambdas", default="auto", help='selective mass scalings: "auto" or numbers, comma-separated')
    parser.add_argument("--max-time", type=float, default=None, help="cap on a collapse's [settle] max_time (s)")
    parser.add_argument("--out", type=Path, default=Path("bench-flexible"))
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--set", action="append", default=[], metavar="TABLE.KEY=VALUE",
                        help="a config key of every run after the pack (repeatable)")
    parser.add_argument("--auto-table", action="store_true", help='print what "auto" chooses under four laws, and stop')
    args = parser.parse_args()
    if args.auto_table:
        auto_table()
        return
    lambdas = [x if x == "auto" else float(x) for x in args.lambdas.split(",")]
    print(f"threads {os.environ.get('NUMBA_NUM_THREADS', 'all')}, load average {os.getloadavg()[0]:.1f}")
    head_on(1.0, selective_mass_scaling=1e6)  # warm-up: the flexible explicit step's kernels compile here
    rows = []
    for name in args.examples.split(","):
        rows += bench(name, args.out / name, lambdas, args.max_time, args.set)
        rigid = next(r for r in rows if r["example"] == name and r["run"] == "rigid")
        for r in rows:
            if r["example"] == name:
                r["wall_ratio_to_rigid"] = r["wall_s"] / rigid["wall_s"]
                print(json.dumps(r))
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
