"""How quasi-static a lid cycle was: the grains' velocity fluctuations and the inertia number.

A pack squeezed uniformly between the floor (height z_f) and a lid at height h moving at w
(m/s, negative while loading) would move with the affine velocity field

    v_aff(z) = w (z - z_f) / (h - z_f) e_z,       strain rate  rate = |w| / (h - z_f).

A grain's velocity fluctuation is what is left of its centroid velocity once the affine field
and the mean flow of its layer are taken out:

    u = v - v_aff(z),     dv = u - <u>_layer,

layers one grain size d thick from the floor. The layer mean removes a mean flow that is not
affine (a loose pack compacts under the lid first, its bottom at rest), which the affine field
alone would count as fluctuation (2-3 rate d before the lid touches). Per frame this module
reports the rms and the median of |dv| in units of rate d (d: the mean equivalent diameter),
and the inertia number (GDR MiDi, Eur. Phys. J. E 14, 341, 2004)

    I = rate d / sqrt(P / rho),       P = lid force / box area,

the ratio of the time a grain takes to move by its size under the pressure to the time the
imposed strain takes to move it by that much: I < 1e-3 is the quasi-static regime, 1e-3 to 1e-1
the dense-flow one. rho is the density the inertia sees (the material's times the mass scaling).

Why it matters here (docs/results.md, "The jam is the grains' own motion"): at the real density
the 515-grain lid cycle enters the quasi-static regime when the pack jams, and there the grains'
fluctuations grow to 15-30 times rate d; an integrator must follow them, on contacts whose gaps
are nanometres, whatever its stability.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..io.results import CsvLog, wall_force_record

HEADER = ("time", "lid_velocity", "strain", "force", "inertia_number", "rms_fluctuation", "median_fluctuation")
T, W, STRAIN, FORCE, INERTIA, RMS, MEDIAN = range(len(HEADER))
QUASI_STATIC = 1e-3  # GDR MiDi's bound of the quasi-static regime


def velocity_fluctuations(z: np.ndarray, v: np.ndarray, floor: float, height: float, lid_speed: float,
                          grain_size: float) -> tuple[float, float]:
    """(rms, median) over the grains of |dv| (module docstring), in units of rate d; lid_speed
    is the lid's vertical velocity (negative while it moves down)."""  # fmt: skip
    gap = height - floor
    if gap <= 0 or lid_speed == 0:
        raise ValueError(f"no affine field: lid {height:g} m over floor {floor:g} m moving at {lid_speed:g} m/s")
    z = np.asarray(z, dtype=float)
    dv = np.array(v, dtype=float, copy=True)
    dv[:, 2] -= lid_speed * (z - floor) / gap
    layer = np.floor((z - floor) / grain_size).astype(np.int64)
    _, member, count = np.unique(layer, return_inverse=True, return_counts=True)
    for k in range(3):
        dv[:, k] -= (np.bincount(member, weights=dv[:, k]) / count)[member]
    speed = np.linalg.norm(dv, axis=1)
    unit = abs(lid_speed) / gap * grain_size
    return float(np.sqrt(np.mean(speed**2)) / unit), float(np.median(speed) / unit)


def inertia_number(rate: float, grain_size: float, pressure: float, density: float) -> float:
    """I = rate d / sqrt(P / rho); infinite when nothing presses (P <= 0)."""
    return float(rate * grain_size / np.sqrt(pressure / density)) if pressure > 0 else float("inf")


