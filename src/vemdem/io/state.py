"""A settled granular state on disk (`DIR/state.npz`), the hand-over between scenarios.

`pack` writes one; `pile_collapse` and `lid_compression` start from it (`initial_state = "path"`).
It holds what rebuilds the scene exactly: every grain's stress-free reference polyhedron (the
grains are deformed in the settled state, and the virtual elements need their undeformed shape),
the current vertex positions and velocities, the friction history of the pairs in contact (each
pair's elastic tangential slip and stick state: without it every contact of a settled heap would
restart from zero slip, and the heap would give a little as the tangential springs reload), and a
JSON record of the box, the grain size and the material and contact settings the pack was made with.
"""

from __future__ import annotations

import json
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..geometry.polyhedron import Polyhedron

# what reading a damaged or foreign .npz raises (np.load, a missing entry, a bad JSON entry): the state
# files here and the checkpoints (driver.checkpoint)
UNREADABLE_NPZ = (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile)

FORMAT = "vemdem-state-1"


@dataclass
class GranularState:
    """A settled pack as a state file holds it: reference shapes, positions, velocities, metadata, friction."""
    grains: list[Polyhedron]  # stress-free reference shapes, in the frame they were built in
    x: np.ndarray  # (N, 3) current vertex positions, grains in order
    v: np.ndarray  # (N, 3) velocities
    meta: dict  # box, floor, centre, grain_size, material, ... (JSON)
    friction: dict | None = None  # keys, c_prev, gt, stick of the contact history; None in older files


FRICTION_FIELDS = ("keys", "c_prev", "gt", "stick")


def friction_arrays(history) -> dict:
    """The arrays of a contact history (contact.model.ContactHistory), as save_state stores them."""
    return {name: np.asarray(getattr(history, name)) for name in FRICTION_FIELDS}


class StateFileError(ValueError):
    """A state file that is missing, of another format or damaged; str(e) names the file."""
    pass


def save_state(path: Path, grains: list[Polyhedron], x: np.ndarray, v: np.ndarray, meta: dict,
               friction: dict | None = None) -> None:  # fmt: skip
    """Write a granular state to `path` (npz, atomically), for another scenario to start from."""
    extra = {f"friction_{k}": friction[k] for k in FRICTION_FIELDS} if friction is not None else {}
    n_v = np.array([g.n_vertices for g in grains])
    n_f = np.array([len(g.faces) for g in grains])
    tmp = Path(path).with_suffix(".tmp.npz")
    np.savez_compressed(tmp, format=FORMAT, vertices=np.vstack([g.vertices for g in grains]),
                        faces=np.vstack([g.faces for g in grains]), vertex_count=n_v, face_count=n_f,
                        x=np.asarray(x, float), v=np.asarray(v, float), meta=json.dumps(meta), **extra)  # fmt: skip
    tmp.replace(path)  # atomic, like the checkpoints


def load_state(path: Path) -> GranularState:
    """Read a state written by `save_state` (a `pack` run's `state.npz`), checking its format and arrays."""
    path = Path(path)
    if not path.is_file():
        raise StateFileError(f"initial_state: no state file at {path} (run a `pack` scenario first)")
    try:
        d = np.load(path, allow_pickle=False)
        if str(d["format"]) != FORMAT:
            raise StateFileError(f"initial_state: {path} has format {d['format']}, expected {FORMAT}")
        vptr = np.concatenate([[0], np.cumsum(d["vertex_count"])])
        fptr = np.concatenate([[0], np.cumsum(d["face_count"])])
        vertices, faces = d["vertices"], d["faces"]
        grains = [Polyhedron(vertices[vptr[i] : vptr[i + 1]], faces[fptr[i] : fptr[i + 1]], f"grain {i} of {path.name}")
                  for i in range(len(vptr) - 1)]  # fmt: skip
        x, v, meta = d["x"], d["v"], json.loads(str(d["meta"]))
        friction = {k: d[f"friction_{k}"] for k in FRICTION_FIELDS} if "friction_keys" in d.files else None
    except UNREADABLE_NPZ as exc:
        if isinstance(exc, StateFileError):
            raise
        raise StateFileError(f"initial_state: {path} is not a readable vemdem state file ({type(exc).__name__})") from None
    if x.shape != (vptr[-1], 3) or v.shape != x.shape or not np.all(np.isfinite(x)) or not np.all(np.isfinite(v)):
        raise StateFileError(f"initial_state: {path} holds positions that do not match its grains or are not finite")
    if friction is not None and not _friction_consistent(friction):
        raise StateFileError(f"initial_state: {path} holds a friction history whose arrays do not match")
    return GranularState(grains, x, v, meta, friction)


def _friction_consistent(f: dict) -> bool:
    m = len(f["keys"])
    shapes_ok = f["c_prev"].shape == (m, 2) and f["gt"].shape == (m, 3) and f["stick"].shape == (m,)
    finite = np.all(np.isfinite(f["c_prev"])) and np.all(np.isfinite(f["gt"]))
    return bool(shapes_ok and finite and f["keys"].dtype.kind == "i" and np.all(np.diff(f["keys"]) > 0))
