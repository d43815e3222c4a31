"""`scenario = "scene"`: any set of grains and walls under gravity, integrated in time.

Outputs in DIR: summary.json, history.csv (energies), grains.csv (centroid position and velocity of
every grain at every frame), walls.csv (force of the grains on every wall at every frame),
grains.pvd + grains/*.vtu (ParaView), checkpoint.npz (the state at the last frame:
`vemdem run ... --resume` continues from it to the same result). A wall with a `[walls.servo]`
table is stress-controlled: its motion along its normal follows a target stress (docs/servo.md).
"""

from __future__ import annotations

import time
from pathlib import Path

from ..config import ConfigError, tables
from ..config.build import build_scene, solver_options_from
from ..driver.loop import simulate
from ..driver.summary import run_summary
from ..io.results import write_json
from ..lab.servo import Servo, ServoWalls
from ..solver.api import make_integrator
from .identity import run_identity

RESUMABLE = True  # `vemdem run ... --resume` continues from DIR/checkpoint.npz
SCHEMA = tables.SCENE


def run(cfg: dict, out_dir: Path, base_dir=None, progress=None, resume: bool = False) -> dict:
    t_start = time.perf_counter()
    scene, v0 = build_scene(cfg, base_dir)
    integrator = make_integrator(solver_options_from(cfg), scene)
    identity = run_identity(cfg, SCHEMA)
    result = simulate(scene, integrator, out_dir, duration=cfg["duration"], every=cfg["output"]["every"],
                      vtk=cfg["output"]["vtk"], identity=identity, v0=v0, resume=resume,
                      progress=progress, control=servo_walls(cfg["walls"], scene.contact))  # fmt: skip
    summary = run_summary("scene", scene, result, t_start)
    write_json(Path(out_dir) / "summary.json", summary)
    return summary


def servo_walls(specs: list, contact) -> ServoWalls | None:
    """The servos of the `[[walls]]` tables with a `servo.stress`, on the scene's walls (in the tables'
    order: planes and meshes each in theirs): the time loop's control; None where no wall has one."""
    servos, schedules = [], []
    count = {"plane": 0, "mesh": 0}
    for i, spec in enumerate(specs):
        kind = spec["type"]
        wall = (contact.planes if kind == "plane" else contact.meshes)[count[kind]]
        count[kind] += 1
        servo = spec.get("servo")
        if not servo or not servo["stress"]:
            continue
        if contact.wall_names.count(wall.name) > 1:
            raise ConfigError(f"walls[{i}].name: a servo wall needs a name of its own, {wall.name!r} is taken twice")
        servos.append(Servo(contact, wall, servo["area"], gain=servo["gain"], max_speed=servo["max_speed"]))
        schedules.append((servo["times"], servo["stress"]))
    return ServoWalls(servos, schedules) if servos else None
