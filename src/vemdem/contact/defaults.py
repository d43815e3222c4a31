"""Contact parameters derived from the grains, so that giving friction coefficients is enough
(every value is documented in docs/contact.md).

    activation gap       gbar  = 0.01 d                 (d: equivalent grain diameter)
    switch factor        0.3, penalty exponent n1 = 2, barrier exponent n2 = -2   (GIRAFFE's law)
    reference force      F_ref = 10 m g                 (m: grain mass; about the largest contact
                                                         force in a pile at rest; `reference_force`
                                                         sets it for loads far above the weight, a lid)
    penalty              eps1  = F_ref / (gbar - gbb)^2 (F_ref is reached where the barrier takes over;
                                                         any larger force is carried by the barrier)
    tangential penalty   eps_t = k(gbb) = 2 eps1 (gbar - gbb)   (the normal stiffness at the switch)
    damping ratio        zeta  = 0.5;  tangential viscosity c_t = 0
The contact stiffness at the switch gap is capped at E d (the grain's own stiffness), a given
reference force's too, so that Newton stays well conditioned: soft grains under a law 170 times
stiffer than themselves took steps a hundred times shorter (docs/oedometer.md, soft grains).
"""

from __future__ import annotations

import numpy as np

from .friction import FrictionLaw
from .law import InterfaceLaw

GAP_FRACTION = 0.01
SWITCH_FACTOR = 0.3
FORCE_MULTIPLE = 10.0
DAMPING_RATIO = 0.5


def default_contact_laws(size: float, E: float, density: float, gravity: float = 9.81, mu_s: float = 0.0,
                         mu_d: float | None = None, **overrides) -> tuple[InterfaceLaw, FrictionLaw]:  # fmt: skip
    """Interface and friction laws for grains of equivalent diameter `size`; keyword overrides
    (activation_gap, reference_force, penalty, switch_factor, penalty_exponent, barrier_exponent,
    tangential_penalty, tangential_viscosity, damping_ratio) replace single defaults."""
    mu_d = mu_s if mu_d is None else mu_d
    gbar = overrides.pop("activation_gap", GAP_FRACTION * size)
    factor = overrides.pop("switch_factor", SWITCH_FACTOR)
    n1 = overrides.pop("penalty_exponent", 2.0)
    n2 = overrides.pop("barrier_exponent", -2.0)
    mass = density * np.pi * size**3 / 6.0
    f_ref = overrides.pop("reference_force", None) or FORCE_MULTIPLE * mass * max(abs(gravity), 9.81)
    band = gbar * (1.0 - factor)
    eps1 = f_ref / band**n1
    k_switch = n1 * eps1 * band ** (n1 - 1)
    if k_switch > E * size:  # never stiffer than the grain itself
        eps1 *= E * size / k_switch
    eps1 = overrides.pop("penalty", eps1)
    law = InterfaceLaw(gbar, eps1, n1, factor, n2)
    friction = FrictionLaw(
        mu_s=mu_s,
        mu_d=mu_d,
        tangential_penalty=overrides.pop("tangential_penalty", n1 * eps1 * band ** (n1 - 1)),
        tangential_viscosity=overrides.pop("tangential_viscosity", 0.0),
        damping_ratio=overrides.pop("damping_ratio", DAMPING_RATIO),
    )
    if overrides:
        raise ValueError(f"contact: unknown parameter {sorted(overrides)[0]!r}")
    return law, friction
