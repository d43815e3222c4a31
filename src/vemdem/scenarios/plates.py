"""Quasi-static compression of one grain between two rigid, frictionless plates.

The plates are roller conditions on the vertices that touch them (within PLATE_TOL of the grain's
height): the bottom ones keep u_z = 0, the top ones move down by strain * h0; `confined` also
holds the lateral displacement of every vertex at zero. In `uniaxial` mode the remaining rigid
modes are removed by pins (see PlateSetup). Used by the `grain_compression` scenario and by the
refined FE reference (verification/fem_reference.py), which load the VEM and the FE mesh alike.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..geometry.shapes import rotation_matrix
from ..solver.statics import Assemble, solve_static

PLATE_TOL = 1e-6


class PlateSetup:
    """Which dofs the plates and the rigid-mode pins prescribe."""

    def __init__(self, vertices: np.ndarray, mode: str, pins: tuple[int, int] | None):
        z = vertices[:, 2]
        self.z0, self.height = z.min(), np.ptp(z)
        tol = PLATE_TOL * self.height
        self.bottom = np.flatnonzero(z <= self.z0 + tol)
        self.top = np.flatnonzero(z >= z.max() - tol)
        n = len(vertices)
        fixed = np.zeros((n, 3), dtype=bool)
        fixed[self.bottom, 2] = True
        fixed[self.top, 2] = True
        if mode == "confined":
            fixed[:, :2] = True
        else:
            a, b = pins
            fixed[a, :2] = True
            fixed[b, 1] = True
        self.free = ~fixed.ravel()

    @staticmethod
    def choose_pins(vertices: np.ndarray):
        """A: first bottom vertex; B: plate vertex (or, failing that, any vertex) farthest from A
        horizontally. Returns (A, B, angle that turns B - A onto +x)."""
        z = vertices[:, 2]
        tol = PLATE_TOL * np.ptp(z)
        plate = np.flatnonzero((z <= z.min() + tol) | (z >= z.max() - tol))
        a = plate[0]
        d = np.linalg.norm(vertices[:, :2] - vertices[a, :2], axis=1)
        candidates = plate if d[plate].max() > 1e-6 * np.ptp(z) else np.arange(len(vertices))
        b = candidates[np.argmax(d[candidates])]
        delta = vertices[b, :2] - vertices[a, :2]
        return a, b, -np.arctan2(delta[1], delta[0])


def prepare_grain(grain, mode: str):
    """Turn the grain about z so that the pins line up with x (uniaxial mode)."""
    if mode == "confined":
        return grain, None
    a, b, angle = PlateSetup.choose_pins(grain.vertices)
    turned = grain.rotated(rotation_matrix([0.0, 0.0, angle]))
    return turned, (a, b)


def compress(
    assemble: Assemble,
    reference: np.ndarray,
    plates: PlateSetup,
    strains,
    force_scale: float,
    rtol: float = 1e-9,
    max_iter: int = 40,
    on_step: Callable | None = None,
):
    """Quasi-static plate compression of any discretisation (VEM, FE, ...) of one grain.

    `assemble(xflat, want_tangent) -> (energy, residual, K)` is the discrete model on the nodes
    `reference` (n, 3); `plates` says which of those dofs are prescribed. One Newton solve of
    static equilibrium per entry of `strains` (the loaded steps, in order; the reference state
    at strain 0 is not among them), the top plate at z = z_top - strain * h0. After each step
    `on_step(k, strain, x, force, result)` is called (k counts from 1).
    Returns (forces on the top plate at each strain, total Newton iterations).
    """
    X = np.asarray(reference, dtype=float)
    x = X.ravel().copy()
    top_z = 3 * plates.top + 2
    forces, iterations = [], 0
    for k, strain in enumerate(np.asarray(strains, dtype=float), start=1):
        target = x.copy()
        target[top_z] = X[plates.top, 2] - strain * plates.height
        result = solve_static(
            assemble, x, target, plates.free, force_scale, plates.height, rtol=rtol, max_iter=max_iter,
        )  # fmt: skip
        x = result.x
        iterations += result.iterations
        force = -result.residual[top_z].sum()
        forces.append(force)
        if on_step is not None:
            on_step(k, strain, x, force, result)
    return np.array(forces), iterations


def body_assembler(bodies) -> Assemble:
    """A body model (one virtual element per grain) as an `assemble` callable for `compress` /
    `solve_static`."""

    def assemble(xflat, want_tangent):
        ev = bodies.evaluate(xflat.reshape(-1, 3), force=True, tangent=want_tangent)
        K = bodies.tangent_matrix(ev.blocks) if want_tangent else None
        return ev.total_energy, ev.force.ravel(), K

    return assemble
