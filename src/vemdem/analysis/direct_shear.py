"""A direct shear test's measures: its frames (shear.csv) and the figures summary.json reports
(docs/direct-shear.md).

The lower half of a split box moves along x at a constant speed under a lid held at the normal
stress sigma_n; tau is the force the lower half carries along x over the box's section. Both
stresses are over the same nominal section, so their ratio is the force ratio F_x / F_z, free of
the area correction the shrinking overlap of the halves would need.

- friction angle phi = atan(tau / sigma_n), the cohesionless Coulomb angle the ratio mobilises;
- peak: the largest ratio over the shear (phi_peak_deg) and the shear displacement there;
- residual: the mean ratio over the last `window` (a share) of the shear displacement
  (phi_residual_deg), with the spread of the frames' angles there;
- dilation angle: the largest slope of the lid's rise against the shear displacement, atan(dy/dx),
  a least-squares line over a moving window as for the triaxial's dilatancy; negative where the
  sample only contracted.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .triaxial import largest_finite, measured

HEADER = ("time", "stage", "shear_displacement", "vertical_displacement", "sigma_n", "tau", "tau_over_sigma_n",
          "void_ratio", "coordination", "inertia_number", "unbalanced", "frame_rise")  # fmt: skip
CONSOLIDATION, SHEAR = 0, 1  # the `stage` column's values
RESIDUAL_WINDOW = 0.2  # the share of the shear displacement the residual ratio is the mean over


def _angle(ratio):
    return np.degrees(np.arctan(ratio))


def shear_rows(rows: np.ndarray) -> np.ndarray:
    """The shear rows (stage == 1) of a shear.csv table."""
    rows = np.asarray(rows, dtype=float).reshape(-1, len(HEADER))
    return rows[rows[:, HEADER.index("stage")] == SHEAR]


def peak(x, ratio) -> dict:
    x, ratio = np.asarray(x, float), np.asarray(ratio, float)
    if not np.any(np.isfinite(ratio)):
        raise ValueError("no row with a finite tau / sigma_n: no peak")
    i = int(np.nanargmax(ratio))
    return {"phi_peak_deg": float(_angle(ratio[i])), "ratio_peak": float(ratio[i]),
            "shear_displacement_at_peak": float(x[i])}  # fmt: skip


def residual(x, ratio, window: float = RESIDUAL_WINDOW) -> dict:
    """The mean ratio over the last `window` share of the shear displacement; ValueError where
    fewer than 3 rows lie there."""
    x, ratio = np.asarray(x, float), np.asarray(ratio, float)
    span = x.max() - x.min() if len(x) else 0.0
    inside = (x >= x.max() - window * span - 1e-15) & np.isfinite(ratio) if len(x) else np.zeros(0, bool)
    n = int(inside.sum())
    if span <= 0 or n < 3:
        raise ValueError(f"{n} rows in the last {window:g} of the shear displacement; the residual state needs 3")
    r = ratio[inside]
    return {"phi_residual_deg": float(_angle(np.mean(r))), "phi_residual_spread_deg": float(np.std(_angle(r))),
            "ratio_residual": float(np.mean(r)), "residual_rows": n}  # fmt: skip


def dilation_angle(x, y, rows: int = 4) -> dict:
    """The largest slope of y (the lid's rise) against x (the shear displacement) over windows of
    `rows` frames, as an angle; ValueError with fewer frames."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    if len(x) < rows:
        raise ValueError(f"{len(x)} shear rows: the dilation angle needs {rows}")
    slopes = []
    for k in range(len(x) - rows + 1):
        xs, ys = x[k : k + rows], y[k : k + rows]
        dx = xs - xs.mean()
        if np.any(dx):
            slopes.append(float(dx @ (ys - ys.mean()) / (dx @ dx)))
    if not slopes:
        raise ValueError("the lower half never moved: no dilation angle")
    return {"dilation_angle_deg": float(_angle(max(slopes)))}


def shear_figures(rows: np.ndarray) -> dict:
    """summary.json's measures over the shear rows (module docstring), with displacements from the
    shear's start; a measure the run cannot give is its `*_error` string."""
    shear = shear_rows(rows)
    out: dict = {"shear_rows": len(shear)}
    if len(shear) < 2:
        out["shear_error"] = f"{len(shear)} shear frames: no direct shear measure"
        return out
    x = shear[:, HEADER.index("shear_displacement")]
    y = shear[:, HEADER.index("vertical_displacement")]
    x, y = x - x[0], y - y[0]
    ratio = shear[:, HEADER.index("tau_over_sigma_n")]
    for name, measure in (("peak", lambda: peak(x, ratio)), ("residual", lambda: residual(x, ratio)),
                          ("dilation", lambda: dilation_angle(x, y))):  # fmt: skip
        measured(out, name, measure)
    out["max_inertia_number"] = largest_finite(shear[:, HEADER.index("inertia_number")])
    return out


def plot_shear(rows: np.ndarray, path: Path, title: str, marks: dict | None = None) -> None:
    """shear.png: tau / sigma_n and the lid's rise against the shear displacement (mm)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    shear = shear_rows(rows)
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(6.5, 6), sharex=True)
    if len(shear):
        x = (shear[:, HEADER.index("shear_displacement")] - shear[0, HEADER.index("shear_displacement")]) * 1e3
        y = (shear[:, HEADER.index("vertical_displacement")] - shear[0, HEADER.index("vertical_displacement")]) * 1e3
        top.plot(x, shear[:, HEADER.index("tau_over_sigma_n")], "-", color="C0")
        bottom.plot(x, y, "-", color="C1")
    marks = marks or {}
    for key, colour, style, label in (("phi_peak_deg", "C3", "--", "peak"), ("phi_residual_deg", "k", ":", "residual")):
        if isinstance(marks.get(key), float):
            top.axhline(np.tan(np.radians(marks[key])), color=colour, ls=style, lw=1,
                        label=f"{label}: phi = {marks[key]:.1f} deg")  # fmt: skip
    top.set(ylabel="tau / sigma_n", title=title)
    bottom.set(xlabel="shear displacement (mm)", ylabel="lid rise (mm, dilation up)")
    for ax in (top, bottom):
        ax.grid(alpha=0.3)
    if marks:
        top.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
