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
  sample only contracted;
- failure states: sigma_n and tau at the peak row and their means over the residual window, the
  points a sweep over the normal stress fits its Coulomb envelopes tau = c + sigma_n tan(phi)
  through (least squares; one test: the cohesionless angle of its ratio).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .envelope import failure_pairs, fit_envelopes, line_fit
from .triaxial import held_stress, largest_finite, measured

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
    if ratio[i] <= 0.0:  # a negative angle: the sample never resisted the shear
        raise ValueError(f"tau / sigma_n never rose above 0 in the shear (largest {ratio[i]:.3g}): no friction angle")
    return {"phi_peak_deg": float(_angle(ratio[i])), "ratio_peak": float(ratio[i]),
            "shear_displacement_at_peak": float(x[i])}  # fmt: skip


def residual_rows(x, ratio, window: float = RESIDUAL_WINDOW) -> np.ndarray:
    """The rows with a finite ratio in the last `window` share of the shear displacement (a mask);
    ValueError where fewer than 3 lie there."""
    x, ratio = np.asarray(x, float), np.asarray(ratio, float)
    span = x.max() - x.min() if len(x) else 0.0
    inside = (x >= x.max() - window * span - 1e-15) & np.isfinite(ratio) if len(x) else np.zeros(0, bool)
    n = int(inside.sum())
    if span <= 0 or n < 3:
        raise ValueError(f"{n} rows in the last {window:g} of the shear displacement; the residual state needs 3")
    return inside


def residual(x, ratio, window: float = RESIDUAL_WINDOW) -> dict:
    """The mean ratio over the last `window` share of the shear displacement; ValueError where
    fewer than 3 rows lie there."""
    inside = residual_rows(x, ratio, window)
    n = int(inside.sum())
    r = np.asarray(ratio, float)[inside]
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


def peak_stresses(ratio, sigma_n, tau) -> dict:
    """sigma_n and tau at the peak row (sigma_n_peak_Pa, tau_peak_Pa): the peak failure state."""
    ratio = np.asarray(ratio, float)
    if not np.any(np.isfinite(ratio)):
        raise ValueError("no row with a finite tau / sigma_n: no peak state")
    i = int(np.nanargmax(ratio))
    if ratio[i] <= 0.0:  # no failure state for an envelope (peak's own refusal)
        raise ValueError(f"tau / sigma_n never rose above 0 in the shear (largest {ratio[i]:.3g}): no peak state")
    return {"sigma_n_peak_Pa": float(sigma_n[i]), "tau_peak_Pa": float(tau[i])}


def residual_stresses(x, ratio, sigma_n, tau, window: float = RESIDUAL_WINDOW) -> dict:
    """The means of sigma_n and tau over the residual window (sigma_n_residual_Pa,
    tau_residual_Pa): the residual failure state."""
    inside = residual_rows(x, ratio, window)
    return {"sigma_n_residual_Pa": float(np.mean(np.asarray(sigma_n, float)[inside])),
            "tau_residual_Pa": float(np.mean(np.asarray(tau, float)[inside]))}  # fmt: skip


def coulomb_fit(sigma_n, tau, through_origin: bool = False) -> dict:
    """The Coulomb line tau = c + sigma_n tan(phi) through one failure state per test, by least
    squares (c = 0 `through_origin`): phi_deg, cohesion_Pa, r2, n. One test: the cohesionless
    angle of its ratio, c = 0, r2 NaN. ValueError on stresses that are not finite (sigma_n not
    positive), on a free line through tests at one normal stress, or on a line that falls with
    the normal stress."""
    s, t = np.atleast_1d(np.asarray(sigma_n, dtype=float)), np.atleast_1d(np.asarray(tau, dtype=float))
    if s.shape != t.shape or s.ndim != 1 or len(s) == 0:
        raise ValueError(f"one tau per sigma_n needed, got {t.shape} and {s.shape}")
    bad = np.flatnonzero(~np.isfinite(s) | (s <= 0) | ~np.isfinite(t))
    if len(bad):
        i = bad[0]
        raise ValueError(f"sigma_n must be finite and positive, tau finite: test {i} has {s[i]!r}, {t[i]!r}")
    if len(s) == 1:
        return {"phi_deg": float(_angle(t[0] / s[0])), "cohesion_Pa": 0.0, "r2": float("nan"), "n": 1}
    if not through_origin and not np.any(s - s.mean()):
        raise ValueError("every test failed at the same normal stress: no envelope slope to fit")
    intercept, slope, r2 = line_fit(s, t, through_origin)
    if slope <= 0.0:
        raise ValueError(f"tau falls with sigma_n (slope {slope:.4g}): no friction angle")
    return {"phi_deg": float(_angle(slope)), "cohesion_Pa": intercept, "r2": r2, "n": len(s)}


