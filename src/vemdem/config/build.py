"""A checked config -> typed options and a scene. Mass scaling is applied here, once, and recorded
in the scene (`Scene.mass_scaling`), from where every summary reports it."""

from __future__ import annotations

import warnings
from dataclasses import fields, replace
from pathlib import Path

import numpy as np

from ..contact.defaults import GAP_FRACTION, default_contact_laws, material_contact_laws
from ..contact.walls import Motion, PlaneWall, ServoMotion
from ..geometry.overlap import first_overlap
from ..geometry.polyhedron import GeometryError, Polyhedron
from ..geometry.shapes import cube, l_prism, rotation_matrix, sand_grain, tetrahedron
from ..io.surfaces import load_mesh_wall, load_surface
from ..model.scene import Scene
from ..model.selective import auto_selective_scaling
from ..solver.api import SolverOptions
from ..vem.element import VemOptions
from ..vem.material import Material
from .schema import ConfigError


def resolve_path(name: str, base_dir) -> Path:
    """A file named in a config: relative to the config file's folder (THE rule for every key)."""
    path = Path(name)
    return path if path.is_absolute() or base_dir is None else Path(base_dir) / path


def material_from(cfg: dict, mass_scaling: float = 1.0) -> Material:
    """The `[material]` table as a Material, its density multiplied by the mass scaling."""
    m = cfg["material"]
    return Material(m["E"], m["nu"], m["density"] * mass_scaling)


def vem_options_from(cfg: dict) -> VemOptions:
    """The `[vem]` table as VemOptions."""
    v = cfg["vem"]
    return VemOptions(v["beta_internal"], v["beta_mass"], v["beta_load"], v["submesh"])


def solver_options_from(cfg: dict) -> SolverOptions:
    """The `[solver]` table as SolverOptions."""
    s = cfg["solver"]
    # every key SolverOptions has (mass_scaling is the scene's: scene_from)
    return SolverOptions(**{f.name: s[f.name] for f in fields(SolverOptions)})


# ---------------------------------------------------------------------------- grains
def make_grain(spec: dict, base_dir=None, truncate: bool = False, where: str = "grain") -> Polyhedron:
    """A grain from a checked grain table (`shape` or `file`); geometry errors become ConfigErrors
    naming the table (`where`: "grain", or "grains[k]" in a scene)."""
    if spec.get("file") and spec["shape"] not in ("file", "cube"):  # "cube" is the default: not a choice
        raise ConfigError(f"{where}.shape: {spec['shape']!r} and a file ({spec['file']}) are given; a grain is one "
                          "or the other (shape = 'file' reads the file)")  # fmt: skip
    shape = "file" if spec.get("file") else spec["shape"]
    try:
        if shape == "file":
            if not spec.get("file"):
                raise ConfigError(f"{where}.file: required when shape = 'file'")
            return load_surface(resolve_path(spec["file"], base_dir))
        if shape == "cube":
            return cube(spec["size"])
        if shape == "tetrahedron":
            t = tetrahedron()
            return t.translated(-t.centroid).scaled(spec["size"] / (6 * t.volume / np.pi) ** (1 / 3))
        if shape == "l-prism":
            return l_prism(spec["size"], 0.5 * spec["size"])
        return sand_grain(size=spec["size"], n_vertices=spec["vertices"], elongation=spec["elongation"],
                          flatness=spec["flatness"], roughness=spec["roughness"], seed=spec["seed"],
                          truncate=spec["truncate"] if truncate else None)  # fmt: skip
    except GeometryError as exc:
        raise ConfigError(f"{where}: {exc}") from None


def place_grain(spec: dict, base_dir=None, where: str = "grain") -> Polyhedron:
    """A `[[grains]]` table's grain, rotated about its centroid and moved to its position."""
    grain = make_grain(spec, base_dir, where=where)
    grain = grain.translated(-grain.centroid).rotated(rotation_matrix(spec["rotation"]))
    return grain.translated(spec["position"])


