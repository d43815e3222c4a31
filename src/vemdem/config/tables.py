"""Every config table of vemdem but the laboratory tests' (config/lab_tables.py): THE room that
knows key names, with its checks (config/checks.py) and cross-field rules (config/rules.py).

A scenario's schema is composed here from the shared tables (material, vem, grains, walls,
contact, solver, settle, output); `config.build` turns a checked config into typed options and
a scene. Each key's default is written here once: the integrators' classes read theirs from
SOLVER (solver/defaults.py). Key names are a contract with users (docs, examples, sweeps):
extend, never rename; a key dropped is listed in REMOVED.
"""

from __future__ import annotations

from ..geometry.submesh import METHODS
from .checks import (
    _AXIS_RATIO,
    _DENSITY,
    _DRIVE_SPEED,
    _DURATION,
    _ITERATIONS,
    _LENGTH,
    _MASS_DAMPING,
    _MODULUS,
    _STEP,
    _TIME,
    MAX_COORDINATE,
    MAX_GRAINS,
    MAX_GRAVITY,
    MAX_ROTATION,
    MAX_SPEED,
    MAX_TIME,
    MAX_VERTICES,
    NEWTON_ITERATIONS,
    RIGID_NEWTON_ITERATIONS,
    _count,
    _file_list,
    _fractions,
    _in,
    _lid_frames,
    _mass_stabilised,
    _stabilised,
    _target_stresses,
    _times_within,
    _vector_within,
    _vectors_within,
    _within,
    with_defaults,
)
from .schema import (REQUIRED, AutoOrNumber, Field, TableList, non_negative, open_unit_interval, poisson, positive,
                     vector3)

# -------------------------------------------------------------------------------- helpers
SHAPES = ("cube", "tetrahedron", "l-prism", "random", "file")
INTEGRATORS = ("implicit", "explicit")
LINEAR_SOLVERS = ("auto", "direct", "grain-block")
# -------------------------------------------------------------------------------- shared tables
MATERIAL = {
    "E": Field(float, REQUIRED, _MODULUS, "Young's modulus (Pa)"),
    "nu": Field(float, REQUIRED, poisson, "Poisson's ratio"),
    "density": Field(float, 2200.0, _DENSITY, "kg/m^3"),
}

VEM = {
    "beta_internal": Field(float, 0.5, _stabilised, "beta_i of paper eq. 8"),
    "beta_mass": Field(float, 1.0, _mass_stabilised, "beta_d of paper eq. 8"),
    "beta_load": Field(float, 1.0, _in(0, 1, lo_open=True), "beta_e of paper eq. 8"),
    "submesh": Field(METHODS, "auto", doc="stabilisation sub-mesh"),
}

GRAIN = {
    "shape": Field(SHAPES, "cube", doc="grain shape; 'file' needs the key file"),
    "file": Field(str, "", doc="surface file (STL/OBJ/PLY), relative to the config file"),
    "size": Field(float, 1.45e-3, _LENGTH, "cube edge, or equivalent diameter of other shapes (m)"),
    "vertices": Field(int, 30, _count(4, MAX_VERTICES), "random: number of vertices"),
    "elongation": Field(float, 0.8, _AXIS_RATIO, "random: intermediate/long axis"),
    "flatness": Field(float, 0.8, _AXIS_RATIO, "random: short/intermediate axis"),
    "roughness": Field(float, 0.15, _in(0, 0.5, hi_open=True), "random: relative radial perturbation"),
    "truncate": Field(float, 0.7, open_unit_interval, "random: flat ends at |z| <= truncate * c (compression)"),
    "seed": Field(int, 0, non_negative, "random: seed; same seed, same grain"),
}

