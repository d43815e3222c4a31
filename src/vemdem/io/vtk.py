"""ParaView output: one VTU per frame and a PVD file that lists them with their times."""

from __future__ import annotations

from pathlib import Path
from xml.sax.saxutils import quoteattr

import meshio
import numpy as np


class PvdSeries:
    def __init__(self, out_dir: Path, name: str):
        self.out_dir = Path(out_dir)
        self.name = name
        self.frames: list[tuple[float, str]] = []
        (self.out_dir / name).mkdir(parents=True, exist_ok=True)

    def write(self, time: float, points: np.ndarray, triangles: np.ndarray, point_data=None, cell_data=None):
        rel = f"{self.name}/{self.name}_{len(self.frames):05d}.vtu"
        cells = [("triangle", np.asarray(triangles))]
        mesh = meshio.Mesh(
            np.asarray(points, float),
            cells,
            point_data=point_data or {},
            cell_data={k: [np.asarray(v)] for k, v in (cell_data or {}).items()},
        )
        mesh.write(self.out_dir / rel, binary=True)
        self.frames.append((float(time), rel))
        self._write_index()

    def _write_index(self):
        lines = ['<?xml version="1.0"?>', '<VTKFile type="Collection" version="0.1">', "  <Collection>"]
        for t, rel in self.frames:
            lines.append(f'    <DataSet timestep="{t!r}" part="0" file={quoteattr(rel)}/>')
        lines += ["  </Collection>", "</VTKFile>", ""]
        (self.out_dir / f"{self.name}.pvd").write_text("\n".join(lines))
