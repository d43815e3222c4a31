"""One set of kernels on every x86-64 machine (vemdem.portable): OpenBLAS chooses its kernels when
it loads and numba reads its target when it is imported, so each case runs in a fresh interpreter."""

import json
import os
import subprocess
import sys

import pytest

from vemdem.portable import NUMBA_CPU, OPENBLAS_CORE, portable_machine

PROBE = "import vemdem, numpy, json; print(json.dumps(vemdem.portable.kernels()))"
OURS = ("OPENBLAS_CORETYPE", "NUMBA_CPU_NAME", "NUMBA_CPU_FEATURES", "VEMDEM_NATIVE", "VEMDEM_PINNED")
pinnable = pytest.mark.skipif(not portable_machine(), reason="the pin needs x86-64 Linux with the Haswell features")


def _probe(code=PROBE, **env):
    base = {k: v for k, v in os.environ.items() if k not in OURS}
    out = subprocess.run([sys.executable, "-c", code], env={**base, **env}, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


@pinnable
def test_importing_vemdem_first_pins_openblas_and_numba():
    kernels = _probe()
    assert kernels["openblas"] == OPENBLAS_CORE  # NumPy's and SciPy's OpenBLAS both
    assert kernels["numba_cpu"] == NUMBA_CPU
    assert kernels["choice"] == f"openblas pinned ({OPENBLAS_CORE}), numba pinned ({NUMBA_CPU})"
    features = _probe("import vemdem, json, numba; print(json.dumps(numba.config.CPU_FEATURES))")
    assert features == ""  # the named CPU's features: not the host's (an AVX-512 host would add its own)


@pinnable
def test_the_users_own_choice_wins():
    kernels = _probe(OPENBLAS_CORETYPE="Sandybridge", NUMBA_CPU_NAME="generic")
    assert (kernels["openblas"], kernels["numba_cpu"]) == ("Sandybridge", "generic")
    assert kernels["choice"] == "openblas set by the user (Sandybridge), numba set by the user (generic)"
    native = _probe(VEMDEM_NATIVE="1")
    assert native["choice"] == "native: VEMDEM_NATIVE=1" and native["numba_cpu"].startswith("host")


def test_libraries_loaded_first_are_left_alone_and_said():
    kernels = _probe("import numpy, numba, vemdem, json; print(json.dumps(vemdem.portable.kernels()))")
    assert kernels["numba_cpu"].startswith("host")
    if portable_machine():
        assert kernels["choice"] == "openblas native (NumPy was imported before vemdem), " \
                                    "numba native (numba was imported before vemdem)"


def test_importing_vemdem_loads_neither_numpy_nor_numba():
    """The pin only works before NumPy loads OpenBLAS and numba reads its target."""
    code = "import vemdem, sys; print(json.dumps(['numpy' in sys.modules, 'numba' in sys.modules]))"
    assert _probe("import json; " + code) == [False, False]


def test_a_runs_summary_names_its_kernels(tmp_path, cli):
    from vemdem.scenarios.registry import example_text

    text = example_text("drop").replace("duration = 0.02", "duration = 0.001")
    (tmp_path / "drop.toml").write_text(text)
    code, _, err = cli("run", tmp_path / "drop.toml", "--out", tmp_path / "out", "--quiet")
    assert code == 0, err
    kernels = json.loads((tmp_path / "out/summary.json").read_text())["kernels"]
    assert set(kernels) == {"openblas", "numba_cpu", "choice"} and kernels["openblas"]


@pinnable
def test_a_child_process_of_a_pinned_run_keeps_the_pin_and_says_whose_it_is():
    """A local sweep's Dask workers inherit the variables: their summaries say "pinned", not "the user"."""
    code = ("import vemdem, subprocess, sys; print(subprocess.run([sys.executable, '-c', "
            "'import vemdem, json; print(json.dumps(vemdem.portable.kernels()))'], capture_output=True, "
            "text=True).stdout)")  # fmt: skip
    child = _probe(code)
    assert child["choice"] == f"openblas pinned ({OPENBLAS_CORE}), numba pinned ({NUMBA_CPU})"
    assert (child["openblas"], child["numba_cpu"]) == (OPENBLAS_CORE, NUMBA_CPU)
