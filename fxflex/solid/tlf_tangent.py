"""TLF implicit iteration matrix S = m M + c C_t + k K_t, factorised once in the hub frame
(paper Eq. 33-35; the rotation argument is in :class:`HubTangent`)."""

from __future__ import annotations

import math
import time
from typing import TYPE_CHECKING

import numpy as np
import ufl
from dolfinx import fem
from petsc4py import PETSc

from fxflex.numerics.director import FactorUpdate
from fxflex.numerics.hub import HubFrameFactor
from fxflex.solid import forms
from fxflex.solid.solvers import direct_solver

if TYPE_CHECKING:
    from fxflex.solid.tlf import TLF

__all__ = ["HubTangent"]


class HubTangent(HubFrameFactor):
    """The iteration matrix of implicit integration, S = m M + c C_t + k K_t, held in the hub frame.

    K_t = dQ_k/du + dQ_d/du and C_t = dQ_d/du' = D = (c/rho) M. The SVK force is objective,
    Q_k(u) = A_d Q_k(U) with U = A_d^T (x0 + u) - x0, so dQ_k/du = A_d K_T(U) A_d^T with K_T the
    ``ufl.derivative`` of the residual (Eq. 33) at U; M (lumped or M_s (x) I_3) commutes with
    A_d. Hence S(t) = A_d(phi(t)) S_hub A_d(phi(t))^T, S_hub = m M + c D + k K_T(U), and one
    factor of S_hub stays the tangent while the beam turns: ``solve`` rotates r into the hub
    frame, solves and rotates back. Left out of S_hub: the relative damping's dQ_d/du =
    -(c/rho) phi' M S_d (skew), k c/rho phi' relative to m: 1e-9 at 1000 rpm and dt = 10 us,
    which keeps S symmetric (MUMPS LDL^T) at no cost to Newton's convergence. Root rows and
    columns are the identity (the prescribed coordinates drop out). A [tip_mass] is isotropic
    node by node too (:mod:`fxflex.solid.tip_mass`): it is added to the assembled matrix here,
    with either mass of the solid; its extent along X adds (m + c c/rho) Pi_XX J^T J with J at the
    hub-frame U (J turns with the hub as the rest does: B_n(A g) = A B_n(g) diag(A, A)^T), and
    ``solve_hub`` replaces that part by the one at the state of the last ``force`` call, with
    c times the director's d(force)/dq' (:class:`fxflex.numerics.director.Director`), by Woodbury
    on the 6 columns S_hub^-1 W^T stored at the factorisation: the director's mass changes with
    the face's rotation while one factor serves many steps (without it the modified Newton
    contracted by 7e-3 with a rod along X at 3000 rpm and dt = 2 us, against 4e-3 with a disc).
    Left out: its dF/dq, k times the derivatives of its mass and velocity force, of the order
    k Omega^2 relative to its mass (1e-4 at 10000 rpm and dt = 10 us).
    """

    def __init__(self, tlf: TLF):
        from dolfinx.fem.petsc import create_matrix

        model, d = tlf.model, tlf.dynamics
        self.tlf, self.d = tlf, d
        t0 = time.perf_counter()
        self.U = fem.Function(model.V)
        self.kc = fem.Constant(model.mesh, 0.0)
        self.mc = fem.Constant(model.mesh, 0.0)
        R = forms.svk_residual(tlf.scene.material, self.U, model.u_test, model.dx)
        a = self.kc * ufl.derivative(R, self.U, model.u_trial)
        if d.mass != "lumped":
            a = a + self.mc * model.mass_form()
        self.form = fem.form(a)
        self.A = create_matrix(self.form)
        self.ksp = direct_solver(self.A)
        self.b, self.x = self.A.createVecs()
        self.b_arr, self.x_arr = self.b.getArray(), self.x.getArray()
        super().__init__(tlf.drive, self.b_arr, self.x_arr)
        if d.mass == "lumped":
            self.diag = self.A.createVecLeft()
            self.m_free = d.m.copy()
            self.m_free[d.root] = 0.0
        self.bcs = [model.bc]
        self.Ul = self.U.x.array
        tlf.timings["tangent_build"] = time.perf_counter() - t0

    def factorize(self, t: float, q: np.ndarray, m: float, c: float, k: float) -> None:
        from dolfinx.fem.petsc import assemble_matrix

        d = self.d
        phi = self.drive.angle(t)
        d.set_angle(math.cos(phi), math.sin(phi))
        n = d.n
        d.ul[:n] = q
        d.u_fn.x.scatter_forward()
        np.add(d.x0l, d.ul, out=d.work)              # U = A^T (x0 + u) - x0, as rows x^T A
        np.matmul(d.work.reshape(-1, 3), d.A, out=self.Ul.reshape(-1, 3))
        self.Ul -= d.x0l
        mass = m + c * d.c_rho
        self.kc.value = k
        self.mc.value = mass
        self.A.zeroEntries()
        assemble_matrix(self.A, self.form, bcs=self.bcs, diagonal=1.0)
        self.A.assemble()
        if d.body is not None:                   # the tip body's mu (x) I_3
            d.body.add_to(self.A, scale=mass)
            if d.director is not None:           # Pi_XX J^T J, J at the hub-frame U
                self._C6 = mass * d.director.mass6(self.Ul[:n])
                d.director.add_to(self.A, self._C6)
        if d.mass == "lumped":
            arr = self.diag.getArray()
            np.multiply(self.m_free, mass, out=arr)
            self.A.setDiagonal(self.diag, addv=PETSc.InsertMode.ADD_VALUES)
        self.ksp.getPC().setUp()                 # the numerical factorisation, now (KSPSetUp
        #                                          would leave it to the next solve)
        if d.director is not None:               # the director's part kept current
            self._update = FactorUpdate(d.director, self._solve_copy, self._C6, mass, c)

    def _solve_copy(self, b: np.ndarray) -> np.ndarray:
        self.b_arr[:] = b
        self.ksp.solve(self.b, self.x)
        return self.x_arr.copy()

    def solve_hub(self) -> None:
        self.ksp.solve(self.b, self.x)
        if self.d.director is not None:          # its mass and c d(force)/dq' at the last
            self._update.correct(self.x_arr, self._rotation)   # force(), in the hub frame
