"""What the TLF time loop touches, built once before it (STYLE habit 4): the internal force route,
the mass of Eq. 29 (lumped row sums or the factorised consistent mass), the loads, the root-node
data of the prescribed drive, the damped rate of Eq. 34 / 68, and the work arrays. A [tip_mass]
joins the mass (:mod:`fxflex.solid.tip_mass`): the inertial frame needs nothing else; its extent
along X (Pi_XX) is a configuration-dependent mass of rank 2, a Woodbury update of this one
(:class:`fxflex.numerics.director.Director`)."""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

import numpy as np
import ufl
from dolfinx import fem
from petsc4py import PETSc
from scipy.linalg.blas import daxpy

from fxflex.scene.kinematics import rotation_cs
from fxflex.solid.model import SolidModel
from fxflex.solid.solvers import direct_solver
from fxflex.solid.tip_mass import tip_body
from fxflex.solid.tlf_force import make_force

if TYPE_CHECKING:
    from fxflex.solid.tlf import TLF

__all__ = ["Dynamics", "axpy", "owned", "scalar_mass"]


class Dynamics:
    """Everything the time loop touches, built once: forces, mass, loads, root data, buffers."""

    def __init__(self, tlf: TLF):
        model, scene = tlf.model, tlf.scene
        t0 = time.perf_counter()
        V = model.V
        n = model.n_owned
        self.n = n
        self.rhs = np.empty(n)
        self.force = make_force(tlf.force_eval, model)
        tlf.timings["force_build"] = time.perf_counter() - t0
        # local (owned + ghost) work functions: displacement in, force out
        self.u_fn, self.f_fn = fem.Function(V), fem.Function(V)
        self.ul, self.fl = self.u_fn.x.array, self.f_fn.x.array
        self.x0l = V.tabulate_dof_coordinates().reshape(-1).copy()
        self.Ul, self.work = np.zeros_like(self.ul), np.zeros_like(self.ul)
        x03 = self.x0l[:n].reshape(-1, 3)
        self.Px0 = (x03 * np.array([1.0, 1.0, 0.0])).reshape(-1)
        self.Sx0 = np.column_stack([-x03[:, 1], x03[:, 0], np.zeros(len(x03))]).reshape(-1)
        # loads (owned parts)
        self.f_line = owned(model.line_load_vector(), n)
        self.tip_force = np.asarray(scene.load.tip_force, float)
        self.tip_now = np.empty(3)
        self.f_tip = [owned(b, n) for b in model.tip_traction_vectors()] \
            if np.any(self.tip_force) else []
        # root nodes (owned)
        self.root = (3 * model.root_owned[:, None] + np.arange(3)).reshape(-1)
        self.Px0_r, self.Sx0_r = self.Px0[self.root], self.Sx0[self.root]
        self._rb, self._rb2 = np.empty(self.root.size), np.empty(self.root.size)
        # mass (Eq. 29)
        t1 = time.perf_counter()
        self.mass = tlf.mass_kind
        self.body = body = tip_body(model)        # [tip_mass] (fxflex.solid.tip_mass)
        if self.mass == "lumped":
            self.m = model.lumped_mass()          # refused unless every entry > 0
            self.m_inv = 1.0 / self.m
            if body is not None:                  # (D + M_tip)^-1 by Sherman-Morrison-Woodbury
                body.diagonal(self.m)
        else:
            Mf = model.compile(model.mass_form())
            M_full = model.matrix(Mf, bcs=[])
            # M_fr u_r'' = alpha M_fr (P x0)_r + beta M_fr (S x0)_r: two fixed vectors
            self.lift_P = self._lifting(M_full, self.Px0_r)
            self.lift_S = self._lifting(M_full, self.Sx0_r)
            M_full.destroy()
            # M = M_s (x) I_3: factorise the scalar mass once (1/9 of the entries) and solve the
            # three components with it
            self.M = scalar_mass(model)
            if body is not None:                  # the scalar mu: the body moves with the tip nodes
                body.add_to(self.M, block=1)
            self.ksp = direct_solver(self.M)
            self.ksp.setUp()                               # factorise once, here
            self.b, self.x = self.M.createVecs()
            b_arr, x_arr = self.b.getArray(), self.x.getArray()
            self.components = [(self.rhs[j::3], b_arr, x_arr) for j in range(3)]
        self.director = body.director if body is not None else None
        if self.director is not None:             # Pi_XX: its Woodbury update of this mass
            self.director.prepare(self.base_solve)
        tlf.timings["mass_build"] = time.perf_counter() - t1
        # damping (Eq. 34 relative, Eq. 68 absolute)
        self.c_rho = scene.damping.c / scene.material.rho
        self.relative = scene.damping.model == "relative"
        # step buffers
        self.A = np.eye(3)
        self.y, self.my = np.empty(n), np.empty(n)
        self.root_nodes = model.root_owned

    def base_solve(self, x: np.ndarray) -> None:
        """x <- M0^-1 x on the owned entries, M0 the solid's mass with the body's isotropic part
        (root rows: the identity of the scalar mass, or 1 / m_a). Collective."""
        if self.mass == "lumped":
            x *= self.m_inv
            if self.body is not None:
                self.body.woodbury(x)
        else:
            for j, (_, b_arr, x_arr) in enumerate(self.components):
                b_arr[:] = x[j::3]
                self.ksp.solve(self.b, self.x)
                x[j::3] = x_arr

    def _lifting(self, M_full: PETSc.Mat, root_values: np.ndarray) -> np.ndarray:
        r, y = M_full.createVecs()
        r.set(0.0)
        r.getArray()[self.root] = root_values
        M_full.mult(r, y)
        out = y.getArray().copy()
        out[self.root] = 0.0
        return out

    def set_angle(self, c: float, s: float) -> None:
        rotation_cs(c, s, self.A)

    def root_combination(self, a: float, b: float) -> np.ndarray:
        """a P x0 + b S x0 on the root coordinates (a work array)."""
        np.multiply(self.Px0_r, a, out=self._rb)
        np.multiply(self.Sx0_r, b, out=self._rb2)
        self._rb += self._rb2
        return self._rb

    def damped_rate(self, dphi: float, c: float, s: float, q: np.ndarray, v: np.ndarray) -> None:
        """y: the velocity the damping acts on, in o-xyz. Relative (Eq. 34):
        u' - phi' S (x0 + u); absolute (Eq. 68): u' - u_r' = u' - phi' (cos phi S x0 -
        sin phi P x0)."""
        y = self.y
        y[:] = v
        if self.relative:
            m = y.size // 3                           # S u = (-u_y, u_x, 0), strided
            axpy(dphi, q, y, n=m, offx=1, incx=3, offy=0, incy=3)
            axpy(-dphi, q, y, n=m, offx=0, incx=3, offy=1, incy=3)
            axpy(-dphi, self.Sx0, y)
        else:
            axpy(-dphi * c, self.Sx0, y)
            axpy(dphi * s, self.Px0, y)


