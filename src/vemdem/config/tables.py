"""Every config table of vemdem, and the cross-field rules: THE room that knows key names.

A scenario's schema is composed here from the shared tables (material, vem, grains, walls,
contact, solver, settle, output); `config.build` turns a checked config into typed options and
a scene. Key names are a contract with users (docs, examples, sweeps): extend, never rename.
"""

from __future__ import annotations

import math
from dataclasses import replace

from ..geometry.submesh import METHODS
from .schema import (
    REQUIRED,
    ConfigError,
    Field,
    TableList,
    finite_numbers,
    non_negative,
    open_unit_interval,
    poisson,
    positive,
    unit_interval,
    vector3,
    vectors3,
)

# -------------------------------------------------------------------------------- helpers
SHAPES = ("cube", "tetrahedron", "l-prism", "random", "file")
INTEGRATORS = ("implicit", "explicit")
LINEAR_SOLVERS = ("auto", "direct", "grain-block")
PREDICTORS = ("rigid", "acceleration", "rest")
BODY_MODELS = ("flexible",)
MAX_FRAMES = 100_000  # more frames than this is a typo in output.every, not a wish


def _lid_frames(v):
    """lid.frames: per phase, so the two phases together within MAX_FRAMES."""
    return positive(v) or (None if 2 * v <= MAX_FRAMES else f"must be at most {MAX_FRAMES // 2:,} per phase")


def with_defaults(schema: dict, **defaults) -> dict:
    """A copy of a schema table with other default values (the keys stay those of `schema`)."""
    out = dict(schema)
    for key, value in defaults.items():
        out[key] = replace(schema[key], default=value)
    return out


def _in(lo, hi, lo_open=False, hi_open=False):
    def check(v):
        ok = (lo < v if lo_open else lo <= v) and (v < hi if hi_open else v <= hi)
        return None if ok else f"must be in {'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"

    return check


def _stabilised(v):
    return None if 0 < v <= 1 else "must be in (0, 1] (0 leaves the element without stabilisation: singular stiffness)"


def _mass_stabilised(v):
    # the projection's own mass matrix has rank 4 (a constant and a linear field): without the
    # sub-mesh's share the implicit step's matrix is singular and every step is rejected
    return None if 0 < v <= 1 else "must be in (0, 1] (0 leaves the mass matrix singular)"


# ------------------------------------------------------------------ bounds of physical magnitudes
# Far beyond any grain run (sand: 2650 kg/m^3, 70 GPa; grains of 0.1-10 mm followed for seconds),
# so a value outside them is a typo or a slip of units. Refused by name here, before it overflows
# in a kernel: a density of 1e300 ran to its end on overflow warnings, a 1e300 m grain ended in an
# OverflowError, a 1e300 m/s grain in a zero-volume grain. The check's message states the bound,
# which is how it reaches the config reference (config/reference.py, its "allowed" column).
def _num(v) -> str:
    """A bound as people write it: 1e5, 1e-7, 0.5, 10 (not 100000 or 1e+05)."""
    if v == 0 or 1e-3 <= abs(v) < 1e3:
        return f"{v:g}"
    mantissa, exponent = f"{v:e}".split("e")
    return f"{mantissa.rstrip('0').rstrip('.')}e{int(exponent)}"


def _within(lo, hi, unit, lo_open=False):
    """Check: a magnitude in [lo, hi] (lo_open: (lo, hi]) `unit`."""
    span = f"{'(' if lo_open else '['}{_num(lo)}, {_num(hi)}] {unit}".rstrip()

    def check(v):
        return None if (lo < v if lo_open else lo <= v) and v <= hi else f"must be in {span}"

    return check


def _count(lo, hi):
    """Check: an integer count from lo to hi; more is a typo that would run out of memory or time."""
    return lambda v: None if lo <= v <= hi else f"must be from {lo:,} to {hi:,}"


def _vector_within(limit, unit):
    """Check: a list of 3 finite numbers whose length is at most `limit` `unit`."""

    def check(v):
        return vector3(v) or (None if math.hypot(*v) <= limit else f"must have a magnitude of at most {_num(limit)} {unit}")

    return check


def _times_within(limit):
    """Check: a list of finite times (s), each within +-limit."""

    def check(v):
        return finite_numbers(v) or (None if all(abs(t) <= limit for t in v) else f"must be times within "
                                     f"+-{_num(limit)} s")  # fmt: skip

    return check


def _vectors_within(limit, unit):
    """Check: a list of [x, y, z] lists, each at most `limit` `unit` long."""

    def check(v):
        return vectors3(v) or (None if all(math.hypot(*d) <= limit for d in v) else f"must be [x, y, z] lists of a "
                               f"magnitude of at most {_num(limit)} {unit}")  # fmt: skip

    return check


