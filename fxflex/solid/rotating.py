"""TLF's motion linearised about its rotating equilibrium, as PETSc matrices on the free nodes.

NOTES.md ("Linearised about that state"), SPEC section 6: with U = A^T x - x0 the displacement seen
from the hub and U* the steady state, a perturbation dU obeys

    M dU'' + (2 Omega M_S + D) dU' + (K_T(U*) - Omega^2 M_P [+ (c/rho) Omega M_S]) dU = 0,

- M_B = int rho (B du) . v for the 3 x 3 matrices B = I, S, P of NOTES.md with the consistent mass
  (Eq. 29), or m_a B on node a with the lumped one that the transient integrates (row sums; HRZ
  on quadratic tetrahedra, :meth:`SolidModel.lumped_mass`): the inertial acceleration
  A (U'' + 2 Omega S U' - Omega^2 P (X0 + U)) seen through a mass that is isotropic node by node;
- D = (c/rho) M: the relative model (Eq. 34) damps the rotating-frame rate U'; the absolute model
  (Eq. 68) damps u' - u_r' = A (U' + Omega S U), which adds the non-symmetric circulatory
  (c/rho) Omega M_S to the stiffness;
- K_T(U*): ``ufl.derivative`` of the St.Venant-Kirchhoff residual (Eq. 33) at the steady state,
  material and geometric (prestress) stiffness; -Omega^2 M_P is the derivative of the centrifugal
  load on the deformed position (spin softening).
- a [tip_mass] adds mu (x) B to each M_B (with the consistent or the lumped mass of the
  solid: the body stays rigid, :mod:`fxflex.solid.tip_mass`); its extent along X (Pi_XX) adds
  the director's J^T J to M, 2 Omega J^T S J (+ (c/rho) J^T J) to C and its steady derivative
  to K, all at U* (:class:`fxflex.numerics.director.Director`: n the unit normal of the tip
  face's fit).

The root clamp is eliminated: every matrix is the sub-matrix on the free coordinates, which each
rank numbers in the order of its owned entries.
"""

from __future__ import annotations

import functools

import numpy as np
import ufl
from dolfinx import fem
from petsc4py import PETSc

from fxflex.numerics.petsc import PetscLinearisation, rigid_body_modes
from fxflex.scene.kinematics import P3, S3
from fxflex.solid import forms
from fxflex.solid.model import SolidModel
from fxflex.solid.tip_mass import tip_body

__all__ = ["Linearisation", "tlf_linearisation", "tlf_matrices", "free_entries", "k_symmetric"]


class Linearisation(PetscLinearisation):
    """(M, C, K) on the free coordinates, with the PEP analysis of
    :class:`~fxflex.numerics.petsc.PetscLinearisation` (``analysis``: its min_pairs, rtol,
    reassemble); ``free`` maps the coordinates to this rank's owned entries."""

    def __init__(self, M: PETSc.Mat, C: PETSc.Mat, K: PETSc.Mat, free: np.ndarray, n_owned: int,
                 **analysis):
        super().__init__(M, C, K, **analysis)
        self.free = free            # owned-entry index of each local free coordinate
        self.n_owned = n_owned


def free_entries(model: SolidModel) -> np.ndarray:
    """Owned-entry indices of the coordinates not on the clamped root, ascending."""
    clamped = np.zeros(model.n_owned, dtype=bool)
    clamped[(3 * model.root_owned[:, None] + np.arange(3)).reshape(-1)] = True
    return np.flatnonzero(~clamped)


def _nodal(model: SolidModel, m: np.ndarray, free: np.ndarray, B: np.ndarray) -> PETSc.Mat:
    """The lumped coupling m_a B on each free node a, on the free layout (CSR, 3 x 3 blocks)."""
    comm = model.comm
    n = free.size
    offset = comm.exscan(n) or 0
    rows, cols = np.nonzero(B)
    per_row = np.bincount(rows, minlength=3)
    nodes = n // 3
    indptr = np.concatenate([[0], np.cumsum(np.tile(per_row, nodes))]).astype(PETSc.IntType)
    base = offset + 3 * np.arange(nodes)[:, None]
    indices = (base + cols[None, :]).reshape(-1).astype(PETSc.IntType)
    data = (m[free].reshape(nodes, 3)[:, rows] * B[rows, cols]).reshape(-1)
    N = comm.allreduce(n)
    A = PETSc.Mat().createAIJ(size=((n, N), (n, N)), csr=(indptr, indices, data), comm=comm)
    A.assemble()
    return A


