"""The lid cycle on the 515-grain 6 mm pack: the real density against mass scaling 1e6
(docs/validation.md, "Real density against mass scaling").

    python docs/data/lid515_real_vs_scaled.py [OUT.png]

Reads the two `force_strain.csv` files beside this file (`phase,strain,force`, as
`lid_compression` writes them): lid515_real.csv, the paper's own method (flexible VEM grains,
implicit Newmark, the real density; a run resumed over several parts, whose loading stops at 29 %
strain), and lid515_scaled.csv, the `paper-compression` example's method (explicit, mass scaling
1e6), both from one rigid-grain pack (`paper-pack` with `[model] grains = "rigid"` and
`mass_scaling = 1`; `python benchmarks/bench_paper.py --only compression-pack --pack-state
rpack/state.npz --no-vtk [--implicit]`). The force is drawn
in pack weights, 515 grains' weight at each run's density (PACK_WEIGHT_N below, times 1e6 for the
mass-scaled run), since mass scaling multiplies the weight and the contact law's force scale
together: in those units the two runs share one law. Writes docs/img/lid515_real_vs_scaled.png by
default and prints the force at a few strains.
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from vemdem.analysis.force_strain import read_force_strain_csv  # noqa: E402

HERE = Path(__file__).resolve().parent
# rho g sum(V) of the pack's 515 grains (exact polyhedron volumes, geometry.mass), 2200 kg/m^3, g = 9.81
PACK_WEIGHT_N = 4.254e-3
RUNS = (
    ("lid515_real.csv", 1.0, "real density, implicit (VEM)", "tab:red"),
    ("lid515_scaled.csv", 1e6, "mass scaling 1e6, explicit (VEM)", "tab:blue"),
)
STRAINS = (0.15, 0.18, 0.20, 0.22, 0.24, 0.26, 0.28, 0.30)


def main(out: Path) -> None:
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), dpi=120)
    for name, scale, label, colour in RUNS:
        phase, strain, force = read_force_strain_csv(HERE / name)
        weights = force / (PACK_WEIGHT_N * scale)
        load = phase == "load"
        for ax in axes:
            ax.plot(100 * strain[load], weights[load], "-", color=colour, lw=1.4, label=f"{label}, loading")
            if (~load).any():
                ax.plot(100 * strain[~load], weights[~load], "--", color=colour, lw=1.2, label=f"{label}, unloading")
        at = [weights[load][np.argmax(strain[load] >= e - 1e-9)] if strain[load].max() >= e - 1e-9 else np.nan
              for e in STRAINS]  # fmt: skip
        print(f"{label}: loading to strain {strain[load].max():.3f}, peak {weights.max():.4g} pack weights; "
              + ", ".join(f"{e:.2f}: {w:.3g}" for e, w in zip(STRAINS, at)))  # fmt: skip
    axes[0].set_ylabel("lid force / pack weight")
    axes[1].set_yscale("symlog", linthresh=0.1)
    for ax, title in zip(axes, ("linear", "symlog")):
        ax.set_xlabel("compressive strain (%)")
        ax.set_title(title)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7, loc="upper left")
    fig.suptitle("the lid on the 515-grain 6 mm pack (0.9 mm grains, mu 0.15): one pack, two methods")
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else HERE.parent / "img" / "lid515_real_vs_scaled.png")
