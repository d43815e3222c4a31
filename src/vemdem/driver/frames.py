"""Frames of a run: history.csv (energies), grains.csv (centroids), walls.csv (wall forces) and
the ParaView series grains.pvd (surfaces, velocity, projected stress, contact points and forces)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..io.results import CsvLog
from ..io.vtk import PvdSeries
from ..model.scene import Scene
from ..solver.state import State

# wall_work: the work the moving walls did on the grains since the start (J; driver.checkpoint.WallWork);
# elastic_slip: the 99th percentile of the pairs' stored elastic tangential slip |g_t| (m;
# summary.friction_reach: a slip beyond the contact layer means the load outgrew the friction spring)
HISTORY_HEADER = ["time", "kinetic", "strain", "gravity", "contact", "dissipated", "n_contacts", "wall_work",
                  "elastic_slip"]  # fmt: skip
GRAINS_HEADER = ["time", "grain", "x", "y", "z", "vx", "vy", "vz"]
WALLS_HEADER = ["time", "wall", "name", "fx", "fy", "fz"]  # force of the grains on each wall (N)
FRAME_CSVS = ("history.csv", "grains.csv", "walls.csv")


SLIP_PERCENTILE = 99.0


def elastic_slip(gt: np.ndarray) -> float:
    """The SLIP_PERCENTILE-th percentile of |g_t| over the pairs (m; 0 without pairs): how far the
    friction springs are stretched. A pair reaches its Coulomb limit at |g_t| = mu F_N / eps_t."""
    if not len(gt):
        return 0.0
    return float(np.percentile(np.linalg.norm(gt, axis=1), SLIP_PERCENTILE))


class FrameWriter:
    def __init__(self, scene: Scene, out_dir: Path, vtk: bool, resume_frames: int | None, lumped: bool = False):
        self.scene = scene
        self.lumped = lumped  # the explicit integrator's energies use its lumped mass
        self.out_dir = out_dir
        mode = "a" if resume_frames is not None else "w"
        self.history = CsvLog(out_dir / "history.csv", HISTORY_HEADER, mode)
        self.grains = CsvLog(out_dir / "grains.csv", GRAINS_HEADER, mode)
        self.walls = CsvLog(out_dir / "walls.csv", WALLS_HEADER, mode)
        self.wall_names = scene.contact.wall_names
        self.vtk = PvdSeries(out_dir, "grains", keep=resume_frames) if vtk else None
        n_grain_faces = scene.contact.topology.grain_face_ptr[scene.n_grains]
        self.faces = scene.contact.topology.faces[:n_grain_faces]
        self.face_grain = scene.contact.topology.face_grain[:n_grain_faces]

    def write(self, state: State, strain: float, contact_result, wall_work: float = 0.0):
        s = self.scene
        self.history.write(state.t, s.kinetic_energy(state.v, self.lumped), strain, s.gravity_energy(state.x, self.lumped),
                           contact_result.energy, state.dissipated, contact_result.n_contacts, wall_work,
                           elastic_slip(state.history.gt))  # fmt: skip
        c = s.grain_centroids(state.x)
        vc = s.grain_centroids(state.v)
        self.grains.write_rows([[state.t, g, *c[g], *vc[g]] for g in range(s.n_grains)])
        self.walls.write_rows([[state.t, w, name, *contact_result.wall_reactions[w]]
                               for w, name in enumerate(self.wall_names)])  # fmt: skip
        if self.vtk is not None:
            self._write_vtk(state, contact_result)

    def _write_vtk(self, state, cr):
        s = self.scene
        x_all = s.contact.all_positions(state.x, state.t)
        points = cr.points(x_all)
        n, m = s.n_vertices, len(points)
        sigma = s.bodies.cauchy_stress(state.x).reshape(-1, 9)
        cells_pt = (n + np.arange(m)).reshape(-1, 1)
        force = np.vstack([np.zeros((n, 3)), cr.pair_force]) if m else np.zeros((n, 3))
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
