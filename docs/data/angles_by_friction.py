"""The angle of repose against the friction coefficient, by method and grain shape
(docs/validation.md, "Angle of repose").

    python docs/data/angles_by_friction.py [OUT.png]

Reads the CSVs beside this file (each row one run, rigid grains at the real density, explicit):
corner500_seeds.csv and corner500_angular.csv (`vemdem sweep` of the 500-grain corner collapse
over packs) and standard_tests_rigid.csv (the 500-grain corner poured heap over packs, and the
long tilting box: 480 grains of 1 mm in a 30 mm box with mirror sides, the surface after the
avalanche; the 10 mm box's rows are left out: docs/validation.md, "The tilting box", says why its
scatter makes it no angle to compare).
Plots, per method and shape, each pack's angle (small markers) and the mean with the sample
standard deviation over packs (error bars) against mu_s, with the dry quartz sand band of
experiments (30-35 deg, Al-Hashemi & Al-Amoudi 2018). Writes docs/img/angles_by_friction.png by
default and prints the table it plots.
"""

from __future__ import annotations

import csv
import sys
from collections import defaultdict
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

HERE = Path(__file__).resolve().parent


def _rows(name: str):
    with (HERE / name).open(newline="") as fh:
        yield from csv.DictReader(fh)


def series() -> dict[tuple[str, str], dict[float, list[float]]]:
    """{(method, shape): {mu_s: [angle per pack]}} from the CSVs."""
    out: dict = defaultdict(lambda: defaultdict(list))
    for name, shape in (("corner500_seeds.csv", "sand"), ("corner500_angular.csv", "angular")):
        for r in _rows(name):
            if r["status"] == "ok" and r["angle_of_repose_deg"]:
                out[("collapse into a corner", shape)][float(r["contact.mu_s"])].append(float(r["angle_of_repose_deg"]))
    for r in _rows("standard_tests_rigid.csv"):
        if r["test"].startswith("poured heap") and r["angle_of_repose_deg"]:
            out[("poured heap into a corner", r["shape"])][float(r["mu_s"])].append(float(r["angle_of_repose_deg"]))
        if r["test"] == "tilting box" and r["box_length_mm"] == "30" and r["sides"] == "mirrors":
            out[("tilting box, 30 mm", r["shape"])][float(r["mu_s"])].append(float(r["angle_of_repose_deg"]))
    return out


STYLE = {
    ("collapse into a corner", "sand"): dict(color="tab:blue", marker="o"),
    ("collapse into a corner", "angular"): dict(color="tab:blue", marker="s", mfc="white"),
    ("poured heap into a corner", "sand"): dict(color="tab:red", marker="o"),
    ("poured heap into a corner", "angular"): dict(color="tab:red", marker="s", mfc="white"),
    ("tilting box, 30 mm", "sand"): dict(color="tab:green", marker="o"),
    ("tilting box, 30 mm", "angular"): dict(color="tab:green", marker="s", mfc="white"),
}


def plot(data, out: Path) -> None:
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    ax.axhspan(30, 35, color="0.85", zorder=0, label="dry quartz sand, experiments")
    for k, (key, by_mu) in enumerate(sorted(data.items())):
        shift = (k - 0.5 * (len(data) - 1)) * 0.012  # side by side, so that the bars do not hide each other
        mus = np.array(sorted(by_mu))
        means = np.array([np.mean(by_mu[m]) for m in mus])
        spread = np.array([np.std(by_mu[m], ddof=1) if len(by_mu[m]) > 1 else 0.0 for m in mus])
        style = STYLE.get(key, {})
        ax.errorbar(mus + shift, means, yerr=spread, capsize=3, lw=1.2, ms=6, label=f"{key[0]}, {key[1]}", **style)
        for m in mus:
            ax.plot(np.full(len(by_mu[m]), m + shift), by_mu[m], ls="none", ms=2.5, alpha=0.6,
                    color=style.get("color"), marker=".")  # fmt: skip
    ax.set_xlabel("static friction coefficient mu_s (mu_d = mu_s - 0.1)")
    ax.set_ylabel("angle of repose (deg)")
    ax.set_xticks([0.3, 0.6, 0.9])
    ax.set_ylim(0, 40)
    ax.set_title("rigid grains at the real density: mean +- sd over packs", fontsize=10)
    ax.legend(fontsize=8, loc="lower right")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out, dpi=130)


def main(argv: list[str]) -> None:
    out = Path(argv[0]) if argv else HERE.parent / "img" / "angles_by_friction.png"
    data = series()
    for (method, shape), by_mu in sorted(data.items()):
        for mu, angles in sorted(by_mu.items()):
            sd = np.std(angles, ddof=1) if len(angles) > 1 else float("nan")
            print(f"{method:28s} {shape:8s} mu_s {mu:.1f}: {np.mean(angles):5.1f} +- {sd:.1f} deg over {len(angles)} packs")
    plot(data, out)
    print("wrote", out)


if __name__ == "__main__":
    main(sys.argv[1:])
