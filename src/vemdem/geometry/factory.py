"""Grains from config tables: `shape = "cube" | "tetrahedron" | "l-prism" | "random"` or `file = ...`."""

from __future__ import annotations

from pathlib import Path

from ..config import ConfigError, Field, open_unit_interval, positive
from .io import load_surface
from .polyhedron import GeometryError, Polyhedron
from .shapes import cube, l_prism, sand_grain, tetrahedron

SHAPES = ("cube", "tetrahedron", "l-prism", "random", "file")


def _roughness(v):
    return None if 0 <= v < 0.5 else "must be in [0, 0.5)"


def _axis_ratio(v):
    return None if 0 < v <= 1 else "must be in (0, 1]"


def _vertex_count(v):
    return None if v >= 4 else "must be >= 4"


GRAIN_SCHEMA = {
    "shape": Field(SHAPES, "cube", doc="grain shape; 'file' needs the key file"),
    "file": Field(str, "", doc="surface file (STL/OBJ/PLY), relative to the config file"),
    "size": Field(float, 1.45e-3, positive, "cube edge, or equivalent diameter of other shapes (m)"),
    "vertices": Field(int, 30, _vertex_count, "random: number of vertices"),
    "elongation": Field(float, 0.8, _axis_ratio, "random: intermediate/long axis"),
    "flatness": Field(float, 0.8, _axis_ratio, "random: short/intermediate axis"),
    "roughness": Field(float, 0.15, _roughness, "random: relative radial perturbation"),
    "truncate": Field(float, 0.7, open_unit_interval, "random: flat ends at |z| <= truncate * c (compression)"),
    "seed": Field(int, 0, doc="random: seed; same seed, same grain"),
}


def make_grain(spec: dict, base_dir: Path | None = None, truncate: bool = False) -> Polyhedron:
    """Build a grain from a checked `GRAIN_SCHEMA` table. Geometry errors become ConfigErrors."""
    shape = "file" if spec.get("file") else spec["shape"]
    try:
        if shape == "file":
            if not spec.get("file"):
                raise ConfigError("grain.file: required when shape = 'file'")
            path = Path(spec["file"])
            if base_dir is not None and not path.is_absolute():
                path = base_dir / path
            return load_surface(path)
        if shape == "cube":
            return cube(spec["size"])
        if shape == "tetrahedron":
            t = tetrahedron()
            return t.translated(-t.centroid).scaled(spec["size"] / (6 * t.volume / 3.141592653589793) ** (1 / 3))
        if shape == "l-prism":
            return l_prism(spec["size"], 0.5 * spec["size"])
        return sand_grain(
            size=spec["size"],
            n_vertices=spec["vertices"],
            elongation=spec["elongation"],
            flatness=spec["flatness"],
            roughness=spec["roughness"],
            seed=spec["seed"],
            truncate=spec["truncate"] if truncate else None,
        )
    except GeometryError as exc:
        raise ConfigError(f"grain: {exc}") from None
