"""A scene: bodies placed in the world, their contact and gravity.

Data flows one way: config -> Scene -> integrator steps (body forces + contact forces) ->
writers and analysis. The reference configuration of every grain is its initial placement
(total Lagrangian); all grains share flat arrays (`BodyModel`, `ContactModel`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..contact.friction import FrictionLaw
from ..contact.law import InterfaceLaw, normal_force
from ..contact.model import ContactModel
from ..geometry.mass import largest_strains, mean_deformation_gradients
from ..geometry.polyhedron import Polyhedron
from ..vem.element import VemOptions
from ..vem.material import Material
from .bodies import BodyModel, VemBodies, equivalent_diameters
from .rigid import RigidBodies


@dataclass
class Scene:
    """Grains in the world: reference shapes, material, body model, contact layer, gravity (`Scene.build` makes one)."""
    grains: list[Polyhedron]  # reference shapes (state files, outputs)
    material: Material  # density already multiplied by mass_scaling
    bodies: BodyModel
    contact: ContactModel
    gravity: np.ndarray
    mass_scaling: float = 1.0  # density factor applied to the material (recorded in every summary)
    selective_auto: dict | None = None  # what chose selective mass scaling's lambda, where "auto" did (model.selective)

    @classmethod
    def build(cls, grains, material: Material, law: InterfaceLaw, friction: FrictionLaw = FrictionLaw(),
              planes=(), meshes=(), gravity=(0.0, 0.0, -9.81), vem: VemOptions = VemOptions(),
              mass_scaling: float = 1.0, grain_model: str = "flexible") -> "Scene":  # fmt: skip
        """grain_model: "flexible" (one virtual element per grain) or "rigid" (model/rigid.py)."""
        if grain_model == "rigid":
            bodies = RigidBodies(list(grains), material, vem)
        elif grain_model == "flexible":
            bodies = VemBodies(list(grains), material, vem)
        else:
            raise ValueError(f'grain_model must be "flexible" or "rigid", got {grain_model!r}')
        contact = ContactModel(bodies.reference, [g.faces for g in grains], bodies.vertex_ptr, bodies.body_mass, law,
                               friction, planes=planes, meshes=meshes)  # fmt: skip
        return cls(list(grains), material, bodies, contact, np.asarray(gravity, float), float(mass_scaling))

    def surface_triangles(self) -> tuple[np.ndarray, np.ndarray]:
        """(faces, face_grain): the grains' surface triangles (indices into the vertex positions)
        and the grain of each, walls left out (pictures)."""
        topo = self.contact.topology
        mine = topo.face_grain < self.n_grains
        return topo.faces[mine], topo.face_grain[mine]

    @property
    def n_vertices(self) -> int:
        return self.bodies.n_vertices

    @property
    def n_grains(self) -> int:
        return self.bodies.n_bodies

    @property
    def grain_sizes(self) -> np.ndarray:
        """Equivalent diameter of every grain (model.bodies.equivalent_diameters)."""
        return equivalent_diameters(self.bodies.volume)

    @property
    def grain_size(self) -> float:
        """Mean equivalent diameter."""
        return float(np.mean(self.grain_sizes))

    def mass_matrix(self) -> sp.csr_matrix:
        return self.bodies.mass_matrix()

    def gravity_force(self) -> np.ndarray:
        """Nodal gravity load (N, 3) of the blended element (beta_e)."""
        return self.bodies.load[:, None] * self.gravity[None, :]

    @property
    def selective_mass_scaling(self) -> float:
        """lambda: the grains' deformation modes carry (1 + lambda) times their inertia in the
        explicit step (vem/selective_mass.py; 0 for rigid grains and unscaled ones)."""
        return float(getattr(self.bodies, "deformation_scaling", 0.0))

    def kinetic_energy(self, v: np.ndarray, lumped: bool = False, x: np.ndarray | None = None) -> float:
        """1/2 v.M v with the consistent mass, or the lumped one (the explicit integrator's). With
        the positions x and selective mass scaling lambda, the lumped one is the scaled mass's,
        1/2 v.M_s v: the deformation modes' part counts (1 + lambda) times (the energy the explicit
        step keeps; without x, the grains' real kinetic energy, as rest criteria measure it)."""
        if lumped:
            real = 0.5 * float(np.sum(self.bodies.lumped[:, None] * v * v))
            lam = self.selective_mass_scaling
            if lam and x is not None:
                return real + lam * self.bodies.deformation_kinetic_energy(x, v)
            return real
        vf = v.ravel()
        return 0.5 * float(vf @ (self.mass_matrix() @ vf))

    def gravity_energy(self, x: np.ndarray, lumped: bool = False) -> float:
        """Potential of gravity measured from the origin (z = 0 for vertical gravity), with the
        element's load vector or the lumped masses (the explicit integrator's)."""
        weights = self.bodies.lumped if lumped else self.bodies.load
        return -float(np.sum(weights[:, None] * self.gravity[None, :] * x))

    def grain_strains(self, x: np.ndarray) -> np.ndarray:
        """Each grain's largest principal strain |stretch - 1| of its mean deformation gradient from
        its reference shape (0 for rigid grains; geometry.mass.mean_deformation_gradients)."""
        n_faces = self.contact.topology.grain_face_ptr[self.n_grains]
        faces, owner = self.contact.topology.faces[:n_faces], self.contact.topology.face_grain[:n_faces]
        return largest_strains(mean_deformation_gradients(x, self.bodies.reference, faces, owner, self.n_grains))

    def grain_centroids(self, x: np.ndarray) -> np.ndarray:
        """Mass-weighted centre of each grain (lumped weights: exact for the centre of mass)."""
        w = self.bodies.lumped[:, None]
        ptr = self.bodies.vertex_ptr[:-1]
        return np.add.reduceat(w * x, ptr, axis=0) / np.add.reduceat(self.bodies.lumped, ptr)[:, None]

    def contact_durations(self) -> np.ndarray:
        """t_c = pi sqrt(m / (2 k)) of every grain: the duration of a contact between two such
        grains, k the normal stiffness at the switch gap (where the law carries its reference
        force, 10 m g). The contact law scales with the weight, so t_c is the same at every mass
        scaling."""
        law = self.contact.law
        k = float(normal_force(law.switch_gap, law.packed())[1])
        return np.pi * np.sqrt(self.bodies.body_mass / (2.0 * k))

    def vibration_contact_ratio(self) -> float:
        """max over grains of T_g / t_c: the grain's slowest vibration period against its contact
        duration. T_g grows as sqrt(mass scaling): above about 0.25 a collision no longer sees a
        stiff grain (verification/impact.py, docs/results.md)."""
        return float(np.max(self.bodies.vibration_periods() / self.contact_durations()))

    def total_mass(self) -> float:
        return float(self.bodies.lumped.sum())
