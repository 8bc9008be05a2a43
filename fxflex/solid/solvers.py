"""PETSc-specific helpers for the solid formulations: direct or iterative linear solvers and a
Newton loop (docs/solvers.md)."""

from __future__ import annotations

import time

import numpy as np
from dolfinx import fem
from petsc4py import PETSc

from fxflex.numerics.petsc import ROUTES, make_direct, make_iterative, rigid_body_modes

__all__ = ["direct_solver", "iterative_solver", "linear_solver", "make_direct", "newton",
           "NewtonResult", "ROUTES"]


def direct_solver(A: PETSc.Mat, *, symmetric: bool = True) -> PETSc.KSP:
    """MUMPS factorisation of A (LDL^T when symmetric: indefinite matrices are fine).

    Changing A's values and calling ``solve`` refactors numerically, reusing the analysis.
    """
    ksp = PETSc.KSP().create(A.getComm())
    ksp.setOperators(A)
    return make_direct(ksp, symmetric=symmetric)


def iterative_solver(A: PETSc.Mat, V, *, symmetric: bool = True,
                     rtol: float = 1e-10) -> PETSc.KSP:
    """CG (GMRES when not ``symmetric``) with GAMG on A, the rigid-body modes of the vector space
    ``V`` as its near-nullspace (:func:`fxflex.numerics.petsc.make_iterative`)."""
    ksp = PETSc.KSP().create(A.getComm())
    ksp.setOperators(A)
    return make_iterative(ksp, symmetric=symmetric, rtol=rtol, nullspace=rigid_body_modes(V))


def linear_solver(A: PETSc.Mat, V, route: str = "direct", *, symmetric: bool = True,
                  rtol: float = 1e-10) -> PETSc.KSP:
    """The KSP of ``route`` (:data:`ROUTES`, the resolved ``[solver] linear``) on A."""
    if route not in ROUTES:
        raise ValueError(f"linear solver route {route!r}; allowed: {', '.join(ROUTES)}")
    if route == "direct":
        return direct_solver(A, symmetric=symmetric)
    return iterative_solver(A, V, symmetric=symmetric, rtol=rtol)


#: Krylov forcing of the iterative route's inexact Newton: a linear solve leaves at most this
#: fraction of the Newton target rtol * reference, so the last step lands below the target ...
FORCING = 0.1
#: ... and, relative to the current residual, at most ETA_EARLY (early steps: a tighter solve
#: buys nothing while the quadratic term of Newton's error is larger) and never more than ETA_MAX
ETA_EARLY, ETA_MAX = 1e-6, 0.1


class NewtonResult:
    def __init__(self):
        self.residuals: list[float] = []
        self.corrections: list[float] = []
        self.converged = False
        self.iterations = 0
        self.timings = {"assemble": 0.0, "factor_solve": 0.0}
        self.krylov: list[int] = []         # iterative route: Krylov iterations per step


#: relative size of a Newton correction below which the iterate is converged to round-off
STEP_TOL = 1e-12


def newton(residual, jacobian, u: fem.Function, bcs, *, rhs: PETSc.Vec | None = None,
           rtol: float = 1e-10, max_it: int = 30, reference: float | None = None,
           symmetric: bool = True, floor: float = 1e-8, extra=None,
           linear: str = "direct") -> NewtonResult:
    """Solve residual(u) - rhs = 0 by Newton's method with a MUMPS LDL^T of the exact Jacobian
    (LU when ``symmetric`` is False), or with ``linear = "iterative"`` by an inexact Newton
    method whose steps are GAMG-preconditioned CG (GMRES) solves (:func:`iterative_solver`)
    converged to eta ||b||, eta = FORCING rtol reference / ||b|| clipped to [ETA_EARLY, ETA_MAX]:
    a step leaves a linear residual below a tenth of the Newton target, or 1e-6 of the current
    residual early on, so the iteration stops on the same residual test as the direct route.

    ``u`` must satisfy the (homogeneous) Dirichlet conditions on entry; ``rhs`` is a constant
    vector (nodal loads that are not a form). Converged when the residual norm falls below
    ``rtol`` times ``reference`` (default: the first residual norm), or at the round-off floor of
    the assembled residual, which can lie above ``rtol``: when the last correction was below
    ``STEP_TOL`` of the solution (with a small load the internal force terms cancel, while the
    iterate is exact), or when the residual is already below ``floor`` times ``reference`` and an
    iteration no longer halves it (large meshes; Q2, 187200 unknowns: 1.2e-10 of the first
    residual, reached in 4 iterations, then 1.47e-7 -> 1.48e-7). ``extra``: terms that are not
    forms (the tip mass, :mod:`fxflex.solid.tip_mass`), an object whose ``residual(u, b)`` and
    ``jacobian(A)`` add theirs to the assembled b and A.
    """
    from dolfinx.fem.petsc import (assemble_matrix, assemble_vector, create_matrix,
                                   create_vector, set_bc)

    F, J = fem.form(residual), fem.form(jacobian)
    A, b = create_matrix(J), create_vector(F)
    du = b.duplicate()
    ksp = linear_solver(A, u.function_space, linear, symmetric=symmetric)
    out = NewtonResult()
    for it in range(max_it + 1):
        t0 = time.perf_counter()
        with b.localForm() as bl:
            bl.set(0.0)
        assemble_vector(b, F)
        b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        if rhs is not None:
            b.axpy(-1.0, rhs)
        if extra is not None:
            extra.residual(u, b)
        set_bc(b, bcs)
        norm = b.norm()
        out.timings["assemble"] += time.perf_counter() - t0
        out.residuals.append(norm)
        if reference is None:
            reference = norm if norm > 0 else 1.0
        stalled = ((bool(out.corrections) and out.corrections[-1] <= STEP_TOL * u.vector.norm())
                   or (len(out.residuals) > 1 and norm <= floor * reference
                       and norm > 0.5 * out.residuals[-2]))
        if norm <= rtol * reference or stalled or not np.isfinite(norm):
            out.converged = bool(np.isfinite(norm))
            break
        if it == max_it:
            break
        t0 = time.perf_counter()
        A.zeroEntries()
        assemble_matrix(A, J, bcs=bcs)
        A.assemble()
        if extra is not None:
            extra.jacobian(A)
        out.timings["assemble"] += time.perf_counter() - t0
        t0 = time.perf_counter()
        if linear == "iterative":
            eta = FORCING * rtol * reference / norm
            ksp.setTolerances(rtol=min(ETA_MAX, max(ETA_EARLY, eta)))
            ksp.getPC().setReusePreconditioner(it > 0)
        ksp.solve(b, du)
        if linear == "iterative":
            out.krylov.append(ksp.getIterationNumber())
            # the clamped rows (1 on the diagonal against stiffness entries ~E h) weigh nothing
            # in CG's energy norm: their small error would displace the root, so the step is
            # put back on the clamp exactly, as the factorisation leaves it
            set_bc(du, bcs)
        out.timings["factor_solve"] += time.perf_counter() - t0
        u.vector.axpy(-1.0, du)
        u.x.scatter_forward()
        out.corrections.append(du.norm())
        out.iterations = it + 1
    ksp.destroy()
    A.destroy()
    return out
