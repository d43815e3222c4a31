"""The cross-field rules: the checks that tie several keys of a config together, run after each
key passed its own (scenarios/registry.checked_config). Each raises a ConfigError naming the key."""

from __future__ import annotations

from .checks import MAX_FRAMES, NEWTON_ITERATIONS
from .lab_rules import check_lab_rules, lab_run_length
from .schema import ConfigError


def _check_selective_scaling(cfg: dict) -> None:
    """A number for selective mass scaling needs flexible grains on the explicit step ("auto" is 0
    elsewhere: nothing to scale)."""
    solver, model = cfg.get("solver"), cfg.get("model")
    if not (isinstance(solver, dict) and isinstance(solver.get("selective_mass_scaling"), float)):
        return
    if solver["selective_mass_scaling"] > 0 and solver.get("integrator") != "explicit":
        raise ConfigError("solver.selective_mass_scaling: scales the explicit step's mass; set solver.integrator = "
                          '"explicit" (or "auto" or 0)')  # fmt: skip
    if solver["selective_mass_scaling"] > 0 and isinstance(model, dict) and model.get("grains") == "rigid":
        raise ConfigError('solver.selective_mass_scaling: rigid grains have no deformation modes to scale ("auto" or 0)')


def _check_grain_files(grains: dict, where: str) -> None:
    """A pack's grains from files: shape = 'file' and its files go together, one fraction per file."""
    files, fractions = grains.get("files") or [], grains.get("fractions") or []
    if grains.get("shape") == "file" and not files:
        raise ConfigError(f"{where}.files: required when {where}.shape = 'file' (a list of surface files)")
    if files and grains.get("shape") != "file":
        raise ConfigError(f"{where}.files: given with {where}.shape = {grains.get('shape')!r}; "
                          "set shape = 'file' to build the grains from them")  # fmt: skip
    if fractions and len(fractions) != len(files):
        raise ConfigError(f"{where}.fractions: one per file in {where}.files ({len(files)}), got {len(fractions)}")


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
    if isinstance(pack, dict) and isinstance(pack.get("grains"), dict):
        _check_grain_files(pack["grains"], "pack.grains")
    if cfg.get("scenario") == "pack" and isinstance(cfg.get("grains"), dict):
        _check_grain_files(cfg["grains"], "grains")
    settle = cfg.get("settle")
    if isinstance(settle, dict) and "min_time" in settle and "max_time" in settle:
        if settle["min_time"] > settle["max_time"]:
            raise ConfigError(f"settle.min_time: must not exceed settle.max_time ({settle['max_time']:g} s), "
                              f"got {settle['min_time']:g}")  # fmt: skip
    solver = cfg.get("solver")
    _check_selective_scaling(cfg)
    if isinstance(solver, dict) and "dt_min" in solver and "dt_max" in solver:
        if solver["dt_min"] > solver["dt_max"]:
            raise ConfigError(f"solver.dt_min: must not exceed solver.dt_max ({solver['dt_max']:g}), got {solver['dt_min']:g}")
        if solver["dt"] < solver["dt_min"]:
            raise ConfigError(f"solver.dt: must not be below solver.dt_min ({solver['dt_min']:g}), got {solver['dt']:g}")
    if isinstance(solver, dict) and "easy_iterations" in solver and "max_iterations" in solver:
        limit = NEWTON_ITERATIONS if solver["max_iterations"] is None else solver["max_iterations"]
        if solver["easy_iterations"] > limit:
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
    check_lab_rules(cfg)
    lid = cfg.get("lid")
    if isinstance(lid, dict) and "end" in lid and lid["end"] >= lid["start"]:
        raise ConfigError(f"lid.end: must be below lid.start ({lid['start']:g} m), got {lid['end']:g}")


def _check_frames(cfg: dict) -> None:
    every = cfg.get("output", {}).get("every")
    if every is None:
        return
    # a lab test's [settle] is its pack's re-equilibration, not the test: its stages bound it
    lab = lab_run_length(cfg)
    duration = lab[1] if lab else cfg.get("duration") or cfg.get("settle", {}).get("max_time")
    if duration is None:
        return
    frames = duration / every
    if frames > MAX_FRAMES:
        raise ConfigError(f"output.every: {every:g} s writes {frames:.3g} frames over {duration:g} s "
                          f"(at most {MAX_FRAMES:,}); choose a larger interval")  # fmt: skip


# the scenarios that run for settle.max_time (the others add a tilt, a lift or load stages to it;
# a lab test's stages bound its run: lab_rules.lab_run_length)
SETTLE_IS_DURATION = ("pack", "pile_collapse")


def _run_length(cfg: dict) -> tuple[str, float] | None:
    """(key, seconds) of the simulated time a run lasts where one key fixes it, else None."""
    if "duration" in cfg:
        return "duration", cfg["duration"]
    if cfg.get("scenario") in SETTLE_IS_DURATION and "max_time" in cfg.get("settle", {}):
        return "settle.max_time", cfg["settle"]["max_time"]
    return lab_run_length(cfg)


def _check_every_within_run(cfg: dict) -> None:
    """A frame interval longer than the run: the loop would cut its only frame to the run's end, so
    the interval asked for is never the one written (a slip of units or of keys). A lab test's
    stages stop it only at frames: an interval longer than all of them ran a 4-second oedometer
    for 1,000 seconds of simulated time, or wrote none of its stages' frames."""
    every = cfg.get("output", {}).get("every")
    length = _run_length(cfg)
    if every is not None and length is not None and every > length[1]:
        key, seconds = length
        raise ConfigError(f"output.every: must not exceed {key} ({seconds:g} s), got {every:g}")


def check_given(raw: dict) -> None:
    """Rules on what a config writes out, not on the values it ends with (run after the schema,
    so the tables are tables): keys that would be ignored without a word."""
    pack = raw.get("pack")
    if raw.get("initial_state") and isinstance(pack, dict) and pack:
        # the run starts from the file: a [pack] beside it (an example's, say) was never settled
        raise ConfigError("initial_state: given beside a [pack] table, which the run would ignore (it starts from "
                          "initial_state); delete the [pack] table, or initial_state to settle that pack")  # fmt: skip
    for i, wall in enumerate(raw.get("walls") or []):
        servo = wall.get("servo") if isinstance(wall, dict) else None
        if isinstance(servo, dict) and not servo.get("stress") and set(servo) - {"stress"}:
            given = ", ".join(f"servo.{k}" for k in sorted(set(servo) - {"stress"}))
            raise ConfigError(f"walls[{i}].servo.stress: empty or not given, so the wall has no servo and its {given} "
                              "would be ignored; give the target stress(es) in Pa, or delete the [walls.servo] "
                              "table")  # fmt: skip
