"""Shared test set-up: quiet JIT logs; MPI-marked tests need >= 2 ranks (the MPI suite)."""

import logging

import pytest

for _name in ("ffcx", "UFL", "ufl", "dolfinx"):
    logging.getLogger(_name).setLevel(logging.WARNING)


def pytest_collection_modifyitems(config, items):
    from mpi4py import MPI

    size = MPI.COMM_WORLD.size
    skip_mpi = pytest.mark.skip(reason="needs mpirun -n 2 (the MPI suite)")
    skip_serial = pytest.mark.skip(reason="serial-only test")
    for item in items:
        if "mpi" in item.keywords and size < 2:
            item.add_marker(skip_mpi)
        if "serial" in item.keywords and size > 1:
            item.add_marker(skip_serial)


@pytest.fixture
def folder(tmp_path, monkeypatch):
    """An empty fxflex cache folder of the test's own (FXFLEX_CACHE), not bypassed."""
    monkeypatch.setenv("FXFLEX_CACHE", str(tmp_path))
    monkeypatch.delenv("FXFLEX_NO_CACHE", raising=False)
    return tmp_path
