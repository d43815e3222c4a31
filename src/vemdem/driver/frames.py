"""Frames of a run: history.csv (energies), grains.csv (centroids, velocities and each grain's largest
strain), walls.csv (wall forces),
fabric.csv (the contact network's microstructure: analysis.microstructure, docs/microstructure.md)
and the ParaView series grains.pvd (surfaces, velocity, projected stress, contact points and
forces); at the end fabric_rose.png (the contact normals and forces of the first frame with
contacts and of the last)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..analysis.microstructure import FABRIC_HEADER, fabric_row, pair_contacts, plot_fabric_rose
from ..io.results import CsvLog
from ..io.vtk import PvdSeries
from ..model.scene import Scene
from ..solver.state import State

# wall_work: the work the moving walls did on the grains since the start (J; driver.checkpoint.WallWork);
# elastic_slip: the 99th percentile of the pairs' stored elastic tangential slip |g_t| (m;
# summary.friction_reach: a slip beyond the contact layer means the load outgrew the friction spring)
HISTORY_HEADER = ["time", "kinetic", "strain", "gravity", "contact", "dissipated", "n_contacts", "wall_work",
                  "elastic_slip"]  # fmt: skip
GRAINS_HEADER = ["time", "grain", "x", "y", "z", "vx", "vy", "vz", "strain"]
WALLS_HEADER = ["time", "wall", "name", "fx", "fy", "fz"]  # force of the grains on each wall (N)
FRAME_CSVS = ("history.csv", "grains.csv", "walls.csv", "fabric.csv")
FABRIC_ROSE = "fabric_rose.png"
# the first frame with contacts' normals and normal forces, kept for the rose of a resumed run
FABRIC_FIRST = "fabric_first.npz"


SLIP_PERCENTILE = 99.0


def elastic_slip(gt: np.ndarray) -> float:
    """The SLIP_PERCENTILE-th percentile of |g_t| over the pairs (m; 0 without pairs): how far the
    friction springs are stretched. A pair reaches its Coulomb limit at |g_t| = mu F_N / eps_t."""
    if not len(gt):
        return 0.0
    return float(np.percentile(np.linalg.norm(gt, axis=1), SLIP_PERCENTILE))


@dataclass
class RoseFrame:
    """What the rose draws of one frame: per grain-grain contact, its normal and normal force."""

    t: float
    normals: np.ndarray
    fn: np.ndarray

    def label(self, which: str) -> str:
        return f"{which} (t = {self.t:.4g} s)"


class FrameWriter:
    def __init__(self, scene: Scene, out_dir: Path, vtk: bool, resume_frames: int | None, lumped: bool = False,
                 volume=None):  # fmt: skip
        """volume(t, x), where given, is the sample's volume (m^3) at time t and vertex positions x,
        for the Love-Weber stress of fabric.csv (its sigma columns stay empty without it; None from
        it leaves them empty at that frame)."""
        self.scene = scene
        self.lumped = lumped  # the explicit integrator's energies use its lumped mass
        self.out_dir = out_dir
        mode = "a" if resume_frames is not None else "w"
        self.history = CsvLog(out_dir / "history.csv", HISTORY_HEADER, mode)
        self.grains = CsvLog(out_dir / "grains.csv", GRAINS_HEADER, mode)
        self.walls = CsvLog(out_dir / "walls.csv", WALLS_HEADER, mode)
        # a resumed run from before fabric.csv existed starts the file afresh, with its header
        fabric_mode = mode if (out_dir / "fabric.csv").is_file() else "w"
        self.fabric = CsvLog(out_dir / "fabric.csv", FABRIC_HEADER, fabric_mode)
        self.volume = volume
        self.first_rose = _load_rose(out_dir / FABRIC_FIRST) if resume_frames is not None else None
        self.last_rose: RoseFrame | None = None
        self._first_checked = resume_frames is None
        self.wall_names = scene.contact.wall_names
        self.vtk = PvdSeries(out_dir, "grains", keep=resume_frames) if vtk else None
        n_grain_faces = scene.contact.topology.grain_face_ptr[scene.n_grains]
        self.faces = scene.contact.topology.faces[:n_grain_faces]
        self.face_grain = scene.contact.topology.face_grain[:n_grain_faces]

    def write(self, state: State, strain: float, contact_result, wall_work: float = 0.0):
        s = self.scene
        self.history.write(state.t, s.kinetic_energy(state.v, self.lumped, state.x), strain, s.gravity_energy(state.x, self.lumped),
                           contact_result.energy, state.dissipated, contact_result.n_contacts, wall_work,
                           elastic_slip(state.history.gt))  # fmt: skip
        c = s.grain_centroids(state.x)
        vc = s.grain_centroids(state.v)
        strain = s.grain_strains(state.x)
        self.grains.write_rows([[state.t, g, *c[g], *vc[g], strain[g]] for g in range(s.n_grains)])
        self.walls.write_rows([[state.t, w, name, *contact_result.wall_reactions[w]]
                               for w, name in enumerate(self.wall_names)])  # fmt: skip
        records = contact_result.records(s.contact.all_positions(state.x, state.t))
        self._write_fabric(state, records, c)
        if self.vtk is not None:
            self._write_vtk(state, contact_result, records.force)

    def _write_fabric(self, state: State, records, centroids: np.ndarray) -> None:
        s = self.scene
        pairs = pair_contacts(records.a, records.b, records.normal, records.force, s.n_grains)
        volume = self.volume(state.t, state.x) if self.volume is not None else None
        row = fabric_row(state.t, records, s.n_grains, centroids, volume, pairs=pairs)
        self.fabric.write(*[row[k] for k in FABRIC_HEADER])
        rose = RoseFrame(float(state.t), pairs.normal, pairs.fn)
        if not self._first_checked:
            # a resumed run redoes the frames after its checkpoint: a first frame kept from one of
            # those is drawn again, from this run
            self._first_checked = True
            if self.first_rose is not None and self.first_rose.t >= state.t * (1.0 - 1e-12):
                self.first_rose = None
        if self.first_rose is None and len(pairs.fn):
            self.first_rose = rose
            np.savez(self.out_dir / FABRIC_FIRST, t=rose.t, normals=rose.normals, fn=rose.fn)
        self.last_rose = rose

    def _write_vtk(self, state, cr, pair_force):
        s = self.scene
        x_all = s.contact.all_positions(state.x, state.t)
        points = cr.points(x_all)
        n, m = s.n_vertices, len(points)
        sigma = s.bodies.cauchy_stress(state.x).reshape(-1, 9)
        cells_pt = (n + np.arange(m)).reshape(-1, 1)
        force = np.vstack([np.zeros((n, 3)), pair_force]) if m else np.zeros((n, 3))
        self.vtk.write(
            state.t,
            np.vstack([state.x, points]),
            [("triangle", self.faces), ("vertex", cells_pt)],
            point_data={"velocity": np.vstack([state.v, np.zeros((m, 3))]), "contact_force": force},
            cell_data={
                "grain": [self.face_grain, np.full(m, -1)],
                "cauchy_stress": [sigma[self.face_grain], np.zeros((m, 9))],
            },
        )

    def close(self):
        self.history.close()
        self.grains.close()
        self.walls.close()
        self.fabric.close()
        self.write_rose()

    def write_rose(self) -> None:
        """fabric_rose.png: the first frame with contacts and the last (one row where they are one)."""
        if self.first_rose is None:
            return
        frames = [(self.first_rose.label("first frame with contacts"), self.first_rose.normals, self.first_rose.fn)]
        if self.last_rose is not None and self.last_rose.t != self.first_rose.t:
            frames.append((self.last_rose.label("last frame"), self.last_rose.normals, self.last_rose.fn))
        plot_fabric_rose(self.out_dir / FABRIC_ROSE, frames)


def _load_rose(path: Path) -> RoseFrame | None:
    if not path.is_file():
        return None
    with np.load(path) as d:
        return RoseFrame(float(d["t"]), d["normals"].copy(), d["fn"].copy())