def lid_fluctuations(grains_csv: Path, walls_csv: Path, lid, start: float, floor: float, area: float,
                     grain_size: float, density: float) -> np.ndarray:
    """One row per frame (columns of HEADER) of a lid run's grains.csv and walls.csv; `lid` is the
    scenario's PlaneWall (its motion gives the lid's height and velocity), `start` its height at
    t = 0. Frames at which the lid is at rest (its turning point) are left out."""  # fmt: skip
    table = np.atleast_1d(np.genfromtxt(grains_csv, delimiter=",", names=True))  # one row reads as 0-d
    force = dict(zip(*wall_force_record(walls_csv, lid.name)))
    rows = []
    for t in np.unique(table["time"]):
        w = float(lid.motion.velocity(t)[2])
        if w == 0:
            continue
        g = table[table["time"] == t]
        height = start + float(lid.motion.displacement(t)[2])
        v = np.column_stack([g["vx"], g["vy"], g["vz"]])
        rms, median = velocity_fluctuations(g["z"], v, floor, height, w, grain_size)
        f = force.get(float(t), 0.0)
        rate = abs(w) / (height - floor)
        inertia = inertia_number(rate, grain_size, f / area, density)
        rows.append((t, w, (start - height) / start, f, inertia, rms, median))
    return np.array(rows, dtype=float).reshape(-1, len(HEADER))


def write_fluctuations_csv(path: Path, rows: np.ndarray) -> None:
    with CsvLog(Path(path), list(HEADER)) as log:
        log.write_rows([list(r) for r in rows])


def fluctuation_figures(rows: np.ndarray) -> dict:
    """summary.json's record: the smallest inertia number of the frames the lid pressed and the
    largest rms fluctuation there (None with a reason where the lid never pressed)."""
    rows = np.asarray(rows, dtype=float).reshape(-1, len(HEADER))
    pressed = rows[np.isfinite(rows[:, INERTIA])]
    if not len(pressed):
        return {"inertia_number_min": None, "reason": "the lid never pressed the pack"}
    quasi = pressed[pressed[:, INERTIA] < QUASI_STATIC]
    figures = {
        "inertia_number_min": float(pressed[:, INERTIA].min()),
        "frames_quasi_static": int(len(quasi)),
        "rms_fluctuation_max": float(pressed[:, RMS].max()),
        "rms_fluctuation_quasi_static_median": float(np.median(quasi[:, RMS])) if len(quasi) else None,
    }
    if not len(quasi):
        figures["reason"] = f"no frame below I = {QUASI_STATIC:g}"
    return figures


def plot_fluctuations(rows: np.ndarray, path: Path, title: str = "") -> None:
    """Velocity fluctuations against strain and against the inertia number (log scales); a panel
    with nothing to show says so (a lid that never pressed, grains at rest)."""
    from .plots import plt  # the package's Agg backend

    rows = np.asarray(rows, dtype=float).reshape(-1, len(HEADER))
    fig, ax = plt.subplots(1, 2, figsize=(10, 3.8))
    load = (rows[:, W] < 0) & (rows[:, RMS] > 0)
    pressed = np.isfinite(rows[:, INERTIA]) & (rows[:, RMS] > 0)
    for a in ax:
        a.set_yscale("log")
        a.grid(alpha=0.3, which="both")
    ax[1].set_xscale("log")
    if load.any():
        ax[0].plot(rows[load, STRAIN], rows[load, RMS], "o-", ms=3, label="rms")
        ax[0].plot(rows[load, STRAIN], rows[load, MEDIAN], "s-", ms=3, label="median")
        ax[0].legend()
    else:
        ax[0].text(0.5, 0.5, "no grain moved while the lid came down", transform=ax[0].transAxes, ha="center")
    ax[0].set_xlabel("lid strain (loading)")
    ax[0].set_ylabel(r"grain velocity fluctuation / ($\dot\varepsilon\, d$)")
    inertia = rows[pressed, INERTIA]
    ax[1].set_xlim(min(1e-4, 0.5 * inertia.min(initial=1e-4)), max(1e-1, 2.0 * inertia.max(initial=1e-1)))
    if pressed.any():
        ax[1].plot(inertia, rows[pressed, RMS], "o", ms=3)
    else:
        ax[1].set_ylim(0.1, 100.0)
        ax[1].text(0.5, 0.5, "the lid never pressed the pack", transform=ax[1].transAxes, ha="center")
    ax[1].axvline(QUASI_STATIC, color="grey", ls="--")
    ax[1].set_xlabel(r"inertia number $I = \dot\varepsilon\, d / \sqrt{P/\rho}$ (left of the line: quasi-static)")
    ax[1].set_ylabel(r"rms velocity fluctuation / ($\dot\varepsilon\, d$)")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
