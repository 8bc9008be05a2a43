"""Each beam demo runs to its checked value."""

import pathlib
import subprocess
import sys

import pytest

# spawns the demos as processes: a child of an mpirun'd process would inherit its MPI environment
pytestmark = pytest.mark.serial

DEMOS = sorted((pathlib.Path(__file__).parents[2] / "demos").glob("beam_*.py"))


@pytest.mark.parametrize("demo", DEMOS, ids=[d.stem for d in DEMOS])
def test_demo_runs(demo):
    p = subprocess.run([sys.executable, str(demo)], capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    assert p.stdout.strip()


def test_demos_found():
    assert len(DEMOS) >= 2