# ---------------------------------------------------------------------------- walls
def _motion(spec: dict, where: str) -> Motion:
    try:
        return Motion(tuple(spec["times"]), tuple(tuple(d) for d in spec["displacements"]),
                      np.inf if spec["removed_at"] is None else spec["removed_at"])  # fmt: skip
    except (ValueError, TypeError) as exc:
        raise ConfigError(f"{where}: {exc}") from None


def _direction(normal: list, key: str) -> np.ndarray:
    """A wall's normal scaled to its largest component: any finite non-zero vector gives the same plane
    (its norm, squared on the way, overflowed to inf for a component of 1e300 and underflowed to 0 for
    one of 1e-300, and the wall lost its normal)."""
    n = np.array(normal, float)
    largest = np.max(np.abs(n))
    if largest == 0:
        raise ConfigError(f"{key}: must not be the zero vector")
    return n / largest


def _servo_motion(spec: dict, where: str) -> ServoMotion | None:
    """A servo wall's steered motion along its `normal` (None for a wall without a servo), after the
    checks a servo's keys need together."""
    servo = spec.get("servo")
    if not servo or not servo["stress"]:
        return None
    if len(servo["stress"]) != len(servo["times"]):
        raise ConfigError(f"{where}.servo.stress: one stress per servo.times ({len(servo['times'])}), "
                          f"got {len(servo['stress'])}")  # fmt: skip
    if np.any(np.diff(servo["times"]) <= 0):
        raise ConfigError(f"{where}.servo.times: must increase")
    for key in ("area", "max_speed"):
        if servo[key] is None:
            raise ConfigError(f"{where}.servo.{key}: required for a servo wall")
    if len(spec["times"]) > 1 or np.any(spec["displacements"]) or spec["removed_at"] is not None:
        raise ConfigError(f"{where}: a servo wall's motion is steered by its target stress; remove its "
                          "times, displacements and removed_at")  # fmt: skip
    return ServoMotion(tuple(_direction(spec["normal"], f"{where}.normal")))


def build_walls(specs: list, base_dir=None):
    """The `[[walls]]` tables as plane and mesh walls with their prescribed or steered motion: (planes, meshes)."""
    planes, meshes = [], []
    for i, spec in enumerate(specs):
        where = f"walls[{i}]"
        name = spec["name"] or f"wall {i}"
        motion = _servo_motion(spec, where) or _motion(spec, where)
        if spec["type"] == "plane":
            normal = _direction(spec["normal"], f"{where}.normal")
            planes.append(PlaneWall(np.array(spec["point"], float), normal, motion, name,
                                    frictionless=spec["frictionless"]))  # fmt: skip
            continue
        if not spec["file"]:
            raise ConfigError(f"{where}.file: required for a mesh wall")
        try:
            wall = load_mesh_wall(resolve_path(spec["file"], base_dir), motion, flip=spec["flip"])
        except (GeometryError, ValueError) as exc:
            raise ConfigError(f"{where}.file: {exc}") from None
        meshes.append(replace(wall, name=spec["name"] or wall.name, frictionless=spec["frictionless"]))
    return planes, meshes


# ---------------------------------------------------------------------------- the scene
def activation_gap_from(cfg: dict, size: float) -> float:
    """The contact layer's thickness scene_from gives grains of mean equivalent diameter `size`:
    for walls placed before the scene is built."""
    return cfg["contact"]["activation_gap"] or GAP_FRACTION * size


def contact_laws_from(cfg: dict, size: float, material) -> tuple:
    """The `[contact]` table's interface and friction laws for grains of mean equivalent diameter
    `size`: the material's law (contact.defaults.material_contact_laws) where `law = "material"`
    and no reference_force is given, the weight's (default_contact_laws, at the given reference
    force where there is one) otherwise."""
    contact = cfg["contact"]
    overrides = {k: v for k, v in contact.items() if k not in ("mu_s", "mu_d", "law") and v is not None}
    material_law = contact.get("law", "weight") == "material" and contact["reference_force"] is None
    try:
        if material_law:
            return material_contact_laws(size, material.E, material.nu, contact["mu_s"], contact["mu_d"], **overrides)
        if "layer_modulus" in overrides:
            raise ValueError("contact.layer_modulus: only the material's law has a layer modulus (law = "
                             "\"material\", without a reference_force)")  # fmt: skip
        return default_contact_laws(size, material.E, material.density, float(np.linalg.norm(cfg["gravity"])),
                                    contact["mu_s"], contact["mu_d"], **overrides)  # fmt: skip
    except ValueError as exc:
        message = str(exc)
        raise ConfigError(message if message.startswith(("contact.", "material.")) else f"contact: {message}") from None


