"""The laboratory tests' config tables: the servo and the load stages they share, and the
oedometer's, the triaxial's and the direct shear's schemas, each the common part of a lab test
(`lab_schema`) plus its own tables; the isotropic compression's."""

from __future__ import annotations

from dataclasses import replace

from .checks import _DURATION, _in, _stress, _within, with_defaults
from .lab_rules import LID_AREA_FACTOR
from .schema import REQUIRED, Field, TableList, open_unit_interval
from .tables import CONTACT, INITIAL_STATE, MODEL, SOLVER, granular_tables, pack_stage

# The servo of a stress-controlled wall (lab/servo.py) and the rule a load path's stage ends by
# (lab/path.py): shared by the laboratory tests
SERVO = {
    "gain": Field(float, 0.3, _in(0, 1, lo_open=True),
                  "share of the force error the wall's travel closes per step, against its own contact layer's "
                  "stiffness (docs/servo.md)"),
    "inertia_number": Field(float, 5e-4, _in(0, 1e-2, lo_open=True),
                            "the wall's speed cap: the speed that gives this inertia number I = rate d / sqrt(sigma / "
                            "rho) at the stage's target stress (quasi-static below 1e-3)"),
    "stress_tolerance": Field(float, 0.01, _in(0, 0.5, lo_open=True),
                              "a stage's target is reached when the wall's stress is within this share of it"),
    "unbalanced_tolerance": Field(float, 0.01, _in(0, 1, lo_open=True),
                                  "...and the sample at rest: mean net force on a grain over the mean contact force "
                                  "below this"),
}

STAGE = {
    "stress": Field(float, REQUIRED, _stress, "target normal stress on the lid (Pa)"),
    "max_time": Field(float, 1.0, _DURATION, "the stage ends after this much simulated time, reached or not (s)"),
    "max_strain": Field(float, 0.6, open_unit_interval,
                        "a loading stage ends when the axial strain passes this (a target the sample cannot reach)"),
}


def reference_force_field(per_stress: str) -> Field:
    """A lab test's `[contact] reference_force`: unset, the material's law; given, the per-force
    law at that force, `per_stress` naming the value that gives the test's per-stress law."""
    return replace(CONTACT["reference_force"], doc="N, force per contact at the switch gap of the per-force law "
                   "(n1 = 2), in place of the material's law (the same at every stress; docs/contact.md); this "
                   f"test's per-stress law: {per_stress} [unset: the material's law]")  # fmt: skip


def lab_schema(scenario: str, mu: float, own: dict, servo: dict = SERVO, damping_ratio: float | None = 0.05,
               reference_force: str = "") -> dict:  # fmt: skip
    """A lab test's schema: its scenario, the pack it starts from, its `own` tables, the servo, the
    granular tables at friction `mu`. As the paper's method: implicit Newmark at the real density by
    default (no mass scaling; the rigid grains with `[model] grains = "rigid"`). Its steps stay at
    most 1e-4 s, as the lid cycles': with 1e-3 s a loose 60-grain pack under the lid stalled twice
    in its seating (Newton at 1e-10 s steps; docs/oedometer.md). A light contact damping
    (`damping_ratio`; None: the package's) and the material's contact law (`[contact] law =
    "material"`: Hertz's law of the grains' E, nu and size, the same at every stress;
    contact/defaults.material_contact_laws); `reference_force` sets the per-force law instead, as
    its doc says (`reference_force`: the old per-stress law's value, named for the test)."""
    schema = {"scenario": Field((scenario,), REQUIRED), "initial_state": INITIAL_STATE, "pack": pack_stage(), **own,
              "servo": servo, **granular_tables(mu_s=mu, mu_d=mu, every=5e-3)}  # fmt: skip
    schema["solver"] = SOLVER
    contact = with_defaults(schema["contact"], law="material")
    if damping_ratio is not None:
        contact = with_defaults(contact, damping_ratio=damping_ratio)
    contact["reference_force"] = reference_force_field(reference_force)
    schema["contact"] = contact
    return schema


def _start_gap(wall: str) -> Field:
    return Field(float, 0.05, _in(0, 10, lo_open=True), f"{wall} starts this many mean grain sizes above the pack's "
                 "highest point")  # fmt: skip


def _shear_time() -> Field:
    return Field(float, 10.0, _DURATION, "shearing ends after this much simulated time in any case (s)")


def _shear_rate(what: str) -> Field:
    return Field(float, 5e-4, _in(0, 1e-2, lo_open=True), f"sets {what}")


# the oedometer's contacts as the lid cycle's: elastic
OEDOMETER = lab_schema("oedometer", 0.15, {
    "lid": {
        "gap": _start_gap("the lid"),
        "area": Field(float, None, _within(1e-12, 1e2, "m^2"),
                      f"loaded area of the lid (m^2), within a factor {LID_AREA_FACTOR:g} of the box's "
                      "cross-section [the box's cross-section]"),
    },
    "ring": {
        "friction": Field(bool, False, doc="the side walls' friction: false, a lubricated ring (the lid's stress is "
                          "the sample's; docs/oedometer.md); true, the grains' contact friction"),
    },
    "stages": TableList(STAGE, min_items=1),
}, reference_force="2 x the path's largest stress x the mean grain size squared; the pack settles under the "
                   "same law")  # fmt: skip

