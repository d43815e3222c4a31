"""One set of BLAS kernels on every x86-64 machine (vemdem.portable): the kernels are chosen when
OpenBLAS loads, so each case runs in a fresh interpreter."""

import json
import os
import platform
import subprocess
import sys

import pytest

from vemdem.portable import PORTABLE_CORE, _cpu_flags

PROBE = "import vemdem, numpy, json; print(json.dumps(vemdem.portable.blas_kernels()))"
PINNABLE = platform.machine().lower() in ("x86_64", "amd64") and sys.platform.startswith("linux") and {
    "avx2",
    "fma",
} <= _cpu_flags()


def _probe(code=PROBE, **env):
    base = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_CORETYPE", "VEMDEM_NATIVE_BLAS")}
    out = subprocess.run([sys.executable, "-c", code], env={**base, **env}, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.skipif(not PINNABLE, reason="the portable kernels need x86-64 Linux with AVX2 and FMA")
def test_importing_vemdem_first_pins_every_openblas_to_the_portable_kernels():
    kernels = _probe()
    assert kernels["choice"] == f"pinned: {PORTABLE_CORE}"
    assert kernels["architecture"] == PORTABLE_CORE  # NumPy's and SciPy's OpenBLAS both


@pytest.mark.skipif(not PINNABLE, reason="the portable kernels need x86-64 Linux with AVX2 and FMA")
def test_the_users_own_choice_wins():
    kernels = _probe(OPENBLAS_CORETYPE="Sandybridge")
    assert kernels == {"architecture": "Sandybridge", "choice": "set by the user: Sandybridge"}
    assert _probe(VEMDEM_NATIVE_BLAS="1")["choice"] == "native: VEMDEM_NATIVE_BLAS=1"


def test_numpy_loaded_first_is_left_alone_and_said():
    kernels = _probe("import numpy, vemdem, json; print(json.dumps(vemdem.portable.blas_kernels()))")
    assert kernels["choice"].startswith("native")


def test_a_runs_summary_names_its_kernels(tmp_path, cli):
    from vemdem.scenarios.registry import example_text

    text = example_text("drop").replace("duration = 0.02", "duration = 0.001")
    (tmp_path / "drop.toml").write_text(text)
    code, _, err = cli("run", tmp_path / "drop.toml", "--out", tmp_path / "out", "--quiet")
    assert code == 0, err
    kernels = json.loads((tmp_path / "out/summary.json").read_text())["blas_kernels"]
    assert set(kernels) == {"architecture", "choice"} and kernels["architecture"]


def test_importing_vemdem_loads_no_numpy():
    """The pin only works before NumPy loads OpenBLAS: vemdem's import must not load NumPy itself."""
    out = subprocess.run([sys.executable, "-c", "import vemdem, sys; print('numpy' in sys.modules)"],
                         capture_output=True, text=True, check=True)  # fmt: skip
    assert out.stdout.strip() == "False"
