"""Clamped eigenmodes from SLEPc (fxflex.solid.cms): against a dense LAPACK solve, and the same
frequencies on 2 ranks as on one."""

import numpy as np
import pytest
import scipy.linalg as la
from mpi4py import MPI

from fxflex.solid.cms import clamped_modes, mass_and_stiffness
from fxflex.scene import load_scene
from fxflex.solid.model import SolidModel


def _dense(A):
    indptr, indices, data = A.getValuesCSR()
    n = A.getSize()[0]
    out = np.zeros((n, n))
    for i in range(n):
        out[i, indices[indptr[i]:indptr[i + 1]]] = data[indptr[i]:indptr[i + 1]]
    return out


@pytest.mark.serial
def test_modes_match_dense_generalised_eigensolve():
    model = SolidModel(load_scene(overrides=["mesh.solid=[8,2,2]"]), MPI.COMM_SELF)
    K, M = mass_and_stiffness(model)
    modes = clamped_modes(model, 12, K=K, M=M, use_cache=False)     # SLEPc itself
    Kd, Md = _dense(K), _dense(M)
    clamped = np.concatenate([3 * model.root_nodes + i for i in range(3)])
    free = np.setdiff1d(np.arange(Kd.shape[0]), clamped)
    w2 = la.eigh(Kd[np.ix_(free, free)], Md[np.ix_(free, free)], eigvals_only=True)[:12]
    assert np.allclose(modes.omega2, w2, rtol=1e-10, atol=0)
    Phi = modes.vectors
    assert np.all(np.diff(modes.omega2) > 0)
    assert np.abs(Phi.T @ Md @ Phi - np.eye(12)).max() < 1e-12           # mass-normalised
    assert np.allclose(Phi.T @ Kd @ Phi, np.diag(modes.omega2), rtol=0, atol=1e-9 * w2[-1])
    assert np.all(Phi[clamped] == 0.0)                                    # clamped root
    assert np.max(modes.errors) < 1e-10


@pytest.mark.mpi
def test_frequencies_on_two_ranks_equal_serial():
    """SLEPc distributed over COMM_WORLD against a COMM_SELF copy on every rank (1e-8)."""
    comm = MPI.COMM_WORLD
    if MPI.COMM_WORLD.size < 2:
        pytest.skip("needs mpirun -n 2")
    s = load_scene(overrides=["mesh.solid=[20,4,2]"])
    par = clamped_modes(SolidModel(s, comm), 30, use_cache=False)
    ser = clamped_modes(SolidModel(s, MPI.COMM_SELF), 30, use_cache=False)
    rel = np.abs(par.omega2 / ser.omega2 - 1).max()
    if comm.rank == 0:
        print(f"\n30 clamped modes on {comm.size} ranks vs 1: max relative difference of "
              f"omega^2 {rel:.2e}; f1 = {par.frequencies_hz[0]:.4f} Hz, "
              f"f30 = {par.frequencies_hz[-1]:.2f} Hz")
    assert comm.size >= 2 and par.vectors.shape[0] < ser.vectors.shape[0]   # really split
    assert rel < 1e-8
