"""Soft grains in the oedometer, flexible against rigid (docs/oedometer.md).

    python docs/data/soft_oedometer.py [OUT.png]

Reads soft_oedometer_flexible.csv and soft_oedometer_rigid.csv beside this file: the
`oedometer.csv` of `vemdem example soft-oedometer` (60 grains, E = 10 MPa, nu = 0.4) with
flexible grains and with `[model] grains = "rigid"` from the same settled pack (`initial_state`
the flexible run's pack). Draws the packing fraction against the lid's stress for both and prints
each run's packing fraction where a frame first carried each of the path's stresses (frames
every 2 ms: a stage that ends between two frames has none) and at the frames' largest stress. Writes
docs/img/soft_oedometer.png by default.
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
RUNS = {"flexible": "soft_oedometer_flexible.csv", "rigid": "soft_oedometer_rigid.csv"}
STRESSES = (50e3, 300e3, 1e6, 3e6)
SEATED = 1e3  # Pa: below, the lid seats on a few grains (the servo takes over at a tenth of 50 kPa)


def read(name: str) -> dict[str, np.ndarray]:
    with (HERE / RUNS[name]).open() as f:
        rows = list(csv.DictReader(f))
    return {k: np.array([float(r[k]) for r in rows]) for k in rows[0]}


def first_loading(run: dict[str, np.ndarray]) -> np.ndarray:
    """The frames before the first unloading stage (the path's last stage unloads)."""
    return run["stage"] < len(STRESSES)


def packing_at(run: dict[str, np.ndarray], stress: float):
    """The packing fraction and axial strain at the first frame that carried `stress`, or None."""
    up = first_loading(run)
    hit = np.flatnonzero(up & (run["sigma_v"] >= 0.95 * stress))
    return (run["packing_fraction"][hit[0]], run["axial_strain"][hit[0]]) if len(hit) else None


def main(out: Path) -> None:
    fig, ax = plt.subplots(figsize=(6.5, 4.4))
    for name, colour in zip(RUNS, ("C0", "C3")):
        run = read(name)
        up = first_loading(run) & (run["sigma_v"] >= SEATED)
        ax.plot(run["sigma_v"][up] / 1e3, run["packing_fraction"][up], "o-", ms=3, color=colour,
                label=f"{name} grains")  # fmt: skip
    for s in STRESSES:
        ax.axvline(s / 1e3, color="0.8", lw=0.8, zorder=0)
    ax.set(xscale="log", xlabel="vertical stress sigma_v (kPa)", ylabel="packing fraction",
           title="60 soft grains (E = 10 MPa), oedometer, first loading")  # fmt: skip
    ax.set_xlim(SEATED / 1e3, 5e3)
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    print(f"wrote {out}")
    for name in RUNS:
        run = read(name)
        for s in STRESSES:
            at = packing_at(run, s)
            text = f"{at[0]:.3f} at {at[1]:.1%} strain" if at else "no frame carried it"
            print(f"{name}: {s / 1e3:g} kPa: {text}")
        k = np.argmax(np.where(first_loading(run), run["sigma_v"], -np.inf))
        print(f"{name}: the frames' largest stress {run['sigma_v'][k] / 1e3:.4g} kPa at packing fraction "
              f"{run['packing_fraction'][k]:.3f}, {run['axial_strain'][k]:.1%} strain")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else HERE.parent / "img" / "soft_oedometer.png")
