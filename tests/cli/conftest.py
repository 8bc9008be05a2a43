"""Fixtures of the command-line tests."""

import subprocess

import pytest


@pytest.fixture
def locked(tmp_path):
    """An empty folder made immutable (``chattr +i``: nothing can be created in it, even by
    root), released after the test; the test is skipped where chattr is not available."""
    folder = tmp_path / "locked"
    folder.mkdir()
    if subprocess.run(["chattr", "+i", str(folder)], capture_output=True).returncode != 0:
        pytest.skip("chattr +i not available (needs root and a filesystem with attributes)")
    yield folder
    subprocess.run(["chattr", "-i", str(folder)], check=True)
