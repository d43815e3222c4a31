"""A lid run's state, written as a state file that `bench_newton.py --state` rebuilds with its lid.

    python benchmarks/jam_state.py RUN/checkpoint.npz --pack rpack/state.npz --out lid515_jam.npz
                                   [--config CONFIG.toml]

RUN is a `lid_compression` run in progress (`bench_paper.py --implicit --only compression-pack
--pack-state rpack/state.npz` writes OUT/compression-pack), rpack/state.npz the pack it started
from (the grains' reference shapes and the box), CONFIG its config (default: the
`paper-compression-implicit` example, whose lid, friction and damping the 515-grain lid run
takes). The state file (io.state) holds the grains, their positions, velocities and friction
history at the checkpoint's time, and in its record the lid ("lid": the config's lid with `start`
the lid's height at that time) and the config's contact settings ("contact": mu_s, mu_d, damping_ratio,
every key it sets).
A lid run's jam costs an hour or more to reach; `benchmarks/data/lid515_jam.npz`, written by this
script from the 515-grain run at the real density, lets anyone measure a Newton iteration there
(docs/linear-solvers.md, "The lid's jam, rerunnable").
"""

from __future__ import annotations

import argparse
import tomllib
from pathlib import Path

import numpy as np

from vemdem.io.state import FRICTION_FIELDS, load_state, save_state
from vemdem.scenarios.lid_compression import lid_wall
from vemdem.scenarios.registry import checked_config, example_text


def lid_height(lid: dict, t: float) -> float:
    """The lid's height at time t of its cycle, as the scenario moves it (lid_compression.lid_wall)."""
    return float(lid_wall(lid, (0.0, 0.0))[0].point_at(t)[2])


def jam_state(checkpoint: Path, pack: Path, cfg: dict, out: Path) -> dict:
    """Write the state file; returns its record."""
    initial = load_state(pack)
    with np.load(checkpoint) as d:
        t = float(d["t"])
        x, v = d["x"].copy(), d["v"].copy()
        friction = {name: d[name].copy() for name in FRICTION_FIELDS}
    if x.shape != initial.x.shape:
        raise SystemExit(f"{checkpoint}: {len(x)} vertices, {pack} has {len(initial.x)}: not the run's pack")
    lid = {key: float(cfg["lid"][key]) for key in ("start", "end", "speed")}
    meta = {**initial.meta, "scenario": "lid_compression", "time": t, "pack_time": initial.meta.get("time"),
            "lid": {**lid, "start": lid_height(lid, t)},
            "contact": {key: value for key, value in cfg["contact"].items() if value is not None}}  # fmt: skip
    save_state(out, initial.grains, x, v, meta, friction)
    return meta


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("checkpoint", type=Path, help="the lid run's checkpoint.npz")
    p.add_argument("--pack", type=Path, required=True, help="the state file the lid run started from")
    p.add_argument("--config", type=Path, help="the lid run's config (default: paper-compression-implicit)")
    p.add_argument("--out", type=Path, required=True)
    args = p.parse_args()
    text = args.config.read_text() if args.config else example_text("paper-compression-implicit")
    cfg, _ = checked_config(tomllib.loads(text))
    meta = jam_state(args.checkpoint, args.pack, cfg, args.out)
    print(f"{args.out}: t = {meta['time']:.6g} s, lid at {meta['lid']['start'] * 1e3:.4f} mm, "
          f"{args.out.stat().st_size / 1e6:.2f} MB")  # fmt: skip


if __name__ == "__main__":
    main()