SCENE_GRAIN = {k: v for k, v in GRAIN.items() if k != "truncate"}
SCENE_GRAIN.update(
    {
        "position": Field(list, REQUIRED, _vector_within(MAX_COORDINATE, "m"), "centroid (m)"),
        "rotation": Field(list, [0.0, 0.0, 0.0], _vector_within(MAX_ROTATION, "rad"), "rotation vector (rad)"),
        "velocity": Field(list, [0.0, 0.0, 0.0], _vector_within(MAX_SPEED, "m/s"), "initial velocity (m/s)"),
    }
)

WALL = {
    "type": Field(("plane", "mesh"), REQUIRED,
                  doc="plane: an infinite plane (point, normal); mesh: a triangulated surface (file)"),
    "point": Field(list, [0.0, 0.0, 0.0], _vector_within(MAX_COORDINATE, "m"), "plane: a point on it (m)"),
    "normal": Field(list, [0.0, 0.0, 1.0], vector3, "plane: normal pointing towards the grains"),
    "file": Field(str, "", doc="mesh: surface file (STL/OBJ/PLY), relative to the config file"),
    "flip": Field(bool, False, doc="mesh: reverse the faces (normals must face the grains)"),
    "name": Field(str, "", doc="label in outputs"),
    "frictionless": Field(bool, False, doc="no friction on this wall's pairs (a mirror plane; docs/contact.md)"),
    "removed_at": Field(float, None, _TIME, "time at which the wall disappears (s)"),
    "times": Field(list, [0.0], _times_within(MAX_TIME), "times of the piecewise-linear displacement history (s)"),
    "displacements": Field(list, [[0.0, 0.0, 0.0]], _vectors_within(MAX_COORDINATE, "m"),
                           "rigid displacement at each time (m)"),
    # a stress-controlled wall (docs/servo.md): its motion along `normal` is steered, not prescribed
    "servo": {
        "stress": Field(list, [], lambda v: _target_stresses(v),
                        "target normal stress on the wall (Pa), one value per `servo.times` (piecewise-linear, held "
                        "after the last); empty: no servo, the wall follows times/displacements"),
        "times": Field(list, [0.0], _times_within(MAX_TIME), "times of `servo.stress` (s), increasing"),
        "area": Field(float, None, _within(1e-12, 1e2, "m^2"),
                      "the wall's loaded area (m^2): its force target is stress x area [required with a servo]"),
        "max_speed": Field(float, None, _DRIVE_SPEED,
                           "the wall's speed cap (m/s) [required with a servo]: quasi-static where the inertia number "
                           "(rate x grain size / sqrt(stress / density)) stays below 1e-3"),
        "gain": Field(float, 0.3, _in(0, 1, lo_open=True),
                      "share of the force error the wall's travel closes per step (docs/servo.md)"),
    },
}

CONTACT = {
    "law": Field(("weight", "material"), "weight",
                 doc="weight: the law set for the grains' weight (its reference force 10 grain weights at the switch "
                     "gap); material: Hertz's law of the grains' material and size (E, nu, d, the activation gap), "
                     "the same at every stress (docs/contact.md, one law per material). A given reference_force sets "
                     "the weight's kind of law at that force whichever is named"),
    "layer_modulus": Field(float, None, _within(1e3, 1e13, "Pa"),
                           "Pa, the modulus in the material's law's E* [the grains' E]; a softer named layer "
                           "(law = \"material\" only)"),
    "mu_s": Field(float, 0.0, non_negative, "static friction coefficient"),
    "mu_d": Field(float, None, non_negative, "dynamic friction coefficient [mu_s]"),
    "activation_gap": Field(float, None, _within(1e-12, 1.0, "m"), "m [0.01 grain size]"),
    "reference_force": Field(float, None, positive, "N, force per contact at the switch gap, for loads far above "
                             "the weight (a lid: its force over its contacts) [10 grain weights]"),
    "penalty": Field(float, None, positive, "eps1 [from the reference force at the switch gap]"),
    "switch_factor": Field(float, None, _in(1e-3, 1, hi_open=True),
                           "the switch gap as a fraction of the activation gap: the penalty acts above it, the "
                           "barrier below (docs/contact.md) [0.3]"),
    "penalty_exponent": Field(float, None, _in(1, 10),
                              "n1: above the switch gap the force is eps1 (gbar - g)^n1, gbar the activation gap [2]"),
    "barrier_exponent": Field(float, None, _in(-10, -1, hi_open=True),
                              "n2: below the switch gap the force grows as g^n2, without bound as the gap g "
                              "closes [-2]"),
    "tangential_penalty": Field(float, None, positive, "N/m [the normal stiffness at the switch gap]"),
    "tangential_viscosity": Field(float, None, non_negative, "N s/m [0]"),
    "damping_ratio": Field(float, None, non_negative,
                           "normal damping ratio zeta, a fraction of a contact's critical damping [0.5]"),
}

