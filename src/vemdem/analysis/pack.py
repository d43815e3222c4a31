"""Measures of a settled pack, from grain volumes and centroids (reads states, runs nothing)."""

from __future__ import annotations

import numpy as np

from ..geometry.packing import centre_of_volume_height


def pack_measures(volume: np.ndarray, centroids: np.ndarray, box: tuple[float, float], floor: float = 0.0) -> dict:
    """pack_height: twice the height of the centre of volume above the floor (as
    geometry.packing.pack_height, which explains why); packing_fraction: grain volume over
    box x pack_height."""
    height = centre_of_volume_height(volume, centroids[:, 2] - floor)
    return {"pack_height": height, "packing_fraction": float(np.sum(volume)) / (box[0] * box[1] * height)}
