"""A head-on impact of two grains: what mass scaling does to a collision.

    head_on(mass_scaling, integrator="explicit") -> Impact(restitution, energy_kept, ratio, ...)
    head_on(1.0, selective_mass_scaling=lam): the same with only the deformation modes scaled

Two copies of one sand grain, no gravity, approach along x at relative speed `speed` from a gap of
1.2 activation gaps; the run ends a few contact durations later. The restitution is the ratio of
the relative velocity of their centres of mass along x after and before (mass-weighted, so the
grains' own vibration does not enter it); `energy_kept` is the kinetic energy after over before
(vibration included: it never exceeds 1 in a closed system).

The contact law's scales follow the weight (contact/defaults.py: F_ref = 10 m g), so the contact
duration does not change with mass scaling s, while a grain's own vibration period grows as
sqrt(s). `Scene.vibration_contact_ratio` is that period over the contact duration; where it is not
small, part of the impact energy goes into the grain's vibration and comes back, and the
restitution no longer is the real one (benchmarks/bench_mass_scaling.py, docs/results.md).
Selective mass scaling lambda leaves the contact duration and the grains' rigid inertia alone and
lengthens the vibration periods by sqrt(1 + lambda) (docs/selective-mass-scaling.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..contact.defaults import default_contact_laws
from ..geometry import sand_grain
from ..model.scene import Scene
from ..solver.api import SolverOptions, make_integrator
from ..solver.state import RunStats
from ..vem.material import Material

E, NU, DENSITY = 90e9, 0.16, 2200.0


@dataclass(frozen=True)
class Impact:
    mass_scaling: float
    integrator: str
    restitution: float  # -(relative centre velocity after) / (before), along the line of approach
    energy_kept: float  # kinetic energy after / before (vibration included)
    vibration_contact_ratio: float  # Scene.vibration_contact_ratio
    steps: int
    selective_mass_scaling: float = 0.0


def impact_scene(mass_scaling: float, size: float = 0.9e-3, n_vertices: int = 30, seed: int = 0,
                 grain_model: str = "flexible", reference_force: float | None = None) -> tuple[Scene, int]:  # fmt: skip
    """Two copies of one grain side by side along x, 1.2 activation gaps apart; no gravity.
    reference_force: the contact law's (N; default: 10 grain weights)."""
    material = Material(E, NU, DENSITY * mass_scaling)
    overrides = {} if reference_force is None else {"reference_force": reference_force}
    law, friction = default_contact_laws(size, E, material.density, 9.81, 0.6, 0.5, **overrides)
    a = sand_grain(size, n_vertices, seed=seed)
    shift = a.vertices[:, 0].max() - a.vertices[:, 0].min() + 1.2 * law.activation_gap
    b = a.translated((shift, 0.0, 0.0))
    scene = Scene.build([a, b], material, law, friction, gravity=(0.0, 0.0, 0.0), mass_scaling=mass_scaling,
                        grain_model=grain_model)  # fmt: skip
    return scene, a.n_vertices


def head_on(mass_scaling: float, integrator: str = "explicit", speed: float = 0.05, size: float = 0.9e-3,
            n_vertices: int = 30, seed: int = 0, contact_durations: float = 4.0, selective_mass_scaling: float = 0.0,
            reference_force: float | None = None) -> Impact:  # fmt: skip
    scene, n_a = impact_scene(mass_scaling, size, n_vertices, seed, reference_force=reference_force)
    scene.bodies.scale_deformation_inertia(selective_mass_scaling)
    v0 = np.zeros((scene.n_vertices, 3))
    v0[:n_a, 0], v0[n_a:, 0] = 0.5 * speed, -0.5 * speed
    run = make_integrator(SolverOptions(integrator=integrator, dt_max=2e-5), scene)
    state = run.initial_state(v0=v0)
    approach = 1.2 * scene.contact.law.activation_gap / speed
    duration = float(scene.contact_durations()[0])
    kinetic0 = scene.kinetic_energy(v0, run.lumped, state.x)
    state, stats = run.advance(state, approach + contact_durations * duration, None, RunStats())
    centres = scene.grain_centroids(state.v)  # mass-weighted: the centres' velocities
    return Impact(mass_scaling, integrator, float((centres[1, 0] - centres[0, 0]) / speed),
                  scene.kinetic_energy(state.v, run.lumped, state.x) / kinetic0, scene.vibration_contact_ratio(),
                  stats.accepted, selective_mass_scaling)  # fmt: skip