def tlf_linearisation(model: SolidModel, U: np.ndarray, omega: float, c_rho: float,
                      absolute: bool, mass: str, **analysis) -> Linearisation:
    """The linearisation of the module docstring about the owned steady displacement U (O-XYZ) at
    speed omega (rad/s), with the ``consistent`` or ``lumped`` mass; its matrices live only for
    an eigensolve and are assembled again if a later one asks for more roots. With
    ``linear="iterative"`` among ``analysis`` the PEP's shift-and-invert is a GAMG-preconditioned
    Krylov solve whose near-nullspace is the rigid-body modes on the free coordinates.
    Collective on ``model.comm``."""
    args = (model, U, omega, c_rho, absolute, mass)
    free = free_entries(model)
    if analysis.get("linear", "direct") == "iterative":
        analysis["nullspace"] = functools.partial(rigid_body_modes, model.V, free)
    return Linearisation(*tlf_matrices(*args), free, model.n_owned,
                         reassemble=functools.partial(tlf_matrices, *args), **analysis)


def k_symmetric(scene) -> bool:
    """The linearisation's K is symmetric: no circulatory term (c/rho) Omega M_S, which only the
    absolute damping model with damping and speed has."""
    return not (scene.damping.model == "absolute" and scene.damping.c > 0.0
                and scene.rotation.omega > 0.0)


def tlf_matrices(model: SolidModel, U: np.ndarray, omega: float, c_rho: float, absolute: bool,
                 mass: str) -> tuple[PETSc.Mat, PETSc.Mat, PETSc.Mat]:
    """(M, C, K) of the module docstring, assembled. Collective on ``model.comm``."""
    free = free_entries(model)
    first = model.V.dofmap.index_map.local_range[0] * 3
    rows = PETSc.IS().createGeneral((first + free).astype(PETSc.IntType), comm=model.comm)

    def sub(form) -> PETSc.Mat:
        full = model.matrix(fem.form(form), bcs=[])
        out = full.createSubMatrix(rows, rows)
        full.destroy()
        return out

    body = tip_body(model)
    if mass == "lumped":
        m = model.lumped_mass()          # HRZ on quadratic tetrahedra, positive

        def coupling(B: np.ndarray) -> PETSc.Mat:
            return _nodal(model, m, free, B)
    else:
        def coupling(B: np.ndarray) -> PETSc.Mat:
            return sub(model.rho * ufl.inner(ufl.dot(ufl.as_matrix(B.tolist()), model.u_trial),
                                             model.u_test) * model.dx)

    eye = np.eye(3)
    M = coupling(eye)

    def coupling_or_zero(B: np.ndarray) -> PETSc.Mat:
        if B.any():
            return coupling(B)
        Z = M.duplicate()                         # UFL drops a zero form: nothing to assemble
        Z.zeroEntries()
        return Z

    C = coupling_or_zero(2.0 * omega * S3 + c_rho * eye)
    u = fem.Function(model.V)
    u.x.array[: model.n_owned] = U
    u.x.scatter_forward()
    residual = forms.svk_residual(model.scene.material, u, model.u_test, model.dx)
    K = sub(ufl.derivative(residual, u, model.u_trial))
    B = -omega**2 * P3 + (c_rho * omega if absolute else 0.0) * S3
    if B.any():
        inertia = coupling(B)
        K.axpy(1.0, inertia, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
        inertia.destroy()
    rows.destroy()
    if body is not None:                 # mu (x) B for each M_B, either mass kind
        at = np.full(model.n_owned, -1, dtype=np.int64)
        at[free] = (model.comm.exscan(free.size) or 0) + np.arange(free.size)
        body.add_to(M, rows=at)
        body.add_to(C, 2.0 * omega * S3 + c_rho * eye, rows=at)
        body.add_to(K, B, rows=at)
        director = body.director
        if director is not None:         # Pi_XX: J^T J, 2 Omega J^T S J, the steady derivative
            circulatory = c_rho * omega if absolute else 0.0
            Bd, _, K6 = director.rotating(U, omega**2, circulatory)
            JJ = director.pi * (Bd.T @ Bd)
            director.add_to(M, JJ, rows=at)
            director.add_to(C, 2.0 * omega * director.pi * (Bd.T @ S3 @ Bd) + c_rho * JJ,
                            rows=at)
            director.add_to(K, K6, rows=at)
    return M, C, K
