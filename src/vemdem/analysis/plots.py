"""Plots people would rather look at than read (matplotlib, no screen needed)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def plot_force_strain(path: Path, strain, force, closed_form=None, mode: str = "", title: str = "") -> None:
    fig, ax = plt.subplots(figsize=(6, 4.2), dpi=120)
    ax.plot(np.asarray(strain) * 100, force, "o-", ms=3, label="VEM, one element")
    if closed_form is not None:
        ax.plot(np.asarray(strain) * 100, closed_form, "k--", lw=1, label=f"closed form ({mode})")
    ax.set_xlabel("compressive strain 1 - h/h0 (%)")
    ax.set_ylabel("compressive force on the top plate (N)")
    ax.set_title(f"{title}: {mode} compression" if title else f"{mode} compression")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
