"""The friction springs' reach (driver.summary.friction_reach, history.csv's elastic_slip): a run
whose contact forces outgrew the tangential penalty says so, in summary.json and in one warning."""

import json
import warnings

import numpy as np
import pytest

from vemdem.driver.frames import HISTORY_HEADER, elastic_slip
from vemdem.driver.summary import FrictionSpringWarning, friction_reach
from vemdem.io.results import strict

GBAR = 9e-6


def write_history(path, slips):
    cols = len(HISTORY_HEADER)
    with open(path, "w") as fh:
        fh.write(",".join(HISTORY_HEADER) + "\n")
        for k, slip in enumerate(slips):
            row = [0.01 * k] + [0.0] * (cols - 2) + [slip]
            fh.write(",".join(repr(v) for v in row) + "\n")
    return path


def test_elastic_slip_is_a_high_percentile_of_the_pairs_slips():
    assert elastic_slip(np.zeros((0, 3))) == 0.0
    rng = np.random.default_rng(3)
    directions = rng.normal(size=(1000, 3))
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    lengths = np.linspace(0.0, 1e-3, 1000)  # one pair stretched to each length
    slip = elastic_slip(lengths[:, None] * directions)
    # 990 of the 1000 pairs are at most this stretched, the direction does not count
    assert np.sum(lengths <= slip) == 990
    assert slip == pytest.approx(0.99e-3, rel=2e-3)


def test_slips_inside_the_contact_layer_pass_quietly(tmp_path):
    history = write_history(tmp_path / "history.csv", [0.0, 1e-7, 2.2e-6, 1e-6])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        record = friction_reach(history, GBAR, 3.2e4)
    assert record["elastic_slip_max"] == 2.2e-6 and record["time"] == pytest.approx(0.02)
    assert record["beyond_contact_layer"] is False


def test_slips_beyond_the_contact_layer_warn_and_name_the_fix(tmp_path):
    # the 515-grain lid jam at the real density with the weight law: 98 um against gbar = 9 um
    history = write_history(tmp_path / "history.csv", [0.0, 3e-5, 9.8e-5, 2e-5])
    with pytest.warns(FrictionSpringWarning, match=r"98 um at t = 0.02 s.*26 N/m.*reference_force"):
        record = friction_reach(history, GBAR, 26.0)
    assert record["elastic_slip_max"] == 9.8e-5 and record["beyond_contact_layer"] is True


def test_a_history_without_the_column_gives_null_with_a_reason(tmp_path):
    old = tmp_path / "history.csv"  # written before the column existed (a run resumed across versions)
    old.write_text(",".join(HISTORY_HEADER[:-1]) + "\n" + ",".join(["0.0"] * (len(HISTORY_HEADER) - 1)) + "\n")
    record = friction_reach(old, GBAR, 26.0)
    assert record["elastic_slip_max"] is None and "reason" in record
    assert friction_reach(tmp_path / "missing.csv", GBAR, 26.0)["elastic_slip_max"] is None
    json.dumps(strict(record), allow_nan=False)