MAX_COORDINATE = 1e3  # m: positions, wall points and displacements lie within a kilometre of the origin
MAX_SPEED = 1e3  # m/s: a grain's initial speed
MAX_GRAVITY = 1e4  # m/s^2: about 1,000 g, above any centrifuge test
MAX_ROTATION = 1e3  # rad: a rotation vector's angle
MAX_TIME = 1e4  # s: durations and times
MAX_GRAINS = 1_000_000
MAX_VERTICES = 1_000  # per grain
MAX_ITERATIONS = 1_000  # Newton's, per step or load step

# the checks of one magnitude each
_DENSITY = _within(1.0, 1e5, "kg/m^3")
_MODULUS = _within(1e3, 1e13, "Pa")
_LENGTH = _within(1e-7, 10.0, "m")  # grain sizes, boxes, lids, discs
_DRIVE_SPEED = _within(1e-6, MAX_SPEED, "m/s")  # a lid's or a box's: a slower one never ends (2 mm: 2,000 s)
_DURATION = _within(0.0, MAX_TIME, "s", lo_open=True)
_TIME = _within(0.0, MAX_TIME, "s")
_STEP = _within(1e-15, 10.0, "s")  # time steps
_ITERATIONS = _count(1, MAX_ITERATIONS)
_MASS_DAMPING = _within(0.0, 1e6, "1/s")  # settling uses 20 1/s
_AXIS_RATIO = _within(0.01, 1.0, "")  # a grain's axes: a needle or a plate of 100 to 1 at the most


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
    "type": Field(("plane", "mesh"), REQUIRED),
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


def _target_stresses(v):
    """Check: finite target stresses in [0, 1e9] Pa (a wall pushes or lets go; it cannot pull)."""
    problem = finite_numbers(v)
    if problem:
        return problem
    return None if all(0 <= x <= 1e9 for x in v) else "must be stresses in [0, 1e9] Pa (a wall cannot pull)"

CONTACT = {
    "mu_s": Field(float, 0.0, non_negative, "static friction coefficient"),
    "mu_d": Field(float, None, non_negative, "dynamic friction coefficient [mu_s]"),
    "activation_gap": Field(float, None, _within(1e-12, 1.0, "m"), "m [0.01 grain size]"),
    "reference_force": Field(float, None, positive, "N, force per contact at the switch gap, for loads far above "
                             "the weight (a lid: its force over its contacts) [10 grain weights]"),
    "penalty": Field(float, None, positive, "eps1 [from the reference force at the switch gap]"),
    "switch_factor": Field(float, None, _in(1e-3, 1, hi_open=True)),
    "penalty_exponent": Field(float, None, _in(1, 10)),
    "barrier_exponent": Field(float, None, _in(-10, -1, hi_open=True)),
    "tangential_penalty": Field(float, None, positive, "N/m [the normal stiffness at the switch gap]"),
    "tangential_viscosity": Field(float, None, non_negative, "N s/m [0]"),
    "damping_ratio": Field(float, None, non_negative, "normal damping ratio [0.5]"),
    "edge_fade": Field(bool, False,
                       doc="weigh edge-edge records out within the activation gap of their edges' ends, so the contact "
                           "potential is continuous there (docs/contact.md: no energy jumps, but Newton is slower in "
                           "jammed packs)"),
    "edge_edge_rule": Field(bool, False,
                            doc="the paper's full contact hierarchy (docs/contact.md): a vertex-edge pair also yields "
                                "to two eligible edge-edge pairs between its edge and edges at its vertex, so a "
                                "touching spot counts once there (off, the default: it may count up to three times, "
                                "which keeps energy jumps out of implicit runs; docs/contact.md)"),
}

