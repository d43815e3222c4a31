"""The paper's 515-grain lid test at the real density, stress-controlled (`paper-oedometer`)
against the strain-controlled cycles turned before the jam (docs/oedometer.md).

    python docs/data/paper_oedometer.py [OUT.png]

Reads paper_oedometer.csv beside this file (the `oedometer.csv` of `vemdem example
paper-oedometer > po.toml && vemdem run po.toml --out po`, copied here) and the strain-controlled
cycles lid515_turn{NN}_real.csv (docs/data/lid515_turned.py: the lid from 7 mm down to NN % strain
and back, flexible grains, implicit, the real density), and paper_oedometer_rigid.csv (the same
servo path with rigid grains, explicit, from a pack settled at mu 0.15 under the 100 kPa law). All are drawn as the lid's force against
its height above the floor, the stress-controlled run's servo stages marked. Writes
docs/img/paper_oedometer.png by default and prints where each run carried the servo's target force.
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
LID_START_MM = 7.0  # the strain-controlled cycles' lid start height
TURNS = (20, 22, 24, 26)
LID_AREA = 8e-3 * 8e-3  # m^2: the 8 mm x 8 mm lid


def read(path: Path) -> dict[str, np.ndarray]:
    with path.open() as f:
        rows = list(csv.DictReader(f))
    return {k: np.array([r[k] for r in rows], dtype=float if k != "phase" else str) for k in rows[0]}


def positive(force: np.ndarray) -> np.ndarray:
    """The force where the lid carries one (a log axis)."""
    return np.where(force > 0, force, np.nan)


def main(out: Path) -> None:
    fig, ax = plt.subplots(figsize=(7.5, 4.8))
    for nn, colour in zip(TURNS, plt.cm.Greys(np.linspace(0.4, 0.85, len(TURNS)))):
        cyc = read(HERE / f"lid515_turn{nn}_real.csv")
        height = LID_START_MM * (1.0 - cyc["strain"])
        ax.plot(height, positive(cyc["force"]), color=colour, lw=1, label=f"strain-controlled, turned at {nn} %")
    po = read(HERE / "paper_oedometer.csv")
    ax.plot(po["lid_height"] * 1e3, positive(po["lid_force"]), color="C3", lw=1.6, label="stress-controlled (servo)")
    rigid = read(HERE / "paper_oedometer_rigid.csv")
    ax.plot(rigid["lid_height"] * 1e3, positive(rigid["lid_force"]), color="C0", lw=1.2,
            label="servo, rigid grains (pack settled at mu 0.15, the 100 kPa law)")  # fmt: skip
    target = 100e3 * LID_AREA
    ax.axhline(target, color="C3", ls=":", lw=0.8)
    ax.set(xlabel="lid height above the floor (mm)", ylabel="lid force (N)", yscale="log",
           title="515 grains, real density (flexible: implicit; rigid: explicit)")  # fmt: skip
    ax.set_ylim(1e-3, 3 * target)
    ax.invert_xaxis()
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    print(f"wrote {out}")
    for name, run in (("servo", po), ("servo, rigid grains", rigid)):
        loaded = np.flatnonzero(run["lid_force"] >= 0.99 * target)
        if len(loaded):
            k = loaded[0]
            print(f"{name}: {run['lid_force'][k]:.3g} N at {run['lid_height'][k] * 1e3:.3f} mm "
                  f"({run['axial_strain'][k]:.1%} of its own start), t = {run['time'][k]:.4g} s")  # fmt: skip
        else:
            print(f"{name}: at most {run['lid_force'].max():.3g} N of {target:.3g} N "
                  f"(lid at {run['lid_height'][-1] * 1e3:.3f} mm, t = {run['time'][-1]:.4g} s)")  # fmt: skip
    for nn in TURNS:
        cyc = read(HERE / f"lid515_turn{nn}_real.csv")
        above = np.flatnonzero(cyc["force"] >= target)
        where = f"{LID_START_MM * (1 - cyc['strain'][above[0]]):.3f} mm" if len(above) else "never"
        print(f"turned at {nn} %: peak {cyc['force'].max():.3g} N; {target:.3g} N first at {where}")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else HERE.parent / "img" / "paper_oedometer.png")
