"""What the 515-grain pack gives back when the lid turns: the real density against mass scaling 1e6
(docs/validation.md, "What the spring-back is made of").

    python docs/data/lid515_spring_back.py [OUT.png]

Reads lid515_spring_back.csv beside this file: for the cycles turned at 20, 22 and 24 % strain
(each method's run of "Cycles turned before the jam", rerun from another rigid pack of the same
config: `bench_paper.py ... --lid-turn 0.20|0.22|0.24 [--implicit]`), the best-fit vertical strain of the grains' branch vectors from the lid's turn to where the
lid lets go of the pack (`to` = release: the first frame whose force is at most 0.01 pack weights)
and to the cycle's end (`to` = end, what summary.json's `spring_back` reports), split by
vemdem.analysis.spring_back into the grains' deformation, the contact layer's gaps, the contacts'
tangential motion and the grains' rotations (the last two: rearrangement); with the stored
strain and contact energies (J) and the lid's force (N) at the turn. Writes
docs/img/lid515_spring_back.png by default and prints each row's shares.
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from vemdem.analysis.spring_back import spring_back_shares  # noqa: E402

HERE = Path(__file__).resolve().parent
PARTS = ("deformation", "contact_gap", "tangential", "rotation")
FLOATS = ("lid_rise", "pack_height", "branch_strain", *PARTS, "strain_energy_turn", "contact_energy_turn",
          "force_turn", "force_release_row")  # fmt: skip
LABELS = {"deformation": "the grains' deformation", "contact_gap": "the contact layer's gaps",
          "rearrangement": "rearrangement (tangential + rotation)"}  # fmt: skip
COLOURS = {"deformation": "tab:orange", "contact_gap": "tab:green", "rearrangement": "tab:gray"}
METHODS = {"real": "real density, implicit", "scaled": "mass scaling 1e6, explicit"}
TICKS = {"real": "real density\nimplicit", "scaled": "mass scaling 1e6\nexplicit"}


def rows(path: Path = HERE / "lid515_spring_back.csv") -> list[dict]:
    """Every row, numbers as numbers, with `rearrangement` = tangential + rotation."""
    with path.open(newline="") as fh:
        out = list(csv.DictReader(fh))
    for r in out:
        r["turn"], r["frame"], r["records"] = int(r["turn"]), int(r["frame"]), int(r["records"])
        r.update({k: float(r[k]) for k in FLOATS})
        r["rearrangement"] = r["tangential"] + r["rotation"]
    return out


def shares(row: dict) -> dict[str, float]:
    """Each part's share of the branch vectors' strain (as bench_paper and force_strain.png give them)."""
    return spring_back_shares(row)


def main(out: Path) -> None:
    data = [r for r in rows() if r["to"] == "release"]
    fig, ax = plt.subplots(figsize=(9, 4.6), dpi=120)
    for i, r in enumerate(data):
        bottom = 0.0
        for k in ("deformation", "contact_gap", "rearrangement"):
            ax.bar(i, 100 * r[k], bottom=100 * bottom, color=COLOURS[k], label=LABELS[k] if i == 0 else None)
            bottom += r[k]
        lid = "the lid's rise / pack height" if i == 0 else None
        ax.plot(i, 100 * r["lid_rise"] / r["pack_height"], "kv", label=lid)
        s = shares(r)
        print(f"turned at {r['turn']} %, {METHODS[r['method']]}: branch strain {100 * r['branch_strain']:.2f} % "
              f"(lid {100 * r['lid_rise'] / r['pack_height']:.2f} %), deformation {s['deformation']:.0%}, "
              f"gaps {s['contact_gap']:.0%}, rearrangement {s['rearrangement']:.0%}; stored at the turn: strain "
              f"{r['strain_energy_turn']:.3g} J, contact {r['contact_energy_turn']:.3g} J")  # fmt: skip
    ax.axhline(0.0, color="k", lw=0.6)
    ax.set_xticks(range(len(data)), [f"turned at {r['turn']} %\n{TICKS[r['method']]}" for r in data], fontsize=7.5)
    ax.set_ylabel("vertical strain given back, turn to release (%)")
    ax.set_title("What the 515-grain pack gives back when the lid turns", fontsize=10)
    ax.legend(fontsize=8, loc="upper left")
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else HERE.parent / "img" / "lid515_spring_back.png")
