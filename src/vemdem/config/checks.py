"""The checks and bounds the config tables use (config/tables.py, config/lab_tables.py): each
returns a problem in words for a value it refuses, None otherwise; the config reference states
the bound a check names (config/reference.py, its "allowed" column)."""

from __future__ import annotations

import math
from dataclasses import replace

from .schema import finite_numbers, positive, vector3, vectors3

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


def _file_list(v):
    """Check: a list of file names."""
    return None if all(isinstance(f, str) and f for f in v) else "must be a list of file names (strings)"


def _fractions(v):
    """Check: a list of positive finite numbers (shares, normalised where used)."""
    ok = all(isinstance(f, int | float) and not isinstance(f, bool) and math.isfinite(f) and f > 0 for f in v)
    return None if ok else "must be a list of positive numbers"


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
# Newton's budget per step where `[solver] max_iterations` is not set: the flexible grains' full
# Newton, and the rigid grains' quasi-Newton (its matrix leaves out the rotation flow's own
# linearisation, so it takes more, smaller iterations: solver/rigid_implicit.py)
NEWTON_ITERATIONS = 15
RIGID_NEWTON_ITERATIONS = 25

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


def _target_stresses(v):
    """Check: finite target stresses in [0, 1e9] Pa (a wall pushes or lets go; it cannot pull)."""
    problem = finite_numbers(v)
    if problem:
        return problem
    return None if all(0 <= x <= 1e9 for x in v) else "must be stresses in [0, 1e9] Pa (a wall cannot pull)"


def _stress(v):
    return None if 0 < v <= 1e9 else "must be in (0, 1e9] Pa"