_LAMBDA = _within(0.0, 1e12, "")

SOLVER = {
    "integrator": Field(INTEGRATORS, "implicit", doc="implicit Newmark or explicit central differences"),
    "linear": Field(LINEAR_SOLVERS, "auto", doc="implicit: linear solver of the Newton systems (docs/linear-solvers.md)"),
    # gamma 0.6 with beta (gamma + 1/2)^2 / 4: numerical damping of the unresolved contact and
    # element modes. With gamma 0.5 a grain at rest on a slope crept (0.15 grain sizes/s at 0.8 of
    # the friction angle) and Newton took 9 iterations per step; with 0.6 it stays (docs/dynamics.md)
    "beta": Field(float, 0.3025, _in(0, 0.5, lo_open=True), "Newmark beta"),
    "gamma": Field(float, 0.6, _in(0.5, 1), "Newmark gamma (> 0.5: damps the unresolved high modes)"),
    "dt": Field(float, 1e-5, _STEP, "initial time step (s)"),
    "dt_min": Field(float, 1e-10, _STEP, "the run stops below this step (s)"),
    "dt_max": Field(float, 1e-4, _STEP, "largest step (s)"),
    "max_iterations": Field(int, None, _ITERATIONS, f"Newton iterations before a step is rejected "
                            f"[{NEWTON_ITERATIONS}; rigid grains: {RIGID_NEWTON_ITERATIONS}]"),
    "newton_xtol": Field(
        float, 1e-6, _in(0, 1e-3, lo_open=True),
        "implicit, flexible grains: Newton ends when its correction is below this share of the step's displacement "
        "(docs/dynamics.md)",
    ),
    "easy_iterations": Field(
        int, 8, positive,
        "implicit, flexible grains: a step is easy when Newton converged in at most this many iterations; "
        "after grow_after easy steps in a row the step grows by 1.5",
    ),
    "grow_after": Field(
        int, 3, _count(1, 1_000),
        "implicit, flexible grains: easy steps in a row after which the step grows by 1.5 (1: after every "
        "easy step; the 515-grain lid jam at the real density, docs/dynamics.md)",
    ),
    "freeze_cycles": Field(
        bool, True,
        doc="implicit, flexible grains: a pair that leaves and rejoins Newton's contact set every other "
            "iteration is kept in the set for the rest of the step, or held out of it where another record "
            "carries its touching spot (docs/dynamics.md; without it a settling 110-grain pack stalled at 1e-7 s steps)",
    ),
    "break_stick_cycles": Field(
        bool, True,
        doc="implicit, flexible and rigid grains: a pair that Newton flips between stick and slip three times in a "
            "step is judged by mu_d for the rest of it, as a pair whose static friction broke (docs/dynamics.md; "
            "without it a single such pair rejected the 515-grain implicit pack's steps down to 8e-7 s)",
    ),
    "hold_damping_cycles": Field(
        bool, True,
        doc="implicit, flexible and rigid grains: a pair whose normal damping Newton switches on and off three "
            "times in a step (the no-adhesion clamp at the layer's outer edge) is undamped for the rest of it "
            "(docs/dynamics.md; without it 14 Newton rejections in the first 0.04 s of the 515-grain mu 0.6/0.5 "
            "collapse, with it 1)",
    ),
    "rotated_tangent": Field(
        float, 1e-4, non_negative,
        "implicit, flexible grains: a grain whose deformation gradients all lie within this strain of a rotation "
        "takes its reference tangent rotated as Newton's matrix block (forces stay exact; 0: always the exact "
        "tangent; docs/vem.md: a third of the element kernel's time, the same Newton iterations)",
    ),
    "woodbury_dofs": Field(
        int, 36, non_negative,
        "implicit, flexible grains, grain-block solver: a rotated block (rotated_tangent) whose contacts touch at "
        "most this many of its dofs is solved by Woodbury's formula from its reference modes instead of its LU "
        "(0: every block its LU; docs/linear-solvers.md: 18 % less per Newton iteration early in a collapse)",
    ),
    "impact_steps": Field(
        float, 0.0, _within(0.0, 1e4, ""), "implicit: contact-impact step control, steps per half contact oscillation "
        "(0: off)"
    ),
    "entry_fraction": Field(
        float, 0.05, _in(0, 1, lo_open=True), "implicit: share of the activation gap an approaching pair may close per step"
    ),
    "energy_growth": Field(
        float, 1e-3, non_negative,
        "implicit: a step that raises the total energy by more than this share of W d is halved (0: off; "
        "W: the grains' weight, or the load the walls carry where larger, up to the weight the contact law "
        "was made for: docs/dynamics.md)",
    ),
    "safety": Field(float, 0.5, _in(0, 1, lo_open=True), "explicit: share of the critical step taken"),
    "mass_damping": Field(float, 0.0, _MASS_DAMPING, "Rayleigh mass-proportional damping alpha (1/s), for settling"),
    "mass_scaling": Field(
        float, 1.0, _within(1.0, 1e8, ""), "density factor for inertia, weight and contact scales (docs/dynamics.md)"
    ),
    "selective_mass_scaling": Field(
        AutoOrNumber, 0.0, lambda v: None if v == "auto" else _LAMBDA(v),
        "explicit, flexible grains: lambda, the grains' deformation modes carry 1 + lambda times their inertia while "
        "translations and rotations keep their real one (0: off); \"auto\": the lambda at which the grains' own "
        "step reaches the contacts', its slowest vibration period kept within three contact durations "
        "(docs/selective-mass-scaling.md)",
    ),
}

