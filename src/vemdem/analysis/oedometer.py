"""An oedometer test's measures: its frames (oedometer.csv), its stages' turning points and the
figures summary.json reports (docs/oedometer.md).

From the stages' records (lab/path.py: each stage's target, end stress, end strain and the
lid's work over it):

- K0: sigma_h / sigma_v at the ends of the first-loading stages (before the first unloading),
  their mean; Jaky's 1 - sin(phi) is its classic estimate for sands.
- constrained moduli M = d sigma_v / d eps_a between consecutive turning points, loading (first
  loading and reloading marked) and unloading, each with the stresses it spans.
- modulus_exponent: the slope of log M against log sigma_v over the first-loading intervals
  (M = C sigma_v^m: m about 0.5 for sands, 1/3 for Hertz's contacts under a fixed fabric), each
  interval's stress the geometric mean of its ends; None with fewer than two such intervals.
- hysteresis_energy: the lid's net work on the sample over the first unload-reload loop, from the
  start of the first unloading to the end of the reloading stage that reaches the stress the
  unloading began from; where the path has no reloading, over the whole path (a load-unload
  cycle: the area of the paper's force-displacement loop, Fig. 7).
- residual_strain: the axial strain at the end of the first unloading.
- love_weber_error_at_turns: the largest relative difference between the contacts' sigma_zz
  (Love-Weber) and the lid's stress where a stage ended at its target, at rest.
- max_inertia_number: the largest inertia number over the frames of the loading stages once the
  lid carries its first target (the approach to the pack's top and the seating under the first
  target are excluded, and named so: no stress there to be quasi-static under).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

HEADER = ("time", "stage", "sigma_v", "sigma_h", "axial_strain", "void_ratio", "packing_fraction", "coordination",
          "inertia_number", "lid_height", "lid_speed", "lid_force", "sigma_v_contacts", "unbalanced")  # fmt: skip


def inertia_number(speed: float, height: float, grain_size: float, stress: float, density: float) -> float:
    """I = rate d / sqrt(sigma / rho), rate = |lid speed| / sample height (GDR MiDi); inf where
    nothing presses."""
    if stress <= 0:
        return float("inf")
    return float(abs(speed) / height * grain_size / np.sqrt(stress / density))


def turning_points(stages: list[dict]) -> list[dict]:
    """The stages that ended, in order, each with whether it is first loading ("virgin": loading
    to a stress above every earlier one), reloading or unloading."""
    out, peak = [], 0.0
    for s in stages:
        if not s["end_reason"]:
            break
        kind = "unloading" if not s["loading"] else ("virgin" if s["target"] > peak else "reloading")
        peak = max(peak, s["target"])
        out.append({**s, "kind": kind})
    return out


def moduli(points: list[dict], start_strain: float = 0.0) -> tuple[list, list]:
    """Constrained moduli between consecutive turning points (module docstring): (loading, unloading),
    each a list of {from_Pa, to_Pa, modulus_Pa, kind}. The first stage's is left out: it starts
    from the lid's first touch, not from a stress."""
    loading, unloading = [], []
    for a, b in zip(points, points[1:]):
        de = b["end_strain"] - a["end_strain"]
        ds = b["end_stress"] - a["end_stress"]
        if de == 0:
            continue
        entry = {"from_Pa": a["end_stress"], "to_Pa": b["end_stress"], "modulus_Pa": ds / de, "kind": b["kind"]}
        (unloading if b["kind"] == "unloading" else loading).append(entry)
    return loading, unloading


def modulus_exponent(loading: list[dict]) -> float | None:
    """The least-squares slope of log(modulus) against log(stress) over the first-loading entries
    of `moduli`'s loading list (kind "virgin"), each at the geometric mean of the stresses it spans:
    for M = C sigma^m and stages a constant ratio apart the secant moduli give m exactly. None with
    fewer than two intervals of positive stresses and moduli."""
    virgin = [e for e in loading
              if e["kind"] == "virgin" and min(e["from_Pa"], e["to_Pa"], e["modulus_Pa"]) > 0]  # fmt: skip
    if len(virgin) < 2:
        return None
    log_stress = np.log([np.sqrt(e["from_Pa"] * e["to_Pa"]) for e in virgin])
    log_modulus = np.log([e["modulus_Pa"] for e in virgin])
    if np.ptp(log_stress) == 0:
        return None
    return float(np.polyfit(log_stress, log_modulus, 1)[0])


def hysteresis_energy(points: list[dict]) -> float | None:
    """The lid's net work over the first unload-reload loop, or over the whole path where it never
    reloads to where the unloading began (module docstring); None without an unloading."""
    first = next((i for i, p in enumerate(points) if p["kind"] == "unloading"), None)
    if first is None:
        return None
    top = points[first - 1]["end_stress"] if first > 0 else points[0]["start_stress"]
    for j in range(first + 1, len(points)):
        if points[j]["kind"] != "unloading" and points[j]["end_stress"] >= top * (1 - 1e-9):
            return float(sum(p["work"] for p in points[first : j + 1]))
    return float(sum(p["work"] for p in points))