# the package's contact damping 0.5 kept the 100-grain example's five servos 5-15 % off their
# target for 0.02 s of consolidation, where 0.05 held them within 1 %. The servo at rest below
# 0.1: a consolidated 100-grain rigid sample (explicit), its five walls within 0.1 % of 50 kPa and
# its height moving by 3e-7 per frame, hovered at 0.02-0.09 for 0.02 s
TRIAXIAL = lab_schema("triaxial", 0.3, {
    "sample": {"gap": _start_gap("the top platen")},
    "consolidation": {
        "stress": Field(float, REQUIRED, _stress, "the confining stress (Pa): on all five moving walls, then on the "
                        "four lateral ones while the sample is sheared"),
        "max_time": Field(float, 0.1, _DURATION, "consolidation ends after this much simulated time, reached or not "
                          "(s)"),
    },
    "shear": {
        "max_strain": Field(float, 0.25, open_unit_interval, "the axial strain (from the consolidated sample) the "
                            "platen compresses it to"),
        "inertia_number": _shear_rate("the platen's constant speed: the axial strain rate that gives this inertia "
                                      "number at the confining stress, rate = I sqrt(sigma_3 / rho) / d"),
        "max_time": _shear_time(),
    },
}, servo=with_defaults(SERVO, unbalanced_tolerance=0.1), reference_force="2 x consolidation.stress x the mean grain "
   "size squared: about the force per contact at a sheared sample's mean stress")  # fmt: skip

# the package's contact damping (0.5): with the oedometer's 0.05 the 120-grain example under its
# lid hovered at an unbalanced force ratio of 0.45-0.6; with 0.5 it was at rest (below 0.01) after
# 0.01 s, its lid within 1 % of the normal stress
DIRECT_SHEAR = lab_schema("direct_shear", 0.3, {
    "sample": {
        "gap": _start_gap("the lid"),
        "split": Field(float, 0.5, _in(0.2, 0.8),
                       "where the box's halves meet, as a share of the pack's height above the floor"),
        "opening": Field(float, 0.0, _in(0, 2),
                         "the gap between the halves' walls, in mean grain sizes (below the smallest grain), as a lab "
                         "box's halves are set apart (docs/direct-shear.md: what 0.5 did)"),
    },
    "normal": {
        "stress": Field(float, REQUIRED, _stress, "the normal stress on the lid (Pa), held by its servo"),
        "max_time": Field(float, 0.1, _DURATION, "the lid's consolidation ends after this much simulated time, "
                          "reached or not (s)"),
    },
    "shear": {
        "max_displacement": Field(float, 0.15, _in(0.01, 0.5),
                                  "the lower half's travel, as a share of the box's length along x (the frames' "
                                  "plates close the box's ends past it)"),
        "inertia_number": _shear_rate("the lower half's speed: the shear rate (speed / sample height) that gives "
                                      "this inertia number at the normal stress"),
        "max_time": _shear_time(),
    },
}, damping_ratio=None, reference_force="2 x normal.stress x the mean grain size squared")  # fmt: skip


ISOTROPIC = {
    "scenario": Field(("isotropic",), REQUIRED),
    "initial_state": INITIAL_STATE,
    "pack": pack_stage(),
    "sample": {
        "gap": Field(float, 0.05, _in(0, 10, lo_open=True),
                     "the top wall starts this many mean grain sizes above the pack's highest point"),
    },
    "stages": TableList({
        "stress": Field(float, REQUIRED, _stress, "target normal stress on all six walls (Pa)"),
        "max_time": STAGE["max_time"],
        "max_strain": Field(float, 0.6, open_unit_interval, "a loading stage ends when the volumetric strain "
                            "passes this (a target the sample cannot reach)"),
    }, min_items=1),
    # at rest below 0.1, as the triaxial's cell of the same walls and grains
    "servo": with_defaults(SERVO, unbalanced_tolerance=0.1),
    **granular_tables(mu_s=0.3, mu_d=0.3, every=5e-3),
}
# rigid grains, explicit, by default: the six walls' stages in a minute or two under the per-stress law
ISOTROPIC["model"] = with_defaults(MODEL, grains="rigid")
ISOTROPIC["solver"] = with_defaults(SOLVER, integrator="explicit")
ISOTROPIC["contact"] = with_defaults(ISOTROPIC["contact"], damping_ratio=0.05, law="material")  # as the triaxial's
ISOTROPIC["contact"]["reference_force"] = reference_force_field("2 x the largest stage stress x the mean grain size "
                                                                "squared")  # fmt: skip
