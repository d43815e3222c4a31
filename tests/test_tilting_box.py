"""The tilting box (docs/repose.md): gravity turns in the box's frame until the surface avalanches.

References: the surface fit against planes of known angle; a cube on the box's floor against
the closed form of a block on a slope whose tilt grows at a constant rate (with mu_s = mu_d it
breaks away at atan(mu), then v(t) = g sqrt(1 + mu^2) omega t^2 / 2, so the kinetic threshold
is passed a known time later, and its slip x(t) = g sqrt(1 + mu^2) omega t^3 / 6 reaches the
surface mark's slip a known time later); resume against an uninterrupted run; energy after the
avalanche, when gravity no longer turns, against the balance of a closed system."""

import json
import math
import warnings

import numpy as np
import pytest

from vemdem.analysis.tilt import fit_surface, surface_grains, tilted_frame, tilted_gravity
from vemdem.config import ConfigError
from vemdem.config.build import MassScalingWarning
from vemdem.driver import loop as loop_mod
from vemdem.geometry import cube
from vemdem.io.state import save_state
from vemdem.scenarios.registry import checked_config

EDGE = 1e-3
CUBE_BOX = [4e-3, 2e-3]


def test_the_tilted_frame_is_gravity_s():
    for theta in (0.0, 17.0, 45.0, 80.0):
        g = tilted_gravity(theta, 9.81)
        e_h, e_u = tilted_frame(theta)
        assert np.allclose(e_u, -g / 9.81) and abs(e_h @ e_u) < 1e-15 and np.isclose(np.linalg.norm(e_h), 1.0)
        assert e_h[0] > 0  # +x is downhill


def _block(top_slope_deg=0.0, nx=14, ny=4, layers=5, d=1e-3, seed=0):
    """Centroids of a lattice block in the box frame whose top falls towards +x at top_slope_deg."""
    rng = np.random.default_rng(seed)
    x, y = np.meshgrid((np.arange(nx) - (nx - 1) / 2) * d, (np.arange(ny) - (ny - 1) / 2) * d, indexing="ij")
    top = 0.5 * d * layers - np.tan(np.radians(top_slope_deg)) * x
    columns = [np.column_stack([np.full(layers, a), np.full(layers, b), t - np.arange(layers) * d])
               for a, b, t in zip(x.ravel(), y.ravel(), top.ravel())]  # fmt: skip
    c = np.vstack(columns)
    return c + rng.normal(scale=1e-3 * d, size=c.shape), (nx * d, ny * d)


@pytest.mark.parametrize("tilt, slope", [(0.0, 0.0), (25.0, 0.0), (25.0, -8.0), (10.0, 12.0)])
def test_the_surface_fit_reads_planes_of_known_angle(tilt, slope):
    c, box = _block(slope)
    top = surface_grains(c, box, (0.0, 0.0), 1e-3)
    assert len(top) == (14 - 2) * 4  # the top of every inner column, nothing below it
    s = fit_surface(c, tilt, box, (0.0, 0.0), 1e-3)
    assert s.angle_deg == pytest.approx(tilt + slope, abs=0.05)
    assert s.stderr_deg < 0.05


def test_a_box_too_short_has_no_surface_angle():
    c, box = _block(nx=3)
    with pytest.raises(ValueError, match="surface grains"):
        fit_surface(c, 20.0, box, (0.0, 0.0), 1e-3)


def _cube_state(path, mass_scaling):
    c = cube(EDGE, center=(0.0, 0.0, 0.5 * EDGE + 9.6e-6))  # near its rest gap: no bounce at t = 0
    save_state(path, [c], c.vertices, np.zeros_like(c.vertices),
               {"scenario": "pack", "box": CUBE_BOX, "centre": [0.0, 0.0], "floor": 0.0, "grain_size": EDGE,
                "seed": 0, "time": 0.0, "mass_scaling": mass_scaling})  # fmt: skip
    return path


def _cube_config(state, mu, integrator="explicit", mass_scaling=1e6, rate=10.0, threshold=1e-3, **tilt):
    start = round(math.degrees(math.atan(mu)) - 3.0, 2)
    cfg, module = checked_config({"scenario": "tilting_box", "initial_state": str(state),
                                  "tilt": {"start": start, "rate": rate, "max": 45.0, "avalanche_kinetic": threshold,
                                           **tilt},
                                  "contact": {"mu_s": mu, "mu_d": mu},
                                  "solver": {"integrator": integrator, "mass_scaling": mass_scaling},
                                  "output": {"vtk": False, "every": 2e-3}})  # fmt: skip
    return cfg, module


