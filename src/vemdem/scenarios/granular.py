"""What the paper's granular scenarios (pack, pile_collapse, lid_compression) share: the rest
criterion."""

from __future__ import annotations

import numpy as np

from ..model.scene import Scene


def rest_energy(scene: Scene) -> float:
    """m g d of the mean grain: the kinetic energy scale of 'at rest' (mass scaling cancels)."""
    mass = scene.total_mass() / scene.n_grains
    return mass * float(np.linalg.norm(scene.gravity)) * scene.grain_size


def at_rest(scene: Scene, settle: dict, lumped: bool):
    """stop(state) for the time loop: the mean kinetic energy per grain below kinetic_threshold
    m g d after min_time. A grain moving at v has v^2 / (2 g d) of that scale: 1e-3 is a grain
    of 1.45 mm at 5 mm/s."""
    limit = settle["kinetic_threshold"] * rest_energy(scene) * scene.n_grains

    def stop(state) -> bool:
        return state.t >= settle["min_time"] and scene.kinetic_energy(state.v, lumped) < limit

    return stop


def kinetic_ratio(scene: Scene, v: np.ndarray, lumped: bool) -> float:
    """Mean kinetic energy per grain over m g d (what `at_rest` compares with its threshold)."""
    return scene.kinetic_energy(v, lumped) / (rest_energy(scene) * scene.n_grains)
