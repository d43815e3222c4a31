"""How much inertia selective mass scaling gives the grains' deformation modes: `[solver]
selective_mass_scaling = "auto"` (docs/selective-mass-scaling.md).

The explicit step of flexible grains is the shortest of the grains' own critical step and the
contacts'. Scaling the deformation modes by 1 + lambda lengthens the first by sqrt(1 + lambda);
the second tends to the rigid grains' contact step as lambda grows (a contact then meets the
grain's rigid mobility). "auto" takes the lambda at which the grains' step reaches the rigid
contact step of a contact at stiffness k, so that the grains' own step binds no step the contacts
would not,

    lambda_contact = (dt_contact / dt_grain)^2 - 1,   dt_contact = 2 / sqrt(k 2 mob_max),

k the law's stiffness at its switch gap, or in a laboratory test at the force of its lightest
loaded contacts, a grain's weight (seating_force; stiffness_at_force: the penalty's stiffness there).
A rigid run's step follows its stiffest contact of the moment, soft through the seating and most of
a quasi-static path; a lambda that matched the strongest contacts (10 sigma d^2) bound every step
of the flexible run at their step: 1.75-2.4 times the rigid run's steps on the oedometers, against
0.77 times with the bound at a grain's weight (docs/selective-mass-scaling.md),

and never more than keeps the scaled slowest vibration period within PERIOD_FRACTION of the
loading time t_load, the shortest time over which anything in the run loads a grain:

    lambda_cap = (PERIOD_FRACTION t_load / T_1)^2 - 1.

In a run where grains collide (a collapse, a pour, an impact) t_load is a contact's duration
t_c = pi sqrt(m / 2 k_switch). A laboratory test is driven quasi-statically: its walls and drives
strain the sample no faster than the rate that gives their inertia number I at the test's stress
sigma, rate = I sqrt(sigma / rho) / d, so neighbours close on each other at rate x d and a
contact's load changes over the time they take to cross one activation gap (lab_loading_time):

    t_load = gbar / (I sqrt(sigma / rho)).

The step's accuracy sets no bound of its own since the drift carries each grain's rigid motion out
exactly (vem.selective_mass.corotational_drift): a 24-grain frictionless collapse closes its energy
books to +0.2 % at lambda 3e6 as at 1e4 (a straight drift gained 57 % of the released potential
there); docs/selective-mass-scaling.md.
"""

from __future__ import annotations

import numpy as np

from ..contact.law import normal_force

# The scaled slowest vibration period may reach this many contact durations: a head-on impact of
# two 0.9 mm grains at 90 GPa kept its restitution within 0.2 % up to 5 durations under the
# weight's law, within 1.2 % at 2.3 (3.5 % at 7) under a law 2,000 times stiffer (a 100 kPa
# test's), and lost 6.5 % at 2.7 under a law 21 times stiffer; docs/selective-mass-scaling.md
PERIOD_FRACTION = 3.0

# the gravity a grain's weight is taken under where a scene has none: a lab sample's lightest loaded
# contacts are those of its settled pack, which settled under gravity
STANDARD_GRAVITY = 9.81


def stiffness_at_force(law, force: float) -> float:
    """The law's normal stiffness where its penalty branch carries `force`, k = n1 eps1 delta^(n1 - 1)
    with eps1 delta^n1 = force; the switch gap's stiffness for a force the penalty does not reach."""
    f_switch, k_switch = normal_force(law.switch_gap, law.packed())
    if force >= f_switch:
        return float(k_switch)
    n1 = law.penalty_exponent
    return float(n1 * law.penalty * (force / law.penalty) ** ((n1 - 1.0) / n1))


def seating_force(scene) -> float:
    """The weight of the mean grain at the density integrated (standard gravity in a scene without
    gravity): the force a settled pack's lightest loaded contacts carry."""
    g = float(np.linalg.norm(scene.gravity)) or STANDARD_GRAVITY
    return float(np.mean(scene.bodies.body_mass) * g)


def lab_loading_time(scene, inertia_number: float, stress: float) -> float:
    """gbar / (I sqrt(sigma / rho)): the time a sample strained at the quasi-static rate of inertia
    number I at stress sigma (lab.servo.quasi_static_rate) takes to close one activation gap
    between neighbouring grains, at the density integrated."""
    speed = inertia_number * np.sqrt(stress / scene.material.density)
    return float(scene.contact.law.activation_gap / speed)


def auto_selective_scaling(scene, quasi_static: tuple[float, float] | None = None) -> dict:
    """The "auto" lambda of a scene of flexible grains (unscaled when called) and what set it:
    summary.json's selective_mass_scaling_auto. `quasi_static` (I, sigma): a laboratory test's
    largest inertia number and its stress, whose strain rate sets the loading time
    (lab_loading_time); None: a contact's duration does."""
    bodies = scene.bodies
    grain_step = float(bodies.critical_steps().min())
    period = float(bodies.vibration_periods().max())
    law = scene.contact.law
    if quasi_static is None:
        k_contact = float(normal_force(law.switch_gap, law.packed())[1])
        loading_time, loaded_by = float(scene.contact_durations().min()), "a contact's duration"
    else:
        k_contact = stiffness_at_force(law, seating_force(scene))
        loading_time, loaded_by = lab_loading_time(scene, *quasi_static), "the test's strain rate"
    contact_step = 2.0 / np.sqrt(k_contact * 2.0 * float(bodies.rigid_mobility().max()))
    lam_contact = max((contact_step / grain_step) ** 2 - 1.0, 0.0)
    lam_cap = max((PERIOD_FRACTION * loading_time / period) ** 2 - 1.0, 0.0)
    bounds = {"contact step": lam_contact, "vibration period": lam_cap}
    bound = min(bounds, key=bounds.get)
    lam = bounds[bound]
    return {
        "lambda": lam,
        "bound": bound,
        "lambda_contact": lam_contact,
        "lambda_period_cap": lam_cap,
        "grain_step_s": grain_step,
        "contact_step_s": contact_step,
        "contact_stiffness_N_per_m": k_contact,
        "loading_time_s": loading_time,
        "loading_time_from": loaded_by,
        "period_fraction": PERIOD_FRACTION,
        "scaled_period_s": period * np.sqrt(1.0 + lam),
    }