def scene_from(grains: list, cfg: dict, planes: list, meshes: list = (), quasi_static: tuple | None = None) -> Scene:
    """A scene of placed grains and walls with the config's material, vem, contact and solver
    (mass scaling) settings; the contact laws' scales come from the mean grain size.
    `quasi_static` (I, sigma): a laboratory test's drive, which sets selective mass scaling's
    loading time (model.selective.auto_selective_scaling)."""
    scaling = cfg["solver"]["mass_scaling"]
    # mass scaling: every mass-born quantity (inertia, weight, contact force scale) grows alike, so
    # rigid-grain kinematics are unchanged and only the elastic (and explicit-step) time scales move
    material = material_from(cfg, scaling)
    size = float(np.mean([np.cbrt(6 * g.volume / np.pi) for g in grains]))
    law, friction = contact_laws_from(cfg, size, material)
    scene = Scene.build(grains, material, law, friction, list(planes), list(meshes), cfg["gravity"],
                        vem_options_from(cfg), mass_scaling=scaling, grain_model=cfg["model"]["grains"])  # fmt: skip
    scale_deformation_modes(scene, cfg["solver"]["selective_mass_scaling"], cfg["solver"]["integrator"], quasi_static)
    if scaling > 1.0:
        warn_if_mass_scaling_shows(scene)
    return scene


class SelectiveMassScalingNotice(UserWarning):
    """The explicit step runs with selectively scaled grains: a model change, named in the log."""


def scale_deformation_modes(scene: Scene, requested, integrator: str, quasi_static: tuple | None = None) -> None:
    """[solver] selective_mass_scaling: "auto" (model.selective, recorded in the scene for
    summary.json) or lambda; flexible grains on the explicit step only ("auto" is 0 elsewhere)."""
    scene.selective_auto = None
    if scene.bodies.kind != "flexible" or integrator != "explicit" or requested == 0:
        return
    lam = requested
    if requested == "auto":
        scene.selective_auto = auto_selective_scaling(scene, quasi_static)
        lam = scene.selective_auto["lambda"]
    scene.bodies.scale_deformation_inertia(lam)
    how = f' ("auto": bound by the {scene.selective_auto["bound"]})' if requested == "auto" else ""
    warnings.warn(SelectiveMassScalingNotice(
        f"selective mass scaling lambda = {lam:.3g}{how}: the grains' deformation modes carry {1 + lam:.3g} times "
        f"their inertia, translations and rotations their real one; their own step is now "
        f"{float(scene.bodies.critical_steps().min()):.3g} s (docs/selective-mass-scaling.md)"), stacklevel=2)


class MassScalingWarning(UserWarning):
    """The mass scaling is large enough to change collisions (Scene.vibration_contact_ratio)."""


# Largest grain vibration period, as a share of the contact duration, under which mass scaling
# leaves a head-on impact within 7 % of its real restitution: 0.260 at scaling 1 and 1e3 (ratios
# 0.002, 0.05), 0.267 at 1e4 (0.16), 0.279 at 2.4e4 (0.25), 0.35 at 1e5 (0.51), 0.68 at 1e6 (1.6);
# verification/impact.py, docs/results.md.
NEUTRAL_RATIO = 0.25


def warn_if_mass_scaling_shows(scene: Scene) -> None:
    """Warn in one line when the mass scaling makes collisions rebound more than real grains do."""
    # selective scaling's share left out: it leaves collisions as they are (docs/selective-mass-scaling.md)
    ratio = scene.vibration_contact_ratio() / np.sqrt(1.0 + scene.selective_mass_scaling)
    if ratio > NEUTRAL_RATIO:
        neutral = scene.mass_scaling * (NEUTRAL_RATIO / ratio) ** 2
        warnings.warn(MassScalingWarning(
            f"solver.mass_scaling = {scene.mass_scaling:g} is not neutral: a grain's slowest vibration lasts "
            f"{ratio:.2g} of a contact (above {NEUTRAL_RATIO:g}), so collisions rebound more than real grains do; "
            f"scalings up to {neutral:.2g} are (docs/results.md, mass scaling)"), stacklevel=2)  # fmt: skip


