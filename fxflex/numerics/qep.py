"""The quadratic eigenproblem of the motion linearised about the rotating steady state, dense.

About an equilibrium in the rotating frame every formulation linearises to (SPEC section 6,
paper Eq. 59-64)

    M x'' + C x' + K x = 0,   C = 2 Omega M_S + D,   K = K_T(q*) - Omega^2 M_P [+ (c/rho) Omega M_S],

(gyroscopic, damping and, for the absolute damping model, circulatory terms) and x = e^(lambda t) x
turns it into (lambda^2 M + lambda C + K) x = 0. The small models (reduced and beam, at most a few
hundred unknowns) solve it here through the first-order companion form
[[0, I], [-M^-1 K, -M^-1 C]] with LAPACK; TLF uses SLEPc (:mod:`fxflex.numerics.petsc`).

Real matrices give eigenvalues in conjugate pairs; :func:`conjugate_pairs` keeps one root per pair
(and every real root), lowest frequency |Im lambda| first. The equilibrium is unstable when any
root has a positive real part (Sect. 4.1): :func:`rightmost` and :func:`unstable`.

Heavy damping makes the problem badly scaled: with ||C|| >> sqrt(||M|| ||K||) (c = 1e30 gives
c/rho = 1.3e26 1/s against w_max = 3.5e5 rad/s) half the roots are about -c/rho and half about
-w^2 rho/c, and the companion form, of norm ||M^-1 C||, computes the small ones with an error of
eps ||M^-1 C|| = 1e10 1/s: they came out at +2.2e10 and were reported next to ``stable: true``.
There the roots are computed twice by the tropical scaling of Gaubert and Sharify (lambda =
gamma mu, gamma = ||C||/||M|| for the n large roots and ||K||/||C|| for the n small ones, each
scaled pencil solved by QZ), and each root's real part is compared with its own error estimate
(:func:`root_errors`), not with a fixed fraction of the largest root.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as la

__all__ = ["companion", "companion_eigenvalues", "quadratic_eigen", "conjugate_pairs",
           "damping_ratios",
           "rightmost", "growth_rate", "unstable", "root_errors", "STABILITY_RTOL",
           "TROPICAL_TAU", "DenseLinearisation", "EigenNotConverged", "verdict"]

#: a root counts as growing when Re lambda > STABILITY_RTOL max|lambda| (:func:`unstable`, for
#: callers without eigenvectors): the round-off of a dense eigensolver is about eps ||A||, so a
#: purely imaginary root of an undamped gyroscopic system can come out with a real part of that
#: size and either sign
STABILITY_RTOL = 1e-10
#: above this tau = ||C|| / sqrt(||M|| ||K||) the problem is solved with the tropical scaling
#: (the bound of Hammarling, Munro and Tisseur's quadeig, beyond which one scaling cannot make
#: both the large and the small roots accurate); the paper's scenes have tau below 1e-3
TROPICAL_TAU = 10.0


class EigenNotConverged(RuntimeError):
    """The eigensolver returned fewer roots than asked for; the ones it has are kept in
    ``eigenvalues`` (k,) and ``vectors`` (n, k) (or None)."""

    def __init__(self, message: str, eigenvalues: np.ndarray, vectors: np.ndarray | None):
        super().__init__(message)
        self.eigenvalues = eigenvalues
        self.vectors = vectors


def verdict(form, steady=None) -> tuple[bool | None, str | None]:
    """(stable, warning): the formulation's ``stable()`` (True, False, or None when its
    eigenvalues cannot decide, the reason then in ``form.stability_note``). A steady state that
    converged is kept whatever the eigensolver does: ``stable`` is null until the modal analysis
    exists (SPEC section 8)."""
    result = form.stable(steady)
    if result is None:
        return None, form.stability_note or "stability not decided"
    return bool(result), None


def companion(M: np.ndarray, C: np.ndarray, K: np.ndarray) -> np.ndarray:
    """The first-order form y' = A y of M x'' + C x' + K x = 0, y = (x, x')."""
    n = M.shape[0]
    A = np.zeros((2 * n, 2 * n))
    A[:n, n:] = np.eye(n)
    A[n:, :n] = -la.solve(M, K, assume_a="pos")
    A[n:, n:] = -la.solve(M, C, assume_a="pos")
    return A


def companion_eigenvalues(M: np.ndarray, C: np.ndarray, K: np.ndarray) -> np.ndarray:
    """All 2n eigenvalues of (lambda^2 M + lambda C + K) x = 0 (tropically scaled when heavily
    damped, :func:`quadratic_eigen`)."""
    m, c, k = _norms(M, C, K)
    if c > TROPICAL_TAU * np.sqrt(m * k):
        return _eigen_lr(M, C, K)[0]
    return la.eigvals(companion(M, C, K))


def _norms(M, C, K) -> tuple[float, float, float]:
    return tuple(float(np.linalg.norm(A, 2)) for A in (M, C, K))


def _scaled_pencil(M, C, K, gamma: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Eigenpairs of the pencil of P(gamma mu) / s (first companion form, QZ): (lambda, right
    vectors, left vectors of P), lambda = gamma mu, s the largest scaled coefficient norm."""
    n = M.shape[0]
    A2, A1, A0 = gamma**2 * M, gamma * C, K
    s = max(_norms(A2, A1, A0))
    A = np.zeros((2 * n, 2 * n))
    B = np.zeros((2 * n, 2 * n))
    A[:n, n:] = np.eye(n)
    A[n:, :n] = -A0 / s
    A[n:, n:] = -A1 / s
    B[:n, :n] = np.eye(n)
    B[n:, n:] = A2 / s
    ab, W, Z = la.eig(A, B, left=True, right=True, homogeneous_eigvals=True)
    alpha, beta = ab
    with np.errstate(divide="ignore", invalid="ignore"):    # infinite roots: beta = 0
        lam = gamma * (alpha / beta)
    return lam, Z[:n], W[n:]


def _eigen_lr(M, C, K) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """All roots with right and left eigenvectors of P: (lambda (2n,), X (n, 2n), Y (n, 2n)).

    tau <= TROPICAL_TAU: the companion form [[0, I], [-M^-1 K, -M^-1 C]], whose left vectors'
    second block w2 gives y = M^-1 w2. Beyond: the tropical scaling, the n largest roots from
    gamma = ||C|| / ||M||, the n smallest from gamma = ||K|| / ||C|| (Gaubert and Sharify: for
    tau >> 1 the roots split into n of modulus about each)."""
    n = M.shape[0]
    m, c, k = _norms(M, C, K)
    if not c > TROPICAL_TAU * np.sqrt(m * k):
        lam, W, Z = la.eig(companion(M, C, K), left=True, right=True)
        return lam, Z[:n], la.solve(M, W[n:], assume_a="pos")
    big, Xb, Yb = _scaled_pencil(M, C, K, c / m)
    small, Xs, Ys = _scaled_pencil(M, C, K, k / c)
    ib = np.argsort(-np.abs(np.nan_to_num(big, nan=np.inf)))[:n]
    is_ = np.argsort(np.abs(np.nan_to_num(small, nan=np.inf)))[:n]
    return (np.concatenate([big[ib], small[is_]]), np.hstack([Xb[:, ib], Xs[:, is_]]),
            np.hstack([Yb[:, ib], Ys[:, is_]]))


def root_errors(M: np.ndarray, C: np.ndarray, K: np.ndarray, lam: np.ndarray, X: np.ndarray,
                Y: np.ndarray) -> np.ndarray:
    """First-order error estimate of each computed root (1/s): the backward error of the pair
    (its residual relative to |lambda|^2 ||M|| + |lambda| ||C|| + ||K||, at least eps) times the
    root's condition number (Tisseur 2000):

        |d lambda| <= eta (|lambda|^2 ||M|| + |lambda| ||C|| + ||K||) ||x|| ||y||
                      / |y^H (2 lambda M + C) x|.

    A root whose real part is within this of zero is not decided by the arithmetic; it is
    counted as not growing (an undamped gyroscopic system's imaginary roots)."""
    m, c, k = _norms(M, C, K)
    eps = np.finfo(float).eps
    err = np.empty(lam.size)
    for i, z in enumerate(lam):
        x, y = X[:, i], Y[:, i]
        scale = abs(z) ** 2 * m + abs(z) * c + k
        res = np.linalg.norm((z * z) * (M @ x) + z * (C @ x) + K @ x)
        eta_scaled = max(res, 2 * M.shape[0] * eps * scale * np.linalg.norm(x))
        denom = abs(np.vdot(y, 2 * z * (M @ x) + C @ x))
        err[i] = eta_scaled * np.linalg.norm(y) / denom if denom > 0 else np.inf
    return err


def quadratic_eigen(M: np.ndarray, C: np.ndarray, K: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
    """All eigenpairs (lambda (2n,), X (n, 2n)) of (lambda^2 M + lambda C + K) x = 0: the
    displacement part of the companion eigenvectors (tropically scaled when heavily damped)."""
    lam, X, _ = _eigen_lr(M, C, K)
    return lam, X


def damping_ratios(lam: np.ndarray) -> np.ndarray:
    """-Re lambda / |lambda| of each root (0 for a root at the origin, NaN for a NaN root)."""
    lam = np.asarray(lam)
    mod = np.abs(lam)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(mod > 0, -lam.real / np.where(mod > 0, mod, 1.0), 0.0)


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


class DenseLinearisation:
    """The linearised motion M x'' + C x' + K x = 0 as dense arrays, and what follows from it:
    every root, computed once by LAPACK (:func:`_eigen_lr`, tropical scaling when badly scaled),
    each with its error estimate (:func:`root_errors`). The reduced and beam formulations'
    ``linearise()``; TLF's is :class:`fxflex.numerics.petsc.PetscLinearisation`, with the same
    methods."""

    kind = "dense"

    def __init__(self, M: np.ndarray, C: np.ndarray, K: np.ndarray):
        self.M, self.C, self.K = M, C, K
        self.dof = K.shape[0]
        self.note: str | None = None        # why :meth:`stable` is undecided, when it is
        self._eigen: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    def _eigenpairs(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(lambda, X, error estimate) of every root, computed once."""
        if self._eigen is None:
            M, C, K = self.M, self.C, self.K
            lam, X, Y = _eigen_lr(M, C, K)
            self._eigen = (lam, X, root_errors(M, C, K, lam, X, Y))
        return self._eigen

    def eigenvalues(self) -> np.ndarray:
        """All eigenvalues of the linearised rotating system (SPEC section 6, Eq. 59-64)."""
        return self._eigenpairs()[0]

    def modes(self, pairs: int) -> tuple[np.ndarray, np.ndarray]:
        """The ``pairs`` lowest roots, one per conjugate pair (:func:`conjugate_pairs`), and
        their mode vectors: (lambda (k,), X (dof, k) complex); all there are when fewer."""
        lam, X, _ = self._eigenpairs()
        keep = conjugate_pairs(lam)[:pairs]
        return lam[keep], X[:, keep]

    def growth_rate(self) -> tuple[float, float]:
        """(Re lambda, |Im lambda|) of the rightmost root (1/s, rad/s)."""
        return rightmost(self.eigenvalues())

    def stable(self) -> bool | None:
        """No root of the linearised rotating system grows: every real part is below its own
        error estimate (:func:`root_errors`). A positive real part within its estimate counts
        as zero when the root itself is resolved (an undamped system's imaginary roots, real
        parts of 1e-11 1/s); None (undecided, the reason in ``note``) when such a
        root is lost in round-off, its estimate at least its modulus (absolute damping
        c = 1e30: the circulatory term (c/rho) Omega M_S, 6e28, buries the stiffness, 6e11,
        below eps times it)."""
        lam, _, err = self._eigenpairs()
        if np.any(lam.real > err):
            return False
        lost = (lam.real > 0.0) & (err >= np.abs(lam))
        if lost.any():
            self.note = (f"stability not decided: {int(lost.sum())} roots of the "
                         "linearised system with a positive real part are below its "
                         f"round-off (error estimate up to {err[lost].max():.3g} 1/s, "
                         "at least their modulus)")
            return None
        return True

    def top_frequency(self) -> float | None:
        """sqrt of the largest eigenvalue of (K, M), the damping and gyroscopic terms left out
        (rad/s): the highest circular frequency about the steady state, for step limits; None
        when K is not finite (no usable steady state)."""
        if not np.all(np.isfinite(self.K)):
            return None
        n = self.K.shape[0]
        lam = la.eigh(0.5 * (self.K + self.K.T), self.M, eigvals_only=True,
                      subset_by_index=[n - 1, n - 1])[0]
        return float(np.sqrt(max(lam, 0.0)))

    def destroy(self) -> None:
        """Nothing to free (the PETSc linearisation frees its matrices)."""
