"""The main job's headline is deterministic: the same config and seed, run twice in one process
(one machine, one thread count), settle the same pack and leave the same heap to the bit.

The README's figure rests on this. What a run rounds with (the BLAS and numba kernels, pinned by
vemdem.portable) is the same for both runs here; across machines and thread counts the README and
docs/errors.md ("Reproducible across machines") say what varies. The main job's own config is
run reduced (six coarse grains, a few hundredths of a second) so that the test takes seconds.
"""

from __future__ import annotations

import json
import math

import numba
import numpy as np
import pytest

from vemdem.scenarios import pile_collapse
from vemdem.scenarios.registry import checked_config, example_text

# what differs between two identical runs by nature: the clock, and where they were written
NOT_COMPARED = {"wall_seconds", "wall_seconds_total", "initial_state", "kernels"}


def reduced_main_job() -> dict:
    import tomllib

    raw = tomllib.loads(example_text("pile"))
    # six coarse grains; the pack counted at rest early (a kinetic threshold 100 times the job's) and
    # a collapse of 0.02 s: a few thousand steps, enough for grains in contact to go chaotic
    raw["pack"].update(n_grains=6, grains={"size": 1.45e-3, "vertices": 12},
                       box={"width": 2.9e-3, "depth": 2.9e-3})  # fmt: skip
    raw["settle"] = {"kinetic_threshold": 0.1, "min_time": 0.01, "max_time": 0.02}
    raw["output"] = {"every": 1e-2, "vtk": False}
    cfg, _ = checked_config(raw)
    return cfg


def _same(a, b) -> bool:
    """Equal to the bit: floats by their bits (nan equals nan), containers element by element."""
    if isinstance(a, float) and isinstance(b, float):
        return a == b or (math.isnan(a) and math.isnan(b))
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    return a == b


def test_the_same_config_and_seed_give_the_same_heap_to_the_bit(tmp_path):
    cfg = reduced_main_job()
    for name in ("first", "second"):
        pile_collapse.run(cfg, tmp_path / name, base_dir=tmp_path)
    summaries = [json.loads((tmp_path / name / "summary.json").read_text()) for name in ("first", "second")]
    assert summaries[0]["n_steps"] > 0
    for key in summaries[0].keys() - NOT_COMPARED:
        assert _same(summaries[0][key], summaries[1][key]), key
    for stage in ("pack/state.npz", "state.npz"):
        first, second = (np.load(tmp_path / name / stage) for name in ("first", "second"))
        assert first.files == second.files
        for array in first.files:
            a, b = first[array], second[array]
            assert a.dtype == b.dtype and a.shape == b.shape, (stage, array)
            assert a.tobytes() == b.tobytes(), (stage, array)  # bitwise, not within a tolerance
    for table in ("history.csv", "grains.csv"):
        assert (tmp_path / "first" / table).read_bytes() == (tmp_path / "second" / table).read_bytes(), table


def _run_bits(cfg, out) -> dict:
    pile_collapse.run(cfg, out, base_dir=out.parent)
    state = np.load(out / "state.npz")
    return {name: state[name].tobytes() for name in state.files}


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2,
                    reason="numba has one thread here (one core, or NUMBA_NUM_THREADS=1)")  # fmt: skip
def test_one_thread_and_two_give_the_same_heap(tmp_path):
    """The parallel kernels compute each pair's or grain's result on its own (fixed chunks, not one
    per thread) and add the results into shared arrays serially, so the thread count changes no
    sum's order: the same bits on one thread and on two."""
    cfg = reduced_main_job()
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = _run_bits(cfg, tmp_path / "one")
        numba.set_num_threads(2)
        two = _run_bits(cfg, tmp_path / "two")
    finally:
        numba.set_num_threads(before)
    assert one == two
