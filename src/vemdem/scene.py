"""A scene: grains placed in the world, their elements and masses, walls, contact and gravity.

Data flows one way: config -> Scene -> integrator steps (element forces + contact forces) ->
writers and analysis. The reference configuration of every grain is its initial placement
(total Lagrangian); all grains share flat arrays (`GrainElements`, `GrainMass`, `ContactModel`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .contact.friction import FrictionLaw
from .contact.law import InterfaceLaw
from .contact.model import ContactModel
from .geometry.polyhedron import Polyhedron
from .vem.element import GrainElements, VemOptions, build_elements
from .vem.mass import GrainMass, build_mass
from .vem.material import Material


@dataclass
class Scene:
    grains: list[Polyhedron]
    material: Material
    elements: GrainElements
    mass: GrainMass
    contact: ContactModel
    gravity: np.ndarray

    @classmethod
    def build(cls, grains, material: Material, law: InterfaceLaw, friction: FrictionLaw = FrictionLaw(),
              planes=(), meshes=(), gravity=(0.0, 0.0, -9.81), vem: VemOptions = VemOptions()) -> "Scene":  # fmt: skip
        elements = build_elements(list(grains), material, vem)
        mass = build_mass(list(grains), elements, material.density)
        grain_mass = material.density * elements.volume
        contact = ContactModel(elements.reference, [g.faces for g in grains], elements.vertex_ptr, grain_mass, law,
                               friction, planes=planes, meshes=meshes)  # fmt: skip
        return cls(list(grains), material, elements, mass, contact, np.asarray(gravity, float))

    @property
    def n_vertices(self) -> int:
        return self.elements.n_vertices

    @property
    def n_grains(self) -> int:
        return self.elements.n_grains

    def mass_matrix(self) -> sp.csr_matrix:
        cached = getattr(self, "_mass_matrix", None)
        if cached is None:
            cached = self.mass.matrix()
            self._mass_matrix = cached
        return cached

    def gravity_force(self) -> np.ndarray:
        """Nodal gravity load (N, 3) of the blended element (beta_e)."""
        return self.mass.load[:, None] * self.gravity[None, :]

    def kinetic_energy(self, v: np.ndarray, lumped: bool = False) -> float:
        """1/2 v.M v with the consistent mass, or the lumped one (the explicit integrator's)."""
        if lumped:
            return 0.5 * float(np.sum(self.mass.lumped[:, None] * v * v))
        vf = v.ravel()
        return 0.5 * float(vf @ (self.mass_matrix() @ vf))

    def gravity_energy(self, x: np.ndarray, lumped: bool = False) -> float:
        """Potential of gravity measured from the origin (z = 0 for vertical gravity), with the
        element's load vector or the lumped masses (the explicit integrator's)."""
        weights = self.mass.lumped if lumped else self.mass.load
        return -float(np.sum(weights[:, None] * self.gravity[None, :] * x))

    def grain_centroids(self, x: np.ndarray) -> np.ndarray:
        """Mass-weighted centre of each grain (lumped weights: exact for the centre of mass)."""
        w = self.mass.lumped[:, None]
        sums = np.add.reduceat(w * x, self.elements.vertex_ptr[:-1], axis=0)
        return sums / np.add.reduceat(self.mass.lumped, self.elements.vertex_ptr[:-1])[:, None]