def _behind_mesh(centroids: np.ndarray, wall, chunk: int = 64) -> np.ndarray:
    """For each point, whether it lies behind the mesh wall: on the back side of the face whose plane
    is nearest among the faces it projects inside of (points that project inside none: False). The
    faces' normals face the grains (MeshWall), so a grain behind is misplaced or its file's normals
    face away (`flip`)."""
    v = wall.vertices_at(0.0)
    a, b, c = (v[wall.faces[:, i]] for i in range(3))
    e1, e2 = b - a, c - a
    n = np.cross(e1, e2)
    n2 = np.einsum("fi,fi->f", n, n)
    out = np.zeros(len(centroids), bool)
    for lo in range(0, len(centroids), chunk):  # points x faces at a time, not all at once
        r = centroids[lo : lo + chunk, None, :] - a[None]
        # barycentric coordinates of the projection onto each face's plane
        u = np.einsum("pfi,fi->pf", np.cross(r, e2[None]), n) / n2
        w = np.einsum("pfi,fi->pf", np.cross(e1[None], r), n) / n2
        inside = (u >= 0) & (w >= 0) & (u + w <= 1)
        signed = np.einsum("pfi,fi->pf", r, n) / np.sqrt(n2)
        distance = np.where(inside, np.abs(signed), np.inf)
        nearest = np.argmin(distance, axis=1)
        rows = np.arange(len(nearest))
        out[lo : lo + chunk] = np.isfinite(distance[rows, nearest]) & (signed[rows, nearest] < 0.0)
    return out


def check_placement(grains: list[Polyhedron], planes: list, meshes: list = ()) -> None:
    """Grains must start apart from each other and in front of every wall: an overlap has no
    contact pair (the barrier acts across a positive gap) and would fail later, misleadingly. A grain
    behind a mesh wall is named with the wall's name (its file)."""
    pair = first_overlap(grains)
    if pair is not None:
        a, b = pair
        raise ConfigError(f"grains[{a}] and grains[{b}]: they overlap at the start (a vertex of one is inside the "
                          "other); move them apart")  # fmt: skip
    for k, plane in enumerate(planes):
        if not plane.motion.active(0.0):
            continue
        for g, grain in enumerate(grains):
            depth = float(np.min((grain.vertices - plane.point_at(0.0)) @ plane.normal))
            if depth <= 0.0:
                raise ConfigError(f"grains[{g}]: it starts {-depth:.3g} m behind walls[{k}] ({plane.name!r}); "
                                  "place it in front of the wall")  # fmt: skip
    centroids = np.array([grain.vertices.mean(axis=0) for grain in grains])
    for mesh in meshes:
        if not mesh.motion.active(0.0) or not len(grains):
            continue
        behind = np.flatnonzero(_behind_mesh(centroids, mesh))
        if len(behind):
            raise ConfigError(f"grains[{int(behind[0])}]: it starts behind the mesh wall {mesh.name!r}: place it in "
                              "front of the wall, or set flip = true on that wall if the file's normals face away "
                              "from the grains")  # fmt: skip


def build_scene(cfg: dict, base_dir=None) -> tuple[Scene, np.ndarray]:
    """The `scene` scenario's grains, walls and initial vertex velocities."""
    grains = [place_grain(g, base_dir, f"grains[{k}]") for k, g in enumerate(cfg["grains"])]
    planes, meshes = build_walls(cfg["walls"], base_dir)
    check_placement(grains, planes, meshes)
    scene = scene_from(grains, cfg, planes, meshes)
    v0 = np.vstack([np.tile(g["velocity"], (grain.n_vertices, 1)) for g, grain in zip(cfg["grains"], grains)])
    return scene, v0
