"""Clamped eigenmodes from SLEPc (fxflex.solid.cms): against a dense LAPACK solve, each side to
the accuracy it certifies (tests/solid/conftest.py), and the same frequencies on 2 ranks as on
one."""

import numpy as np
import pytest
import scipy.linalg as la
from mpi4py import MPI

from fxflex.solid.cms import clamped_modes, mass_and_stiffness
from fxflex.scene import load_scene
from fxflex.solid.model import SolidModel


@pytest.mark.serial
def test_modes_match_dense_generalised_eigensolve(eig):
    """SLEPc's 12 lowest pairs against LAPACK's (scipy eigh) on the free unknowns, each eigenvalue
    to the sum of both sides' certified radii; M-orthonormality and K-orthogonality to the
    round-off of the products that measure them."""
    model = SolidModel(load_scene(overrides=["mesh.solid=[8,2,2]"]), MPI.COMM_SELF)
    K, M = mass_and_stiffness(model)
    tol = 1e-12
    modes = clamped_modes(model, 12, K=K, M=M, tol=tol, use_cache=False)     # SLEPc itself
    Kd, Md = eig.dense(K), eig.dense(M)
    Kf, Mf, free = eig.free_pencil(model)
    clamped = np.setdiff1d(np.arange(Kd.shape[0]), free)
    chol = la.cho_factor(Mf)
    w2, V = la.eigh(Kf, Mf)
    w2, V = w2[:12], V[:, :12]
    Phi = modes.vectors
    assert np.all(Phi[clamped] == 0.0)                                    # clamped root
    assert np.all(np.diff(modes.omega2) > 0)
    radius = eig.radii(model, modes)
    dense_radius = np.array([eig.radius(Kf, Mf, chol, lam, v) for lam, v in zip(w2, V.T)])
    # the intervals are far narrower than the gaps, so the j-th of each side holds the j-th
    # eigenvalue: a missed or spurious mode cannot pass
    gap = np.minimum(np.r_[np.inf, np.diff(w2)], np.r_[np.diff(w2), np.inf])
    assert np.all(radius + dense_radius < 0.5 * gap)
    assert np.all(np.abs(modes.omega2 - w2) <= radius + dense_radius)
    n, k = len(free), np.count_nonzero(Kf, axis=1).max() + 1
    # Ritz vectors from SLEPc's basis, M-orthonormalised by iterated Gram-Schmidt: orthonormal to
    # the round-off of its M inner products, n eps ||M||_2 ||x||_2^2 <= n eps cond(M) when
    # x^T M x = 1 (the eigenvectors' own error, radius / gap, is far larger as a bound)
    gram = Phi.T @ Md @ Phi
    assert np.abs(gram - np.eye(12)).max() <= n * eig.EPS * np.linalg.cond(Mf)
    # x_i^T K x_j = lam_j x_i^T M x_j + x_i^T r_j, and |x_i^T r_j| <= ||x_i||_M ||r_j||_M^-1
    bound = (np.sqrt(np.diag(gram))[:, None] * radius[None, :]
             + modes.omega2[None, :] * np.abs(gram - np.eye(12))
             + eig.gamma(n) * (np.abs(Phi).T @ np.abs(Kd) @ np.abs(Phi)))
    assert np.all(np.abs(Phi.T @ Kd @ Phi - np.diag(modes.omega2)) <= bound)
    # the reported errors are SLEPc's relative residuals ||r|| / (lam ||x||): ours to the
    # round-off of forming r on either side
    for lam, x, err in zip(modes.omega2, Phi[free].T, modes.errors):
        r, slack = eig.residual(Kf, Mf, lam, x)
        scale = lam * np.linalg.norm(x)
        assert abs(err - np.linalg.norm(r) / scale) <= 2 * np.linalg.norm(slack) / scale
    # SLEPc converged on the shift-inverted operator to tol relative to 1/lam, and
    # K x - lam M x = -lam K (K^-1 M x - x / lam): a relative residual below tol ||K||_2 / lam,
    # plus the round-off of forming it
    knorm, mnorm = np.linalg.norm(np.abs(Kf), 2), np.linalg.norm(np.abs(Mf), 2)
    g = eig.gamma(k)
    assert np.all(modes.errors <= (tol + g) * knorm / modes.omega2 + g * mnorm)


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
