"""A drained triaxial test's measures: its frames (triaxial.csv), the strength and stiffness
figures summary.json reports, and the Mohr-Coulomb envelope over several confining stresses
(docs/triaxial.md).

Soil mechanics' signs: compression positive, stresses and strains alike. sigma_1 is the axial
(major) stress, sigma_3 the lateral (minor, confining) one; q = sigma_1 - sigma_3 and
p = (sigma_1 + 2 sigma_3) / 3; eps_v = eps_1 + 2 eps_3, so a dilating sample has eps_v falling.
Strains are measured from the start of shear: the consolidation stage is the sample's reference.

- friction angle phi: the Mohr-Coulomb angle without cohesion that the principal stress ratio
  R = sigma_1 / sigma_3 mobilises, sin(phi) = (R - 1) / (R + 1). A cohesionless granular
  material's strength is a ratio, not a stress, so this is the number to compare across
  confining stresses and with the literature.
- peak: the largest R over the shear (phi_peak), where it happens, and the largest deviator q.
  Dense packs peak and then soften; loose ones harden monotonically to their critical state.
- critical state: the state sheared at constant volume and stress ratio. Measured as the mean of
  eta = q / p over the last `window` of axial strain, phi_cs its triaxial-compression angle
  sin(phi) = 3 eta / (6 + eta); the spread (standard deviation of the frames' angles over that
  window) says whether the run got there or is still drifting. eta is linear in the stresses'
  fluctuations where R = sigma_1 / sigma_3 divides by the smaller, noisier one: the mean of R
  reads high by about half its variance over (R + 1)^2 (1.6 deg at a 7 deg spread), so the angle
  of the mean R is reported beside it (phi_cs_from_ratio_deg), not as phi_cs.
- dilatancy angle psi: Bolton's (1986) triaxial form sin(psi) = -(d eps_v / d eps_a) /
  (2 - d eps_v / d eps_a), its largest value over the test. The slope is a least-squares line
  over a moving window of axial strain, so that frame-to-frame noise of a DEM sample does not
  set the maximum. Negative psi: the sample only contracted.
- E50: the secant modulus at half the peak deviator, the usual stiffness of a triaxial curve
  (Duncan-Chang's reference modulus); the initial tangent of a DEM curve is too noisy to use.
- Mohr-Coulomb envelope: a least-squares line through the tests' failure states in the s-t
  plane (s = (sigma_1 + sigma_3) / 2, t = (sigma_1 - sigma_3) / 2): t = a + s tan(alpha) maps
  to sin(phi) = tan(alpha), c = a / cos(phi). The s-t line is exact for Mohr circles tangent to
  a straight envelope, where fitting tau-sigma points would need the tangent points first.
  A sweep's envelope goes through the origin (a = 0: a cohesionless material), the free line
  beside it (analysis.envelope.fit_envelopes).
- max_inertia_number: the largest inertia number over the shear frames, the check that the
  shear was quasi-static.
- held stress: the lateral walls' sigma_3 against the confining stress over the shear frames,
  its mean relative error (signed and absolute) and its largest.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .envelope import fit_envelopes, line_fit

HEADER = ("time", "stage", "axial_strain", "volumetric_strain", "sigma_1", "sigma_3", "q", "p", "void_ratio",
          "coordination", "fabric_anisotropy", "inertia_number", "sigma_1_contacts", "sigma_3_contacts", "unbalanced")  # fmt: skip
CONSOLIDATION, SHEAR = 0, 1  # the `stage` column's values

# Rows whose axial strain lies on a window's edge count as inside it: the strains are sums of
# floats, and a row dropped at one edge only would skew the window's fit
_EDGE = 1e-12


def friction_angle(ratio):
    """The mobilised friction angle (degrees) of the principal stress ratio R = sigma_1 / sigma_3,
    cohesionless Mohr-Coulomb: sin(phi) = (R - 1) / (R + 1). Scalars give a float, arrays an array."""
    r = np.asarray(ratio, dtype=float)
    phi = np.degrees(np.arcsin((r - 1.0) / (r + 1.0)))
    return float(phi) if phi.ndim == 0 else phi


def friction_angle_of_eta(eta):
    """The mobilised friction angle (degrees) of eta = q / p in triaxial compression (sigma_2 =
    sigma_3): sin(phi) = 3 eta / (6 + eta), friction_angle of R = (3 + 2 eta) / (3 - eta)."""
    e = np.asarray(eta, dtype=float)
    phi = np.degrees(np.arcsin(3.0 * e / (6.0 + e)))
    return float(phi) if phi.ndim == 0 else phi


def stress_ratio_from_angle(phi_deg):
    """friction_angle's inverse: R = (1 + sin phi) / (1 - sin phi) = tan^2(45 deg + phi / 2)."""
    s = np.sin(np.radians(np.asarray(phi_deg, dtype=float)))
    r = (1.0 + s) / (1.0 - s)
    return float(r) if r.ndim == 0 else r


