"""TLF steady state: the rotating-frame equilibrium of the St.Venant-Kirchhoff solid.

Steady state (SPEC section 6, NOTES.md): in the rotating frame, with U = A^T x - x0,

    int S(E(U)) : dE dV - Omega^2 int rho P (X0 + U) . dU dV = F . dU,

St.Venant-Kirchhoff material, the centrifugal load acting on the deformed position, solved by
Newton's method with the Jacobian from ``ufl.derivative`` (geometric stiffness and spin softening
included). The absolute damping model adds its circulatory (c/rho) Omega int rho (S U) . dU (Eq. 68
seen from the hub, SPEC section 5), non-symmetric: Newton then factorises with LU. Above the speed
where the unstressed K_L - Omega^2 M_P loses definiteness the first Newton step would follow the
unstable linear mode, so the speed is raised in stages (continuation in Omega^2), each stage
starting from the previous equilibrium. A [tip_mass] adds its centrifugal load on its deformed
position (and circulatory term) through :class:`fxflex.solid.tip_mass.SteadyTerms`.

A sweep over speeds (the Campbell diagram, :mod:`fxflex.solid.tlf_sweep`) passes ``start``: an
equilibrium already known at a nearby speed (or a prediction of the one sought). Newton then
starts from it, the stages raising Omega^2 from that speed's in steps no larger than the cold
path's, and converges to the same absolute residual as a cold single-stage solve: rtol times the
residual of the undeformed body at this speed (the load the cold solve measures itself against).
Both end at the one equilibrium of the stable branch, so the two differ by the Newton tolerance,
not by which start was taken (tests/analysis/test_campbell_speed.py).
"""

from __future__ import annotations

import math
import time

import numpy as np
import ufl
from dolfinx import fem

from fxflex.formulation import SteadyState
from fxflex.solid import forms
from fxflex.solid.model import SolidModel
from fxflex.solid.solvers import newton
from fxflex.solid.tip_mass import SteadyTerms, tip_body

__all__ = ["tlf_steady", "STAGE_OMEGA"]

#: highest speed reached in one Newton solve from the undeformed state (rad/s); above it the
#: continuation raises Omega^2 in equal stages (1000 rpm default scene needs 1, 10000 rpm needs 3)
STAGE_OMEGA = 2 * math.pi * 6000 / 60


def tlf_steady(model: SolidModel, omega: float | None = None, *, rtol: float = 1e-10,
               max_it: int = 30, start: tuple[float, np.ndarray] | None = None,
               linear: str = "direct") -> SteadyState:
    """Rotating-frame TLF equilibrium at speed omega (rad/s; default the scene's), its Newton
    steps solved by the ``linear`` route (:func:`fxflex.solid.solvers.newton`). ``start`` =
    (omega0, U0): continue from the owned displacement U0, the equilibrium at omega0 or a
    prediction of it at omega (then omega0 = omega), as the module docstring says."""
    omega = model.scene.rotation.omega if omega is None else omega
    t0 = time.perf_counter()
    U = fem.Function(model.V)
    v, du = model.u_test, model.u_trial
    w2 = fem.Constant(model.mesh, 0.0)
    R = (forms.svk_residual(model.scene.material, U, v, model.dx)
         - w2 * forms.centrifugal(model.rho, model.X0 + U, v, model.dx))
    damping = model.scene.damping
    absolute = damping.model == "absolute" and damping.c > 0
    if absolute:                    # the circulatory (c/rho) Omega M_S U of Eq. 68 (SPEC 5)
        w1 = fem.Constant(model.mesh, 0.0)
        R = R + w1 * (damping.c / model.rho) * forms.mass_S(model.rho, U, v, model.dx)
    J = ufl.derivative(R, U, du)
    body = tip_body(model)                  # [tip_mass]: its terms are not forms
    extra = None if body is None else SteadyTerms(body, w2, w1 if absolute else None,
                                                  damping.c / model.rho)
    F_ext = model.rotating_load()
    reference, w2_start = None, 0.0
    if start is not None:
        # the cold single stage's reference: the residual of the undeformed body at omega
        w2.value = omega**2
        if absolute:
            w1.value = omega
        reference = newton(R, J, U, [model.bc], rhs=F_ext, max_it=0, symmetric=not absolute,
                           extra=extra).residuals[0]
        w2_start = start[0] ** 2
        U.x.array[: model.n_owned] = start[1]
        U.x.scatter_forward()
    t_setup = time.perf_counter() - t0
    if start is None:
        stages = max(1, math.ceil((omega / STAGE_OMEGA) ** 2))
    else:
        stages = max(1, math.ceil(abs(omega**2 - w2_start) / STAGE_OMEGA**2))
    residuals, iterations, converged, krylov = [], 0, True, []
    timings = {"setup": t_setup, "assemble": 0.0, "factor_solve": 0.0}
    for k in range(1, stages + 1):
        w2.value = w2_start + (omega**2 - w2_start) * k / stages
        if absolute:
            w1.value = math.sqrt(w2.value)
        res = newton(R, J, U, [model.bc], rhs=F_ext, rtol=rtol, max_it=max_it,
                     reference=reference, symmetric=not absolute, extra=extra, linear=linear)
        residuals = res.residuals
        krylov += res.krylov
        iterations += res.iterations
        for key in ("assemble", "factor_solve"):
            timings[key] += res.timings[key]
        if not res.converged:
            converged = False
            break
    tip = model.tip_displacement(U.x.array)
    return SteadyState(tip=tip, q=U.x.array[: model.n_owned].copy(), iterations=iterations,
                       residuals=residuals, converged=converged, timings=timings,
                       extra={"continuation_stages": stages, "linear": linear,
                              **({"krylov_iterations": krylov} if krylov else {})})