MODEL = {
    "grains": Field(
        ("flexible", "rigid"), "flexible",
        doc="flexible: one virtual element per grain (the paper); rigid: six dofs per grain (both integrators)",
    ),
}

OUTPUT = {
    "every": Field(float, 1e-3, positive, "simulated time between written frames (s), from a 100,000th of the run's "
                   "duration to all of it"),
    "vtk": Field(bool, True, doc="write the ParaView series grains.pvd"),
}

SETTLE = {
    "kinetic_threshold": Field(
        float, 1e-3, positive, "at rest when the mean kinetic energy per grain is below this share of m g d"
    ),
    "min_time": Field(float, 0.02, _TIME, "s before rest is checked"),
    "max_time": Field(float, 1.0, _DURATION, "s of simulated time at most (the run stops, unsettled, then)"),
}

# -------------------------------------------------------------------------------- scenario schemas
SCENE = {
    "scenario": Field(("scene",), REQUIRED),
    "gravity": Field(list, [0.0, 0.0, -9.81], _vector_within(MAX_GRAVITY, "m/s^2"), "m/s^2"),
    "duration": Field(float, REQUIRED, _DURATION, "simulated time (s)"),
    "material": MATERIAL,
    "vem": VEM,
    "model": MODEL,
    "contact": CONTACT,
    "solver": SOLVER,
    "grains": TableList(SCENE_GRAIN, min_items=1),
    "walls": TableList(WALL),
    "output": OUTPUT,
}

