"""Scenario names (a contract: `scenario = "..."` in the config) -> schema and run function."""

from __future__ import annotations

from importlib import import_module
from importlib.resources import files

from ..config import ConfigError, apply_schema
from ..config.tables import check_rules

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
                 "triaxial-flexible": "triaxial-flexible.toml", "direct-shear": "direct-shear.toml",
                 "isotropic": "isotropic.toml"})


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
    cfg = apply_schema(raw, module.SCHEMA)
    check_rules(cfg)
    return cfg, module


def example_text(name: str) -> str:
    if name not in EXAMPLES:
        raise ConfigError(f"example: unknown example {name!r} (known: {', '.join(EXAMPLES)})")
    return files("vemdem").joinpath("examples", EXAMPLES[name]).read_text()


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
