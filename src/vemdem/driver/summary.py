"""The summary fields every dynamic scenario writes (summary.json): what ran, how long, with which
model changes (mass scaling, body model, integrator) and which contact parameters."""

from __future__ import annotations

import time

from ..model.scene import Scene
from .loop import Run


def run_summary(scenario: str, scene: Scene, run: Run, t_start: float | None = None) -> dict:
    """t_start: perf_counter() when the scenario began (building included); else the loop's own time."""
    stats, state = run.stats, run.state
    return {
        "scenario": scenario,
        "integrator": run.integrator.name,
        "grain_model": scene.bodies.kind,
        "mass_scaling": scene.mass_scaling,  # density factor: inertia, weight and contact force scales
        "n_grains": scene.n_grains,
        "n_vertices": scene.n_vertices,
        "n_steps": stats.accepted,
        "n_rejected_steps": stats.rejected,
        "n_newton_iterations": stats.newton_iterations,
        "n_krylov_iterations": stats.krylov_iterations,
        "newton_iterations_per_step": stats.newton_iterations / max(stats.accepted, 1),
        "newton_iterations_per_simulated_second": stats.newton_iterations / state.t if state.t > 0 else 0.0,
        "n_energy_gain_steps": stats.energy_gains,  # implicit: tiny steps accepted although the energy grew
        "simulated_time": state.t,
        "mean_time_step": state.t / max(stats.accepted, 1),
        "wall_seconds": run.wall_seconds if t_start is None else time.perf_counter() - t_start,
        "contact": {
            "activation_gap": scene.contact.law.activation_gap,
            "penalty": scene.contact.law.penalty,
            "tangential_penalty": scene.contact.friction.tangential_penalty,
            "damping_ratio": scene.contact.friction.damping_ratio,
        },
    }
