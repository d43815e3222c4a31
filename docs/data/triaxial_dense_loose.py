"""Dense against loose samples of 500 rigid grains in the drained triaxial (docs/triaxial.md).

    python docs/data/triaxial_dense_loose.py [OUT.png]

Reads triaxial_dense_loose_500.csv beside this file: the shear frames of six tests (dense: settled
without friction; loose: settled with mu = 0.5; sheared with mu = 0.3 at 50 kPa; seeds 1-3), from
their `triaxial.csv` (q/p = q / p; the frame written after the platen stopped left out, as the
summary leaves it). Draws q/p, the volumetric strain and the void ratio against the
axial strain, one line per test, and prints each preparation's void ratio at the end. Writes
docs/img/triaxial_dense_loose.png by default.
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

HERE = Path(__file__).parent
COLOURS = {"dense": "C3", "loose": "C0"}


def tests(path: Path = HERE / "triaxial_dense_loose_500.csv") -> dict[tuple[str, str], dict[str, np.ndarray]]:
    """{(preparation, seed): {column: values over the shear frames}}."""
    with path.open() as f:
        rows = list(csv.DictReader(f))
    out: dict = {}
    for r in rows:
        columns = out.setdefault((r["preparation"], r["seed"]), {})
        for k in ("axial_strain", "volumetric_strain", "q_over_p", "void_ratio"):
            columns.setdefault(k, []).append(float(r[k]))
    return {key: {k: np.array(v) for k, v in columns.items()} for key, columns in out.items()}


def main(out: Path) -> None:
    data = tests()
    fig, (ratio, volume, voids) = plt.subplots(1, 3, figsize=(14.0, 4.2))
    for (preparation, seed), t in data.items():
        style = dict(color=COLOURS[preparation], lw=1, label=f"{preparation}, seed {seed}")
        strain = 100 * t["axial_strain"]
        ratio.plot(strain, t["q_over_p"], **style)
        volume.plot(strain, -100 * t["volumetric_strain"], **style)
        voids.plot(strain, t["void_ratio"], **style)
    ratio.set(xlabel="axial strain (%)", ylabel="q / p")
    volume.set(xlabel="axial strain (%)", ylabel="volumetric strain (%), dilation up")
    voids.set(xlabel="axial strain (%)", ylabel="void ratio")
    for ax in (ratio, volume, voids):
        ax.grid(alpha=0.3)
    ratio.legend(fontsize=8, loc="lower right")
    fig.suptitle("drained triaxial, 500 rigid grains, mu = 0.3, 50 kPa: dense and loose, three seeds each")
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    print(f"wrote {out}")
    for preparation in COLOURS:
        ends = [t["void_ratio"][-1] for (p, _), t in data.items() if p == preparation]
        print(f"{preparation}: void ratio at the end {np.mean(ends):.3f} (from {min(ends):.3f} to {max(ends):.3f})")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else HERE.parent / "img" / "triaxial_dense_loose.png")
