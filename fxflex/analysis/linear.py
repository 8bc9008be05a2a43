"""The quadratic eigenproblem of the motion linearised about the rotating steady state, dense.

About an equilibrium in the rotating frame every formulation linearises to (SPEC section 6,
paper Eq. 59-64)

    M x'' + C x' + K x = 0,   C = 2 Omega M_S + D,   K = K_T(q*) - Omega^2 M_P [+ (c/rho) Omega M_S],

(gyroscopic, damping and, for the absolute damping model, circulatory terms) and x = e^(lambda t) x
turns it into (lambda^2 M + lambda C + K) x = 0. The small models (reduced and beam, at most a few
hundred unknowns) solve it here through the first-order companion form
[[0, I], [-M^-1 K, -M^-1 C]] with LAPACK; TLF uses SLEPc (:mod:`fxflex.analysis.petsc`).

Real matrices give eigenvalues in conjugate pairs; :func:`conjugate_pairs` keeps one root per pair
(and every real root), lowest frequency |Im lambda| first. The equilibrium is unstable when any
root has a positive real part (Sect. 4.1): :func:`rightmost` and :func:`unstable`.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as la

__all__ = ["companion", "companion_eigenvalues", "quadratic_eigen", "conjugate_pairs",
           "rightmost", "growth_rate", "unstable", "STABILITY_RTOL", "DenseStability"]

#: a root counts as growing when Re lambda > STABILITY_RTOL max|lambda|: the round-off of a dense
#: eigensolver is about eps ||A||, so a purely imaginary root of an undamped gyroscopic system can
#: come out with a real part of that size and either sign
STABILITY_RTOL = 1e-10


def companion(M: np.ndarray, C: np.ndarray, K: np.ndarray) -> np.ndarray:
    """The first-order form y' = A y of M x'' + C x' + K x = 0, y = (x, x')."""
    n = M.shape[0]
    A = np.zeros((2 * n, 2 * n))
    A[:n, n:] = np.eye(n)
    A[n:, :n] = -la.solve(M, K, assume_a="pos")
    A[n:, n:] = -la.solve(M, C, assume_a="pos")
    return A


def companion_eigenvalues(M: np.ndarray, C: np.ndarray, K: np.ndarray) -> np.ndarray:
    """All 2n eigenvalues of (lambda^2 M + lambda C + K) x = 0."""
    return la.eigvals(companion(M, C, K))


def quadratic_eigen(M: np.ndarray, C: np.ndarray, K: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
    """All eigenpairs (lambda (2n,), X (n, 2n)) of (lambda^2 M + lambda C + K) x = 0: the
    displacement part of the companion eigenvectors."""
    lam, Y = la.eig(companion(M, C, K))
    return lam, Y[: M.shape[0]]


def conjugate_pairs(lam: np.ndarray) -> np.ndarray:
    """Indices of one root per conjugate pair (Im >= 0) and of every real root, sorted by
    frequency |Im lambda|, then by decreasing real part."""
    keep = np.flatnonzero(lam.imag >= 0.0)
    order = np.lexsort((-lam[keep].real, np.abs(lam[keep].imag)))
    return keep[order]


def rightmost(lam: np.ndarray) -> tuple[float, float]:
    """(Re lambda, |Im lambda|) of the root with the largest real part."""
    i = int(np.argmax(lam.real))
    return float(lam[i].real), float(abs(lam[i].imag))


def growth_rate(M: np.ndarray, C: np.ndarray, K: np.ndarray) -> tuple[float, float]:
    """(largest real part, |imaginary part| of that root) of the quadratic eigenproblem."""
    return rightmost(companion_eigenvalues(M, C, K))


def unstable(lam: np.ndarray, rtol: float = STABILITY_RTOL) -> bool:
    """True when a root grows: Re lambda > rtol max|lambda| (round-off, see STABILITY_RTOL)."""
    lam = np.asarray(lam)
    return bool(lam.real.max() > rtol * np.abs(lam).max())


class DenseStability:
    """Eigenvalues, growth rate and stability verdict from a formulation's dense ``linearise()``
    -> (M, C, K); mixed into the reduced and beam formulations (each built for one scene, so the
    eigenvalues are computed once)."""

    _eigenvalues: np.ndarray | None = None

    def linearise(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        raise NotImplementedError

    def eigenvalues(self) -> np.ndarray:
        """All eigenvalues of the linearised rotating system (SPEC section 6, Eq. 59-64)."""
        if self._eigenvalues is None:
            self._eigenvalues = companion_eigenvalues(*self.linearise())
        return self._eigenvalues

    def rotating_modes(self, pairs: int) -> tuple[np.ndarray, np.ndarray]:
        """The ``pairs`` lowest roots, one per conjugate pair (:func:`conjugate_pairs`), and
        their mode vectors: (lambda (k,), X (dof, k) complex)."""
        lam, X = quadratic_eigen(*self.linearise())
        keep = conjugate_pairs(lam)[:pairs]
        return lam[keep], X[:, keep]

    def growth_rate(self) -> tuple[float, float]:
        """(Re lambda, |Im lambda|) of the rightmost root (1/s, rad/s)."""
        return rightmost(self.eigenvalues())

    def stable(self, steady=None) -> bool:
        """No root of the linearised rotating system grows (:func:`unstable`)."""
        return not unstable(self.eigenvalues())