SOLVER = {
    "integrator": Field(INTEGRATORS, "implicit", doc="implicit Newmark or explicit central differences"),
    "linear": Field(LINEAR_SOLVERS, "auto", doc="implicit: linear solver of the Newton systems (docs/linear-solvers.md)"),
    "predictor": Field(PREDICTORS, "rigid",
                       doc="implicit, flexible grains: Newton's first iterate: rigid, each grain's rigid part of the "
                           "constant-acceleration motion; acceleration, all of it; rest, the step's start "
                           "(docs/dynamics.md)"),
    # gamma 0.6 with beta (gamma + 1/2)^2 / 4: numerical damping of the unresolved contact and
    # element modes. With gamma 0.5 a grain at rest on a slope crept (0.15 grain sizes/s at 0.8 of
    # the friction angle) and Newton took 9 iterations per step; with 0.6 it stays (docs/dynamics.md)
    "beta": Field(float, 0.3025, _in(0, 0.5, lo_open=True), "Newmark beta"),
    "gamma": Field(float, 0.6, _in(0.5, 1), "Newmark gamma (> 0.5: damps the unresolved high modes)"),
    "dt": Field(float, 1e-5, _STEP, "initial time step (s)"),
    "dt_min": Field(float, 1e-10, _STEP, "the run stops below this step (s)"),
    "dt_max": Field(float, 1e-4, _STEP, "largest step (s)"),
    "max_iterations": Field(int, 15, _ITERATIONS, "Newton iterations before a step is rejected"),
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
        "mode": Field(("uniaxial", "confined"), "uniaxial"),
        "max_strain": Field(float, 0.3, open_unit_interval, "engineering strain 1 - h/h0"),
        "steps": Field(int, 30, _count(1, 100_000), "load steps"),
    },
    "solver": {
        "rtol": Field(float, 1e-9, open_unit_interval, "Newton tolerance, relative"),
        "max_iterations": Field(int, 40, _ITERATIONS),
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
        "shape": Field(("sand", "angular"), "sand",
                       doc="sand: hull of points on an ellipsoid (rounded); angular: an ellipsoid cut by planes "
                           "(flat faces, sharp edges; docs/results.md, grain shapes)"),
        "vertices": Field(int, 30, _count(8, MAX_VERTICES), "vertices per grain (angular: about)"),
        "elongation": Field(float, 0.8, _AXIS_RATIO),
        "flatness": Field(float, 0.8, _AXIS_RATIO),
        "roughness": Field(float, 0.15, _in(0, 1, hi_open=True)),
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


def _stress(v):
    return None if 0 < v <= 1e9 else "must be in (0, 1e9] Pa"


STAGE = {
    "stress": Field(float, REQUIRED, _stress, "target normal stress on the lid (Pa)"),
    "max_time": Field(float, 1.0, positive, "the stage ends after this much simulated time, reached or not (s)"),
    "max_strain": Field(float, 0.6, open_unit_interval,
                        "a loading stage ends when the axial strain passes this (a target the sample cannot reach)"),
}

OEDOMETER = {
    "scenario": Field(("oedometer",), REQUIRED),
    "initial_state": INITIAL_STATE,
    "pack": pack_stage(),
    "lid": {
        "gap": Field(float, 0.05, _in(0, 10, lo_open=True),
                     "the lid starts this many mean grain sizes above the pack's highest point"),
        "area": Field(float, None, positive, "loaded area of the lid (m^2) [the box's cross-section]"),
    },
    "ring": {
        "friction": Field(bool, False, doc="the side walls' friction: false, a lubricated ring (the lid's stress is "
                          "the sample's; docs/oedometer.md); true, the grains' contact friction"),
    },
    "stages": TableList(STAGE, min_items=1),
    "servo": SERVO,
    **granular_tables(mu_s=0.15, mu_d=0.15, every=5e-3),
}
# The paper's method by default: implicit Newmark at the real density (no mass scaling). Its
# steps stay at most 1e-4 s, as the lid cycles': with 1e-3 s a loose 60-grain pack under the lid
# stalled twice in its seating (Newton at 1e-10 s steps; docs/oedometer.md)
OEDOMETER["solver"] = SOLVER
OEDOMETER["contact"] = with_defaults(OEDOMETER["contact"], damping_ratio=0.05)  # as the lid cycle's: elastic contacts
OEDOMETER["contact"]["reference_force"] = replace(
    OEDOMETER["contact"]["reference_force"],
    doc="N, force per contact at the switch gap [2 x the path's largest stress x the mean grain size squared; "
        "the pack settles under the weight's law]")  # fmt: skip

TRIAXIAL = {
    "scenario": Field(("triaxial",), REQUIRED),
    "initial_state": INITIAL_STATE,
    "pack": pack_stage(),
    "sample": {
        "gap": Field(float, 0.05, _in(0, 10, lo_open=True),
                     "the top platen starts this many mean grain sizes above the pack's highest point"),
    },
    "consolidation": {
        "stress": Field(float, REQUIRED, _stress, "the confining stress (Pa): on all five moving walls, then on the "
                        "four lateral ones while the sample is sheared"),
        "max_time": Field(float, 0.1, positive, "consolidation ends after this much simulated time, reached or not (s)"),
    },
    "shear": {
        "max_strain": Field(float, 0.25, open_unit_interval, "the axial strain (from the consolidated sample) the "
                            "platen compresses it to"),
        "inertia_number": Field(float, 5e-4, _in(0, 1e-2, lo_open=True),
                                "sets the platen's constant speed: the axial strain rate that gives this inertia "
                                "number at the confining stress, rate = I sqrt(sigma_3 / rho) / d"),
        "max_time": Field(float, 10.0, positive, "shearing ends after this much simulated time in any case (s)"),
    },
    # at rest below 0.1: a consolidated 100-grain rigid sample (explicit), its five walls within
    # 0.1 % of 50 kPa and its height moving by 3e-7 per frame, hovered at 0.02-0.09 for 0.02 s
    "servo": with_defaults(SERVO, unbalanced_tolerance=0.1),
    **granular_tables(mu_s=0.3, mu_d=0.3, every=5e-3),
}
# As the oedometer's: implicit Newmark at the real density by default; the rigid grains with
# `[model] grains = "rigid"`
TRIAXIAL["solver"] = SOLVER
# As the oedometer's: light contact damping (the package's 0.5 kept the 100-grain example's five
# servos 5-15 % off their target for 0.02 s of consolidation, where 0.05 held them within 1 %)
TRIAXIAL["contact"] = with_defaults(TRIAXIAL["contact"], damping_ratio=0.05)
# the law is set for the test's load, not the grains' weight (scenarios/lab.contact_at_stress)
TRIAXIAL["contact"]["reference_force"] = replace(
    TRIAXIAL["contact"]["reference_force"],
    doc="N, force per contact at the switch gap [2 x consolidation.stress x the mean grain size squared: "
        "about the force per contact at a sheared sample's mean stress]")  # fmt: skip

DIRECT_SHEAR = {
    "scenario": Field(("direct_shear",), REQUIRED),
    "initial_state": INITIAL_STATE,
    "pack": pack_stage(),
    "sample": {
        "gap": Field(float, 0.05, _in(0, 10, lo_open=True),
                     "the lid starts this many mean grain sizes above the pack's highest point"),
        "split": Field(float, 0.5, _in(0.2, 0.8),
                       "where the box's halves meet, as a share of the pack's height above the floor"),
        "opening": Field(float, 0.0, _in(0, 2),
                         "the gap between the halves' walls, in mean grain sizes (below the smallest grain), as a lab "
                         "box's halves are set apart (docs/direct-shear.md: what 0.5 did)"),
    },
    "normal": {
        "stress": Field(float, REQUIRED, _stress, "the normal stress on the lid (Pa), held by its servo"),
        "max_time": Field(float, 0.1, positive, "the lid's consolidation ends after this much simulated time, "
                          "reached or not (s)"),
    },
    "shear": {
        "max_displacement": Field(float, 0.15, _in(0.01, 0.5),
                                  "the lower half's travel, as a share of the box's length along x (the frames' "
                                  "plates close the box's ends past it)"),
        "inertia_number": Field(float, 5e-4, _in(0, 1e-2, lo_open=True),
                                "sets the lower half's speed: the shear rate (speed / sample height) that gives "
                                "this inertia number at the normal stress"),
        "max_time": Field(float, 10.0, positive, "shearing ends after this much simulated time in any case (s)"),
    },
    "servo": SERVO,
    **granular_tables(mu_s=0.3, mu_d=0.3, every=5e-3),
}
DIRECT_SHEAR["solver"] = SOLVER
# the package's contact damping (0.5): with the oedometer's 0.05 the 120-grain example under its
# lid hovered at an unbalanced force ratio of 0.45-0.6; with 0.5 it was at rest (below 0.01) after
# 0.01 s, its lid within 1 % of the normal stress
DIRECT_SHEAR["contact"] = dict(DIRECT_SHEAR["contact"])
DIRECT_SHEAR["contact"]["reference_force"] = replace(
    TRIAXIAL["contact"]["reference_force"],
    doc="N, force per contact at the switch gap [2 x normal.stress x the mean grain size squared]")


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
# rigid grains, explicit, by default: the six walls' stages in a minute or two
ISOTROPIC["model"] = with_defaults(MODEL, grains="rigid")
ISOTROPIC["solver"] = with_defaults(SOLVER, integrator="explicit")
ISOTROPIC["contact"] = with_defaults(ISOTROPIC["contact"], damping_ratio=0.05)  # as the triaxial's
ISOTROPIC["contact"]["reference_force"] = replace(
    TRIAXIAL["contact"]["reference_force"],
    doc="N, force per contact at the switch gap [2 x the largest stage stress x the mean grain size squared]")


# -------------------------------------------------------------------------------- cross-field rules
def check_rules(cfg: dict) -> None:
    """Rules that tie several keys together; each raises a ConfigError naming the key."""
    contact = cfg.get("contact")
    if isinstance(contact, dict) and contact.get("mu_d") is not None and contact["mu_d"] > contact["mu_s"]:
        raise ConfigError(f"contact.mu_d: must not exceed contact.mu_s ({contact['mu_s']:g}), got {contact['mu_d']:g} "
                          "(its default where not set: give both)")  # fmt: skip
    pack = cfg.get("pack")
    if isinstance(pack, dict) and "mu_d" in pack and pack["mu_d"] > pack["mu_s"]:
        raise ConfigError(f"pack.mu_d: must not exceed pack.mu_s ({pack['mu_s']:g}), got {pack['mu_d']:g} "
                          "(its default where not set: give both)")  # fmt: skip
    settle = cfg.get("settle")
    if isinstance(settle, dict) and "min_time" in settle and "max_time" in settle:
        if settle["min_time"] > settle["max_time"]:
            raise ConfigError(f"settle.min_time: must not exceed settle.max_time ({settle['max_time']:g} s), "
                              f"got {settle['min_time']:g}")  # fmt: skip
    solver = cfg.get("solver")
    if isinstance(solver, dict) and "dt_min" in solver and "dt_max" in solver:
        if solver["dt_min"] > solver["dt_max"]:
            raise ConfigError(f"solver.dt_min: must not exceed solver.dt_max ({solver['dt_max']:g}), got {solver['dt_min']:g}")
        if solver["dt"] < solver["dt_min"]:
            raise ConfigError(f"solver.dt: must not be below solver.dt_min ({solver['dt_min']:g}), got {solver['dt']:g}")
    if isinstance(solver, dict) and "easy_iterations" in solver and "max_iterations" in solver:
        if solver["easy_iterations"] > solver["max_iterations"]:
            limit = solver["max_iterations"]
            raise ConfigError(f"solver.easy_iterations: must not exceed solver.max_iterations ({limit}), "
                              f"got {solver['easy_iterations']}")  # fmt: skip
    tilt = cfg.get("tilt")
    if isinstance(tilt, dict) and "start" in tilt and "max" in tilt and tilt["start"] >= tilt["max"]:
        raise ConfigError(f"tilt.start: must be below tilt.max ({tilt['max']:g} degrees), got {tilt['start']:g}")
    gravity = cfg.get("gravity")
    if isinstance(tilt, dict) and isinstance(gravity, list) and (gravity[0] != 0 or gravity[1] != 0 or gravity[2] >= 0):
        raise ConfigError(f"gravity: the tilting box turns gravity from straight down; give [0, 0, -g], got "
                          f"{[float(v) for v in gravity]}")  # fmt: skip
    _check_frames(cfg)
    _check_every_within_run(cfg)
    lid = cfg.get("lid")
    if isinstance(lid, dict) and "end" in lid and lid["end"] >= lid["start"]:
        raise ConfigError(f"lid.end: must be below lid.start ({lid['start']:g} m), got {lid['end']:g}")


def _check_frames(cfg: dict) -> None:
    every = cfg.get("output", {}).get("every")
    if every is None:
        return
    duration = cfg.get("duration") or cfg.get("settle", {}).get("max_time")
    if duration is None:
        return
    frames = duration / every
    if frames > MAX_FRAMES:
        raise ConfigError(f"output.every: {every:g} s writes {frames:.3g} frames over {duration:g} s "
                          f"(at most {MAX_FRAMES:,}); choose a larger interval")  # fmt: skip


# the scenarios that run for settle.max_time (the others add a tilt, a lift or load stages to it)
SETTLE_IS_DURATION = ("pack", "pile_collapse")


def _run_length(cfg: dict) -> tuple[str, float] | None:
    """(key, seconds) of the simulated time a run lasts where one key fixes it, else None."""
    if "duration" in cfg:
        return "duration", cfg["duration"]
    if cfg.get("scenario") in SETTLE_IS_DURATION and "max_time" in cfg.get("settle", {}):
        return "settle.max_time", cfg["settle"]["max_time"]
    return None


def _check_every_within_run(cfg: dict) -> None:
    """A frame interval longer than the run: the loop would cut its only frame to the run's end, so
    the interval asked for is never the one written (a slip of units or of keys)."""
    every = cfg.get("output", {}).get("every")
    length = _run_length(cfg)
    if every is not None and length is not None and every > length[1]:
        key, seconds = length
        raise ConfigError(f"output.every: must not exceed {key} ({seconds:g} s), got {every:g}")
