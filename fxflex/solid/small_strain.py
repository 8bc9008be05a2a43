"""Full-order small-strain equilibrium in the rotating frame.

(K_L - Omega^2 M_P) U = F + Omega^2 f_c: paper Eq. 59 with the time derivatives set to zero, on
all nodal coordinates instead of modes. It is what the reduced FFRF and GCMS equilibria approach as
modes are added (SPEC section 6).
"""

from __future__ import annotations

import time

import numpy as np
from dolfinx import fem

from fxflex.formulation import SteadyState
from fxflex.solid.model import SolidModel
from fxflex.solid.solvers import direct_solver

__all__ = ["linear_steady"]


def linear_steady(model: SolidModel, omega: float | None = None) -> SteadyState:
    """Solve the linear rotating-frame equilibrium at speed omega (rad/s; default the scene's)."""
    omega = model.scene.rotation.omega if omega is None else omega
    t0 = time.perf_counter()
    K = model.matrix(model.compile(model.stiffness_form()))
    MP = model.matrix(model.compile(model.mass_P_form()), diagonal=0.0)
    K.axpy(-omega**2, MP)
    b = model.rotating_load()
    b.axpy(omega**2, model.vector(model.centrifugal_form()))
    t1 = time.perf_counter()
    ksp = direct_solver(K)
    U = fem.Function(model.V)
    ksp.solve(b, U.vector)
    U.x.scatter_forward()
    t2 = time.perf_counter()
    tip = model.tip_displacement(U.x.array)
    res = K.createVecLeft()
    K.mult(U.vector, res)
    res.axpy(-1.0, b)
    rel = res.norm() / max(b.norm(), 1e-300)
    ksp.destroy()
    return SteadyState(tip=tip, q=U.x.array[: model.n_owned].copy(), iterations=1,
                       residuals=[rel], converged=bool(np.isfinite(tip).all()),
                       timings={"assemble": t1 - t0, "factor_solve": t2 - t1})
