"""The body-model seam: what integrators, the time loop and the measures know of the grains.

Integrators never call the VEM kernels: they see a `BodyModel`, whose coordinates q they step,
whose `positions(q)` the contact code sees, and whose `evaluate` returns internal forces and the
dense tangent block of every body (the linear solvers' grain blocks). Contact works on vertex
positions only, so a body model is free in its choice of coordinates:

- `VemBodies` (flexible grains, the paper's model): q = the vertex positions x (N, 3), one
  virtual element per grain (vem/), consistent or lumped mass (vem/mass.py); `positions` and
  `pullback` are identities.
- a rigid model (next) maps 6 dofs per grain to its vertices, x = R X + c, and pulls vertex forces
  back with J^T.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
import scipy.sparse as sp

from ..geometry.polyhedron import Polyhedron
from ..vem.element import (
    Evaluation,
    GrainElements,
    InvertedElementError,
    VemOptions,
    build_elements,
    evaluate,
    projected_cauchy_stress,
    reference_tangent,
    tangent_matrix,
)
from ..vem.mass import GrainMass, build_mass
from ..vem.material import Material
from ..vem.selective_mass import (
    corotational_drift,
    deformation_kinetic_energy,
    grain_frames,
    rigid_point_mobility,
    selective_accelerations,
)

RIGID_MODES = 6  # a free grain's zero eigenvalues: three translations, three rotations

__all__ = ["BodyModel", "Evaluation", "InvertedElementError", "VemBodies", "equivalent_diameters"]


def equivalent_diameters(volume: np.ndarray) -> np.ndarray:
    """Diameter of the sphere of each grain's volume: THE grain size of vemdem (contact scales,
    rest criterion, angle of repose)."""
    return np.cbrt(6.0 * np.asarray(volume, float) / np.pi)


class BodyModel(Protocol):
    """The mechanics of the grains as integrators see it (flat arrays; no per-grain objects)."""

    kind: str  # "flexible" or "rigid": recorded in every summary
    vertex_ptr: np.ndarray  # (G+1,) vertices of body g on the contact surface
    reference: np.ndarray  # (N, 3) vertex positions at q0
    volume: np.ndarray  # (G,)
    lumped: np.ndarray  # (N,) vertex masses (kinetic energy, centroids, explicit steps)
    load: np.ndarray  # (N,) gravity weights: f_g[v] = load[v] g
    block_ptr: np.ndarray  # (G+1,) offsets of each body's flat dense tangent block
    dof_ptr: np.ndarray  # (G+1,) dofs of body g

    @property
    def n_bodies(self) -> int: ...

    @property
    def n_vertices(self) -> int: ...

    def evaluate(self, x: np.ndarray, force: bool = True, tangent: bool = False, mass_shift: float = 0.0,
                 rotated_strain: float = 0.0) -> Evaluation:  # fmt: skip
        ...

    def mass_matrix(self) -> sp.csr_matrix: ...

    def critical_steps(self) -> np.ndarray: ...

    def vibration_periods(self) -> np.ndarray: ...

    def accelerations(self, force: np.ndarray, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """M^-1 f with the mass an explicit step integrates (the explicit integrators' mass
        operator), less what `drift` carries out itself."""

    def drift(self, x: np.ndarray, v: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
        """(x, v) after the explicit step's drift of h between its two kicks."""


@dataclass
class RotationReference:
    """What the Newton block of a grain near a rotation R is made of (vem.element.evaluate's
    rotated tangent): Q (K_g + s M_g) Q^T, Q = I (x) R, plus the contact terms within the grain.
    The grain-block solver factors such blocks from these (docs/linear-solvers.md)."""

    tangent: np.ndarray  # flat reference tangent blocks K_g, at block_ptr
    mass: np.ndarray  # flat scalar mass blocks M_g (n_g x n_g for n_g vertices), at mass_ptr
    mass_ptr: np.ndarray
    positions: np.ndarray  # (N, 3) reference vertex positions
    vertex_ptr: np.ndarray
    block_ptr: np.ndarray
    cache: dict = field(default_factory=dict, repr=False)  # what a solver derives once (its modal basis)