def _ratio(sigma_1, sigma_3) -> np.ndarray:
    """sigma_1 / sigma_3, NaN where the lateral walls carry nothing (no ratio to speak of there)."""
    s1, s3 = np.asarray(sigma_1, dtype=float), np.asarray(sigma_3, dtype=float)
    out = np.full(np.broadcast(s1, s3).shape, np.nan)
    np.divide(s1, s3, out=out, where=s3 > 0)
    return out


def peak(axial, sigma_1, sigma_3) -> dict:
    """The peak of the principal stress ratio (phi_peak_deg, ratio_peak, axial_strain_at_peak, and
    the principal stresses there: one failure state of an envelope) and the largest deviator
    q_peak. With sigma_3 held by the servos the two peaks coincide up to its noise; q_peak is the
    deviator's own maximum, the one E50 halves."""
    axial, s1, s3 = (np.asarray(a, dtype=float) for a in (axial, sigma_1, sigma_3))
    ratio = _ratio(s1, s3)
    if not np.any(np.isfinite(ratio)):
        raise ValueError("no row with a positive sigma_3: no stress ratio to find a peak of")
    i = int(np.nanargmax(ratio))
    if ratio[i] <= 1.0:  # its arcsine would be a negative angle: no strength of a compression test
        raise ValueError(f"sigma_1 never exceeded sigma_3 in the shear (largest ratio {ratio[i]:.3g}): no friction "
                         "angle; a sample the consolidation did not bring to its confining stress (its end_reason "
                         "in `stages`), or a shear too short")  # fmt: skip
    return {"phi_peak_deg": friction_angle(ratio[i]), "ratio_peak": float(ratio[i]),
            "axial_strain_at_peak": float(axial[i]), "q_peak": float(np.max(s1 - s3)),
            "sigma_1_peak_Pa": float(s1[i]), "sigma_3_peak_Pa": float(s3[i])}  # fmt: skip