def predicted_onset_deg(mu, rate, threshold, grain_size):
    """atan(mu) plus the tilt gained while the block speeds up to the threshold's velocity."""
    g, omega = 9.81, math.radians(rate)
    v = math.sqrt(2 * threshold * g * grain_size)
    return math.degrees(math.atan(mu)) + rate * math.sqrt(2 * v / (g * math.sqrt(1 + mu * mu) * omega))


@pytest.mark.parametrize("mu, integrator, mass_scaling", [(0.5, "explicit", 1e6), (0.3, "explicit", 1e6),
                                                          (0.5, "implicit", 1.0)])  # fmt: skip
@pytest.mark.filterwarnings("ignore::vemdem.config.build.MassScalingWarning")
def test_a_cube_slides_off_at_the_friction_angle(tmp_path, mu, integrator, mass_scaling):
    cfg, module = _cube_config(_cube_state(tmp_path / "cube.npz", mass_scaling), mu, integrator, mass_scaling)
    summary = module.run(cfg, tmp_path / "run")
    size = (6 / math.pi) ** (1 / 3) * EDGE  # the scenes' grain size: equivalent diameter
    expected = predicted_onset_deg(mu, 10.0, 1e-3, size)
    # frames every 2 ms at 10 deg/s: the onset is read 0.02 deg late at most
    assert expected - 0.05 <= summary["tilt_at_avalanche_deg"] <= expected + 0.1
    assert summary["settled"] and summary["tilt_deg"] == summary["tilt_at_avalanche_deg"]
    assert abs(summary["energy"]["balance_error"]) < 1e-2  # after the onset gravity is fixed: a closed system
    onset = json.loads((tmp_path / "run" / "tilt.json").read_text())["avalanche"]
    assert onset["tilt_deg"] == summary["tilt_at_avalanche_deg"]
    assert (tmp_path / "run" / "tilt.png").stat().st_size > 10_000


def predicted_slip_onset_deg(mu, rate, slip):
    """atan(mu) plus the tilt gained while the block slides `slip` metres (slip = g sqrt(1 + mu^2)
    omega t^3 / 6: the downhill acceleration g (sin - mu cos) grows as g sqrt(1 + mu^2) omega t
    from the breakaway, with no second-order term there)."""
    g, omega = 9.81, math.radians(rate)
    return math.degrees(math.atan(mu)) + rate * (6 * slip / (g * math.sqrt(1 + mu * mu) * omega)) ** (1 / 3)


@pytest.mark.filterwarnings("ignore::vemdem.config.build.MassScalingWarning")
def test_the_surface_mark_finds_a_sliding_cube_where_its_slip_says(tmp_path):
    """A lone cube is its own surface layer: the avalanche is marked when it has slid
    tilt.surface_slip grain sizes, at the tilt the closed form gives; the kinetic mark on the same
    cube fires as much earlier as the two closed forms say (at the threshold's speed, after a
    slip of about 0.1 grain sizes)."""
    state = _cube_state(tmp_path / "cube.npz", 1e6)
    cfg, module = _cube_config(state, 0.5, avalanche="surface", surface_slip=0.4)
    summary = module.run(cfg, tmp_path / "surface")
    size = (6 / math.pi) ** (1 / 3) * EDGE
    expected = predicted_slip_onset_deg(0.5, 10.0, 0.4 * size)
    assert expected - 0.05 <= summary["tilt_at_avalanche_deg"] <= expected + 0.1
    assert summary["avalanche_mark"] == "surface" and summary["surface_layer_grains"] == 1
    assert 0.4 <= summary["surface_slip_at_avalanche_grains"] < 0.45  # found at the first frame past the mark
    kinetic = module.run(_cube_config(state, 0.5)[0], tmp_path / "kinetic")
    assert kinetic["avalanche_mark"] == "kinetic"
    lead = predicted_slip_onset_deg(0.5, 10.0, 0.4 * size) - predicted_onset_deg(0.5, 10.0, 1e-3, size)  # 0.44 deg
    assert abs(summary["tilt_at_avalanche_deg"] - kinetic["tilt_at_avalanche_deg"] - lead) < 0.1


def test_mirror_sides_are_the_frictionless_y_walls():
    from vemdem.scenarios.tilting_box import tilt_walls

    meta = {"box": [10e-3, 3e-3], "floor": 0.0, "centre": [0.0, 0.0]}
    walls = {w.name: w for w in tilt_walls(meta, "mirrors")}
    assert {n for n, w in walls.items() if w.frictionless} == {"wall -y", "wall +y"}
    assert [abs(walls[n].normal[1]) for n in ("wall -y", "wall +y")] == [1.0, 1.0]
    assert not any(w.frictionless for w in tilt_walls(meta, "walls"))