class VemBodies:
    """Flexible grains: one linear virtual element per grain (paper eq. 8), q = vertex positions."""

    kind = "flexible"

    def __init__(self, grains: list[Polyhedron], material: Material, options: VemOptions = VemOptions()):
        self.elements: GrainElements = build_elements(list(grains), material, options)
        self.mass: GrainMass = build_mass(list(grains), self.elements, material.density)
        el = self.elements
        self.vertex_ptr = el.vertex_ptr
        self.reference = el.reference
        self.volume = el.volume
        self.lumped = self.mass.lumped
        self.load = self.mass.load
        self.block_ptr = el.block_ptr
        self.dof_ptr = 3 * el.vertex_ptr
        self.body_mass = material.density * el.volume
        self._spectrum = None  # per-grain eigenvalues at rest (critical_steps, vibration_periods)
        # lambda of selective mass scaling: the deformation modes' inertia is (1 + lambda) times
        # their real one (vem/selective_mass.py); 0: the lumped mass as it is
        self.deformation_scaling = 0.0

    @property
    def n_bodies(self) -> int:
        return self.elements.n_grains

    @property
    def n_vertices(self) -> int:
        return self.elements.n_vertices

    # ------------------------------------------------------------------ mechanics
    def evaluate(self, x: np.ndarray, force: bool = True, tangent: bool = False, mass_shift: float = 0.0,
                 rotated_strain: float = 0.0) -> Evaluation:  # fmt: skip
        """Strain energy per grain, internal force dW/dx and the flat dense tangent blocks, of
        K_int + mass_shift M (M the consistent mass, scalar n x n per grain times I_3): the Newmark
        matrix a1 M + K_int without a sparse sum. rotated_strain: vem.element.evaluate."""
        return evaluate(self.elements, x, force=force, tangent=tangent, mass=self.mass, mass_shift=mass_shift,
                        rotated_strain=rotated_strain)  # fmt: skip

    def tangent_matrix(self, blocks: np.ndarray) -> sp.csr_matrix:
        return tangent_matrix(self.elements, blocks)

    def rotation_reference(self) -> RotationReference:
        """The reference blocks of `evaluate`'s rotated tangent (made once)."""
        if getattr(self, "_rotation_reference", None) is None:
            el = self.elements
            self._rotation_reference = RotationReference(reference_tangent(el), self.mass.blocks, self.mass.block_ptr,
                                                         el.reference, el.vertex_ptr, el.block_ptr)  # fmt: skip
        return self._rotation_reference

    def mass_matrix(self) -> sp.csr_matrix:
        return self.mass.matrix()

    # ------------------------------------------------------------------ the explicit step's mass
    def scale_deformation_inertia(self, lam: float) -> None:
        """Selective mass scaling: the deformation modes carry (1 + lam) times their inertia in
        the explicit step (`accelerations`), translations and rotations their real one."""
        if not (np.isfinite(lam) and lam >= 0):
            raise ValueError(f"selective mass scaling must be a finite number >= 0, got {lam!r}")
        self.deformation_scaling = float(lam)

    def accelerations(self, force: np.ndarray, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """M_s^-1 f: the lumped masses' accelerations, blended with each grain's rigid-body
        acceleration when the deformation modes are scaled, less the free rotation that `drift`
        then carries out (vem/selective_mass.py)."""
        if self.deformation_scaling == 0.0:
            return force / self.lumped[:, None]
        return selective_accelerations(force, x, v, self.lumped, self.vertex_ptr, self.deformation_scaling)

    def drift(self, x: np.ndarray, v: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
        """x + h v unscaled; with scaled deformation modes each grain's rigid motion is carried
        out exactly and its deformation velocity turns with it (vem.selective_mass.corotational_drift):
        a straight drift of a turning grain stretches it by a chord's sagitta each step, which the
        scaled modes then keep as energy."""
        if self.deformation_scaling == 0.0:
            return x + h * v, v
        return corotational_drift(x, v, self.lumped, self.vertex_ptr, h)

    def node_inverse_masses(self) -> np.ndarray:
        """(N,) what a contact at a vertex sees of its grain's inertia along a unit force, at most:
        1/m_i unscaled; (1/m_i + lambda mob_g) / (1 + lambda) with deformation scaling lambda,
        mob_g the grain's rigid point mobility (vem.selective_mass.rigid_point_mobility)."""
        lam = self.deformation_scaling
        inverse = 1.0 / self.lumped
        if lam == 0.0:
            return inverse
        mobility = np.repeat(self.rigid_mobility(), np.diff(self.vertex_ptr))
        return (inverse + lam * mobility) / (1.0 + lam)

    def rigid_mobility(self) -> np.ndarray:
        """(G,) 1/M + rho^2 / I_min of every grain (vem.selective_mass.rigid_point_mobility)."""
        return rigid_point_mobility(self.reference, self.lumped, self.vertex_ptr)

    def rigid_frames(self, x: np.ndarray):
        """(masses, centroids, principal axes, principal moments) of every grain's lumped masses at x
        (vem.selective_mass.grain_frames): its rigid inertia as it stands."""
        return grain_frames(x, self.lumped, self.vertex_ptr)

    def deformation_kinetic_energy(self, x: np.ndarray, v: np.ndarray) -> float:
        """1/2 sum m |v - v_rigid|^2 of all grains: the part of the kinetic energy that selective
        mass scaling weighs by (1 + lambda)."""
        return float(deformation_kinetic_energy(x, v, self.lumped, self.vertex_ptr))

    def critical_steps(self) -> np.ndarray:
        """2/omega_max of every grain: the largest eigenvalue of m^-1/2 K m^-1/2 at rest (K the
        tangent block of the grain, m its lumped vertex masses), times sqrt(1 + lambda) with
        selective mass scaling (exact: K's deformation modes are M-orthogonal to the rigid ones,
        on which the scaled mass acts as (1 + lambda) M)."""
        return 2.0 / np.sqrt(self._spectra()[:, -1]) * np.sqrt(1.0 + self.deformation_scaling)

    def vibration_periods(self) -> np.ndarray:
        """2 pi/omega_1 of every grain: its slowest elastic mode (the seventh eigenvalue, after
        the six rigid-body modes), with the lumped masses. Mass scaling s lengthens it by sqrt(s),
        selective mass scaling lambda by sqrt(1 + lambda)."""
        return 2.0 * np.pi / np.sqrt(self._spectra()[:, RIGID_MODES]) * np.sqrt(1.0 + self.deformation_scaling)

    def _spectra(self) -> np.ndarray:
        """The eigenvalues of m^-1/2 K m^-1/2 of every grain at rest, ascending, padded with the
        largest where grains have fewer vertices; grains with the same number of vertices are
        solved as one batch, once per run."""
        if self._spectrum is None:
            el = self.elements
            blocks = evaluate(el, el.reference, force=False, tangent=True).blocks
            counts = np.diff(el.vertex_ptr)
            out = np.empty((self.n_bodies, 3 * counts.max()))
            for n in np.unique(counts):
                grains = np.flatnonzero(counts == n)
                K = np.stack([blocks[el.block_ptr[g] : el.block_ptr[g + 1]] for g in grains]).reshape(-1, 3 * n, 3 * n)
                m = np.stack([np.repeat(self.lumped[el.vertex_ptr[g] : el.vertex_ptr[g + 1]], 3) for g in grains])
                s = 1.0 / np.sqrt(m)
                lam = np.linalg.eigvalsh(s[:, :, None] * K * s[:, None, :])
                out[grains] = np.pad(lam, ((0, 0), (0, out.shape[1] - 3 * n)), mode="edge")
            self._spectrum = out
        return self._spectrum

    def cauchy_stress(self, x: np.ndarray) -> np.ndarray:
        """(G, 3, 3) Cauchy stress of each grain's projected deformation (frames)."""
        return projected_cauchy_stress(self.elements, x)
