"""The data behind docs/results.md's angle figure: the script reads every run's row and draws it,
and the rows say what the docs say they say (the angle rises with friction in every series)."""

import importlib.util
from pathlib import Path

import numpy as np

SCRIPT = Path(__file__).resolve().parents[1] / "docs" / "data" / "angles_by_friction.py"


def _module():
    spec = importlib.util.spec_from_file_location("angles_by_friction", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_every_series_has_its_packs_and_rises_with_friction(tmp_path):
    module = _module()
    data = module.series()
    assert {("collapse into a corner", "sand"), ("collapse into a corner", "angular"),
            ("poured heap into a corner", "sand"), ("poured heap into a corner", "angular")} <= set(data)  # fmt: skip
    for key, by_mu in data.items():
        assert all(len(angles) >= 2 for angles in by_mu.values()), key  # a spread over packs at every point
        mus = sorted(by_mu)
        if 0.3 in by_mu and len(mus) > 1:  # low friction stands lowest, by more than the packs' spread
            low = np.mean(by_mu[0.3])
            for mu in mus[1:]:
                assert np.mean(by_mu[mu]) > low + np.std(by_mu[mu]) + np.std(by_mu[0.3]), (key, mu)
    assert all(len(a) == 5 for a in data[("collapse into a corner", "sand")].values())
    out = tmp_path / "angles.png"
    module.main([str(out)])
    assert out.stat().st_size > 20_000
