"""Closed-form homogeneous Neo-Hookean states for F = diag(a, a, l) (uniaxial and confined).

Written out independently of the compiled kernel in vem/material.py, so the single-grain
compression tests compare two separate derivations of paper eq. 2:

    J = a^2 l,  I1 = 2 a^2 + l^2,
    P11 = mu J^(-2/3) (a - I1 / (3 a)) + kappa/2 (J^2 - 1) / a
    P33 = mu J^(-2/3) (l - I1 / (3 l)) + kappa/2 (J^2 - 1) / l
Uniaxial (free lateral faces): a solves P11 = 0. Confined: a = 1.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import brentq


def _p11(a, l, mu, kappa):
    J = a * a * l
    I1 = 2 * a * a + l * l
    return mu * J ** (-2 / 3) * (a - I1 / (3 * a)) + 0.5 * kappa * (J * J - 1) / a


def _p33(a, l, mu, kappa):
    J = a * a * l
    I1 = 2 * a * a + l * l
    return mu * J ** (-2 / 3) * (l - I1 / (3 * l)) + 0.5 * kappa * (J * J - 1) / l


def lateral_stretch(l: float, mu: float, kappa: float) -> float:
    """Stretch a of the free lateral faces under axial stretch l (uniaxial stress)."""
    return brentq(_p11, 1e-3, 1e3, args=(l, mu, kappa), xtol=1e-15, rtol=1e-15)


def nominal_axial_stress(strain, mu: float, kappa: float, mode: str = "uniaxial") -> np.ndarray:
    """Compressive first Piola stress -P33 (positive in compression) at engineering strain 1 - l."""
    out = []
    for e in np.atleast_1d(strain):
        l = 1.0 - e
        a = lateral_stretch(l, mu, kappa) if mode == "uniaxial" else 1.0
        out.append(-_p33(a, l, mu, kappa))
    return np.array(out)
