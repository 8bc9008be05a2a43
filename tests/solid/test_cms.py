"""Clamped eigenmodes from SLEPc (fxflex.solid.cms): against a dense LAPACK solve, and the same
frequencies on 2 ranks as on one.

Neither eigensolver gives the exact eigenvalues, and their round-off differs from one CPU and BLAS
to the next, so the comparison uses tolerances that each side certifies for itself: for a
symmetric-definite pencil (K, M) and any pair (lam, x), some eigenvalue lies within
||K x - lam M x||_{M^-1} / ||x||_M of lam (the residual bound applied to M^-1/2 K M^-1/2; Parlett,
The Symmetric Eigenvalue Problem, Thm 4.5.1). The residual is formed in double precision here, so
the bound adds its round-off, at most gamma_k (|K| |x| + |lam| |M| |x|) componentwise for k terms
per row (Higham, Accuracy and Stability of Numerical Algorithms, Eq. 3.11)."""

import numpy as np
import pytest
import scipy.linalg as la
from mpi4py import MPI

from fxflex.solid.cms import clamped_modes, mass_and_stiffness
from fxflex.scene import load_scene
from fxflex.solid.model import SolidModel

EPS = np.finfo(float).eps


def _dense(A):
    indptr, indices, data = A.getValuesCSR()
    n = A.getSize()[0]
    out = np.zeros((n, n))
    for i in range(n):
        out[i, indices[indptr[i]:indptr[i + 1]]] = data[indptr[i]:indptr[i + 1]]
    return out


def _gamma(k):
    """Higham's gamma_k = k u / (1 - k u), u the unit round-off: the relative error bound of a
    sum of k products."""
    return k * (EPS / 2) / (1 - k * EPS / 2)


def _residual(K, M, lam, x):
    """K x - lam M x as computed here, and the bound on its round-off (module docstring)."""
    k = max(np.count_nonzero(K, axis=1).max(), np.count_nonzero(M, axis=1).max()) + 1
    r = K @ x - lam * (M @ x)
    return r, _gamma(k) * (np.abs(K) @ np.abs(x) + abs(lam) * (np.abs(M) @ np.abs(x)))


def _certified_radius(K, M, chol_M, lam, x):
    """Radius around ``lam`` that holds an eigenvalue of (K, M) (module docstring): the residual in
    the M^-1 norm plus its round-off, both over ||x||_M."""
    r, slack = _residual(K, M, lam, x)

    def m_inv_norm(y):
        return np.sqrt(max(y @ la.cho_solve(chol_M, y), 0.0))

    return (m_inv_norm(r) + m_inv_norm(slack)) / np.sqrt(x @ M @ x)


@pytest.mark.serial
def test_modes_match_dense_generalised_eigensolve():
    """SLEPc's 12 lowest pairs against LAPACK's (scipy eigh) on the free unknowns, each eigenvalue
    to the sum of both sides' certified radii; M-orthonormality and K-orthogonality to the
    round-off of the products that measure them."""
    model = SolidModel(load_scene(overrides=["mesh.solid=[8,2,2]"]), MPI.COMM_SELF)
    K, M = mass_and_stiffness(model)
    tol = 1e-12
    modes = clamped_modes(model, 12, K=K, M=M, tol=tol, use_cache=False)     # SLEPc itself
    Kd, Md = _dense(K), _dense(M)
    clamped = np.concatenate([3 * model.root_nodes + i for i in range(3)])
    free = np.setdiff1d(np.arange(Kd.shape[0]), clamped)
    Kf, Mf = Kd[np.ix_(free, free)], Md[np.ix_(free, free)]
    chol = la.cho_factor(Mf)
    w2, V = la.eigh(Kf, Mf)
    w2, V = w2[:12], V[:, :12]
    Phi = modes.vectors
    assert np.all(Phi[clamped] == 0.0)                                    # clamped root
    assert np.all(np.diff(modes.omega2) > 0)
    radius = np.array([_certified_radius(Kf, Mf, chol, lam, x)
                       for lam, x in zip(modes.omega2, Phi[free].T)])
    dense_radius = np.array([_certified_radius(Kf, Mf, chol, lam, v) for lam, v in zip(w2, V.T)])
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
    assert np.abs(gram - np.eye(12)).max() <= n * EPS * np.linalg.cond(Mf)
    # x_i^T K x_j = lam_j x_i^T M x_j + x_i^T r_j, and |x_i^T r_j| <= ||x_i||_M ||r_j||_M^-1
    bound = (np.sqrt(np.diag(gram))[:, None] * radius[None, :]
             + modes.omega2[None, :] * np.abs(gram - np.eye(12))
             + _gamma(n) * (np.abs(Phi).T @ np.abs(Kd) @ np.abs(Phi)))
    assert np.all(np.abs(Phi.T @ Kd @ Phi - np.diag(modes.omega2)) <= bound)
    # the reported errors are SLEPc's relative residuals ||r|| / (lam ||x||): ours to the
    # round-off of forming r on either side
    for lam, x, err in zip(modes.omega2, Phi[free].T, modes.errors):
        r, slack = _residual(Kf, Mf, lam, x)
        scale = lam * np.linalg.norm(x)
        assert abs(err - np.linalg.norm(r) / scale) <= 2 * np.linalg.norm(slack) / scale
    # SLEPc converged on the shift-inverted operator to tol relative to 1/lam, and
    # K x - lam M x = -lam K (K^-1 M x - x / lam): a relative residual below tol ||K||_2 / lam,
    # plus the round-off of forming it
    knorm, mnorm = np.linalg.norm(np.abs(Kf), 2), np.linalg.norm(np.abs(Mf), 2)
    assert np.all(modes.errors <= (tol + _gamma(k)) * knorm / modes.omega2 + _gamma(k) * mnorm)


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
