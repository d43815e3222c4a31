"""Compressible Neo-Hookean material of paper eq. 2 (isochoric exponent -2/3).

    psi(F) = mu/2 (J^(-2/3) tr(F^T F) - 3) + kappa/4 (J^2 - 1 - 2 ln J)

The paper prints the exponent as -3/2, a typo: only with -2/3 is the first term blind to a
pure dilation F = J^(1/3) I (J^(-2/3) tr(F^T F) = 3 for every J), so that shape change and
volume change are split as intended (docs/vem.md). Derivatives:

    P = dpsi/dF = mu J^(-2/3) (F - tr(C)/3 F^-T) + kappa/2 (J^2 - 1) F^-T
    A = dP/dF   (written out in `neo_hooke`, index order A[3i+I, 3j+J] = dP_iI / dF_jJ)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit


@dataclass(frozen=True)
class Material:
    """Compressible Neo-Hookean material: E (Pa), Poisson's ratio, density (kg/m^3, mass scaling applied)."""
    E: float
    nu: float
    density: float

    def __post_init__(self):
        if not (np.isfinite(self.E) and self.E > 0):
            raise ValueError(f"material.E must be positive, got {self.E}")
        if not (-1.0 < self.nu < 0.5):
            raise ValueError(f"material.nu must be in (-1, 0.5), got {self.nu}")
        if not (np.isfinite(self.density) and self.density > 0):
            raise ValueError(f"material.density must be positive, got {self.density}")

    @property
    def mu(self) -> float:
        return lame_parameters(self.E, self.nu)[0]

    @property
    def kappa(self) -> float:
        return lame_parameters(self.E, self.nu)[1]


def lame_parameters(E: float, nu: float) -> tuple[float, float]:
    """Shear modulus mu = E / (2 (1 + nu)) and bulk modulus kappa = E / (3 (1 - 2 nu))."""
    return E / (2.0 * (1.0 + nu)), E / (3.0 * (1.0 - 2.0 * nu))


@njit(cache=True, fastmath=False)
def det3(F):
    return (
        F[0, 0] * (F[1, 1] * F[2, 2] - F[1, 2] * F[2, 1])
        - F[0, 1] * (F[1, 0] * F[2, 2] - F[1, 2] * F[2, 0])
        + F[0, 2] * (F[1, 0] * F[2, 1] - F[1, 1] * F[2, 0])
    )


@njit(cache=True)
def inv3(F, J):
    """Inverse of a 3x3 matrix with known determinant J (adjugate / J)."""
    out = np.empty((3, 3))
    out[0, 0] = (F[1, 1] * F[2, 2] - F[1, 2] * F[2, 1]) / J
    out[0, 1] = (F[0, 2] * F[2, 1] - F[0, 1] * F[2, 2]) / J
    out[0, 2] = (F[0, 1] * F[1, 2] - F[0, 2] * F[1, 1]) / J
    out[1, 0] = (F[1, 2] * F[2, 0] - F[1, 0] * F[2, 2]) / J
    out[1, 1] = (F[0, 0] * F[2, 2] - F[0, 2] * F[2, 0]) / J
    out[1, 2] = (F[0, 2] * F[1, 0] - F[0, 0] * F[1, 2]) / J
    out[2, 0] = (F[1, 0] * F[2, 1] - F[1, 1] * F[2, 0]) / J
    out[2, 1] = (F[0, 1] * F[2, 0] - F[0, 0] * F[2, 1]) / J
    out[2, 2] = (F[0, 0] * F[1, 1] - F[0, 1] * F[1, 0]) / J
    return out


@njit(cache=True)
def neo_hooke_energy(F, mu, kappa):
    """psi(F); +inf when J <= 0 (an inverted element has no admissible energy)."""
    J = det3(F)
    if not (J > 0.0):
        return np.inf
    I1 = 0.0
    for i in range(3):
        for k in range(3):
            I1 += F[i, k] * F[i, k]
    return 0.5 * mu * (J ** (-2.0 / 3.0) * I1 - 3.0) + 0.25 * kappa * (J * J - 1.0 - 2.0 * np.log(J))


@njit(cache=True)
def neo_hooke(F, mu, kappa, want_tangent, P, A):
    """Energy psi(F); fills P (3x3) and, if want_tangent, A (9x9). Returns +inf if J <= 0."""
    J = det3(F)
    if not (J > 0.0):
        return np.inf
    Fi = inv3(F, J)  # Fi[I, i] = (F^-1)_Ii, so (F^-T)_iI = Fi[I, i]
    I1 = 0.0
    for i in range(3):
        for k in range(3):
            I1 += F[i, k] * F[i, k]
    Jm23 = J ** (-2.0 / 3.0)
    a = mu * Jm23
    b = 0.5 * kappa * (J * J - 1.0)
    psi = 0.5 * mu * (Jm23 * I1 - 3.0) + 0.25 * kappa * (J * J - 1.0 - 2.0 * np.log(J))
    for i in range(3):
        for I in range(3):
            P[i, I] = a * (F[i, I] - I1 / 3.0 * Fi[I, i]) + b * Fi[I, i]
    if want_tangent:
        kJ2 = kappa * J * J
        for i in range(3):
            for I in range(3):
                dev = F[i, I] - I1 / 3.0 * Fi[I, i]
                row = 3 * i + I
                for j in range(3):
                    for K in range(3):
                        v = -2.0 / 3.0 * a * Fi[K, j] * dev
                        v += a * (-2.0 / 3.0 * F[j, K] * Fi[I, i] + I1 / 3.0 * Fi[I, j] * Fi[K, i])
                        if i == j and I == K:
                            v += a
                        v += kJ2 * Fi[K, j] * Fi[I, i] - b * Fi[I, j] * Fi[K, i]
                        A[row, 3 * j + K] = v
    return psi
