"""The two grain shapes of the `triaxial-two-shapes` example (docs/gallery.md).

    python docs/data/two_shapes.py [OUT.png]

Reads the example's surface files from the package (examples/shapes/rounded.stl and
crushed.stl, each of equivalent diameter 0.9 mm) and draws them side by side, as a pack of that
example turns and scales them. Prints each file's vertex and face count and its equivalent
diameter. Writes docs/img/two_shapes.png by default.
"""

from __future__ import annotations

import sys
from importlib.resources import files
from pathlib import Path

import numpy as np

from vemdem.analysis.plots import plot_grains_3d
from vemdem.io.surfaces import load_surface

HERE = Path(__file__).parent
SHAPES = ("rounded.stl", "crushed.stl")


def main(out: Path) -> None:
    xs, faces, owner, offset = [], [], [], 0
    for k, name in enumerate(SHAPES):
        grain = load_surface(files("vemdem").joinpath("examples", "shapes", name))
        d = (6.0 * grain.volume / np.pi) ** (1.0 / 3.0)
        print(f"{name}: {len(grain.vertices)} vertices, {len(grain.faces)} faces, equivalent diameter {d * 1e3:.3f} mm")
        x = grain.vertices - grain.centroid + [1.3e-3 * k, 0.0, 0.0]
        xs.append(x)
        faces.append(grain.faces + offset)
        owner.append(np.full(len(grain.faces), k))
        offset += len(x)
    plot_grains_3d(out, np.vstack(xs), np.vstack(faces), np.concatenate(owner),
                   title="triaxial-two-shapes: rounded.stl (70 %) and crushed.stl (30 %)")  # fmt: skip


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else HERE.parent / "img" / "two_shapes.png")