def oedometer_figures(stages: list[dict], rows: np.ndarray) -> dict:
    """summary.json's measures from the stage records and the frames (rows: columns of HEADER)."""
    points = turning_points(stages)
    out: dict = {"turning_points": [{k: p[k] for k in ("stage", "target", "end_stress", "end_strain", "end_reason",
                                                        "kind", "overshoot", "unbalanced")} for p in points]}  # fmt: skip
    first_unload = next((i for i, p in enumerate(points) if p["kind"] == "unloading"), len(points))
    virgin = [p for p in points[:first_unload] if p["kind"] == "virgin"]
    ratios = [p["sigma_h_end"] / p["end_stress"] for p in virgin if p.get("sigma_h_end") is not None and p["end_stress"] > 0]
    out["K0_by_stage"] = ratios
    out["K0"] = float(np.mean(ratios)) if ratios else None
    loading, unloading = moduli(points)
    out["constrained_modulus_loading_Pa"] = loading
    out["constrained_modulus_unloading_Pa"] = unloading
    out["modulus_exponent"] = modulus_exponent(loading)
    out["hysteresis_energy"] = hysteresis_energy(points)
    out["residual_strain"] = points[first_unload]["end_strain"] if first_unload < len(points) else None
    out["stress_error_at_turns"] = max((abs(p["end_stress"] - p["target"]) / p["target"] for p in points), default=None)
    out["max_overshoot"] = max((p["overshoot"] for p in points), default=None)
    out["love_weber_error_at_turns"] = _love_weber_error(points)
    out["max_inertia_number"], out["inertia_number_frames"] = _loading_inertia(stages, rows)
    return out


def _love_weber_error(points: list[dict]) -> float | None:
    """The largest |sigma_zz(contacts) / sigma_v(lid) - 1| where a stage ended at its target (at rest):
    the lid's stress against the one its contacts carry inside the sample (Love-Weber)."""
    errors = [abs(p["sigma_v_contacts_end"] / p["end_stress"] - 1.0) for p in points
              if p["end_reason"] == "reached" and p.get("sigma_v_contacts_end") is not None and p["end_stress"] > 0]  # fmt: skip
    return max(errors) if errors else None


def _loading_inertia(stages: list[dict], rows: np.ndarray) -> tuple[float | None, str]:
    if len(rows) == 0 or not stages:
        return None, "no frames"
    loading = {s["stage"] for s in stages if s["loading"]}
    seated = stages[0]["end_time"] if stages[0]["end_reason"] else np.inf
    keep = [r for r in rows if int(r[1]) in loading and r[0] > seated and np.isfinite(r[8])]
    what = "frames of the loading stages after the first stage (the approach and the seating left out)"
    return (float(max(r[8] for r in keep)) if keep else None), what


# The strain up to which one virtual element per grain was validated against refined FE (the
# paper: about 20 %; docs/fem_comparison.md)
VALIDATED_STRAIN = 0.2


def grain_strain_maxima(grains_csv: Path) -> np.ndarray:
    """Each grain's largest strain over a run's frames (grains.csv's `strain`: |stretch - 1| of its
    mean deformation gradient)."""
    table = np.atleast_1d(np.genfromtxt(grains_csv, delimiter=",", names=True))
    grains = table["grain"].astype(int)
    out = np.zeros(grains.max() + 1 if len(grains) else 0)
    np.maximum.at(out, grains, table["strain"])
    return out


def grain_strain_summary(strains: np.ndarray) -> dict:
    """summary.json's `largest_grain_strain`: the largest, its grain, how many passed the validated
    range, and every grain's."""
    g = int(np.argmax(strains)) if len(strains) else -1
    return {"max": float(strains[g]) if g >= 0 else None, "grain": g, "validated_range": VALIDATED_STRAIN,
            "grains_past_validated_range": int(np.sum(strains > VALIDATED_STRAIN)), "by_grain": strains.tolist()}  # fmt: skip


def read_rows(path: Path) -> np.ndarray:
    """oedometer.csv as an (n, len(HEADER)) float array (empty where no frame was written)."""
    data = np.genfromtxt(path, delimiter=",", skip_header=1, ndmin=2)
    return data.reshape(-1, len(HEADER)) if data.size else np.zeros((0, len(HEADER)))


def plot_oedometer(rows: np.ndarray, points: list[dict], path: Path, title: str, area: float) -> None:
    """oedometer.png: void ratio against log sigma_v; sigma_h against sigma_v; the lid's force
    against the axial strain (the paper's Fig. 7 view), turning points marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 3, figsize=(14, 4.2))
    loaded = rows[rows[:, 2] > 0] if len(rows) else rows
    ax[0].semilogx(loaded[:, 2] / 1e3, loaded[:, 5], "-", color="C0", lw=1)
    ax[0].set(xlabel="vertical stress sigma_v (kPa)", ylabel="void ratio e", title="compression curve")
    ax[1].plot(rows[:, 2] / 1e3, rows[:, 3] / 1e3, "-", color="C1", lw=1)
    ax[1].set(xlabel="sigma_v (kPa)", ylabel="lateral stress sigma_h (kPa)", title="lateral stress")
    ax[2].plot(rows[:, 4], rows[:, 11], "-", color="C2", lw=1)
    ax[2].set(xlabel="axial strain", ylabel="lid force (N)", title="force against strain (Fig. 7 view)")
    for p in points:
        ax[2].plot(p["end_strain"], p["end_stress"] * area, "o", color="k", ms=3)
        if p.get("sigma_h_end") is not None:
            ax[1].plot(p["end_stress"] / 1e3, p["sigma_h_end"] / 1e3, "o", color="k", ms=3)
    for a in ax:
        a.grid(alpha=0.3)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
