"""Single-grain compression against the closed form of a compressed cube, and the
grain_compression job's outputs."""

import csv
import json

import numpy as np
import pytest

from vemdem.analysis.homogeneous import lateral_stretch, nominal_axial_stress
from vemdem.config import apply_schema
from vemdem.scenarios import grain_compression
from vemdem.vem.material import Material

MAT = Material(90e9, 0.16, 2200.0)


def config(**overrides):
    raw = {
        "scenario": "grain_compression",
        "material": {"E": MAT.E, "nu": MAT.nu, "density": MAT.density},
        "grain": {"shape": "cube", "size": 1.45e-3},
        "loading": {"mode": "uniaxial", "max_strain": 0.3, "steps": 10},
        "output": {"vtk": False, "plot": False},
    }
    for key, value in overrides.items():
        section, name = key.split("__")
        raw.setdefault(section, {})[name] = value
    return apply_schema(raw, grain_compression.SCHEMA)


def read_csv(path):
    with open(path) as fh:
        rows = list(csv.reader(fh))
    return rows[0], np.array(rows[1:], dtype=float)


def test_closed_form_reference_is_consistent():
    """The closed form itself: tiny strain gives E (uniaxial) and the P-wave modulus (confined)."""
    e = 1e-7
    assert nominal_axial_stress(e, MAT.mu, MAT.kappa, "uniaxial")[0] / e == pytest.approx(MAT.E, rel=1e-5)
    m_oedo = MAT.kappa + 4 / 3 * MAT.mu
    assert nominal_axial_stress(e, MAT.mu, MAT.kappa, "confined")[0] / e == pytest.approx(m_oedo, rel=1e-5)
    assert lateral_stretch(1 - e, MAT.mu, MAT.kappa) == pytest.approx(1 + MAT.nu * e, rel=1e-9)


@pytest.mark.parametrize("beta", [0.1, 0.25, 0.5, 1.0])
@pytest.mark.parametrize("mode", ["uniaxial", "confined"])
def test_cube_compression_matches_closed_form(tmp_path, mode, beta):
    cfg = config(loading__mode=mode, vem__beta_internal=beta)
    summary = grain_compression.run(cfg, tmp_path)
    header, data = read_csv(tmp_path / "force_strain.csv")
    assert header == ["strain", "force"]
    assert data[0].tolist() == [0.0, 0.0]
    strain, force = data[:, 0], data[:, 1]
    np.testing.assert_allclose(strain, np.linspace(0, 0.3, 11), atol=1e-15)
    expected = 1.45e-3**2 * nominal_axial_stress(strain, MAT.mu, MAT.kappa, mode)
    np.testing.assert_allclose(force, expected, rtol=1e-8, atol=1e-9 * expected.max())
    assert summary["max_force"] == pytest.approx(expected.max(), rel=1e-8)


def test_random_grain_job_writes_its_outputs(tmp_path):
    cfg = config(grain__shape="random", loading__steps=5, loading__max_strain=0.1, output__vtk=True, output__plot=True)
    summary = grain_compression.run(cfg, tmp_path)
    for name in ["force_strain.csv", "summary.json", "force_strain.png", "grain.pvd"]:
        assert (tmp_path / name).is_file(), name
    on_disk = json.loads((tmp_path / "summary.json").read_text())
    for key in ["scenario", "n_vertices", "n_steps", "wall_seconds", "max_force"]:
        assert key in on_disk
    assert on_disk == json.loads(json.dumps(summary))
    _, data = read_csv(tmp_path / "force_strain.csv")
    assert len(data) == 6 and np.all(np.diff(data[:, 1]) > 0)
    assert len(list((tmp_path / "grain").glob("*.vtu"))) == 6


def test_same_config_same_result(tmp_path):
    cfg = config(grain__shape="random", loading__steps=4)
    grain_compression.run(cfg, tmp_path / "a")
    grain_compression.run(cfg, tmp_path / "b")
    assert (tmp_path / "a/force_strain.csv").read_bytes() == (tmp_path / "b/force_strain.csv").read_bytes()
