"""The highest circular frequency of the clamped solid at rest, w_max, behind the stable step of
central differences (dt < 2 / w_max, SPEC section 4): one SLEPc eigensolve."""

from __future__ import annotations

import math

import numpy as np

from fxflex.solid.model import SolidModel
from fxflex.solid.solvers import make_direct

__all__ = ["largest_frequency"]


def largest_frequency(model: SolidModel, mass: str, *, tol: float = 1e-8) -> float:
    """w_max = sqrt(lambda_max) of K_L x = lambda M x on the free coordinates (SLEPc).

    Lumped mass: the symmetric standard problem M^-1/2 K_L M^-1/2 (Krylov-Schur, largest
    eigenvalue). Consistent mass: the generalised Hermitian problem, with M factorised by MUMPS.
    Clamped rows carry 1 on the diagonal of both matrices (eigenvalue 1, far below the top).
    """
    from slepc4py import SLEPc

    K = model.matrix(model.compile(model.stiffness_form()))
    eps = SLEPc.EPS().create(model.comm)
    if mass == "lumped":
        m = model.vector(model.lumped_mass_form(), zero_clamped=False)
        owned = m.getArray()                       # ghost slots are not used by the scaling
        owned[:] = 1.0 / np.sqrt(model.lumped_mass())      # the same entries, checked > 0
        owned[(3 * model.root_owned[:, None] + np.arange(3)).reshape(-1)] = 1.0
        K.diagonalScale(m, m)
        eps.setOperators(K)
        eps.setProblemType(SLEPc.EPS.ProblemType.HEP)
    else:
        M = model.matrix(model.compile(model.mass_form()))
        eps.setOperators(K, M)
        eps.setProblemType(SLEPc.EPS.ProblemType.GHEP)
        st = eps.getST()
        st.setType(SLEPc.ST.Type.SHIFT)
        make_direct(st.getKSP())
    eps.setType(SLEPc.EPS.Type.KRYLOVSCHUR)
    eps.setWhichEigenpairs(SLEPc.EPS.Which.LARGEST_REAL)
    eps.setDimensions(nev=1, ncv=64)
    eps.setTolerances(tol, 2000)
    eps.solve()
    if eps.getConverged() < 1:
        raise RuntimeError("omega_max: SLEPc did not converge")
    lam = eps.getEigenvalue(0).real
    eps.destroy()
    return math.sqrt(lam)
