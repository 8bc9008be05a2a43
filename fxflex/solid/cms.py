"""Clamped-root eigenmodes of the solid for component mode synthesis (paper Sect. 2.1).

The reference condition of the floating frame is the clamped root (the paper's [16]), so the
component modes are the lowest eigenpairs of

    K_L x = omega^2 M x,    x = 0 on the root face,

with K_L the linear stiffness (Eq. 14) and M = M_ff the consistent mass (Eq. 11). SLEPc solves the
generalised Hermitian problem by shift-and-invert about 0 (MUMPS Cholesky of K_L), distributed over
the model's communicator. The clamped rows carry 1 on the diagonal of K_L and 0 on that of M: their
eigenvalues are infinite and never reach the target. Each mode is scaled to x^T M x = 1 and its
sign fixed so that the largest tip-centre component is positive (deterministic across ranks).

Everything the eigenmodes depend on is the scene's geometry, material and mesh, so this one
function is the place to cache them later.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from petsc4py import PETSc
from slepc4py import SLEPc

from fxflex.solid.model import SolidModel
from fxflex.solid.petsc import make_direct

__all__ = ["ClampedModes", "clamped_modes", "mass_and_stiffness"]


@dataclass(frozen=True)
class ClampedModes:
    """The lowest clamped eigenpairs; ``vectors`` holds this rank's owned entries."""

    omega2: np.ndarray          # (m,) eigenvalues omega^2 (rad^2/s^2), ascending
    vectors: np.ndarray         # (n_owned, m) mass-normalised modes, zero on the clamp
    errors: np.ndarray          # (m,) SLEPc relative residual norms
    timings: dict = field(default_factory=dict)

    @property
    def count(self) -> int:
        return self.omega2.size

    @property
    def omega(self) -> np.ndarray:
        """Circular frequencies (rad/s)."""
        return np.sqrt(self.omega2)

    @property
    def frequencies_hz(self) -> np.ndarray:
        return self.omega / (2 * np.pi)


def mass_and_stiffness(model: SolidModel) -> tuple[PETSc.Mat, PETSc.Mat]:
    """(K_L, M) assembled with the root clamp: 1 on K_L's clamped diagonal, 0 on M's."""
    K = model.matrix(model.compile(model.stiffness_form()))
    M = model.matrix(model.compile(model.mass_form()), diagonal=0.0)
    return K, M


def clamped_modes(model: SolidModel, count: int, *, K: PETSc.Mat | None = None,
                  M: PETSc.Mat | None = None, tol: float = 1e-12) -> ClampedModes:
    """The ``count`` lowest clamped eigenmodes of (K_L, M) on ``model.comm``.

    K and M may be passed when the caller has assembled them already (they must carry the clamp
    as :func:`mass_and_stiffness` does).
    """
    if count < 1:
        raise ValueError(f"count must be >= 1, got {count}")
    t0 = time.perf_counter()
    if K is None or M is None:
        K, M = mass_and_stiffness(model)
    t1 = time.perf_counter()
    eps = SLEPc.EPS().create(model.comm)
    eps.setOperators(K, M)
    eps.setProblemType(SLEPc.EPS.ProblemType.GHEP)
    eps.setDimensions(nev=count)
    eps.setWhichEigenpairs(SLEPc.EPS.Which.TARGET_MAGNITUDE)
    eps.setTarget(0.0)
    st = eps.getST()
    st.setType(SLEPc.ST.Type.SINVERT)
    st.setShift(0.0)
    make_direct(st.getKSP())
    eps.setTolerances(tol, 500)
    eps.solve()
    nconv = eps.getConverged()
    if nconv < count:
        raise RuntimeError(f"SLEPc converged {nconv} of {count} clamped eigenmodes")
    x = K.createVecRight()
    Mx = M.createVecLeft()
    pairs = []
    for i in range(nconv):
        lam = eps.getEigenpair(i, x).real
        pairs.append((lam, i))
    pairs.sort()
    n_owned = x.getLocalSize()
    vectors = np.empty((n_owned, count))
    omega2 = np.empty(count)
    errors = np.empty(count)
    for j, (lam, i) in enumerate(pairs[:count]):
        eps.getEigenpair(i, x)
        M.mult(x, Mx)
        x.scale(1.0 / np.sqrt(x.dot(Mx)))
        omega2[j] = lam
        errors[j] = eps.computeError(i)
        vectors[:, j] = x.getArray(readonly=True)
    eps.destroy()
    _fix_signs(model, vectors)
    t2 = time.perf_counter()
    return ClampedModes(omega2=omega2, vectors=vectors, errors=errors,
                        timings={"assemble_KM": t1 - t0, "eigensolve": t2 - t1})


def _fix_signs(model: SolidModel, vectors: np.ndarray) -> None:
    """Flip each mode so that its largest tip-centre component is positive."""
    local = np.zeros((3, vectors.shape[1]))
    if model.tip_node is not None:
        local[:] = vectors[3 * model.tip_node: 3 * model.tip_node + 3]
    tip = model.comm.allreduce(local)
    idx = np.argmax(np.abs(tip), axis=0)
    signs = np.sign(tip[idx, np.arange(tip.shape[1])])
    signs[signs == 0] = 1.0
    vectors *= signs
