"""Scenario names (a contract: `scenario = "..."` in the config) -> schema and run function."""

from __future__ import annotations

from importlib import import_module
from importlib.resources import files
from pathlib import Path

from ..config import ConfigError, apply_schema
from ..config.rules import check_given, check_rules
from ..config.tables import REMOVED

SCENARIOS = {
    "grain_compression": "vemdem.scenarios.grain_compression",
    "scene": "vemdem.scenarios.scene",
    "pack": "vemdem.scenarios.pack",
    "pile_collapse": "vemdem.scenarios.pile_collapse",
    "lid_compression": "vemdem.scenarios.lid_compression",
    "poured_heap": "vemdem.scenarios.poured_heap",
    "tilting_box": "vemdem.scenarios.tilting_box",
    "oedometer": "vemdem.scenarios.oedometer",
    "triaxial": "vemdem.scenarios.triaxial",
    "direct_shear": "vemdem.scenarios.direct_shear",
    "isotropic": "vemdem.scenarios.isotropic",
}

EXAMPLES = {
    "grain_compression": "grain_compression.toml",
    "drop": "drop.toml",
    "pile": "pile.toml",
    "pile-flexible": "pile-flexible.toml",
    "paper-pack": "paper-pack.toml",
    "paper-collapse-high": "paper-collapse-high.toml",
    "paper-collapse-mid": "paper-collapse-mid.toml",
    "paper-collapse-low": "paper-collapse-low.toml",
    "paper-compression": "paper-compression.toml",
    "poured-heap": "poured-heap.toml",
    "tilting-box": "tilting-box.toml",
}
# the paper's own method at the real density (docs/results.md): the same runs, implicit, no mass scaling
EXAMPLES.update({f"{name}-implicit": f"{name}-implicit.toml" for name in list(EXAMPLES) if name.startswith("paper-")})
# the laboratory tests, at the real density
EXAMPLES.update({"oedometer": "oedometer.toml", "paper-oedometer": "paper-oedometer.toml",
                 "soft-oedometer": "soft-oedometer.toml", "triaxial": "triaxial.toml",
                 "triaxial-flexible": "triaxial-flexible.toml", "triaxial-two-shapes": "triaxial-two-shapes.toml",
                 "direct-shear": "direct-shear.toml",
                 "isotropic": "isotropic.toml"})

# what `vemdem example` prints beside each name: one line each
EXAMPLE_LINES = {
    "grain_compression": "one sand grain squeezed between two frictionless plates: force against strain",
    "drop": "two sand grains dropped into a box: the smallest scene, a template for your own",
    "pile": "the main job: 160 rigid grains collapse into a corner; the heap's angle of repose",
    "pile-flexible": "the main job's collapse with flexible grains, implicit (run pile first)",
    "paper-pack": "the paper's 515-grain pack settling in an 8 mm box (mass scaling 1e6)",
    "paper-collapse-high": "the paper's collapse at mu 0.9/0.8 from paper-pack (run it first)",
    "paper-collapse-mid": "the paper's collapse at mu 0.6/0.5 from paper-pack (run it first)",
    "paper-collapse-low": "the paper's collapse at mu 0.3/0.2 from paper-pack (run it first)",
    "paper-compression": "the paper's lid compression of a 110-grain pack: force against strain",
    "poured-heap": "500 rigid grains flow out from under a rising box onto a disc: a poured heap's angle",
    "tilting-box": "a pack tilts until its surface avalanches: the maximum angle of stability",
    "paper-pack-implicit": "paper-pack at the real density, implicit Newmark (the paper's method)",
    "paper-collapse-high-implicit": "paper-collapse-high at the real density, from paper-pack-implicit",
    "paper-collapse-mid-implicit": "paper-collapse-mid at the real density, from paper-pack-implicit",
    "paper-collapse-low-implicit": "paper-collapse-low at the real density, from paper-pack-implicit",
    "paper-compression-implicit": "paper-compression at the real density, implicit Newmark",
    "oedometer": "60 grains under a servo lid, 25 -> 50 -> 25 -> 50 kPa: K0 and the constrained moduli",
    "paper-oedometer": "the paper's 515-grain pack under a servo lid to 100 kPa and back",
    "soft-oedometer": "rubber-like flexible grains compressed past jamming to 3 MPa",
    "triaxial": "drained triaxial compression of 100 rigid grains at 50 kPa: friction angles, dilatancy",
    "triaxial-flexible": "the triaxial example with flexible grains, implicit (mass scaling 100)",
    "triaxial-two-shapes": "the triaxial example on grains of two STL shapes (write it with --dir)",
    "direct-shear": "a split box of 240 rigid grains sheared at 50 kPa: peak and residual angles",
}

# the files an example's config names beside it (in examples/, written beside the config)
EXAMPLE_FILES = {"triaxial-two-shapes": ("shapes/rounded.stl", "shapes/crushed.stl")}


def example_line(name: str) -> str:
    """An example's one line: EXAMPLE_LINES, else the first comment line of its config."""
    if name in EXAMPLE_LINES:
        return EXAMPLE_LINES[name]
    first = example_text(name).lstrip().splitlines()[0]
    return first.lstrip("#").strip() if first.startswith("#") else ""


def scenario_module(name):
    if not isinstance(name, str):
        raise ConfigError(f"scenario: must be a string, one of {', '.join(SCENARIOS)}; got {name!r}")
    if name not in SCENARIOS:
        raise ConfigError(f"scenario: unknown scenario {name!r} (known: {', '.join(SCENARIOS)})")
    return import_module(SCENARIOS[name])


def checked_config(raw: dict) -> tuple[dict, object]:
    if "scenario" not in raw:
        raise ConfigError("scenario: required key is missing")
    module = scenario_module(raw["scenario"])
    cfg = apply_schema(raw, module.SCHEMA, removed=REMOVED)
    check_rules(cfg)
    check_given(raw)
    return cfg, module


def example_text(name: str) -> str:
    if name not in EXAMPLES:
        raise ConfigError(f"example: unknown example {name!r} (known: {', '.join(EXAMPLES)})")
    return files("vemdem").joinpath("examples", EXAMPLES[name]).read_text()


def write_example(name: str, folder) -> list[Path]:
    """The example's config as folder/NAME.toml, with the files it names beside it; the paths
    written, the config first. A file already there is replaced."""
    text = example_text(name)
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    written = [folder / f"{name}.toml"]
    written[0].write_text(text)
    for item in EXAMPLE_FILES.get(name, ()):
        target = folder / Path(item).name
        target.write_bytes(files("vemdem").joinpath("examples", item).read_bytes())
        written.append(target)
    return written


def pack_stage(raw: dict) -> tuple[str, dict] | None:
    """The pack a scenario settles into DIR/pack before its own stage, as (fingerprint, pack
    config); None when it has no pack stage or starts from `initial_state`. Two cases with the
    same fingerprint settle the same pack, to the bit."""
    cfg, module = checked_config(raw)
    if "pack" not in module.SCHEMA or cfg.get("initial_state"):
        return None
    from . import pack
    from .identity import run_identity

    config = getattr(module, "pack_config_for", pack.pack_config)(cfg)
    return run_identity(config, pack.SCHEMA).fingerprint, config


def settle_pack(config: dict, folder, progress=None) -> None:
    """Run a pack stage on its own (the config from `pack_stage`) into `folder`, where a scenario
    finds it, with the scenario's rules: a pack settled there from the same config is kept, one
    from another config refused (scenarios.pack.settle_stage). Progress lines start "pack: "."""
    from . import pack

    pack.settle_stage(config, folder, progress)
