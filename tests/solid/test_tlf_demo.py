"""The TLF demo runs and its checked value holds: the 1000 rpm window mean within 2 % of the
steady state (the demo prints the largest relative difference)."""

import pathlib
import re
import subprocess
import sys

import pytest

DEMO = pathlib.Path(__file__).parents[2] / "demos" / "tlf_transient.py"


@pytest.mark.serial
def test_tlf_demo_runs_to_its_checked_value():
    p = subprocess.run([sys.executable, str(DEMO)], capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    m = re.search(r"largest difference of the window mean from the steady state: ([\d.]+) %",
                  p.stdout)
    assert m, p.stdout
    assert float(m.group(1)) < 2.0
