"""The summary fields every dynamic scenario writes (summary.json): what ran, how long, with which
model changes (mass scaling, body model, integrator) and which contact parameters."""

from __future__ import annotations

import csv
import time
import warnings

from ..model.scene import Scene
from ..portable import kernels
from .loop import Run


class FrictionSpringWarning(UserWarning):
    """The pairs' elastic tangential slip outgrew the contact layer (friction_reach)."""


def history_rows(history_csv) -> list[dict]:
    """The frames of a run's history.csv as dicts of strings; none where the file cannot be read."""
    try:
        with open(history_csv) as fh:
            return list(csv.DictReader(fh))
    except OSError:
        return []


def energy_balance(history_csv, since: float | None = None) -> dict | None:
    """From the first and last frames of history.csv: the mechanical energy E = kinetic + strain +
    gravity + contact at both, what damping and friction dissipated between them, the potential
    energy gravity released, the work the moving walls did on the grains (W), and the balance
    error (E_end + dissipated - E_start - W) relative to the largest of the released potential,
    the initial kinetic energy and |W| (within 1 % when the integrator keeps the books, docs/dynamics.md;
    a removed wall takes its contact energy with it). `since`: from the first frame at or after
    that time (a scenario that works on the grains until then, as the tilting box turning
    gravity). None when there are fewer than two frames."""
    rows = history_rows(history_csv)
    if since is not None:
        rows = [r for r in rows if float(r["time"]) >= since]
    if len(rows) < 2:
        return None
    first, last = ({k: float(v) for k, v in r.items() if k is not None} for r in (rows[0], rows[-1]))

    def mechanical(r):
        return r["kinetic"] + r["strain"] + r["gravity"] + r["contact"]

    released = first["gravity"] - last["gravity"]
    dissipated = last["dissipated"] - first["dissipated"]
    # the moving walls' work on the grains (an early 0.1.0 run's history.csv has no column for it)
    work = last["wall_work"] - first["wall_work"] if "wall_work" in last else 0.0
    scale = max(abs(released), first["kinetic"], abs(work), 1e-300)
    return {
        "start": mechanical(first),
        "end": mechanical(last),
        "dissipated": dissipated,
        "released_potential": released,
        "wall_work": work,
        "balance_error": (mechanical(last) + dissipated - mechanical(first) - work) / scale,
    }


def friction_reach(history_csv, activation_gap: float, tangential_penalty: float) -> dict:
    """summary.json's "friction": the largest elastic tangential slip of the pairs over the run's
    frames (history.csv's elastic_slip, a 99th percentile over the pairs) and when it was reached.

    A pair sticks while eps_t |g_t| <= mu F_N, so it slides only after an elastic slip of
    mu F_N / eps_t. The default eps_t is the normal stiffness at the switch gap, 2 F_ref / (gbar -
    gbb): made for forces near F_ref (10 grain weights). Under loads far above it (a lid at the real
    density: 1e3-1e5 F_ref per contact) that slip grows beyond the contact layer gbar, and
    friction is barely mobilised: the 515-grain lid cycle's side walls carried 0.002-0.007 of their
    normal force as friction with mu = 0.15 (docs/results.md, "The real-density jam has almost no
    friction"). Such a run warns (FrictionSpringWarning) and says what to set."""
    rows = [r for r in history_rows(history_csv) if r.get("elastic_slip") not in (None, "")]
    if not rows:
        return {"elastic_slip_max": None, "reason": "no frames with the elastic slip recorded"}
    worst = max(rows, key=lambda r: float(r["elastic_slip"]))
    slip = float(worst["elastic_slip"])
    record = {"elastic_slip_max": slip, "time": float(worst["time"]), "activation_gap": activation_gap,
              "beyond_contact_layer": slip > activation_gap}  # fmt: skip
    if slip > activation_gap:
        warnings.warn(FrictionSpringWarning(
            f"friction springs stretched to {slip * 1e6:.3g} um at t = {record['time']:.6g} s (99th percentile of the "
            f"pairs' elastic tangential slip), beyond the contact layer ({activation_gap * 1e6:.3g} um): the contact "
            f"forces outgrew the tangential penalty ({tangential_penalty:.3g} N/m), and pairs slide only after that "
            "much slip (under a lid at the real density friction is then barely mobilised); for loads far above the "
            "grains' weight set [contact] reference_force to the expected force per contact (docs/contact.md)"),
            stacklevel=2)  # fmt: skip
    return record


