"""The lid's jam stepped for a wall-time budget from a saved lid state, with Newton's or the step
control's settings changed: which of them buys the jam's pace (docs/design-notes.md).

    python benchmarks/bench_jam.py [--state benchmarks/data/lid515_jam.npz] [--seconds 1200] [--steps N]
                                   [--dt 1e-6] [--set solver.max_iterations=30] [--newton stall_share=0.25]
                                   [--json PATH]

The state is a lid run's (benchmarks/jam_state.py writes one; the shipped file is the 515-grain
lid cycle at the real density at 28.5 % strain), rebuilt with its lid on its way down, its contact
law and its friction history (bench_newton.state_case). The integrator is the one `vemdem run`
makes from the `paper-compression-implicit` example's `[solver]` table, with `--set` changing a
config value (as `vemdem sweep --set` spells it) and `--newton KEY=VALUE` a field of
NewmarkParameters that no config key reaches (stall_share, ccd_fraction, krylov_forcing, ...). From
the state's positions, velocities and history (the acceleration solved afresh) it takes steps of
`--dt` at first, the step control choosing the rest, until `--seconds` of wall time or `--steps`
accepted steps, and prints: simulated time, its pace (simulated seconds per wall second), steps
accepted and rejected by cause, Newton iterations per step, Krylov iterations per Newton
iteration, the steps' range and the lid's force. Two settings are compared by running both from
the same state, side by side, with the same threads (docs/design-notes.md, "Newton and the
implicit step"). Nothing asserts a timing.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import platform
import time
import tomllib
from pathlib import Path

import numpy as np

from bench_newton import state_case
from vemdem.config.build import solver_options_from
from vemdem.config.schema import ConfigError
from vemdem.scenarios.registry import checked_config, example_text
from vemdem.solver.api import make_integrator
from vemdem.solver.newmark import NewmarkParameters
from vemdem.solver.state import RunStats
from vemdem.sweep import parse_sets, with_values

JAM = Path(__file__).resolve().parent / "data" / "lid515_jam.npz"
EXAMPLE = "paper-compression-implicit"
# fields of NewmarkParameters that are objects, not settings
NOT_SETTINGS = ("linear", "trace")


def newton_settings(texts: list[str]) -> dict:
    """`KEY=VALUE` texts as NewmarkParameters fields, each typed like the field's default."""
    fields = {f.name: f for f in dataclasses.fields(NewmarkParameters) if f.name not in NOT_SETTINGS}
    settings = {}
    for text in texts:
        key, sep, value = text.partition("=")
        if not sep or key not in fields:
            raise ValueError(f"--newton {text}: KEY=VALUE with KEY one of {', '.join(fields)}")
        kind = type(fields[key].default)
        if kind is bool:
            if value.lower() not in ("true", "false"):
                raise ValueError(f"--newton {key}: true or false, got {value!r}")
            settings[key] = value.lower() == "true"
        else:
            try:
                settings[key] = kind(value)
            except ValueError:
                raise ValueError(f"--newton {key}: a {kind.__name__}, got {value!r}") from None
    return settings


def jam_integrator(state_path: Path, overrides: dict, newton: dict):
    """(integrator, state): the state file's scene under the example's solver, overrides and Newton settings."""
    _, scene, state = state_case(state_path)
    cfg, _ = checked_config(with_values(tomllib.loads(example_text(EXAMPLE)), overrides))
    integrator = make_integrator(solver_options_from(cfg), scene)
    for key, value in newton.items():
        setattr(integrator.params, key, value)
    return integrator, integrator.initial_state(state.x, state.v, history=state.history)


class _Budget(Exception):
    pass


def run_jam(integrator, state, dt: float, seconds: float, steps: int | None = None) -> dict:
    """Step until `seconds` of wall time or `steps` accepted steps; the figures of the module's docstring."""
    integrator.control.dt = dt
    t0, start, rows, stats = state.t, time.perf_counter(), [], RunStats()

    def on_step(s, info, h):
        rows.append((s.t, h, info.iterations, float(info.wall_reactions[-1][2])))
        if time.perf_counter() - start > seconds or (steps is not None and len(rows) >= steps):
            raise _Budget

    try:
        integrator.advance(state, t0 + 1.0, on_step, stats)
    except _Budget:
        pass
    wall = time.perf_counter() - start
    t, h, _, force = np.array(rows).T
    return {"wall_s": wall, "simulated_s": float(t[-1] - t0), "pace": float((t[-1] - t0) / wall),
            "accepted": stats.accepted, "rejected": stats.rejected, "rejections": dict(stats.rejections),
            "newton_per_step": stats.newton_iterations / stats.accepted,
            "krylov_per_newton": stats.krylov_iterations / max(stats.newton_iterations, 1),
            "dt_min": float(h.min()), "dt_median": float(np.median(h)), "dt_max": float(h.max()),
            "lid_force_first": float(force[0]), "lid_force_last": float(force[-1]),
            "lid_force_max": float(force.max())}  # fmt: skip


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--state", type=Path, default=JAM, help=f"a lid run's state file [{JAM.name}]")
    p.add_argument("--seconds", type=float, default=1200.0, help="wall-time budget [1200]")
    p.add_argument("--steps", type=int, help="stop after this many accepted steps instead, if sooner")
    p.add_argument("--dt", type=float, default=1e-6, help="the first step [1e-6 s, the jam's]")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help=f"a config value of the {EXAMPLE} example (solver.max_iterations=30)")
    p.add_argument("--newton", action="append", default=[], metavar="KEY=VALUE",
                   help="a NewmarkParameters field no config key reaches (stall_share=0.25, ccd_fraction=0.5)")
    p.add_argument("--json", type=Path, help="also write the figures here")
    args = p.parse_args(argv)
    if not args.state.is_file():
        p.error(f"--state: no file {args.state}")
    try:
        sets = parse_sets(args.set)
        newton = newton_settings(args.newton)
    except (ConfigError, ValueError) as exc:
        p.error(str(exc))
    if any(len(values) != 1 for values in sets.values()):
        p.error("--set: one value per key")
    overrides = {key: values[0] for key, values in sets.items()}
    print(f"jam bench, {time.strftime('%Y-%m-%d %H:%M')}, {platform.processor() or platform.machine()}, "
          f"{os.cpu_count()} cores, NUMBA_NUM_THREADS={os.environ.get('NUMBA_NUM_THREADS', 'default')}")  # fmt: skip
    try:
        integrator, state = jam_integrator(args.state, overrides, newton)
    except ConfigError as exc:
        p.error(str(exc))
    print(f"{args.state}: {integrator.scene.n_grains} grains; --set {overrides or 'none'}, --newton {newton or 'none'}")
    result = {"state": str(args.state), "set": overrides, "newton": newton,
              **run_jam(integrator, state, args.dt, args.seconds, args.steps)}  # fmt: skip
    for key, value in result.items():
        print(f"  {key}: {value:.4g}" if isinstance(value, float) else f"  {key}: {value}")
    if args.json:
        args.json.write_text(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
