"""The combined penalty/barrier normal interface law (docs/contact.md).

With the unsigned gap g >= 0 between the two contact points, activation gap gbar and the
switch gap gbb = factor * gbar:

    f_n(g) = 0                        g >= gbar
           = eps1 (gbar - g)^n1        gbb < g < gbar    (penalty, active before touching)
           = eps2 g^n2 + c2            g <= gbb          (barrier, n2 < 0: f_n -> inf as g -> 0)
    eps2 = -eps1 n1 (gbar - gbb)^(n1-1) / (n2 gbb^(n2-1))    (slope continuous at gbb)
    c2   =  eps1 (gbar - gbb)^n1 - eps2 gbb^n2                (value continuous at gbb)

k(g) = -df_n/dg >= 0 is the contact stiffness, and the potential Phi(g) = int_g^gbar f_n ds is
closed form, so the law is conservative (its work is path independent).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

# indices into the packed parameter array used by the kernels
GBAR, GBB, EPS1, N1, EPS2, N2, C2 = range(7)


@dataclass(frozen=True)
class InterfaceLaw:
    activation_gap: float  # gbar (m)
    penalty: float  # eps1 (N / m^n1)
    penalty_exponent: float = 2.0  # n1
    switch_factor: float = 0.3  # gbb / gbar
    barrier_exponent: float = -2.0  # n2

    def __post_init__(self):
        checks = [
            (np.isfinite(self.activation_gap) and self.activation_gap > 0, "activation_gap must be finite and > 0"),
            (np.isfinite(self.penalty) and self.penalty > 0,
             "penalty must be finite and > 0 (contact.reference_force sets it: give a finite force)"),
            (self.penalty_exponent >= 1, "penalty_exponent must be >= 1"),
            (0 < self.switch_factor < 1, "switch_factor must be in (0, 1)"),
            (self.barrier_exponent < -1, "barrier_exponent must be < -1 (the potential must blow up at contact)"),
        ]
        for ok, message in checks:
            if not ok:  # each its own test: the first message names the value that is wrong
                raise ValueError(f"contact law: {message}")

    @property
    def switch_gap(self) -> float:
        return self.switch_factor * self.activation_gap

    @property
    def switch_force(self) -> float:
        """The normal force at the switch gap: the reference force F_ref (contact/defaults.py)."""
        return float(normal_force(self.switch_gap, self.packed())[0])

    def packed(self) -> np.ndarray:
        gbar, n1, n2 = self.activation_gap, self.penalty_exponent, self.barrier_exponent
        gbb = self.switch_gap
        eps1 = self.penalty
        eps2 = -eps1 * n1 * (gbar - gbb) ** (n1 - 1) / (n2 * gbb ** (n2 - 1))
        c2 = eps1 * (gbar - gbb) ** n1 - eps2 * gbb**n2
        return np.array([gbar, gbb, eps1, n1, eps2, n2, c2])


@njit(cache=True)
def normal_force(g, p):
    """(f_n, k) at gap g: repulsive force magnitude and stiffness -df_n/dg. One definition for
    real gaps and for the complex gaps of the complex-step reference tangent (friction.py, the
    tests' check of the analytic one): the branches read the real part, the formulas carry the
    imaginary one."""
    zero = 0.0 * g
    if g.real >= p[GBAR]:
        return zero, zero
    if g.real > p[GBB]:
        d = p[GBAR] - g
        return p[EPS1] * d ** p[N1], p[EPS1] * p[N1] * d ** (p[N1] - 1.0)
    if g.real <= 0.0:
        return zero + np.inf, zero + np.inf
    return p[EPS2] * g ** p[N2] + p[C2], -p[EPS2] * p[N2] * g ** (p[N2] - 1.0)


@njit(cache=True)
def normal_stiffness_slope(g, p):
    """dk/dg, the law's second derivative (the analytic friction tangent needs it through the
    damping coefficient 2 zeta sqrt(k m))."""
    if g >= p[GBAR]:
        return 0.0
    if g > p[GBB]:
        n1 = p[N1]
        return 0.0 if n1 == 1.0 else -p[EPS1] * n1 * (n1 - 1.0) * (p[GBAR] - g) ** (n1 - 2.0)
    if g <= 0.0:
        return -np.inf
    return -p[EPS2] * p[N2] * (p[N2] - 1.0) * g ** (p[N2] - 2.0)


@njit(cache=True)
def normal_potential(g, p):
    """Phi(g) = int_g^gbar f_n(s) ds, closed form."""
    if g >= p[GBAR]:
        return 0.0
    n1 = p[N1]
    if g > p[GBB]:
        return p[EPS1] / (n1 + 1.0) * (p[GBAR] - g) ** (n1 + 1.0)
    if g <= 0.0:
        return np.inf
    gbb, n2 = p[GBB], p[N2]
    penalty_part = p[EPS1] / (n1 + 1.0) * (p[GBAR] - gbb) ** (n1 + 1.0)
    return penalty_part + p[EPS2] / (n2 + 1.0) * (gbb ** (n2 + 1.0) - g ** (n2 + 1.0)) + p[C2] * (gbb - g)


@njit(cache=True)
def normal_stiffness(gaps, p):
    """k(g) for an array of gaps (the explicit integrator's contact step limit)."""
    out = np.empty(len(gaps))
    for i in range(len(gaps)):
        out[i] = normal_force(gaps[i], p)[1]
    return out