def run_summary(scenario: str, scene: Scene, run: Run, t_start: float | None = None) -> dict:
    """t_start: perf_counter() when the scenario began (building included); else the loop's own time."""
    stats, state = run.stats, run.state
    wall = run.wall_seconds if t_start is None else time.perf_counter() - t_start
    return {
        "scenario": scenario,
        "integrator": run.integrator.name,
        "grain_model": scene.bodies.kind,
        "mass_scaling": scene.mass_scaling,  # density factor: inertia, weight and contact force scales
        "selective_mass_scaling": scene.selective_mass_scaling,  # lambda: deformation inertia x (1 + lambda)
        "selective_mass_scaling_auto": scene.selective_auto,  # what "auto" weighed (model/selective.py)
        # a grain's slowest vibration over a contact's duration: above 0.25 the scaling changes collisions
        "vibration_contact_ratio": scene.vibration_contact_ratio(),
        "n_grains": scene.n_grains,
        "n_vertices": scene.n_vertices,
        "n_steps": stats.accepted,
        "n_rejected_steps": stats.rejected,
        "rejections": dict(sorted(stats.rejections.items())),  # by cause: newton, energy, missed_pairs, ...
        "n_newton_iterations": stats.newton_iterations,
        "n_krylov_iterations": stats.krylov_iterations,
        "newton_iterations_per_step": stats.newton_iterations / max(stats.accepted, 1),
        "newton_iterations_per_simulated_second": stats.newton_iterations / state.t if state.t > 0 else 0.0,
        "linear_solver": _linear(run.integrator),
        "n_energy_gain_steps": stats.energy_gains,  # implicit: steps accepted although the energy grew
        "n_frozen_pair_steps": stats.frozen_pair_steps,  # implicit: steps converged with cycling pairs kept
        # implicit: steps with pairs judged by mu_d after stick-slip cycles (break_stick_cycles)
        "n_stick_break_steps": stats.stick_break_steps,
        # implicit: steps with pairs undamped after cycles on the damping's clamp (hold_damping_cycles)
        "n_damping_hold_steps": stats.damping_hold_steps,
        # implicit: grain blocks of Newton's matrices, and those of the exact element tangent (the rest were
        # reference tangents rotated: solver.rotated_tangent, docs/vem.md)
        "n_tangent_blocks": stats.tangent_blocks,
        "n_exact_tangent_blocks": stats.exact_tangent_blocks,
        "simulated_time": state.t,
        "mean_time_step": state.t / max(stats.accepted, 1),
        "wall_seconds": wall,
        # over every part of a resumed run (each part's time loop up to its last checkpoint, then this one's
        # wall_seconds); None where a part's checkpoint kept no wall time (an early format-0 one:
        # driver/checkpoint.py)
        "wall_seconds_total": None if run.earlier_wall_seconds is None else run.earlier_wall_seconds + wall,
        # step-control keys a --resume changed, each {key, then, now, time, frame}: [] for a run stepped as
        # configured from its start (docs/errors.md)
        "resume_changes": run.resume_changes,
        # the kernels the run rounded with (OpenBLAS's, numba's target): runs on two machines agree to
        # the bit where these do (docs/errors.md)
        "kernels": kernels(),
        "energy": _books(run),
        "contact": {
            "activation_gap": scene.contact.law.activation_gap,
            "penalty": scene.contact.law.penalty,
            "penalty_exponent": scene.contact.law.penalty_exponent,  # 1.5: the material's (Hertz's) law
            "reference_force": scene.contact.law.switch_force,
            "tangential_penalty": scene.contact.friction.tangential_penalty,
            "damping_ratio": scene.contact.friction.damping_ratio,
            # the two options the contact law no longer has, kept for the readers of summary.json: always off
            "edge_fade": False,
            "edge_edge_rule": False,
        },
        "friction": friction_reach(run.out_dir / "history.csv", scene.contact.law.activation_gap,
                                   scene.contact.friction.tangential_penalty) if run.out_dir is not None else None,
    }


def _linear(integrator) -> dict | None:
    """Counters of the implicit flexible integrator's linear solver (None for the others)."""
    stats = getattr(integrator, "linear_stats", None)
    if stats is None:
        return None
    return {"factorisations": stats.factorisations, "krylov_iterations": stats.iterations,
            # auto: systems handed to the direct solver after GMRES failed, and those sent there
            # straight after a hand-over (solver/linear/__init__.py AutoSolver)
            "fallbacks": stats.fallbacks, "held": stats.held,
            # grain-block: solves that ended at GMRES's attainable accuracy (grain_block.STALL_ACCEPT)
            "stalled": stats.stalled,
            # grain-block: SuperLU factorisations of coarse matrices, and the inner GMRES iterations of
            # those solved with an LU kept from an earlier Newton matrix (grain_block.KEPT_COARSE_*)
            "coarse_factorisations": stats.coarse_factorisations, "coarse_iterations": stats.coarse_iterations,
            # grain-block: grain blocks solved by Woodbury's formula ([solver] woodbury_dofs), all matrices
            "woodbury_blocks": stats.woodbury_blocks,
            "counted_since": "the run started (checkpoints carry the counters)"}  # fmt: skip


def _books(run: Run) -> dict | None:
    return energy_balance(run.out_dir / "history.csv") if run.out_dir is not None else None
