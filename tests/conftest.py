import os
import sys
from pathlib import Path

import vemdem  # noqa: F401  first: it pins the kernels before NumPy and numba load, as the command line does

import numba  # noqa: E402
import numpy as np  # noqa: E402
import pytest

sys.path.insert(0, str(Path(__file__).parent))


@pytest.fixture(autouse=True, scope="session")
def one_numba_thread_per_worker():
    """Under pytest-xdist (`-n auto`, pyproject.toml) the workers already fill the cores: one numba
    thread each, rather than a thread per core in every worker. Thread-local, so set where the
    tests run; a test may still ask for more (up to NUMBA_NUM_THREADS)."""
    if os.environ.get("PYTEST_XDIST_WORKER"):
        numba.set_num_threads(1)


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


@pytest.fixture
def cli(capsys):
    """Run the vemdem command line in-process: cli(*args) -> (exit code, stdout, stderr)."""
    from vemdem.cli import main  # noqa: PLC0415

    def run(*args):
        code = main([str(a) for a in args])
        out = capsys.readouterr()
        return code, out.out, out.err

    return run
