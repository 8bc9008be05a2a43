"""The quadratic eigenproblem of :mod:`fxflex.numerics.qep` for distributed PETSc matrices.

(lambda^2 M + lambda C + K) x = 0 by SLEPc's PEP solver (TOAR, the Krylov method on the companion
linearisation that never forms it) with shift-and-invert about a target sigma: each Krylov step
solves with P(sigma) = K + sigma C + sigma^2 M, factorised once by MUMPS (LU: K carries the
non-symmetric circulatory term of the absolute damping model). Around sigma = 0 the roots nearest
in magnitude are the lowest modes, the ones a rotating beam loses stability through (divergence,
where a root passes through 0, or flutter of the low modes). Collective on the matrices'
communicator; the vectors come back as this rank's entries.
"""

from __future__ import annotations

import numpy as np
from petsc4py import PETSc
from slepc4py import SLEPc

from fxflex.numerics.qep import EigenNotConverged

__all__ = ["pep_eigen", "make_direct", "TOL", "MAX_IT"]

#: relative residual the PEP converges each root to, by default
TOL = 1e-10
#: restarts of the Krylov iteration before the PEP gives up (SLEPc's max_it)
MAX_IT = 200


def make_direct(ksp: PETSc.KSP, *, symmetric: bool = True) -> PETSc.KSP:
    """Turn ``ksp`` (e.g. a SLEPc spectral transformation's) into one MUMPS factorisation and
    solve: LDL^T (Cholesky) when symmetric, LU otherwise."""
    ksp.setType("preonly")
    pc = ksp.getPC()
    pc.setType("cholesky" if symmetric else "lu")
    pc.setFactorSolverType("mumps")
    return ksp


def pep_eigen(M: PETSc.Mat, C: PETSc.Mat, K: PETSc.Mat, pairs: int, *, target: float = 0.0,
              tol: float | None = None, vectors: bool = True
              ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """The ``pairs`` roots nearest ``target`` with Im >= 0 (one per conjugate pair), as
    (lambda (k,), X (n_local, k) complex or None, backward errors (k,)), unsorted.

    SLEPc returns a complex pair as two consecutive roots; ``nev`` asks for both members of each
    pair plus a margin, so that at least ``pairs`` roots with Im >= 0 converge, and never more
    than the 2n roots there are (n the size of the matrices). Fewer converged roots raise
    :class:`~fxflex.numerics.qep.EigenNotConverged` carrying those that did."""
    pep = SLEPc.PEP().create(K.getComm())
    pep.setOperators([K, C, M])
    pep.setProblemType(SLEPc.PEP.ProblemType.GENERAL)
    pep.setType(SLEPc.PEP.Type.TOAR)
    pep.setScale(SLEPc.PEP.Scale.SCALAR)
    size = 2 * K.getSize()[0]
    nev = min(2 * pairs + 4, size)
    pep.setDimensions(nev=nev, ncv=min(max(2 * nev, nev + 32), size))
    pep.setTarget(target)
    pep.setWhichEigenpairs(SLEPc.PEP.Which.TARGET_MAGNITUDE)
    st = pep.getST()
    st.setType(SLEPc.ST.Type.SINVERT)
    make_direct(st.getKSP(), symmetric=False)
    pep.setTolerances(TOL if tol is None else tol, MAX_IT)
    pep.solve()
    nconv = pep.getConverged()
    xr, xi = K.createVecRight(), K.createVecRight()
    lam, cols, errors = [], [], []
    for i in range(nconv):
        value = pep.getEigenpair(i, xr, xi)
        if value.imag < 0.0:
            continue
        lam.append(complex(value))
        errors.append(pep.computeError(i, SLEPc.PEP.ErrorType.BACKWARD))
        if vectors:
            cols.append(xr.getArray(readonly=True) + 1j * xi.getArray(readonly=True))
    pep.destroy()
    xr.destroy()
    xi.destroy()
    X = np.column_stack(cols) if vectors and cols else None
    if len(lam) < pairs:
        raise EigenNotConverged(f"SLEPc PEP converged {len(lam)} of {pairs} eigenvalue pairs",
                                np.array(lam, dtype=complex), X)
    return np.array(lam), X, np.array(errors)
