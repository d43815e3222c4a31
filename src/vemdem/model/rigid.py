"""Rigid grains: the body-model seam's second model (docs/dynamics.md, "Rigid grains").

Each grain is a rigid polyhedron with six dofs: its centroid c and the rotation R of its
principal axes. Its vertices are x_i = c + R X_i, X_i the vertex in the principal frame at the
reference, so contact (which sees vertex positions only) runs unchanged. Mass, centroid and
inertia are exact (geometry.mass_properties); the gravity load and the kinetic energy of vertex
velocities use the grains' consistent VEM mass and load vector, which are exact for linear
fields and therefore for rigid motions (tests/test_rigid.py checks both against the rigid values).
There are no internal forces: `evaluate` returns zeros and the critical elastic step is infinite.
The integrator is solver/rigid.py's.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numba import njit, prange

from ..geometry.mass import mass_properties
from ..geometry.polyhedron import Polyhedron
from ..vem.element import Evaluation, VemOptions, build_elements
from ..vem.mass import build_mass
from ..vem.material import Material

__all__ = ["RigidBodies", "fit_rigid", "place_vertex", "place_vertices"]


@njit(cache=True)
def place_vertex(x, i, centre, rotation, body, g):
    """x_i = c_g + R_g X_i, into row i of x."""
    for a in range(3):
        x[i, a] = centre[g, a] + rotation[g, a, 0] * body[i, 0] + rotation[g, a, 1] * body[i, 1] + rotation[g, a, 2] * body[i, 2]


@njit(cache=True, parallel=True)
def place_vertices(centre, rotation, body, vertex_grain):
    """x_i = c_g + R_g X_i for every vertex."""
    x = np.empty_like(body)
    for i in prange(len(body)):
        # np.int64: a prange index is uint64 in the parallel body, a second compilation of the callee
        place_vertex(x, np.int64(i), centre, rotation, body, vertex_grain[i])
    return x


def fit_rigid(x: np.ndarray, body: np.ndarray, weights: np.ndarray, vertex_ptr: np.ndarray):
    """(centre, rotation) of every grain that best place its body-frame vertices `body` on x
    (weighted least squares, Kabsch): a flexible run's state becomes a rigid one."""
    G = len(vertex_ptr) - 1
    centre = np.empty((G, 3))
    rotation = np.empty((G, 3, 3))
    for g in range(G):
        sl = slice(vertex_ptr[g], vertex_ptr[g + 1])
        w = weights[sl] / weights[sl].sum()
        c = w @ x[sl]
        H = (body[sl] * w[:, None]).T @ (x[sl] - c)
        U, _, Vt = np.linalg.svd(H)
        d = np.sign(np.linalg.det(Vt.T @ U.T))
        rotation[g] = Vt.T @ np.diag([1.0, 1.0, d]) @ U.T
        centre[g] = c - rotation[g] @ (w @ body[sl])  # the body frame's origin is the centroid
    return centre, rotation


class RigidBodies:
    """Rigid polyhedra, six dofs each (module docstring). Arrays shared by every kernel:

    body (N, 3)      vertices in their grain's principal frame, about its centroid
    mass (G,)        grain masses; moments (G, 3) principal moments of inertia
    centre0 (G, 3), rotation0 (G, 3, 3)   the reference placement (x = reference)"""

    kind = "rigid"

    def __init__(self, grains: list[Polyhedron], material: Material, options: VemOptions = VemOptions()):
        elements = build_elements(list(grains), material, options)
        vem_mass = build_mass(list(grains), elements, material.density)
        self._vem_mass = vem_mass
        self.vertex_ptr = elements.vertex_ptr
        self.reference = elements.reference
        self.volume = elements.volume
        self.lumped = vem_mass.lumped
        self.load = vem_mass.load
        G = len(grains)
        self.vertex_grain = np.repeat(np.arange(G), np.diff(self.vertex_ptr))
        self.dof_ptr = 6 * np.arange(G + 1, dtype=np.int64)
        self.block_ptr = 36 * np.arange(G + 1, dtype=np.int64)
        self.mass = np.empty(G)
        self.moments = np.empty((G, 3))
        self.centre0 = np.empty((G, 3))
        self.rotation0 = np.empty((G, 3, 3))
        self.body = np.empty_like(self.reference)
        for g, grain in enumerate(grains):
            props = mass_properties(grain.vertices, grain.faces).scaled(material.density)
            moments, axes = np.linalg.eigh(props.inertia)
            if np.linalg.det(axes) < 0:
                axes[:, 2] *= -1.0
            self.mass[g] = material.density * props.volume
            self.moments[g] = moments
            self.centre0[g] = props.centroid
            self.rotation0[g] = axes
            sl = slice(self.vertex_ptr[g], self.vertex_ptr[g + 1])
            self.body[sl] = (self.reference[sl] - props.centroid) @ axes
        self.body_mass = self.mass

    @property
    def n_bodies(self) -> int:
        return len(self.mass)

    @property
    def n_vertices(self) -> int:
        return len(self.reference)

    def positions(self, centre: np.ndarray, rotation: np.ndarray) -> np.ndarray:
        return place_vertices(centre, rotation, self.body, self.vertex_grain)

    # ------------------------------------------------------------------ the BodyModel protocol
    def evaluate(self, x: np.ndarray, force: bool = True, tangent: bool = False, mass_shift: float = 0.0,
                 rotated_strain: float = 0.0) -> Evaluation:  # fmt: skip
        """No strain energy, no internal force: the grains do not deform."""
        if tangent and mass_shift != 0.0:
            raise NotImplementedError("rigid grains have no vertex mass blocks: "
                                      "solver/rigid_implicit.py works on six dofs")
        G = self.n_bodies
        return Evaluation(np.zeros(G), np.zeros_like(x) if force else None, np.zeros(36 * G) if tangent else None)

    def mass_matrix(self) -> sp.csr_matrix:
        """The consistent VEM mass on vertex velocities: exact for rigid motions (1/2 v.M v is the
        rigid kinetic energy 1/2 m |v_c|^2 + 1/2 omega.I omega)."""
        return self._vem_mass.matrix()

    def critical_steps(self) -> np.ndarray:
        return np.full(self.n_bodies, np.inf)

    def vibration_periods(self) -> np.ndarray:
        return np.zeros(self.n_bodies)  # no elastic modes: infinitely stiff

    def cauchy_stress(self, x: np.ndarray) -> np.ndarray:
        return np.zeros((self.n_bodies, 3, 3))