# the failure states a sweep's envelopes go through: (name, summary key of sigma_n, of tau)
FAILURE_STATES = (("peak", "sigma_n_peak_Pa", "tau_peak_Pa"), ("residual", "sigma_n_residual_Pa", "tau_residual_Pa"))


def envelopes(summaries: list[dict]) -> dict:
    """The Coulomb envelopes through a set of direct shear tests' summaries (one per normal
    stress), at the peak and at the residual state (analysis.envelope.fit_envelopes: keys
    envelope_*_{peak,residual})."""
    return fit_envelopes(summaries, FAILURE_STATES, coulomb_fit)


def envelope_panel(title: str, summaries: list[dict], fit: dict) -> tuple:
    """One panel of a sweep's envelope.png: (title, [(state, sigma_n, tau, phi_deg, cohesion_Pa)])
    for the states that have an envelope."""
    lines = []
    for name, s_key, t_key in FAILURE_STATES:
        if f"envelope_phi_{name}_deg" in fit:
            s, t = failure_pairs(summaries, s_key, t_key)
            lines.append((name, s, t, fit[f"envelope_phi_{name}_deg"], fit[f"envelope_cohesion_{name}_Pa"]))
    return title, lines


def plot_envelopes(panels: list[tuple], path: Path) -> None:
    """envelope.png: per panel the tests' failure states (tau against sigma_n, kPa) and the
    Coulomb lines through them."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(panels), figsize=(6 * len(panels), 4.2), squeeze=False)
    for ax, (title, lines) in zip(axes[0], panels):
        top = max((float(np.max(s)) for _, s, _, _, _ in lines if len(s)), default=1.0) / 1e3
        sigma = np.linspace(0.0, 1.1 * top, 50)
        for k, (name, s, t, phi, c) in enumerate(lines):
            marker, style = (("o", "--"), ("s", ":"))[k % 2]
            ax.plot(s / 1e3, t / 1e3, marker, color=f"C{k}", label=f"{name} states")
            ax.plot(sigma, c / 1e3 + sigma * np.tan(np.radians(phi)), style, color=f"C{k}", lw=1,
                    label=f"{name}: phi = {phi:.1f} deg, c = {c / 1e3:.3g} kPa")  # fmt: skip
        ax.set(xlabel="normal stress sigma_n (kPa)", ylabel="shear stress tau (kPa)", title=title)
        ax.set_xlim(left=0.0)
        ax.set_ylim(bottom=0.0)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc="upper left")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def shear_figures(rows: np.ndarray, normal_stress: float | None = None) -> dict:
    """summary.json's measures over the shear rows (module docstring), with displacements from the
    shear's start, and given the target normal stress how closely the lid held it (sigma_n_error_*,
    analysis.triaxial.held_stress); a measure the run cannot give is its `*_error` string."""
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
    sigma_n, tau = shear[:, HEADER.index("sigma_n")], shear[:, HEADER.index("tau")]
    measured(out, "peak_state", lambda: peak_stresses(ratio, sigma_n, tau))
    measured(out, "residual_state", lambda: residual_stresses(x, ratio, sigma_n, tau))
    if normal_stress is not None:
        out.update(held_stress(sigma_n, normal_stress, "sigma_n"))
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
