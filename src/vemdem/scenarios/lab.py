"""What the lab tests' scenarios share on the config's side (the tests themselves run in lab/):
the sample and its scene, and the typed options their tables give the room. Their contact law is
the material's, the same at every stress (`[contact] law = "material"`, config.build.contact_laws_from),
or the per-force law at a given `[contact] reference_force`."""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass
from pathlib import Path

from ..config import ConfigError
from ..config.build import scene_from, solver_options_from
from ..config.lab_rules import few_grains_note, sample_problem
from ..lab.run import Output
from ..solver.api import make_integrator
from .pack import initial_state_from


# the inertia number below which a test's measures do not depend on its rate (GDR MiDi 2004;
# da Cruz et al. 2005): the lab tests are driven below it at the density they integrate
QUASI_STATIC = 1e-3


class RateWarning(UserWarning):
    """A lab test driven at an inertia number above QUASI_STATIC: its measures depend on its rate."""


def warn_if_not_quasi_static(cfg: dict) -> None:
    """One warning line where `[servo]` or `[shear]` `inertia_number` (at the density integrated:
    the material's times `solver.mass_scaling`) exceeds QUASI_STATIC."""
    for table in ("servo", "shear"):
        value = cfg.get(table, {}).get("inertia_number")
        if value is not None and value > QUASI_STATIC:
            scaled = cfg["solver"]["mass_scaling"]
            at = f"mass_scaling {scaled:g}: the density integrated" if scaled != 1.0 else "the real density"
            warnings.warn(RateWarning(f"{table}.inertia_number = {value:g} at {at}: above {QUASI_STATIC:g} the test "
                                      "is not quasi-static and its measures depend on its rate"), stacklevel=3)  # fmt: skip


def quasi_static_drive(cfg: dict, stress: float) -> tuple[float, float]:
    """(I, sigma): the largest inertia number the test's servos and drives move at (`servo` and,
    where the test shears, `shear`), at the test's stress: the fastest the test loads its grains,
    which sets selective mass scaling's loading time (model.selective.lab_loading_time)."""
    shear = cfg["shear"]["inertia_number"] if "shear" in cfg else 0.0
    return max(cfg["servo"]["inertia_number"], shear), stress


@dataclass(frozen=True)
class Sample:
    """What a lab test starts from: when it started (`t_start`, for the summary's wall time), its
    folder, the settled pack (`initial`) and the file it came from, the cell around it, the scene
    in that cell and its integrator."""

    t_start: float
    out_dir: Path
    initial: object
    state_path: Path
    cell: object
    scene: object
    integrator: object


def sample_in(cfg: dict, out_dir: Path, base_dir, progress, resume: bool, cell_of, stress: float) -> Sample:
    """The pack (settled into DIR/pack, or `initial_state`), the cell `cell_of(cfg, initial)` around
    it, and the scene of its grains in the cell's walls under the config's contact law (the
    material's, whatever the test's stress; module docstring), its selective mass scaling loaded at
    the rate the test drives it at its `stress` (quasi_static_drive)."""
    t_start, out_dir = time.perf_counter(), Path(out_dir)
    initial, state_path = initial_state_from(cfg, base_dir, out_dir, progress, resume)
    check_sample(cfg, initial)
    warn_if_not_quasi_static(cfg)
    cell = cell_of(cfg, initial)
    scene = scene_from(initial.grains, cfg, cell.walls, cell.meshes, quasi_static_drive(cfg, stress))
    return Sample(t_start, out_dir, initial, state_path, cell, scene, make_integrator(solver_options_from(cfg), scene))


class SmallSampleWarning(UserWarning):
    """A lab sample of fewer grains than config.lab_rules.FEW_GRAINS: its measures are a few contacts'."""


def check_sample(cfg: dict, initial) -> None:
    """The grains a lab test starts from, counted: too few are refused (config.lab_rules; a
    `[pack]` is refused before it settles, a pack read from `initial_state` here), a few tens draw
    one warning line."""
    n, key = len(initial.grains), "initial_state" if cfg["initial_state"] else "pack.n_grains"
    problem = sample_problem(cfg["scenario"], n, key)
    if problem:
        raise ConfigError(problem)
    note = few_grains_note(cfg["scenario"], n)
    if note:
        warnings.warn(SmallSampleWarning(f"{key}: {note}"), stacklevel=3)


def check_every(cfg: dict, length: float, what: str) -> None:
    """`output.every` against the test's own length where its stages end before their max_time (a
    shear that ends at its strain): a longer interval would write no frame of the test. The config's
    rule (config.lab_rules) bounds it by the max_time alone, before a pack is settled."""
    every = cfg["output"]["every"]
    if every > length:
        raise ConfigError(f"output.every: must not exceed the test's length ({length:.3g} s: {what}), "
                          f"got {every:g}")  # fmt: skip


class UnmeasuredWarning(UserWarning):
    """A shear test's friction angle could not be taken from its frames (summary.json says why)."""


def warn_unmeasured(figures: dict) -> None:
    """One warning line where a shear test reports no peak friction angle: the summary's `*_error`
    says why, where a negative angle was once reported beside a consolidation warning alone."""
    for name in ("shear", "peak"):
        if f"{name}_error" in figures:
            warnings.warn(UnmeasuredWarning(f"phi_peak_deg not reported (summary.json {name}_error): "
                                            f"{figures[f'{name}_error']}"), stacklevel=3)  # fmt: skip
            return


def output_of(cfg: dict) -> Output:
    """The `[output]` table as the lab room takes it."""
    return Output(cfg["output"]["every"], cfg["output"]["vtk"])


def servo_options(cfg: dict) -> dict:
    """The `[servo]` table's stage-end tolerances, as lab.path.LoadPath takes them."""
    return {"stress_tolerance": cfg["servo"]["stress_tolerance"],
            "unbalanced_tolerance": cfg["servo"]["unbalanced_tolerance"]}  # fmt: skip