GRAIN_COMPRESSION = {
    "scenario": Field(("grain_compression",), REQUIRED),
    "material": MATERIAL,
    "vem": VEM,
    "grain": GRAIN,
    "loading": {
        "mode": Field(("uniaxial", "confined"), "uniaxial",
                      doc="uniaxial: the sides free; confined: every vertex held laterally (no lateral strain)"),
        "max_strain": Field(float, 0.3, open_unit_interval, "engineering strain 1 - h/h0"),
        "steps": Field(int, 30, _count(1, 100_000), "load steps"),
    },
    "solver": {
        "rtol": Field(float, 1e-9, open_unit_interval, "Newton tolerance, relative"),
        "max_iterations": Field(int, 40, _ITERATIONS, "Newton iterations per load step before the run stops"),
    },
    "output": {
        "vtk": Field(bool, True, doc="write the ParaView series grain.pvd"),
        "plot": Field(bool, True, doc="write force_strain.png"),
    },
}

# The paper's sand (section 3): E = 90 GPa, nu = 0.16, 2200 kg/m^3.
PAPER_MATERIAL = with_defaults(MATERIAL, E=90e9, nu=0.16, density=2200.0)

# Explicit with mass scaling: these runs follow grains for tenths of a second, where the stiff
# grains' elastic periods (~1e-7 s) would otherwise set the step (docs/results.md, docs/dynamics.md).
# mass_scaling 1e4: the largest power of ten that leaves a collision unchanged (config.build.NEUTRAL_RATIO)
GRANULAR_SOLVER = with_defaults(SOLVER, integrator="explicit", mass_scaling=1e4, dt_max=1e-4)

# Settling is preparation, not the experiment: a mass damping of 20 1/s caps the fall at about
# g / 20 = 0.5 m/s, so grains from the top of a 100 mm column do not hit the pack at 1.4 m/s,
# where the barrier stiffens and the explicit step fell to 6e-7 s (docs/results.md)
SETTLING_DAMPING = 20.0


def granular_tables(mu_s: float, mu_d: float, every: float) -> dict:
    """The tables pack, pile_collapse and lid_compression share (the paper's material)."""
    return {
        "gravity": Field(list, [0.0, 0.0, -9.81], _vector_within(MAX_GRAVITY, "m/s^2"), "m/s^2"),
        "material": PAPER_MATERIAL,
        "vem": VEM,
        "model": MODEL,
        "contact": with_defaults(CONTACT, mu_s=mu_s, mu_d=mu_d),
        "solver": GRANULAR_SOLVER,
        "settle": SETTLE,
        "output": with_defaults(OUTPUT, every=every),
    }


PACK = {
    "scenario": Field(("pack",), REQUIRED),
    "n_grains": Field(int, 515, _count(1, MAX_GRAINS), "number of grains"),
    "seed": Field(int, 0, non_negative, "seeds the sizes, shapes, orientations and positions"),
    "grains": {
        "size": Field(float, 1.45e-3, _LENGTH, "mean equivalent diameter (m)"),
        "size_spread": Field(float, 0.1, _in(0, 1, hi_open=True), "sizes uniform in size (1 +- size_spread)"),
        "shape": Field(("sand", "angular", "file"), "sand",
                       doc="sand: hull of points on an ellipsoid (rounded); angular: an ellipsoid cut by planes "
                           "(flat faces, sharp edges; docs/results.md, grain shapes); file: the surfaces named "
                           "in files"),
        "files": Field(list, [], _file_list,
                       "shape = 'file': surface files (STL/OBJ/PLY, relative to the config file), each grain one "
                       "of them scaled to its drawn size"),
        "fractions": Field(list, [], _fractions,
                           "shape = 'file': the share of the grains each file makes, in number (not set: equal)"),
        "vertices": Field(int, 30, _count(8, MAX_VERTICES), "vertices per grain (angular: about)"),
        "elongation": Field(float, 0.8, _AXIS_RATIO, "intermediate/long axis of the grains' ellipsoid (Zingg's I/L)"),
        "flatness": Field(float, 0.8, _AXIS_RATIO, "short/intermediate axis of the grains' ellipsoid (Zingg's S/I)"),
        "roughness": Field(float, 0.15, _in(0, 0.5, hi_open=True),
                           "relative radial perturbation of a grain's points (sand) or of its cutting planes "
                           "(angular)"),
        "clearance": Field(float, 0.02, _within(0.0, 10.0, "radii"),
                           "gap between grains in the column, in circumscribed radii"),
    },
    "box": {
        "width": Field(float, 8e-3, _LENGTH, "x side (m)"),
        "depth": Field(float, 8e-3, _LENGTH, "y side (m)"),
    },
    **granular_tables(mu_s=0.6, mu_d=0.5, every=5e-3),
}
PACK["solver"] = with_defaults(PACK["solver"], mass_damping=SETTLING_DAMPING)


