"""Small dense linear algebra shared by the beam formulations and the reduced solid models:
Newton steady states, the highest circular frequency, and the LU factor handle of implicit
integration (the eigenvalues of the linearised rotating system are in
:mod:`fxflex.numerics.qep`).

The beam models have at most a few thousand unknowns, so dense LAPACK is simple and fast.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as la

__all__ = ["newton", "omega_max", "DenseLU"]


def newton(residual, tangent, x0: np.ndarray, *, rtol: float = 1e-10, maxit: int = 30,
           steps: tuple[float, ...] = (1.0,)) -> tuple[np.ndarray, int, list[float], bool]:
    """Solve residual(x, s) = 0 by Newton's method, s stepping through ``steps`` (a load and
    speed-squared factor for continuation; the last must be 1). Converged when the residual norm
    has dropped by rtol relative to its initial value at s = 1 (or to zero-state scale), or when
    it has reached the round-off floor of its own evaluation and no longer halves: r = K x - f
    sums products whose size is |K| |x|, so it cannot be computed more accurately than about
    n_row eps || |J| |x| || (J the tangent, n_row its nonzeros per row). Fine beam meshes need
    this: K's entries grow as 1/h^3 while the loads do not, so 100 LEBB elements put the floor
    at 7e-10 of the initial residual, above ``rtol``.

    Returns (x, iterations, residual norms, converged)."""
    x = np.array(x0, dtype=float)
    history: list[float] = []
    iterations = 0
    r_zero = residual(np.zeros_like(x), 1.0)
    r0 = np.linalg.norm(r_zero)
    r_start = residual(x, 1.0) if np.any(x) else r_zero
    ref = max(r0, float(np.linalg.norm(r_start)))
    ref = ref if ref > 0 else 1.0
    # the residual at x0 for s = 1 is already known: the first iteration does not recompute it
    known = r_start if steps[0] == 1.0 else None
    converged = True
    for s in steps:
        ok = False
        for _ in range(maxit):
            r, known = (residual(x, s) if known is None else known), None
            rn = float(np.linalg.norm(r))
            history.append(rn)
            if rn <= rtol * ref:
                ok = True
                break
            J = tangent(x, s)
            if (len(history) > 1 and rn > 0.5 * history[-2]          # no longer halving
                    and rn <= _residual_floor(J, x)):
                ok = True
                break
            dx = np.linalg.solve(J, -r)
            x += dx
            iterations += 1
            if np.linalg.norm(dx) <= 1e-14 * max(np.linalg.norm(x), 1e-300):
                history.append(float(np.linalg.norm(residual(x, s))))
                ok = history[-1] <= min(1e3 * rtol, max(rtol, 1e-7)) * ref
                break
        converged = converged and ok
        if not np.all(np.isfinite(x)):
            return x, iterations, history, False
    return x, iterations, history, converged


def _residual_floor(J: np.ndarray, x: np.ndarray) -> float:
    """Round-off floor of ||J x - f|| evaluated in floating point: n_row eps || |J| |x| ||,
    n_row the largest count of nonzeros in a row of J (the products summed per entry)."""
    n_row = max(int(np.count_nonzero(J, axis=1).max(initial=1)), 1)
    return float(n_row * np.finfo(float).eps * np.linalg.norm(np.abs(J) @ np.abs(x)))


def omega_max(K: np.ndarray, M: np.ndarray) -> float:
    """Highest circular frequency sqrt(lambda_max) of K x = lambda M x (rad/s)."""
    n = K.shape[0]
    lam = la.eigh(K, M, eigvals_only=True, subset_by_index=[n - 1, n - 1])
    return float(np.sqrt(max(lam[0], 0.0)))


class DenseLU:
    """LU factor of a dense n x n matrix kept in one Fortran-ordered array (LAPACK getrf, in
    place), solved with getrs: the :class:`~fxflex.formulation.TangentFactor` of the small models.
    ``matrix`` is the array to fill before ``factor``; ``solve`` allocates no arrays."""

    def __init__(self, n: int):
        self.matrix = np.zeros((n, n), order="F")
        self.piv = np.zeros(n, dtype=np.int32)
        self._b = np.zeros(n)

    def factor(self) -> "DenseLU":
        lu, piv, info = la.lapack.dgetrf(self.matrix, overwrite_a=1)
        if info != 0:
            raise np.linalg.LinAlgError(f"iteration matrix is singular (getrf info {info})")
        if lu is not self.matrix:
            self.matrix[...] = lu
        self.piv[:] = piv
        return self

    def solve_into(self, r: np.ndarray, out: np.ndarray) -> None:
        """out = S^-1 r (r and out may be strided views, lengths n)."""
        b = self._b
        b[:] = r
        x, info = la.lapack.dgetrs(self.matrix, self.piv, b, overwrite_b=1)
        out[:] = x

    def solve(self, t: float, r: np.ndarray, out: np.ndarray) -> None:
        self.solve_into(r, out)