def critical_state(axial, sigma_1, sigma_3, window: float = 0.05) -> dict:
    """The means over the rows in the last `window` of axial strain (module docstring): phi_cs_deg
    from the mean q / p (q_over_p_cs, and its spread), phi_cs_spread_deg the standard deviation of
    the rows' own angles, phi_cs_from_ratio_deg the angle of the mean principal stress ratio,
    critical_state_window and window_rows, and the mean principal stresses sigma_1_cs_Pa and
    sigma_3_cs_Pa (the critical state's failure state for an envelope).
    ValueError where the run spans less than `window` or fewer than 3 rows lie in it (no mean
    worth reporting)."""
    axial, s1, s3 = (np.asarray(a, dtype=float) for a in (axial, sigma_1, sigma_3))
    if len(axial) == 0 or axial.max() - axial.min() < window - _EDGE:
        reached = axial.max() - axial.min() if len(axial) else 0.0
        raise ValueError(f"the run reached {reached:.4g} of axial strain, "
                         f"less than the critical-state window {window:g}")
    ratio = _ratio(s1, s3)
    inside = (axial >= axial.max() - window - _EDGE) & np.isfinite(ratio)
    n = int(inside.sum())
    if n < 3:
        raise ValueError(f"{n} rows with a stress ratio in the last {window:g} of axial strain; "
                         "the critical state needs 3")
    r, q, p = ratio[inside], (s1 - s3)[inside], ((s1 + 2.0 * s3) / 3.0)[inside]
    if np.mean(r) <= 1.0:
        raise ValueError(f"sigma_1 did not exceed sigma_3 over the last {window:g} of axial strain (mean ratio "
                         f"{np.mean(r):.3g}): no critical state of a compression test")
    eta = q / p
    return {"phi_cs_deg": friction_angle_of_eta(np.mean(eta)),
            "phi_cs_spread_deg": float(np.std(friction_angle_of_eta(eta))),
            "phi_cs_from_ratio_deg": friction_angle(np.mean(r)), "q_over_p_cs": float(np.mean(eta)),
            "q_over_p_cs_spread": float(np.std(eta)), "critical_state_window": window, "window_rows": n,
            "sigma_1_cs_Pa": float(np.mean(s1[inside])), "sigma_3_cs_Pa": float(np.mean(s3[inside]))}  # fmt: skip


def bolton_dilatancy(slope):
    """Bolton's triaxial dilatancy angle (degrees) of d eps_v / d eps_a (compression positive):
    sin(psi) = -slope / (2 - slope)."""
    s = np.asarray(slope, dtype=float)
    psi = np.degrees(np.arcsin(-s / (2.0 - s)))
    return float(psi) if psi.ndim == 0 else psi


def dilatancy_slopes(axial, volumetric, window: float = 0.02) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares slopes d eps_v / d eps_a over windows of `window` axial strain centred on each
    row whose whole window lies inside the run (a window cut short by the run's ends would weigh
    its few rows as much as a full one): (centres, slopes). ValueError where no window fits."""
    order = np.argsort(np.asarray(axial, dtype=float), kind="stable")
    a, v = np.asarray(axial, dtype=float)[order], np.asarray(volumetric, dtype=float)[order]
    half = 0.5 * window
    centres, slopes = [], []
    for c in a[(a >= a[0] + half - _EDGE) & (a <= a[-1] - half + _EDGE)] if len(a) else []:
        lo, hi = np.searchsorted(a, c - half - _EDGE, "left"), np.searchsorted(a, c + half + _EDGE, "right")
        x, y = a[lo:hi] - c, v[lo:hi]
        dx = x - x.mean()
        if hi - lo < 3 or not np.any(dx):
            continue
        centres.append(c)
        slopes.append(float(dx @ (y - y.mean()) / (dx @ dx)))
    if not slopes:
        span = a[-1] - a[0] if len(a) else 0.0
        raise ValueError(f"no window of {window:g} axial strain with 3 rows fits in the run's {span:.4g}")
    return np.array(centres), np.array(slopes)


def dilatancy_window(axial, window: float = 0.02, rows: int = 4) -> float:
    """`window` of axial strain, widened to hold `rows` frames where the frames are further apart
    (a coarse output interval would otherwise leave no window a slope can be fitted over)."""
    steps = np.diff(np.sort(np.asarray(axial, dtype=float)))
    return max(window, rows * float(np.median(steps))) if len(steps) else window


def dilatancy_angle(axial, volumetric, window: float = 0.02) -> dict:
    """The largest Bolton dilatancy angle over the test (module docstring) and the axial strain at
    its window's centre; negative where the sample only contracted."""
    centres, slopes = dilatancy_slopes(axial, volumetric, window)
    i = int(np.argmin(slopes))  # dilation: eps_v falling; psi grows as the slope falls
    if slopes[i] > 1.0:  # beyond Bolton's range: the arcsine of less than -1
        raise ValueError(f"the volume shrank faster than the axial strain throughout (d eps_v / d eps_a at least "
                         f"{slopes[i]:.3g}): the lateral walls were still closing in, no dilatancy angle")
    return {"dilatancy_angle_deg": bolton_dilatancy(slopes[i]), "axial_strain_at_max_dilatancy": float(centres[i])}