def prolongate(coarse: SolidModel, U: np.ndarray, fine: SolidModel) -> np.ndarray | None:
    """The owned entries of ``fine``'s displacement interpolated from the owned entries U of a
    displacement on ``coarse``: a starting guess for the fine equilibrium (nested iteration, the
    ``--tol`` ladder). Both meshes must be the generated ones of the paper's section (their
    nodes sit on the structured grid of the unit block mapped by the twist and the taper,
    :func:`fxflex.mesh.solid._generate`) and Q2 ``coarse``: U is then a tensor-product quadratic
    on that grid, evaluated at the fine nodes' grid coordinates (not the element's own geometric
    map, so a guess, not an interpolant of the finite-element function). None for any other
    mesh. Collective (the coarse field is gathered on every rank: the ladder's coarse meshes are
    small)."""
    from mpi4py import MPI

    from fxflex.mesh.geometry import BeamShape

    sc = fine.scene
    if (not sc.geometry.paper_shape or sc.mesh.solid_file or coarse.scene.mesh.solid_file
            or coarse.degree != 2 or coarse.scene.geometry != sc.geometry):
        return None
    shape = BeamShape(sc.geometry)

    def unit(X):                    # O-XYZ -> (x / L, eta + 1/2, zeta + 1/2) in [0, 1]^3
        return shape.unit_from_point(X) / np.array([shape.L, 1.0, 1.0]) + np.array([0, .5, .5])

    comm = coarse.comm
    n = np.array(coarse.scene.mesh.solid)                       # coarse divisions
    Xc = np.concatenate(comm.allgather(coarse.node_coordinates()))
    Uc = np.concatenate(comm.allgather(np.asarray(U)[: coarse.n_owned].reshape(-1, 3)))
    idx = np.rint(unit(Xc) * 2 * n).astype(int)                 # Q2 nodes: a 2n grid
    if np.any(idx < 0) or np.any(idx > 2 * n) or np.abs(unit(Xc) * 2 * n - idx).max() > 1e-6:
        return None
    grid = np.full(tuple(2 * n + 1) + (3,), np.nan)
    grid[idx[:, 0], idx[:, 1], idx[:, 2]] = Uc
    if comm.allreduce(bool(np.isnan(grid).any()), op=MPI.LOR):
        return None
    p = np.clip(unit(fine.node_coordinates()), 0.0, 1.0) * n   # in element units
    e = np.minimum(np.floor(p).astype(int), n - 1)
    t = p - e
    basis = np.stack([2 * (t - 0.5) * (t - 1), -4 * t * (t - 1), 2 * t * (t - 0.5)], axis=-1)
    out = np.zeros((len(p), 3))
    for a in range(3):
        for b in range(3):
            for c in range(3):
                w = basis[:, 0, a] * basis[:, 1, b] * basis[:, 2, c]
                out += w[:, None] * grid[2 * e[:, 0] + a, 2 * e[:, 1] + b, 2 * e[:, 2] + c]
    return out.reshape(-1)
