"""The lid's compression cycle: load to a peak strain, unload, and what the loop says.

force_strain.csv holds one row per step, header `phase,strain,force`: phase 'load' or
'unload' (all loading rows first), compressive strain (lid travel / initial pile height
height0, positive in compression) and the compressive force on the lid (N, positive when
the pile pushes back).

Sign conventions, with displacement u = strain * height0 (growing while loading):

- loading work W_load = integral of F du along the loading rows: work done on the pile;
- unloading work W_unload = -(integral of F du) along the unloading rows, u decreasing, so
  positive: the work the pile gives back to the lid. The unloading branch starts at the
  last loading row (the turning point), so the way back from the peak counts;
- hysteresis energy = W_load - W_unload, the area between the two curves in the
  force-displacement plane (J) once the unloading force is back to zero; if it never gets
  there, it also holds the elastic energy still stored at the last row.

Both integrals are trapezoidal in row order, so a branch that doubles back is integrated
along the path it took.

Residual strain: where the unloading force first falls to `zero_fraction` (1e-3) of the
peak force, interpolated linearly between the rows on either side; the last strain if it
never does. A small threshold rather than exact zero, so that a grain barely touching the
lid does not hold the reading back; small, because the force usually reaches zero
tangentially (each contact's penalty is quadratic in its overlap): for
F ~ (e - e_r)^n the reading comes late by zero_fraction^(1/n) of the unloading range,
3 % of it for n = 2 and 0.1 % for n = 1. zero_fraction=0 gives the first exact zero.

Absolute residual strain: where the unloading force first falls to a given force (`zero_force`,
lid_compression passes RESIDUAL_PACK_WEIGHTS = 0.01 of the pack's weight). One force for runs
whose peaks differ by orders of magnitude in pack weights: a pack at the real density jams at
hundreds of pack weights where the same pack with mass scaling 1e6 carries a few, so 1e-3 of each
run's own peak reads the two unloadings at forces a hundred times apart (docs/results.md, "Cycles
turned before the jam").
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
from scipy.integrate import trapezoid

from ..io.results import CsvLog
from .spring_back import spring_back_shares

HEADER = ("phase", "strain", "force")
LOAD, UNLOAD = "load", "unload"
ZERO_FRACTION = 1e-3
RESIDUAL_PACK_WEIGHTS = 0.01


def cycle_branches(phase, strain, force) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Loading (strain, force) and unloading (strain, force), the latter from the turning point."""
    phase = np.asarray(phase, dtype=str)
    strain = np.asarray(strain, dtype=float)
    force = np.asarray(force, dtype=float)
    if not (phase.shape == strain.shape == force.shape) or phase.ndim != 1:
        raise ValueError(
            f"phase, strain and force must be 1-D and equally long, got {phase.shape}, {strain.shape}, {force.shape}"
        )
    unknown = set(phase.tolist()) - {LOAD, UNLOAD}
    if unknown:
        raise ValueError(f"phase must be {LOAD!r} or {UNLOAD!r}, got {min(unknown)!r}")
    loading = phase == LOAD
    n_load = int(loading.sum())
    if not loading[:n_load].all():
        raise ValueError("one cycle expected: every 'load' row before the first 'unload' row")
    if n_load < 2 or n_load == len(phase):
        raise ValueError(f"need at least 2 'load' rows and 1 'unload' row, got {n_load} and {len(phase) - n_load}")
    if not (np.isfinite(strain).all() and np.isfinite(force).all()):
        raise ValueError("strain and force must be finite")
    turn = n_load - 1
    return strain[:n_load], force[:n_load], strain[turn:], force[turn:]


def _residual_strain(strain: np.ndarray, force: np.ndarray, threshold: float) -> float:
    """First crossing of force <= threshold along the unloading branch (module docstring)."""
    below = np.flatnonzero(force <= threshold)
    if len(below) == 0:
        return float(strain[-1])
    i = below[0]
    if i == 0:
        return float(strain[0])
    t = (force[i - 1] - threshold) / (force[i - 1] - force[i])
    return float(strain[i - 1] + t * (strain[i] - strain[i - 1]))