def secant_modulus_50(axial, q) -> float:
    """E50 (Pa): half the peak deviator over the axial strain where the deviator first reaches it,
    linearly interpolated between rows; both measured from the first row (the start of shear,
    where q is the consolidation's own deviator, not necessarily zero)."""
    a = np.asarray(axial, dtype=float) - float(axial[0])
    dq = np.asarray(q, dtype=float) - float(q[0])
    half = 0.5 * float(np.max(dq))
    if not half > 0:
        raise ValueError("the deviator never rose above its value at the start of shear: no E50")
    j = int(np.argmax(dq >= half))  # the first row at or past half the peak; j > 0 since dq[0] = 0 < half
    strain = a[j - 1] + (half - dq[j - 1]) / (dq[j] - dq[j - 1]) * (a[j] - a[j - 1])
    if not strain > 0:
        raise ValueError(f"the deviator reached half its peak at axial strain {strain:.3g}: no E50")
    return float(half / strain)


def mohr_coulomb_fit(sigma_3, sigma_1, through_origin: bool = False) -> dict:
    """The Mohr-Coulomb envelope through one failure state per test (module docstring): phi_deg,
    cohesion_Pa (0 `through_origin`), r2 of the s-t line, n. One test: the cohesionless angle of
    its ratio, c = 0, r2 NaN. ValueError on stresses that are not finite and positive, or on an
    envelope no friction angle gives."""
    s3, s1 = np.atleast_1d(np.asarray(sigma_3, dtype=float)), np.atleast_1d(np.asarray(sigma_1, dtype=float))
    if s3.shape != s1.shape or s3.ndim != 1 or len(s3) == 0:
        raise ValueError(f"one sigma_1 per sigma_3 needed, got {s1.shape} and {s3.shape}")
    for name, values in (("sigma_3", s3), ("sigma_1", s1)):
        bad = np.flatnonzero(~np.isfinite(values) | (values <= 0))
        if len(bad):
            raise ValueError(f"{name} must be finite and positive: test {bad[0]} has {values[bad[0]]!r}")
    n = len(s3)
    if n == 1:
        return {"phi_deg": friction_angle(s1[0] / s3[0]), "cohesion_Pa": 0.0, "r2": float("nan"), "n": 1}
    s, t = 0.5 * (s1 + s3), 0.5 * (s1 - s3)
    if not through_origin and not np.any(s - s.mean()):
        raise ValueError("every test failed at the same mean stress s: no envelope slope to fit")
    intercept, slope, r2 = line_fit(s, t, through_origin)
    if not -1.0 < slope < 1.0:
        raise ValueError(f"the s-t line's slope {slope:.4g} is sin(phi), which must lie in (-1, 1)")
    phi = np.arcsin(slope)
    return {"phi_deg": float(np.degrees(phi)), "cohesion_Pa": intercept / float(np.cos(phi)), "r2": r2, "n": n}


def until_sheared(rows: np.ndarray, shear_end) -> np.ndarray:
    """The rows without the shear frames written after the shear stage ended at `shear_end` (the
    time loop stops at the next frame: meanwhile the platen stands and the sample relaxes, which is
    no state of the constant-rate test)."""
    rows = np.asarray(rows, dtype=float).reshape(-1, len(HEADER))
    if not isinstance(shear_end, float) or not np.isfinite(shear_end):  # not ended ("nan" in a record)
        return rows
    after = (rows[:, HEADER.index("stage")] == SHEAR) & (rows[:, HEADER.index("time")] > shear_end)
    return rows[~after]


