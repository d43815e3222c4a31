"""Whole lid cycles on the 515-grain 6 mm pack, turned before the jam: the real density against
mass scaling 1e6 (docs/validation.md, "Cycles turned before the jam").

    python docs/data/lid515_turned.py [OUT.png]

Reads the `force_strain.csv` files beside this file (`phase,strain,force`, as `lid_compression`
writes them): lid515_turn{NN}_real.csv, the paper's own method (flexible VEM grains, implicit
Newmark, the real density), and lid515_turn{NN}_scaled.csv, the `paper-compression` example's
method (explicit, mass scaling 1e6), both from the rigid-grain pack of lid515_real_vs_scaled.py,
the lid from 7 mm at 0.02 m/s down to a strain of NN % and back (`[lid] end`; `python
benchmarks/bench_paper.py --only compression-pack --pack-state rpack/state.npz --no-vtk --lid-turn
0.NN [--implicit]`). The force is in pack weights, as in
lid515_real_vs_scaled.py (whose PACK_WEIGHT_N this reads), the works in pack weights times the
lid's 7 mm start height, the residual strain at one force for both (RESIDUAL_PACK_WEIGHTS).
Writes docs/img/lid515_turned.png by default and prints each cycle's figures.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from vemdem.analysis.force_strain import (  # noqa: E402
    RESIDUAL_PACK_WEIGHTS,
    cycle_branches,
    cycle_figures,
    read_force_strain_csv,
)

HERE = Path(__file__).resolve().parent
START_HEIGHT = 7e-3  # m: the lid's start, the strain's reference height
TURNS = (20, 22, 24, 26)  # % strain where the lid turns
# the residual strain where the unloading force falls below RESIDUAL_PACK_WEIGHTS pack weights (summary.json's
# residual_strain_absolute): one threshold for both runs, where its residual_strain, at 1e-3 of each run's own
# peak, reads the jam's peaks a hundred times higher in pack weights for the real-density run
METHODS = (
    ("real", 1.0, "real density, implicit (VEM)", "tab:red"),
    ("scaled", 1e6, "mass scaling 1e6, explicit (VEM)", "tab:blue"),
)


def _pack_weight() -> float:
    spec = importlib.util.spec_from_file_location("lid515_real_vs_scaled", HERE / "lid515_real_vs_scaled.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.PACK_WEIGHT_N


def cycles() -> dict[tuple[int, str], dict]:
    """{(turn, method): {branches, figures}}: each cycle's loading and unloading (strain, pack weights),
    the unloading from the turning point (cycle_branches), and its figures (cycle_figures) with the
    works in pack weights times START_HEIGHT."""
    weight = _pack_weight()
    out = {}
    for turn in TURNS:
        for method, scale, *_ in METHODS:
            phase, strain, force = read_force_strain_csv(HERE / f"lid515_turn{turn}_{method}.csv")
            weights = force / (weight * scale)
            figures = cycle_figures(phase, strain, weights, START_HEIGHT,
                                    zero_fraction=RESIDUAL_PACK_WEIGHTS / weights.max())  # fmt: skip
            for key in ("loading_work", "unloading_work", "hysteresis_energy"):
                figures[key] /= START_HEIGHT
            out[turn, method] = {"branches": cycle_branches(phase, strain, weights), "figures": figures}
    return out


def main(out: Path) -> None:
    data = cycles()
    fig, axes = plt.subplots(2, len(TURNS) // 2, figsize=(10, 8.4), dpi=120)
    axes = axes.ravel()
    for ax, turn in zip(axes, TURNS):
        for method, _, label, colour in METHODS:
            load_e, load_w, unload_e, unload_w = data[turn, method]["branches"]
            f = data[turn, method]["figures"]
            ax.plot(100 * load_e, load_w, "-", color=colour, lw=1.4, label=f"{label}, loading")
            ax.plot(100 * unload_e, unload_w, "--", color=colour, lw=1.2,
                    label=f"unloading: {f['hysteresis_energy'] / f['loading_work']:.0%} of the work lost, "
                    f"residual strain {100 * f['residual_strain']:.1f} %")  # fmt: skip
            print(f"turned at {turn} %, {label}: peak {f['peak_force']:.3g} pack weights, loading work "
                  f"{f['loading_work']:.4g}, hysteresis {f['hysteresis_energy']:.4g} (pack weights x 7 mm), "
                  f"{f['hysteresis_energy'] / f['loading_work']:.3f} of the loading work; residual strain "
                  f"{f['residual_strain']:.4f}")  # fmt: skip
        ax.set_xlim(10, turn + 0.5)
        ax.set_yscale("symlog", linthresh=0.1)  # the jam's force is tens of times the mass-scaled run's
        ax.set_ylim(bottom=0.0)
        ax.set_xlabel("compressive strain (%)")
        ax.set_title(f"the lid turned at {turn} % strain")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="upper left")
    for ax in axes[:: len(TURNS) // 2]:
        ax.set_ylabel("lid force / pack weight")
    fig.suptitle("whole lid cycles on the 515-grain 6 mm pack (0.9 mm grains, mu 0.15), turned at 20-26 % strain")
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else HERE.parent / "img" / "lid515_turned.png")