def _counting_checkpoints(monkeypatch, stop_at=None):
    original = loop_mod.save_checkpoint
    written = []

    def counting(path, *args, **kwargs):
        original(path, *args, **kwargs)
        written.append(path)
        if stop_at is not None and len(written) == stop_at:
            raise KeyboardInterrupt

    monkeypatch.setattr(loop_mod, "save_checkpoint", counting)
    return written


@pytest.mark.parametrize("mark", ["kinetic", "surface"])
@pytest.mark.filterwarnings("ignore::vemdem.config.build.MassScalingWarning")
def test_a_killed_tilt_resumes_to_the_same_bits(tmp_path, monkeypatch, mark):
    """Killed while the cube comes to rest at tilt.start, while tilting, and right after the
    checkpoint of the frame that finds the avalanche (not yet in tilt.json): each ends as the run
    that was never interrupted (with the surface mark, the layer's start is read back from
    tilt.json)."""
    cfg, module = _cube_config(_cube_state(tmp_path / "cube.npz", 1e6), 0.5, avalanche=mark)
    whole = module.run(cfg, tmp_path / "whole")
    tilting_frame, onset_frame = (round(whole[k] / 2e-3) for k in ("tilting_from", "avalanche_time"))
    kills = {"resting": tilting_frame // 2, "tilting": (tilting_frame + onset_frame) // 2, "at": onset_frame}
    for name, frame in kills.items():
        _counting_checkpoints(monkeypatch, stop_at=frame + 1)  # +1: the frame-0 checkpoint
        with pytest.raises(KeyboardInterrupt):
            module.run(cfg, tmp_path / name)
        monkeypatch.undo()
        events = tmp_path / name / "tilt.json"
        assert not events.exists() or json.loads(events.read_text())["avalanche"] is None
        resumed = module.run(cfg, tmp_path / name, resume=True)
        for f in ("history.csv", "grains.csv", "tilt.json"):
            assert (tmp_path / name / f).read_bytes() == (tmp_path / "whole" / f).read_bytes(), f"{name}: {f} differs"
        walls = {"wall_seconds": 0, "wall_seconds_total": 0}
        assert {**resumed, **walls} == {**whole, **walls}


@pytest.fixture(scope="module")
def small_tilt(tmp_path_factory):
    out = tmp_path_factory.mktemp("tilt")
    cfg, module = checked_config({"scenario": "tilting_box",
                                  "pack": {"n_grains": 24, "seed": 2, "grains": {"vertices": 12},
                                           "box": {"width": 6e-3, "depth": 3e-3}},
                                  "tilt": {"start": 10.0, "rate": 40.0, "max": 40.0, "avalanche_kinetic": 3e-4},
                                  "solver": {"mass_scaling": 1e6},
                                  "contact": {"mu_s": 0.2, "mu_d": 0.2},
                                  "output": {"vtk": False, "every": 5e-3}})  # fmt: skip
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MassScalingWarning)  # 1e6: the test is about the tilt, not the collisions
        return module.run(cfg, out), out


def test_a_small_pack_avalanches_and_its_books_close_after(small_tilt):
    summary, out = small_tilt
    # not before its grains' own friction angle atan(mu_s) (a detection that fired on the pack's
    # settling or the tilt's start would), and within the tilt's range (32.8 deg measured: angular
    # grains in a box 2 grains deep whose side walls have the grains' friction)
    assert math.degrees(math.atan(0.2)) < summary["tilt_at_avalanche_deg"] < 40.0
    assert summary["settled"] and summary["energy_from"] == "avalanche"
    assert abs(summary["energy"]["balance_error"]) < 1e-2
    assert summary["fill_height_grains"] > 2
    for name in ("tilt.png", "tilt_3d.png", "state.npz", "tilt.json"):
        assert (out / name).is_file()
    json.loads((out / "summary.json").read_text())  # strict JSON, nulls with reasons


@pytest.mark.parametrize("change, message", [({"gravity": [0.0, 1.0, -9.81]}, "gravity"),
                                             ({"tilt": {"start": 40.0, "max": 30.0}}, "tilt.start")])  # fmt: skip
def test_a_tilt_it_cannot_do_is_refused(tmp_path, change, message):
    raw = {"scenario": "tilting_box", "initial_state": str(_cube_state(tmp_path / "c.npz", 1e6)), **change}
    with pytest.raises(ConfigError, match=message):
        cfg, module = checked_config(raw)
        module.run(cfg, tmp_path / "run")