def shear_strains(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The shear rows (stage == 1) of a triaxial.csv table, with their axial and volumetric strain
    measured from the first of them."""
    rows = np.asarray(rows, dtype=float).reshape(-1, len(HEADER))
    shear = rows[rows[:, HEADER.index("stage")] == SHEAR]
    if len(shear) == 0:
        return shear, np.zeros(0), np.zeros(0)
    axial = shear[:, HEADER.index("axial_strain")]
    volumetric = shear[:, HEADER.index("volumetric_strain")]
    return shear, axial - axial[0], volumetric - volumetric[0]


def held_stress(values, target: float, name: str = "sigma_3") -> dict:
    """How closely a servo held a stress over the shear frames, relative to `target`:
    {name}_error_mean (signed: above the target positive), {name}_error_abs_mean and
    {name}_error_max (the largest magnitude)."""
    error = (np.asarray(values, dtype=float) - target) / target
    return {f"{name}_error_mean": float(np.mean(error)), f"{name}_error_abs_mean": float(np.mean(np.abs(error))),
            f"{name}_error_max": float(np.max(np.abs(error)))}  # fmt: skip


def triaxial_figures(rows: np.ndarray, confining_stress: float | None = None) -> dict:
    """summary.json's measures from the frames (rows: columns of HEADER), over the shear rows: peak,
    critical_state, dilatancy_angle, E50_Pa, max_inertia_number (over the frames where it is
    finite) and, given the confining stress, held_stress. A measure the run cannot give (too
    short, no shear at all) is reported as its `*_error` string instead of failing the run's
    summary."""
    shear, axial, volumetric = shear_strains(rows)
    out: dict = {"shear_rows": len(shear)}
    if len(shear) < 2:
        out["shear_error"] = f"{len(shear)} shear frames: no triaxial measure"
        return out
    s1, s3 = shear[:, HEADER.index("sigma_1")], shear[:, HEADER.index("sigma_3")]
    for name, measure in (("peak", lambda: peak(axial, s1, s3)),
                          ("critical_state", lambda: critical_state(axial, s1, s3)),
                          ("dilatancy", lambda: dilatancy_angle(axial, volumetric, dilatancy_window(axial))),
                          ("E50", lambda: {"E50_Pa": secant_modulus_50(axial, s1 - s3)})):  # fmt: skip
        measured(out, name, measure)
    if confining_stress is not None:
        out.update(held_stress(s3, confining_stress))
    out["max_inertia_number"] = largest_finite(shear[:, HEADER.index("inertia_number")])
    return out


def measured(out: dict, name: str, measure) -> None:
    """out updated with measure(), or with `{name}_error` where the run cannot give it."""
    try:
        out.update(measure())
    except ValueError as error:
        out[f"{name}_error"] = str(error)


def largest_finite(values) -> float | None:
    """The largest finite value (an inertia number over the frames), None where none is finite."""
    values = np.asarray(values, dtype=float)
    finite = values[np.isfinite(values)]
    return float(finite.max()) if len(finite) else None


def _eta(ratio):
    """q / p of a principal stress ratio R under sigma_2 = sigma_3: 3 (R - 1) / (R + 2)."""
    return 3.0 * (ratio - 1.0) / (ratio + 2.0)


def plot_triaxial(rows: np.ndarray, path: Path, title: str, marks: dict | None = None) -> None:
    """triaxial.png: q/p (top) and the volumetric strain, dilation up (bottom), against the axial
    strain of the shear rows; the critical-state q/p dashed and the peak marked where `marks`
    (triaxial_figures' dict) has them."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    marks = marks or {}
    shear, axial, volumetric = shear_strains(rows)
    q, p = shear[:, HEADER.index("q")], shear[:, HEADER.index("p")]
    eta = np.divide(q, p, out=np.full(len(q), np.nan), where=p > 0)
    fig, ax = plt.subplots(2, 1, sharex=True, figsize=(6.4, 6.4))
    ax[0].plot(axial * 100, eta, "-", color="C0", lw=1)
    if marks.get("q_over_p_cs") is not None:
        ax[0].axhline(marks["q_over_p_cs"], color="k", ls="--", lw=1,
                      label=f"critical state q/p = {marks['q_over_p_cs']:.3g}")  # fmt: skip
    if marks.get("axial_strain_at_peak") is not None and marks.get("ratio_peak") is not None:
        phi = f", phi = {marks['phi_peak_deg']:.1f} deg" if marks.get("phi_peak_deg") is not None else ""
        ax[0].plot(marks["axial_strain_at_peak"] * 100, _eta(marks["ratio_peak"]), "o", color="C3", ms=5,
                   label=f"peak{phi}")  # fmt: skip
    ax[0].set(ylabel="stress ratio q/p", title=title)
    ax[1].plot(axial * 100, -volumetric * 100, "-", color="C1", lw=1)
    ax[1].axhline(0.0, color="0.5", lw=0.6)
    ax[1].set(xlabel="axial strain from the start of shear (%)", ylabel="volumetric strain (%), dilation up")
    for a in ax:
        a.grid(alpha=0.3)
    if ax[0].get_legend_handles_labels()[0]:
        ax[0].legend(loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# the failure states a sweep's envelopes go through: (name, summary key of sigma_3, of sigma_1)
FAILURE_STATES = (("peak", "sigma_3_peak_Pa", "sigma_1_peak_Pa"), ("cs", "sigma_3_cs_Pa", "sigma_1_cs_Pa"))


def envelopes(summaries: list[dict]) -> dict:
    """The Mohr-Coulomb envelopes through a set of triaxial tests' summaries (one per confining
    stress), at the peak and at the critical state (analysis.envelope.fit_envelopes: keys
    envelope_*_{peak,cs})."""
    return fit_envelopes(summaries, FAILURE_STATES, mohr_coulomb_fit)


def _draw_envelope(ax, sigma_3, sigma_1, fit: dict, title: str, cs_fit: dict | None = None) -> None:
    s3 = np.atleast_1d(np.asarray(sigma_3, dtype=float)) / 1e3  # kPa on the axes
    s1 = np.atleast_1d(np.asarray(sigma_1, dtype=float)) / 1e3
    angle = np.linspace(0.0, np.pi, 181)
    for k, (a, b) in enumerate(zip(s3, s1)):
        centre, radius = 0.5 * (a + b), 0.5 * (b - a)
        ax.plot(centre + radius * np.cos(angle), radius * np.sin(angle), "-", color=f"C{k % 10}", lw=1,
                label=f"sigma_3 = {a:g} kPa")  # fmt: skip
    sigma = np.linspace(0.0, 1.05 * float(np.max(s1)) if len(s1) else 1.0, 50)
    for f, style, what in ((fit, "k--", "peak"), (cs_fit, "k:", "critical state")):
        if f is not None:
            phi, c = np.radians(f["phi_deg"]), f["cohesion_Pa"] / 1e3
            ax.plot(sigma, c + sigma * np.tan(phi), style, lw=1,
                    label=f"{what}: phi = {f['phi_deg']:.1f} deg, c = {c:.3g} kPa")  # fmt: skip
    ax.set(xlabel="normal stress sigma (kPa)", ylabel="shear stress tau (kPa)", title=title)
    ax.set_aspect("equal", adjustable="datalim")  # circles look like circles
    ax.set_ylim(bottom=0.0)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper left")


def plot_envelope(sigma_3, sigma_1, fit: dict, path: Path, title: str) -> None:
    """envelope.png: each test's Mohr circle at failure and the fitted envelope tau = c + sigma
    tan(phi), in kPa, for a sweep over confining stresses."""
    plot_envelopes([(title, sigma_3, sigma_1, fit, None)], path)


def plot_envelopes(panels: list[tuple], path: Path) -> None:
    """One panel per (title, sigma_3, sigma_1, peak fit, critical-state fit or None): the peak
    states' Mohr circles and both envelopes; a sweep's envelope.png."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(panels), figsize=(7 * len(panels), 4.2), squeeze=False)
    for ax, (title, s3, s1, fit, cs_fit) in zip(axes[0], panels):
        _draw_envelope(ax, s3, s1, fit, title, cs_fit)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
