"""Accuracy bounds of clamped eigenpairs, for tests that compare two eigensolves.

Neither of two eigensolvers gives the exact eigenvalues, and their round-off differs from one CPU
and BLAS to the next, so comparisons use tolerances each side certifies for itself: for a
symmetric-definite pencil (K, M) and any pair (lam, x), some eigenvalue lies within
||K x - lam M x||_{M^-1} / ||x||_M of lam (the residual bound applied to M^-1/2 K M^-1/2; Parlett,
The Symmetric Eigenvalue Problem, Thm 4.5.1). The residual is formed in double precision, so the
bound adds its round-off, at most gamma_k (|K| |x| + |lam| |M| |x|) componentwise for k terms per
row (Higham, Accuracy and Stability of Numerical Algorithms, Eq. 3.11).
"""

from types import SimpleNamespace

import numpy as np
import pytest
import scipy.linalg as la

EPS = np.finfo(float).eps


def dense(A) -> np.ndarray:
    """A serial PETSc matrix as a dense array."""
    indptr, indices, data = A.getValuesCSR()
    n = A.getSize()[0]
    out = np.zeros((n, n))
    for i in range(n):
        out[i, indices[indptr[i]:indptr[i + 1]]] = data[indptr[i]:indptr[i + 1]]
    return out


def gamma(k: int) -> float:
    """Higham's gamma_k = k u / (1 - k u), u the unit round-off: the relative error bound of a
    sum of k products."""
    return k * (EPS / 2) / (1 - k * EPS / 2)


def residual(K, M, lam, x):
    """K x - lam M x as computed here, and the bound on its round-off (module docstring)."""
    k = max(np.count_nonzero(K, axis=1).max(), np.count_nonzero(M, axis=1).max()) + 1
    r = K @ x - lam * (M @ x)
    return r, gamma(k) * (np.abs(K) @ np.abs(x) + abs(lam) * (np.abs(M) @ np.abs(x)))


def radius(K, M, chol_M, lam, x) -> float:
    """Radius around ``lam`` that holds an eigenvalue of (K, M) (module docstring): the residual in
    the M^-1 norm plus its round-off, both over ||x||_M."""
    r, slack = residual(K, M, lam, x)

    def m_inv_norm(y):
        return np.sqrt(max(y @ la.cho_solve(chol_M, y), 0.0))

    return (m_inv_norm(r) + m_inv_norm(slack)) / np.sqrt(x @ M @ x)


def free_pencil(model):
    """(K, M, free): the dense clamped pencil of a serial SolidModel on its free unknowns."""
    from fxflex.solid.cms import mass_and_stiffness

    Kd, Md = (dense(A) for A in mass_and_stiffness(model))
    clamped = np.concatenate([3 * model.root_nodes + i for i in range(3)])
    free = np.setdiff1d(np.arange(Kd.shape[0]), clamped)
    return Kd[np.ix_(free, free)], Md[np.ix_(free, free)], free


def radii(model, modes) -> np.ndarray:
    """The certified radius of each clamped mode of a serial SolidModel (module docstring)."""
    K, M, free = free_pencil(model)
    chol = la.cho_factor(M)
    return np.array([radius(K, M, chol, lam, x) for lam, x in zip(modes.omega2,
                                                                   modes.vectors[free].T)])


@pytest.fixture(scope="session")
def eig():
    """The helpers above, for the tests of this folder."""
    return SimpleNamespace(EPS=EPS, dense=dense, gamma=gamma, residual=residual, radius=radius,
                           free_pencil=free_pencil, radii=radii)
