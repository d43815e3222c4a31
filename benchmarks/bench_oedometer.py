"""Steps and Newton iterations per decade of stress: the oedometer's lid stress-controlled (the
servo and its stages) against displacement-controlled (the lid at a constant speed), on the same
settled pack, the same contact law and solver.

    python benchmarks/bench_oedometer.py                          # the `oedometer` example's pack
    python benchmarks/bench_oedometer.py --config job.toml --low 25e3 --high 250e3

Both runs start from the config's pack (settled into --out/pack first, or its `initial_state`), under
the oedometer's law for the decade (set for --high unless the config gives `reference_force`).
Stress-controlled: the config's servo with two stages, --low then --high; the decade is the second
stage (from the first target, reached at rest, to the second, reached at rest). Displacement-
controlled: the lid at a constant speed, the servo's speed cap at --high (the fastest the
quasi-static bound allows), from where the lid's stress passes --low to where it passes --high.
Printed per run: steps (rejected), Newton iterations, simulated and wall time, per decade of stress
(log10(high / low) decades), and the ratio displacement / stress control.
"""

from __future__ import annotations

import argparse
import sys
import time
import tomllib
from pathlib import Path

import numpy as np

from vemdem.config.build import scene_from, solver_options_from
from vemdem.driver.loop import simulate
from vemdem.lab.path import LoadPath
from vemdem.lab.servo import Servo
from vemdem.scenarios.identity import run_identity
from vemdem.scenarios.oedometer import SCHEMA, Oedometer, pack_config_for, stages_from
from vemdem.scenarios.pack import initial_state_from
from vemdem.scenarios.registry import checked_config, example_text
from vemdem.solver.api import make_integrator


class Counter:
    """The time loop's control hook for a lid at constant speed: steps and Newton iterations from
    where the lid's stress first passes `low` to where it passes `high`."""

    def __init__(self, index: int, area: float, low: float, high: float):
        self.index, self.area, self.low, self.high = index, area, low, high
        self.steps = self.newton = 0
        self.t_low = self.t_high = None
        self.wall_low = self.wall_high = None

    def after_step(self, state, info) -> None:
        stress = float(info.wall_reactions[self.index][2]) / self.area
        if self.t_low is None and stress >= self.low:
            self.t_low, self.wall_low = state.t, time.perf_counter()
        elif self.t_low is not None and self.t_high is None:
            self.steps += 1
            self.newton += int(info.iterations)
            if stress >= self.high:
                self.t_high, self.wall_high = state.t, time.perf_counter()

    def stop(self, state) -> bool:
        return self.t_high is not None

    def carried(self) -> None:  # the loop checkpoints at frames only
        return None

    def carry_on(self, carried: dict) -> None:
        pass


def _setup(cfg: dict, out: Path):
    initial, _ = initial_state_from(cfg, None, out, None, pack_cfg=pack_config_for(cfg))
    test = Oedometer(cfg, initial)
    scene = scene_from(initial.grains, cfg, test.walls)
    test.bind(scene, out, stages_from(cfg, scene.material.density, test.height0, test.grain_size))
    return initial, test, scene


def stress_controlled(cfg: dict, out: Path, max_time: float) -> dict:
    """The servo along the config's two stages (main sets them: --low, then --high)."""
    initial, test, scene = _setup(cfg, out)
    integrator = make_integrator(solver_options_from(cfg), scene)
    stages = stages_from(cfg, scene.material.density, test.height0, test.grain_size)
    servo = Servo(scene.contact, test.lid, test.area, gain=cfg["servo"]["gain"])
    path = LoadPath([servo], stages, test.strain, scene.bodies.lumped, scene.bodies.vertex_ptr,
                    stress_tolerance=cfg["servo"]["stress_tolerance"],
                    unbalanced_tolerance=cfg["servo"]["unbalanced_tolerance"])  # fmt: skip
    marks = {}

    class Control:  # the load path, and the wall clock where its second stage begins
        def after_step(self, state, info):
            path.after_step(state, info)
            if path.current >= 1 and "start" not in marks:
                marks["start"] = time.perf_counter()

        carried, carry_on = path.carried, path.carry_on

    t0 = time.perf_counter()
    simulate(scene, integrator, out / "stress", duration=2 * max_time, every=1e-3, vtk=False,
             identity=run_identity(cfg, SCHEMA), x0=initial.x, v0=initial.v, friction0=initial.friction,
             stop=path.stop, control=Control())  # fmt: skip
    end = time.perf_counter()
    first, decade = path.stage_records()
    return {"steps": decade["steps"], "newton": decade["newton_iterations"],
            "simulated": float(decade["end_time"]) - float(decade["start_time"]), "end_reason": decade["end_reason"] or "not ended",
            "first_stage_end": first["end_reason"], "wall_total": end - t0, "wall": end - marks.get("start", end)}  # fmt: skip


