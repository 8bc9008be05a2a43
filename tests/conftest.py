"""Shared test set-up: quiet JIT logs; MPI-marked tests need >= 2 ranks (the MPI suite)."""

import logging

import numpy as np
import pytest

for _name in ("ffcx", "UFL", "ufl", "dolfinx"):
    logging.getLogger(_name).setLevel(logging.WARNING)

# PetscInitialize is collective on MPI_COMM_WORLD: done here, on every rank at once, it cannot
# fall inside a test's rank-0-only work (writing a mesh file) while the other rank waits in a
# barrier, which deadlocked tests/mesh/test_imported.py when it ran first under mpirun -n 2
from petsc4py import PETSc  # noqa: E402,F401


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


EPS = np.finfo(float).eps


def _distributed_rtol(form, steady) -> float:
    """How far two equal solves of ``form``'s steady state may differ, relative to it: 0 where
    the solve is repeatable (one rank), otherwise the forward-error bound cond(K) eps of the
    distributed direct solve (MUMPS schedules its work across ranks dynamically, so its sums run
    in a different order from one run to the next), times 10 for the few Newton steps that
    carry it. cond(K) of the tangent about ``steady``, from the dense matrix (small meshes only).
    Collective."""
    if form.comm.size == 1:
        return 0.0
    lin = form.linearise(steady)
    try:
        dense = _gathered_dense(lin.K, form.comm)
    finally:
        lin.destroy()
    return 10.0 * np.linalg.cond(dense) * EPS


def _gathered_dense(K, comm) -> np.ndarray:
    """A distributed PETSc matrix as the whole dense array on every rank (small meshes only).
    Collective."""
    indptr, indices, data = K.getValuesCSR()
    first, last = K.getOwnershipRange()
    n = K.getSize()[0]
    local = np.zeros((last - first, n))
    for i in range(last - first):
        local[i, indices[indptr[i]:indptr[i + 1]]] = data[indptr[i]:indptr[i + 1]]
    return np.vstack(comm.allgather(local))


@pytest.fixture
def gathered_dense():
    """:func:`_gathered_dense`: a distributed PETSc matrix, dense on every rank."""
    return _gathered_dense


@pytest.fixture
def distributed_rtol():
    """:func:`_distributed_rtol`: the accuracy of a steady state solved on several ranks."""
    return _distributed_rtol