def cycle_figures(phase, strain, force, height0: float, zero_fraction: float = ZERO_FRACTION,
                  zero_force: float | None = None) -> dict[str, float]:  # fmt: skip
    """peak_force (N), loading_work, unloading_work, hysteresis_energy (J) and residual_strain
    of one load-unload cycle; height0 (m) turns strain into lid displacement. With `zero_force`
    (N) also residual_strain_absolute: where the unloading force first falls to it."""
    if not height0 > 0:
        raise ValueError(f"height0 must be > 0, got {height0}")
    load_e, load_f, unload_e, unload_f = cycle_branches(phase, strain, force)
    peak = float(max(load_f.max(), unload_f.max()))
    if not peak > 0:
        raise ValueError(f"the lid never carried a compressive force (peak {peak} N)")
    loading_work = float(trapezoid(load_f, load_e * height0))
    unloading_work = -float(trapezoid(unload_f, unload_e * height0))
    figures = {
        "peak_force": peak,
        "loading_work": loading_work,
        "unloading_work": unloading_work,
        "hysteresis_energy": loading_work - unloading_work,
        "residual_strain": _residual_strain(unload_e, unload_f, zero_fraction * peak),
    }
    if zero_force is not None:
        if not zero_force >= 0:
            raise ValueError(f"zero_force must be >= 0, got {zero_force}")
        figures["residual_strain_absolute"] = _residual_strain(unload_e, unload_f, zero_force)
    return figures


def write_force_strain_csv(path: Path, phase, strain, force) -> None:
    """One row per step under the header `phase,strain,force`; floats written exactly."""
    with CsvLog(path, list(HEADER)) as log:
        log.write_rows(zip(phase, strain, force))


def read_force_strain_csv(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(phase, strain, force) arrays from a file written by write_force_strain_csv."""
    with Path(path).open(newline="") as fh:
        rows = list(csv.reader(fh))
    if not rows or tuple(rows[0]) != HEADER:
        raise ValueError(f"{path}: header must be {','.join(HEADER)}, got {','.join(rows[0]) if rows else 'nothing'}")
    body = rows[1:]
    for line, row in enumerate(body, start=2):
        if len(row) != len(HEADER):
            raise ValueError(f"{path}, line {line}: expected {len(HEADER)} fields, got {len(row)}")
    phase = np.array([row[0] for row in body], dtype=str)
    try:
        values = np.array([row[1:] for row in body], dtype=float).reshape(-1, 2)
    except ValueError as exc:
        raise ValueError(f"{path}: strain and force must be numbers ({exc})") from None
    return phase, values[:, 0], values[:, 1]


def _figures_text(figures: dict) -> str:
    lines = [
        f"peak force {figures['peak_force']:.4g} N",
        f"loading work {figures['loading_work']:.4g} J",
        f"unloading work {figures['unloading_work']:.4g} J",
        f"hysteresis {figures['hysteresis_energy']:.4g} J",
        f"residual strain {100 * figures['residual_strain']:.3g} %",
    ]
    back = figures.get("spring_back", {})
    share = spring_back_shares(back)
    if share is not None:
        lines.append(f"spring-back {100 * back['branch_strain']:.3g} %: grains {share['deformation']:.0%},")
        lines.append(f"  contact gaps {share['contact_gap']:.0%}, rearrangement {share['rearrangement']:.0%}")
    return "\n".join(lines)


def plot_force_strain(phase, strain, force, path: Path, figures: dict | None = None) -> None:
    """Loading and unloading curves with the loop between them shaded; `figures` (from
    cycle_figures, and lid_compression's spring_back where it has one), when given, in a text box,
    and the residual strain as a dotted line."""
    from .plots import plt  # the package's Agg backend

    load_e, load_f, unload_e, unload_f = cycle_branches(phase, strain, force)
    fig, ax = plt.subplots(figsize=(6, 4.2), dpi=120)
    # loading out and unloading back close the loop along the strain axis (zero force)
    ax.fill(np.r_[load_e, unload_e] * 100, np.r_[load_f, unload_f], color="0.85", label="hysteresis")
    ax.plot(load_e * 100, load_f, "-", color="tab:red", lw=1.5, label="loading")
    ax.plot(unload_e * 100, unload_f, "-", color="tab:blue", lw=1.5, label="unloading")
    if figures is not None:
        ax.axvline(100 * figures["residual_strain"], color="k", ls=":", lw=1, label="residual strain")
        ax.text(
            0.03,
            0.97,
            _figures_text(figures),
            transform=ax.transAxes,
            va="top",
            fontsize=8,
            bbox={"boxstyle": "round", "facecolor": "white", "alpha": 0.9},
        )
    ax.set_xlabel("compressive strain (%)")
    ax.set_ylabel("force on the lid (N)")
    ax.set_title("lid compression cycle")
    ax.grid(alpha=0.3)
    ax.legend(loc="center left")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
