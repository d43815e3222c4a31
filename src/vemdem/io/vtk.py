"""ParaView output: one VTU per frame and a PVD file that lists them with their times."""

from __future__ import annotations

from pathlib import Path
from xml.sax.saxutils import quoteattr

import meshio
import numpy as np


class PvdSeries:
    """keep: resume an existing series, keeping its first `keep` frames."""

    def __init__(self, out_dir: Path, name: str, keep: int | None = None):
        self.out_dir = Path(out_dir)
        self.name = name
        self.frames: list[tuple[float, str]] = []
        (self.out_dir / name).mkdir(parents=True, exist_ok=True)
        if keep is not None and (self.out_dir / f"{name}.pvd").is_file():
            self.frames = _read_pvd(self.out_dir / f"{name}.pvd")[:keep]

    def write(self, time: float, points: np.ndarray, cells, point_data=None, cell_data=None):
        """cells: triangles (m, 3), or a list of (cell type, connectivity) blocks; cell_data values
        are one array (one block) or a list with one array per block."""
        rel = f"{self.name}/{self.name}_{len(self.frames):05d}.vtu"
        if isinstance(cells, np.ndarray):
            cells = [("triangle", cells)]
        blocks = [(kind, np.asarray(conn)) for kind, conn in cells]
        mesh = meshio.Mesh(
            np.asarray(points, float),
            blocks,
            point_data=point_data or {},
            cell_data={k: (list(v) if isinstance(v, list) else [np.asarray(v)]) for k, v in (cell_data or {}).items()},
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


def _read_pvd(path: Path) -> list[tuple[float, str]]:
    import xml.etree.ElementTree as ET

    root = ET.parse(path).getroot()
    return [(float(d.get("timestep")), d.get("file")) for d in root.iter("DataSet")]