def pack_stage() -> dict:
    """The `[pack]` table of pile_collapse and lid_compression: the pack scenario's own keys, used
    when no `initial_state` is given (the pack is then settled first, into DIR/pack)."""
    table = {k: PACK[k] for k in ("n_grains", "seed", "grains", "box")}
    table["mu_s"] = Field(float, 0.6, non_negative, "friction while settling")
    table["mu_d"] = Field(float, 0.5, non_negative, "friction while settling")
    table["mass_damping"] = Field(float, SETTLING_DAMPING, _MASS_DAMPING, "1/s, mass damping while settling")
    table["model"] = Field(("same", "rigid"), "same",
                           doc="the grains the pack settles with: same, the run's [model] grains; rigid, rigid grains "
                               "and explicit steps (a stiff grain strains by nanometres under its weight, so the pack "
                               "is the flexible one's at a fraction of the cost; docs/oedometer.md)")  # fmt: skip
    return table


INITIAL_STATE = Field(str, "", doc="state.npz written by a pack run, relative to the config file [settle [pack] first]")

PILE_COLLAPSE = {
    "scenario": Field(("pile_collapse",), REQUIRED),
    "initial_state": INITIAL_STATE,
    "pack": pack_stage(),
    "collapse": {
        "open": Field(("all", "front", "corner"), "all",
                      doc="which walls go at t = 0: all (the paper's experiment: the column spreads around its axis "
                          "into a heap), front (only the +x wall: the grains run out along the channel of the "
                          "back and side walls, a two-dimensional collapse whose deposit leans on the back wall; "
                          "a flank as tall from about a third of the grains a cone needs) or corner (the +x and +y "
                          "walls: the -x and -y walls stay, frictionless, as mirror planes, and the grains spread "
                          "into a quarter of the heap of a column four times as large: a flank as tall from a "
                          "quarter of the grains)"),
    },
    **granular_tables(mu_s=0.6, mu_d=0.5, every=5e-3),
}
PILE_COLLAPSE["settle"] = with_defaults(SETTLE, min_time=0.05)  # the pile must first start to move

POURED_HEAP = {
    "scenario": Field(("poured_heap",), REQUIRED),
    "initial_state": INITIAL_STATE,
    "pack": pack_stage(),
    "source": {
        "lift_speed": Field(float, 0.02, _DRIVE_SPEED, "speed at which the box around the pack rises (m/s): the grains "
                            "flow out under it, slow against their settling speed"),
        "open": Field(("all", "corner"), "all",
                      doc="all: the four sides rise, the disc is centred under the box; corner: the -x and -y "
                          "sides stay as frictionless mirror planes, the +x and +y sides rise, and the disc is "
                          "centred on the corner: a quarter of the heap of a pack four times as large"),
    },
    "disc": {
        "radius": Field(float, 8e-3, _LENGTH, "radius of the floor disc (m); grains that roll off it are lost"),
        "catch_depth": Field(float, 5e-3, _LENGTH, "depth of the catch floor below the disc (m)"),
    },
    **granular_tables(mu_s=0.6, mu_d=0.5, every=5e-3),
}
POURED_HEAP["settle"] = with_defaults(SETTLE, min_time=0.05)

