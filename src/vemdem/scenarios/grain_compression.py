"""`scenario = "grain_compression"`: one grain squeezed between two rigid frictionless plates.

Quasi-static: one Newton solve of static equilibrium per load step. The plates are roller
conditions on the vertices that touch them (within 1e-6 of the grain's height): the bottom
ones keep u_z = 0, the top ones move down by strain * h0. `mode = "confined"` also holds the
lateral displacement of every vertex at zero. In `uniaxial` mode the remaining rigid modes
(translation in x, y and rotation about z) are removed by pinning x, y of one plate vertex A
and y of the plate vertex B farthest from it, after turning the grain about z so that B - A
lies along x: a homogeneous lateral expansion about A then meets no reaction.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ..analysis.homogeneous import nominal_axial_stress
from ..config import tables
from ..config.build import make_grain, material_from, vem_options_from
from ..io.results import CsvLog, write_json
from ..io.vtk import PvdSeries
from ..model.bodies import VemBodies
from .plates import PlateSetup, body_assembler, compress, prepare_grain

SCHEMA = tables.GRAIN_COMPRESSION


def run(cfg: dict, out_dir: Path, base_dir: Path | None = None, progress=None) -> dict:
    t_start = time.perf_counter()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    mode = cfg["loading"]["mode"]
    grain = make_grain(cfg["grain"], base_dir, truncate=True)
    grain, pins = prepare_grain(grain, mode)
    material = material_from(cfg)
    bodies = VemBodies([grain], material, vem_options_from(cfg))
    X = bodies.reference
    plates = PlateSetup(X, mode, pins)

    steps = cfg["loading"]["steps"]
    strains = np.linspace(0.0, cfg["loading"]["max_strain"], steps + 1)
    force_scale = material.E * grain.volume ** (2 / 3)
    vtk = PvdSeries(out_dir, "grain") if cfg["output"]["vtk"] else None
    with CsvLog(out_dir / "force_strain.csv", ["strain", "force"]) as log:
        log.write(0.0, 0.0)
        _write_frame(vtk, 0.0, bodies, grain, X.ravel())

        def on_step(k, strain, x, force, result):
            log.write(strain, force)
            _write_frame(vtk, strain, bodies, grain, x)
            if progress:
                progress(k, steps, f"strain {strain:.3f} force {force:.4g} N ({result.iterations} Newton it.)")

        loaded, iterations = compress(
            body_assembler(bodies), X, plates, strains[1:], force_scale,
            rtol=cfg["solver"]["rtol"], max_iter=cfg["solver"]["max_iterations"], on_step=on_step,
        )  # fmt: skip
    forces = [0.0] + loaded.tolist()
    summary = _summary(mode, grain, bodies, plates, strains, forces, iterations)
    if cfg["grain"]["shape"] == "cube" and not cfg["grain"]["file"]:
        area = cfg["grain"]["size"] ** 2
        closed = area * nominal_axial_stress(strains, material.mu, material.kappa, mode)
        summary["closed_form_max_force"] = float(closed.max())
    else:
        closed = None
    if cfg["output"]["plot"]:
        from ..analysis.plots import plot_compression_curve

        plot_compression_curve(out_dir / "force_strain.png", strains, np.array(forces), closed, mode, grain.name)
    summary["wall_seconds"] = time.perf_counter() - t_start
    write_json(out_dir / "summary.json", summary)
    return summary


def _summary(mode, grain, bodies, plates, strains, forces, iterations) -> dict:
    """summary.json's figures of the loading (the wall time is added at the end)."""
    return {
        "scenario": "grain_compression",
        "mode": mode,
        "n_vertices": grain.n_vertices,
        "n_faces": len(grain.faces),
        "n_steps": len(strains) - 1,
        "n_newton_iterations": iterations,
        "max_force": float(max(forces)),
        "final_force": float(forces[-1]),
        "max_strain": float(strains[-1]),
        "grain_volume": grain.volume,
        "grain_height": float(plates.height),
        "n_top_vertices": int(len(plates.top)),
        "n_bottom_vertices": int(len(plates.bottom)),
        "submesh": bodies.elements.submeshes[0].method,
        "beta_internal": bodies.elements.options.beta_internal,
    }


def _write_frame(vtk, strain, bodies, grain, xflat):
    if vtk is None:
        return
    x = xflat.reshape(-1, 3)
    sigma = bodies.cauchy_stress(x)[0]
    n_faces = len(grain.faces)
    vtk.write(
        strain,
        x,
        grain.faces,
        point_data={"displacement": x - bodies.reference},
        cell_data={
            "cauchy_stress": np.repeat(sigma.reshape(1, 9), n_faces, axis=0),
            "von_mises": np.full(n_faces, _von_mises(sigma)),
        },
    )


def _von_mises(s: np.ndarray) -> float:
    dev = s - np.trace(s) / 3 * np.eye(3)
    return float(np.sqrt(1.5 * np.sum(dev * dev)))
