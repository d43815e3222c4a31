"""The triaxial friction angles against the grains' friction (docs/triaxial.md).

    python docs/data/triaxial_friction.py [OUT.png]

Reads triaxial_friction.csv beside this file: one row per triaxial run (the `summary.json` of
`vemdem sweep triaxial.toml --set contact.mu_s=... --set contact.mu_d=... --zip`, the example's
100 grains, dense, 50 kPa), with the grain model, shape and mass scaling it ran with (s = 100: the real density's strain
rate at I = 5e-4, docs/triaxial.md). Draws phi_peak and phi_cs (with its spread over the last 5 %
of strain) against mu per grain model, shape and scaling, beside the
range of sands' critical-state angles (30-37 deg) and prints the table. Writes
docs/img/triaxial_friction.png by default.
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
SANDS_CS_DEG = (30.0, 37.0)  # critical-state angles of quartz and feldspar sands (Bolton 1986)
NUMBERS = ("mu", "phi_peak_deg", "phi_cs_deg", "phi_cs_spread_deg", "dilatancy_angle_deg", "max_inertia_number",
           "wall_seconds")  # fmt: skip


def series(path: Path = HERE / "triaxial_friction.csv") -> dict[tuple[str, str, float], dict[str, np.ndarray]]:
    """{(grain model, shape, mass scaling): {column: values sorted by mu}}."""
    with path.open() as f:
        rows = list(csv.DictReader(f))
    out = {}
    key_of = lambda r: (r["grains"], r["shape"], float(r["mass_scaling"]))  # noqa: E731
    for key in sorted({key_of(r) for r in rows}):
        mine = sorted((r for r in rows if key_of(r) == key), key=lambda r: float(r["mu"]))
        out[key] = {k: np.array([float(r[k]) for r in mine]) for k in NUMBERS}
    return out


def main(out: Path) -> None:
    data = series()
    fig, (peak, cs) = plt.subplots(1, 2, figsize=(11.0, 4.6), sharey=True)
    sands = cs.axhspan(*SANDS_CS_DEG, color="0.85", label="sands (Bolton 1986)")
    for i, ((grains, shape, scaling), s) in enumerate(data.items()):
        style = dict(color=f"C{i}", label=f"{grains}, {shape}, s = {scaling:g}")
        peak.plot(s["mu"], s["phi_peak_deg"], "o-", **style)
        cs.errorbar(s["mu"], s["phi_cs_deg"], yerr=s["phi_cs_spread_deg"], fmt="s--", capsize=3, **style)
    peak.set(xlabel="interparticle friction mu", ylabel="friction angle (deg)", title="peak", ylim=(15, 60))
    cs.set(xlabel="interparticle friction mu", title="critical state (spread over the last 5 % of strain)")
    for ax in (peak, cs):
        ax.grid(alpha=0.3)
    peak.legend(fontsize=8, loc="lower right")
    cs.legend(handles=[sands], fontsize=8, loc="upper left")  # the series' colours: the peak panel's
    fig.suptitle("drained triaxial, 100 grains, dense, 50 kPa")
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    print(f"wrote {out}")
    print("| grains | shape | mass scaling | mu | phi_peak | phi_cs (spread) | dilatancy | max I | wall s |")
    print("|---|---|---|---|---|---|---|---|---|")
    for (grains, shape, scaling), s in data.items():
        for j in range(len(s["mu"])):
            print(f"| {grains} | {shape} | {scaling:g} | {s['mu'][j]:g} | {s['phi_peak_deg'][j]:.1f} | {s['phi_cs_deg'][j]:.1f} "
                  f"({s['phi_cs_spread_deg'][j]:.1f}) | {s['dilatancy_angle_deg'][j]:.1f} | "
                  f"{s['max_inertia_number'][j]:.1e} | {s['wall_seconds'][j]:.0f} |")  # fmt: skip


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else HERE.parent / "img" / "triaxial_friction.png")
