"""The laboratory tests' cross-field rules (config/rules.py runs them after every key passed its
own): how long a test can run against its frame interval, its lid's area against its box, and
the size of its sample. Each raises a ConfigError naming the key. `lid_area_problem` and
`sample_problem` are asked again by the scenarios once a pack read from `initial_state` tells its
box and its grains (docs/servo.md, what a lab test refuses)."""

from __future__ import annotations

import math

from .checks import _num
from .schema import ConfigError

# the tables whose `max_time` bound a test's stages (the oedometer's and the isotropic test's
# are their [[stages]])
STAGE_TABLES = {"triaxial": ("consolidation", "shear"), "direct_shear": ("normal", "shear")}
LAB = ("oedometer", "isotropic", *STAGE_TABLES)

# A sample of fewer grains than MIN_GRAINS measures nothing: a grain alone under a lid touches no
# other, so its K0 was 0 and a one-grain triaxial "peaked" at 16 degrees. The tests run samples of
# 4-20 grains on purpose (seconds, not minutes: they check the machinery, not the soil), so below
# FEW_GRAINS a sample only draws a warning; the shipped examples hold 60 grains and more.
MIN_GRAINS = 4
FEW_GRAINS = 30

# A lid's area this many times off the box's section is a slip of units (mm^2 or cm^2 for m^2),
# not a choice: its stress would be off by as much, and so would the servo's force target.
LID_AREA_FACTOR = 10.0


def lab_run_length(cfg: dict) -> tuple[str, float] | None:
    """(what bounds it, seconds): the longest a lab test's stages run, their max_time added up;
    None for another scenario."""
    scenario = cfg.get("scenario")
    if scenario in ("oedometer", "isotropic"):
        return "the stages' max_time added up", math.fsum(s["max_time"] for s in cfg["stages"])
    tables = STAGE_TABLES.get(scenario)
    if tables is None:
        return None
    return " + ".join(f"{t}.max_time" for t in tables), math.fsum(cfg[t]["max_time"] for t in tables)


def lid_area_problem(area: float | None, section: float, where: str) -> str | None:
    """The problem of an oedometer's `lid.area` against the box's section (`where` says whose),
    None where it is not set or within LID_AREA_FACTOR of it."""
    if area is None or section / LID_AREA_FACTOR <= area <= section * LID_AREA_FACTOR:
        return None
    return (f"lid.area: {_short(area)} m^2 is {_short(area / section)} times the box's section ({_short(section)} "
            f"m^2, {where}); give it in m^2, within a factor {LID_AREA_FACTOR:g} of the section, or leave it out "
            "(the section)")  # fmt: skip


def sample_problem(scenario: str, n_grains: int, key: str) -> str | None:
    """A lab sample too small to test: fewer than MIN_GRAINS grains (`key` says where the count
    comes from)."""
    if n_grains >= MIN_GRAINS:
        return None
    return (f"{key}: {_a(scenario)} sample of {n_grains} grain{'s' if n_grains != 1 else ''} measures its walls, "
            f"not a granular material; at least {MIN_GRAINS} grains, and {FEW_GRAINS} or more for measures worth "
            "reporting")  # fmt: skip


def few_grains_note(scenario: str, n_grains: int) -> str | None:
    """A warning's line for a sample below FEW_GRAINS, None otherwise."""
    if n_grains >= FEW_GRAINS:
        return None
    return (f"{_a(scenario)} sample of {n_grains} grains: its measures are a few contacts' and scatter from "
            f"seed to seed; {FEW_GRAINS} grains or more for a measure worth reporting")  # fmt: skip


def _short(v: float) -> str:
    """Three digits, as a bound is written (1.6e-5, not 1.6e-05)."""
    return _num(float(f"{v:.3g}"))


def _a(scenario: str) -> str:
    return f"{'an' if scenario[0] in 'aeiou' else 'a'} {scenario.replace('_', ' ')}"


def check_lab_rules(cfg: dict) -> None:
    """The rules of a lab test's config (nothing for another scenario)."""
    if cfg.get("scenario") not in LAB:
        return
    problem = None
    if not cfg["initial_state"]:  # a pack read from a file is checked when it is read
        pack = cfg["pack"]
        section = pack["box"]["width"] * pack["box"]["depth"]
        problem = sample_problem(cfg["scenario"], pack["n_grains"], "pack.n_grains")
        if cfg["scenario"] == "oedometer":
            problem = problem or lid_area_problem(cfg["lid"]["area"], section,
                                                  "pack.box.width x pack.box.depth")  # fmt: skip
    if problem:
        raise ConfigError(problem)
