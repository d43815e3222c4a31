"""Contact parameters derived from the grains, so that giving friction coefficients is enough
(every value is documented in docs/contact.md). Two laws: the weight's (below, the default of the
scenarios that settle and pour under gravity) and the material's (`material_contact_laws`, the
laboratory tests': one law per material, the same at every stress).

The weight's law:

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
        raise ValueError(f"contact: unknown parameter {min(overrides)!r}")
    return law, friction


# ---------------------------------------------------------------------------- the material's law
HERTZ_EXPONENT = 1.5


def effective_modulus(E: float, nu: float) -> float:
    """Hertz's contact modulus of two grains of one material: 1/E* = 2 (1 - nu^2) / E, so
    E* = E / (2 (1 - nu^2))."""
    return E / (2.0 * (1.0 - nu**2))


def effective_radius(size: float) -> float:
    """Hertz's radius of two spheres of the equivalent diameter d: 1/R* = 1/R + 1/R = 4/d, R* = d/4."""
    return size / 4.0


def hertz_penalty(E: float, nu: float, size: float) -> float:
    """eps1 = (4/3) E* sqrt(R*) (N/m^1.5): with n1 = 3/2 the penalty branch f = eps1 (gbar - g)^(3/2)
    is Hertz's force-overlap law F = (4/3) E* sqrt(R*) delta^(3/2), the overlap delta = gbar - g
    measured from the activation gap; its stiffness k = (3/2) eps1 delta^(1/2) = 2 E* sqrt(R* delta)
    grows as F^(1/3)."""
    return 4.0 / 3.0 * effective_modulus(E, nu) * np.sqrt(effective_radius(size))


def mindlin_ratio(nu: float) -> float:
    """Mindlin's tangential over normal stiffness of two grains of one material under one normal
    force: k_t / k_n = 8 G* a / (2 E* a) = 2 (1 - nu) / (2 - nu)."""
    return 2.0 * (1.0 - nu) / (2.0 - nu)


def check_material(size: float, E: float, nu: float, layer_modulus: float | None) -> None:
    """Each input of the material's law, its own message naming it."""
    checks = [
        (np.isfinite(size) and size > 0, f"grain size must be finite and > 0, got {size!r}"),
        (np.isfinite(E) and E > 0, f"material.E must be finite and > 0, got {E!r}"),
        (np.isfinite(nu) and -1.0 < nu < 0.5, f"material.nu must be in (-1, 0.5), got {nu!r}"),
        (layer_modulus is None or (np.isfinite(layer_modulus) and layer_modulus > 0),
         f"contact.layer_modulus must be finite and > 0, got {layer_modulus!r}"),
    ]  # fmt: skip
    for ok, message in checks:
        if not ok:
            raise ValueError(message)


def material_contact_laws(size: float, E: float, nu: float, mu_s: float = 0.0, mu_d: float | None = None,
                          layer_modulus: float | None = None,
                          **overrides) -> tuple[InterfaceLaw, FrictionLaw]:  # fmt: skip
    """The material's law: Hertz's between two grains of modulus E (or `layer_modulus`, a named
    softer layer), Poisson's ratio nu and equivalent diameter `size`, the same at every stress:

        activation gap       gbar  = 0.01 d        (the contact layer: the overlap counts from it)
        penalty              f_n   = eps1 (gbar - g)^(3/2),  eps1 = (4/3) E* sqrt(R*)   (hertz_penalty)
        switch, barrier      gbb   = 0.3 gbar, n2 = -2: the barrier keeps the grains apart
        tangential penalty   eps_t = 2 (1 - nu) / (2 - nu) k_n(gbb)   (Mindlin's ratio at the
                                     switch force, the largest the penalty carries)
        damping ratio        zeta  = 0.5

    One law for every contact, walls included (contact/model.py has one; a rigid wall's own Hertz
    law, R* = d/2 and E* = E / (1 - nu^2), would be 2 sqrt(2) times stiffer). Keyword overrides as
    default_contact_laws' (activation_gap, penalty, switch_factor, barrier_exponent,
    tangential_penalty, tangential_viscosity, damping_ratio); a reference_force or a
    penalty_exponent belongs to the weight's law (default_contact_laws)."""
    check_material(size, E, nu, layer_modulus)
    for key in ("reference_force", "penalty_exponent"):
        if key in overrides:
            raise ValueError(f"contact.{key}: the material's law is Hertz's (n1 = 3/2, eps1 from E, nu and d); "
                             f"{key} sets the per-force law: give it without the material's law")  # fmt: skip
    mu_d = mu_s if mu_d is None else mu_d
    gbar = overrides.pop("activation_gap", GAP_FRACTION * size)
    factor = overrides.pop("switch_factor", SWITCH_FACTOR)
    n2 = overrides.pop("barrier_exponent", -2.0)
    eps1 = overrides.pop("penalty", hertz_penalty(E if layer_modulus is None else layer_modulus, nu, size))
    law = InterfaceLaw(gbar, eps1, HERTZ_EXPONENT, factor, n2)
    k_switch = HERTZ_EXPONENT * eps1 * (gbar - law.switch_gap) ** (HERTZ_EXPONENT - 1.0)
    friction = FrictionLaw(
        mu_s=mu_s,
        mu_d=mu_d,
        tangential_penalty=overrides.pop("tangential_penalty", mindlin_ratio(nu) * k_switch),
        tangential_viscosity=overrides.pop("tangential_viscosity", 0.0),
        damping_ratio=overrides.pop("damping_ratio", DAMPING_RATIO),
    )
    if overrides:
        raise ValueError(f"contact: unknown parameter {min(overrides)!r}")
    return law, friction