def displacement_controlled(cfg: dict, out: Path, low: float, high: float, max_time: float) -> dict:
    initial, test, scene = _setup(cfg, out)
    integrator = make_integrator(solver_options_from(cfg), scene)
    speed = stages_from({"servo": cfg["servo"], "stages": [{"stress": high, "max_time": 1, "max_strain": 1}]},
                        scene.material.density, test.height0, test.grain_size)[0].max_speed[0]  # fmt: skip
    test.lid.motion.steer(0.0, speed)  # never steered again: a lid at constant speed
    counter = Counter(test.lid_index, test.area, low, high)
    t0 = time.perf_counter()
    simulate(scene, integrator, out / "displacement", duration=max_time, every=1e-3, vtk=False,
             identity=run_identity(cfg, SCHEMA), x0=initial.x, v0=initial.v, friction0=initial.friction,
             stop=counter.stop, control=counter)  # fmt: skip
    if counter.t_high is None:
        return {"steps": counter.steps, "newton": counter.newton, "simulated": np.nan, "end_reason": "max_time",
                "wall": time.perf_counter() - (counter.wall_low or t0), "speed": speed}  # fmt: skip
    return {"steps": counter.steps, "newton": counter.newton, "simulated": counter.t_high - counter.t_low,
            "end_reason": "reached", "wall": counter.wall_high - counter.wall_low, "speed": speed,
            "wall_total": time.perf_counter() - t0}  # fmt: skip


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--config", help="an oedometer config (default: the `oedometer` example)")
    ap.add_argument("--low", type=float, default=25e3, help="Pa, where the decade starts")
    ap.add_argument("--high", type=float, default=250e3, help="Pa, where it ends")
    ap.add_argument("--max-time", type=float, default=0.5, help="s of simulated time per run at most")
    ap.add_argument("--out", default="bench_oedometer_out", help="folder for the pack and the two runs")
    args = ap.parse_args(argv)
    raw = tomllib.loads(Path(args.config).read_text() if args.config else example_text("oedometer"))
    cfg, _ = checked_config(raw)
    # both runs under the oedometer's own law (the material's, or the config's reference force) and
    # from the pack it settles under that law, as `vemdem run` would
    cfg["stages"] = [{"stress": args.low, "max_time": args.max_time, "max_strain": 0.6},
                     {"stress": args.high, "max_time": args.max_time, "max_strain": 0.6}]  # fmt: skip
    out = Path(args.out)
    decades = np.log10(args.high / args.low)
    print(f"{args.low:g} -> {args.high:g} Pa ({decades:.2f} decades)", flush=True)
    runs = {"stress": stress_controlled(cfg, out, args.max_time),
            "displacement": displacement_controlled(cfg, out, args.low, args.high, args.max_time)}  # fmt: skip
    print(f"{'control':<14}{'steps/decade':>14}{'Newton/decade':>15}{'sim s/decade':>14}{'wall s/decade':>15}  end")
    for name, r in runs.items():
        print(f"{name:<14}{r['steps'] / decades:>14.0f}{r['newton'] / decades:>15.0f}"
              f"{r['simulated'] / decades:>14.4g}{r['wall'] / decades:>15.1f}  {r['end_reason']}")  # fmt: skip
    s, d = runs["stress"], runs["displacement"]
    print(f"displacement / stress: steps {d['steps'] / max(s['steps'], 1):.2f}, Newton {d['newton'] / max(s['newton'], 1):.2f}, "
          f"wall {d['wall'] / max(s['wall'], 1e-9):.2f}; the lid's constant speed {d['speed']:.3g} m/s")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