def axpy(a: float, x: np.ndarray, y: np.ndarray, **strides) -> None:
    """y += a x in place (BLAS daxpy, no temporary); y must be contiguous float64, which is
    checked because f2py would otherwise update a copy silently."""
    if daxpy(x, y, a=a, **strides) is not y:
        raise ValueError("axpy: y must be a contiguous float64 array")


def owned(vec: PETSc.Vec, n: int) -> np.ndarray:
    """A copy of the n owned entries of an assembled PETSc vector (ghost slots left out)."""
    return vec.getArray()[:n].copy()


def scalar_mass(model: SolidModel) -> PETSc.Mat:
    """The scalar consistent mass int rho N_a N_b (Eq. 29 per component), root rows and columns
    replaced by the identity. Its scalar space (Lagrange of the model's degree) numbers the nodes
    as the vector space does (checked)."""
    V1 = fem.FunctionSpace(model.mesh, ("Lagrange", model.degree))
    im, imv = V1.dofmap.index_map, model.V.dofmap.index_map
    if not (np.array_equal(V1.dofmap.list.array, model.V.dofmap.list.array)
            and im.size_local == imv.size_local and np.array_equal(im.ghosts, imv.ghosts)):
        raise RuntimeError("scalar and vector spaces number the nodes differently")
    u, v = ufl.TrialFunction(V1), ufl.TestFunction(V1)
    bc = fem.dirichletbc(0.0, model.root_nodes, V1)
    return model.matrix(fem.form(model.rho * u * v * model.dx), bcs=[bc])
