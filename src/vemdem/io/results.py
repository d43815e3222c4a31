"""Small result writers shared by scenarios: CSV rows written as they come, JSON summaries."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np


class CsvLog:
    """A CSV file with a fixed header, flushed after every row so an interrupted run keeps
    everything it computed."""

    def __init__(self, path: Path, header: list[str], mode: str = "w"):
        """mode "w" starts the file with its header; "a" appends to one (a resumed run)."""
        self.path = Path(path)
        self._fh = self.path.open(mode, newline="")
        self._writer = csv.writer(self._fh, lineterminator="\n")
        if mode == "w":
            self._writer.writerow(header)
        self._fh.flush()

    def write(self, *row) -> None:
        self._writer.writerow([_plain(v) for v in row])
        self._fh.flush()

    def write_rows(self, rows) -> None:
        self._writer.writerows([[_plain(v) for v in row] for row in rows])
        self._fh.flush()

    def close(self) -> None:
        self._fh.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def wall_force_record(walls_csv: Path, name: str) -> tuple[np.ndarray, np.ndarray]:
    """(times, fz) of the wall called `name` in a run's walls.csv, every frame in file order."""
    times, force = [], []
    with Path(walls_csv).open() as fh:
        for row in csv.DictReader(fh):
            if row["name"] == name:
                times.append(float(row["time"]))
                force.append(float(row["fz"]))
    return np.array(times), np.array(force)


def _plain(v):
    if isinstance(v, (float, np.floating)):
        return repr(float(v))
    if isinstance(v, np.integer):
        return int(v)
    return v


def strict(value):
    """JSON-ready: NumPy values as Python ones, and non-finite floats as null (strict JSON has no
    NaN; the field's `*_error` sibling, where there is one, says why)."""
    if isinstance(value, dict):
        return {k: strict(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [strict(v) for v in value]
    if isinstance(value, np.ndarray):
        return strict(value.tolist())
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not np.isfinite(value):
        return None
    return value


def write_json(path: Path, data: dict) -> None:
    """A summary as strict JSON (allow_nan=False: a NaN that slipped through is an error here,
    not an unreadable file for the user's tools)."""
    Path(path).write_text(json.dumps(strict(data), indent=2, allow_nan=False) + "\n")
