import sys
from pathlib import Path

import vemdem  # noqa: F401  first: it pins the kernels before NumPy and numba load, as the command line does

import numpy as np  # noqa: E402
import pytest

sys.path.insert(0, str(Path(__file__).parent))


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