TILTING_BOX = {
    "scenario": Field(("tilting_box",), REQUIRED),
    "initial_state": INITIAL_STATE,
    "pack": pack_stage(),
    "tilt": {
        "start": Field(float, 10.0, _in(0.0, 90.0, hi_open=True), "tilt of the box at t = 0 (degrees)"),
        "rate": Field(float, 20.0, _within(1e-3, 1e4, "degrees/s"),
                      "tilt rate (degrees/s): slow against an avalanche's growth"),
        "max": Field(float, 60.0, _in(0.0, 90.0, lo_open=True, hi_open=True),
                     "largest tilt (degrees): a box that has not avalanched by then ends the run"),
        "avalanche": Field(("kinetic", "surface"), "kinetic", doc="what marks the avalanche: the pack's mean kinetic "
                           "energy (avalanche_kinetic) or the surface layer's downhill slip (surface_slip)"),
        "avalanche_kinetic": Field(float, 1e-3, positive, "mean kinetic energy per grain, as a share of m g d, that "
                                   "marks the avalanche: the tilt stops there"),
        "surface_slip": Field(float, 0.5, positive, "avalanche = \"surface\": mean downhill slip of the surface "
                              "layer since the tilting began, in grain sizes, that marks the avalanche"),
        "sides": Field(("walls", "mirrors"), "walls", doc="the box's +-y sides: walls with the grains' friction, or "
                       "frictionless mirror planes (a box as wide as many mirrored copies: no side-wall support)"),
    },
    **granular_tables(mu_s=0.6, mu_d=0.5, every=5e-3),
}
# min_time counts from the avalanche; at rest ten times below the avalanche's kinetic energy
TILTING_BOX["settle"] = with_defaults(SETTLE, min_time=0.05, kinetic_threshold=1e-4)

LID_COMPRESSION = {
    "scenario": Field(("lid_compression",), REQUIRED),
    "initial_state": INITIAL_STATE,
    "pack": pack_stage(),
    "lid": {
        "start": Field(float, 7e-3, _LENGTH, "lid height above the floor at the start and the end (m)"),
        "end": Field(float, 4.9e-3, _LENGTH, "lowest lid height (m)"),
        "speed": Field(float, 0.02, _DRIVE_SPEED, "lid speed (m/s): slow against the grains' settling speed"),
        "frames": Field(int, 100, _lid_frames, "frames (force samples) per phase"),
    },
    **granular_tables(mu_s=0.15, mu_d=0.15, every=1e-3),
}
LID_COMPRESSION["output"] = {"vtk": OUTPUT["vtk"]}  # frames come from lid.frames
# A light normal damping: with the scenes' 0.5 the viscous force of the lid's stiff contacts
# (2 zeta sqrt(k m), m mass-scaled) rivalled the elastic one at the lid's speed, and the force
# fell from 15 kN to 0.4 kN and back when the lid turned; with 0.05 the curve is continuous there
# (the paper-compression run, docs/results.md)
LID_COMPRESSION["contact"] = with_defaults(LID_COMPRESSION["contact"], damping_ratio=0.05)


# -------------------------------------------------------------------------------- removed keys
# Keys the package had and dropped (docs/design-notes.md says what each measured): a config that
# still sets one is refused with its name and why, not as an unknown key. Dotted, without indices.
REMOVED = {
    "contact.edge_fade": "the edge-edge fade removed the energy jumps of the contact hierarchy's twins but "
                         "made the lid jam 3.5 times slower; it was off by default",
    "contact.edge_edge_rule": "the paper's last vertex-edge clause switches a record on inside the layer (an "
                              "energy jump) and moved the angle of repose within its scatter; it was off by default",
    "solver.predictor": "Newton always starts from each grain's rigid constant-acceleration motion, which "
                        "measured a quarter fewer iterations than the other two predictors",
}
