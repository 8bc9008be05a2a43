"""TLF: total Lagrangian solid with Green-Lagrange strain (paper Sect. 2.3, Eq. 25-35).

Transient (Eq. 35), inertial frame, nodal displacements u = x - x0 (Eq. 25) as unknowns:

    M u'' + Q_d + Q_k(u) = Q_e(t).

- Q_k, the St.Venant-Kirchhoff internal force (Eq. 30-33), two ways on the same Gauss rule:
  ``ufl`` assembles the residual form every evaluation (the per-step integration of Eq. 65) and
  ``invariant`` applies the system invariant matrices K_L, K_N1, K_N2, K_N3 (Eq. 33, 35; see
  :mod:`fxflex.solid.invariant`). Both are evaluated on the displacement seen from the hub,
  U = A^T (x0 + u) - x0, and turned back, Q_k(u) = A Q_k(U): an identity (the Green-Lagrange strain
  does not change under the rigid rotation A, Eq. 30) that keeps the strain, which is small, from
  being computed as the difference of O(1) rotation terms. Measured at a 0.8 rad hub angle on the
  default mesh, evaluating on u directly loses 3e-7 (invariant) and 3e-11 (ufl) of the force.
- M, the mass of Eq. 29, ``consistent`` (factorised once, MUMPS) or ``lumped`` (row sums).
- Q_d = D [A A'^T (u - u_r) + (u' - u_r')] (Eq. 34, ``relative``) with D = (c / rho) M and u_r the
  rigid-rotation displacement (A - I) x0. Since A A'^T = -phi' S, this is D (u' - phi' S (x0 + u)):
  the rotating-frame deformation rate, turned to o-xyz. ``absolute`` (Eq. 68): D (u' - u_r'),
  u_r' = phi' S A x0. M^-1 D = c / rho, so damping costs no solve.
- Q_e: the centerline line load (along z, unchanged by the rotation) and the tip force, fixed in
  the rotating frame so A(phi) F in o-xyz, both times the load ramp.
- Root nodes follow the drive (NOTES.md): u = (A - I) x0, u' = phi' S A x0 and
  u'' = (phi'' S - phi'^2 P) A x0, written exactly by ``constrain`` and returned by
  ``acceleration``; the consistent mass moves their inertia to the right-hand side (M_fr u_r'').
- Initial state: undeformed, rigid rotation u = 0, u' = phi'(0) S x0.

Steady state (SPEC section 6, NOTES.md): in the rotating frame, with U = A^T x - x0,

    int S(E(U)) : dE dV - Omega^2 int rho P (X0 + U) . dU dV = F . dU,

St.Venant-Kirchhoff material, the centrifugal load acting on the deformed position, solved by
Newton's method with the Jacobian from ``ufl.derivative`` (geometric stiffness and spin softening
included). The absolute damping model adds its circulatory (c/rho) Omega int rho (S U) . dU (Eq. 68
seen from the hub, SPEC section 5), non-symmetric: Newton then factorises with LU. Above the speed where the unstressed K_L - Omega^2 M_P loses definiteness the first
Newton step would follow the unstable linear mode, so the speed is raised in stages (continuation
in Omega^2), each stage starting from the previous equilibrium.
"""

from __future__ import annotations

import math
import time
from typing import TYPE_CHECKING

import numpy as np
import ufl
from dolfinx import cpp, fem
from petsc4py import PETSc
from scipy.linalg.blas import daxpy

from fxflex.formulation import FORCE_EVAL, BuildOptions, FormulationBase, SteadyState
from fxflex.numerics.hub import HubFrameFactor
from fxflex.scene import Drive, Scene
from fxflex.scene.kinematics import rotation_cs, rotation_z
from fxflex.solid import forms
from fxflex.solid.model import SolidModel, solid_dof_count
from fxflex.solid.petsc import direct_solver, make_direct, newton

if TYPE_CHECKING:
    from fxflex.solid.rotating import Linearisation

__all__ = ["TLF", "UflForce", "FieldWriter", "build", "dof_count", "tlf_steady", "largest_frequency",
           "DEFAULT_MASS"]

#: highest speed reached in one Newton solve from the undeformed state (rad/s); above it the
#: continuation raises Omega^2 in equal stages (1000 rpm default scene needs 1, 10000 rpm needs 3)
_STAGE_OMEGA = 2 * math.pi * 6000 / 60

#: C flags for the residual kernel of the time loop: vector instructions of this CPU and
#: reassociated sums (the kernel's sums over the 8 nodes then vectorise), NaN and inf still
#: propagate (no -ffinite-math-only). 4.7 -> 3.7 ms per evaluation on the default mesh.
KERNEL_FLAGS = ["-O2", "-march=native", "-fno-math-errno", "-fno-trapping-math",
                "-fno-signed-zeros", "-fassociative-math"]

#: mass used when --mass is not given: lumped (see docs/tlf.md, the consistent mass needs a
#: triangular solve per step and lowers the stable CD step)
DEFAULT_MASS = "lumped"


#: lowest eigenvalue pairs behind ``stable()`` and ``growth_rate()``
STABILITY_PAIRS = 8
#: a root counts as growing when Re lambda > this x max|lambda| of the computed roots: the PEP
#: converges to a relative residual of 1e-10, so a purely imaginary root of the undamped system
#: comes out with a real part of about that size
PEP_STABILITY_RTOL = 1e-8


def dof_count(scene: Scene) -> int:
    return solid_dof_count(scene)


def tlf_steady(model: SolidModel, omega: float | None = None, *, rtol: float = 1e-10,
               max_it: int = 30) -> SteadyState:
    """Rotating-frame TLF equilibrium at speed omega (rad/s; default the scene's)."""
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
    F_ext = model.rotating_load()
    t_setup = time.perf_counter() - t0
    stages = max(1, math.ceil((omega / _STAGE_OMEGA) ** 2))
    residuals, iterations, converged = [], 0, True
    timings = {"setup": t_setup, "assemble": 0.0, "factor_solve": 0.0}
    for k in range(1, stages + 1):
        w2.value = omega**2 * k / stages
        if absolute:
            w1.value = math.sqrt(w2.value)
        res = newton(R, J, U, [model.bc], rhs=F_ext, rtol=rtol, max_it=max_it,
                     symmetric=not absolute)
        residuals = res.residuals
        iterations += res.iterations
        for key in ("assemble", "factor_solve"):
            timings[key] += res.timings[key]
        if not res.converged:
            converged = False
            break
    tip = model.tip_displacement(U.x.array)
    return SteadyState(tip=tip, q=U.x.array[: model.n_owned].copy(), iterations=iterations,
                       residuals=residuals, converged=converged, timings=timings,
                       extra={"continuation_stages": stages})


class UflForce:
    """Q_k(u) by assembling the SVK residual int (F S) : grad v (Eq. 33) each evaluation.

    The coefficient array of the form is packed in place from the local displacement array (one
    gather), so an evaluation allocates nothing in Python; ``apply(u, out)`` takes and fills local
    (owned + ghost) arrays, ghost entries holding partial sums like any assembled vector.
    """

    def __init__(self, model: SolidModel):
        t0 = time.perf_counter()
        self.u = fem.Function(model.V)
        self.form = fem.form(forms.svk_residual(model.scene.material, self.u, model.u_test,
                                                model.dx),
                             jit_params={"cffi_extra_compile_args": KERNEL_FLAGS})
        self.constants = cpp.fem.pack_constants(self.form)
        self.coeffs = cpp.fem.pack_coefficients(self.form)
        (self._packed,) = self.coeffs.values()          # (cells, 24), refilled in place
        n_cells = self._packed.shape[0]
        nodes = model.V.dofmap.list.array.reshape(-1, 8)[:n_cells]
        self._gather = (3 * nodes[:, :, None] + np.arange(3)).reshape(-1)
        self._flat = self._packed.reshape(-1)
        self.build_time = time.perf_counter() - t0

    def apply(self, u: np.ndarray, out: np.ndarray) -> None:
        np.take(u, self._gather, out=self._flat, mode="clip")   # "raise" buffers out
        out[:] = 0.0
        cpp.fem.assemble_vector(out, self.form, self.constants, self.coeffs)

    def memory_bytes(self) -> dict[str, int]:
        """Bytes held beyond the mesh: the packed coefficient and its gather indices."""
        return {"coefficients": self._packed.nbytes, "gather_index": self._gather.nbytes}


def _make_force(kind: str, model: SolidModel):
    if kind == "ufl":
        return UflForce(model)
    from fxflex.solid.invariant import InvariantForce
    return InvariantForce(model)


class TLF(FormulationBase):
    """The TLF formulation behind the :class:`~fxflex.formulation.Formulation` interface.

    The transient operators are built on the first call of ``initial_state`` (eagerly when the
    options say no steady state is needed, as ``fxflex run`` does), never inside the time loop.
    """

    method = "tlf"
    #: a distributed mesh field whose nodal displacements turn with the hub; the SLEPc PEP gives
    #: the lowest roots only
    distributed, steady_at_rest, all_roots = True, False, False
    #: geometrically exact (Green-Lagrange strain): a run stops only beyond 2 L of deflection
    #: (fxflex.time.driver.divergence_limit)
    deflection_range = 2.0

    def __init__(self, scene: Scene, comm, options: BuildOptions, *, hub_frame: bool = True):
        t0 = time.perf_counter()
        self.scene, self.options = scene, options
        self.model = SolidModel(scene, comm)
        self.comm = comm
        self.dof = self.model.dof
        self.force_eval = options.force_eval or FORCE_EVAL["tlf"][0]
        self.mass_kind = options.mass or DEFAULT_MASS
        self.drive = Drive(scene.rotation)
        # at rest A = I: the hub-frame turn of the force (below) would multiply by identities
        self.hub_frame = hub_frame and not self.drive.at_rest
        self.timings = dict(self.model.timings)
        self._dyn: _Dynamics | None = None
        self._tangent: HubTangent | None = None
        self._omega_max: float | None = None
        self._root: tuple | None = None
        self._steady: SteadyState | None = None
        if not options.need_steady:
            self._dyn = _Dynamics(self)
        self.timings["build"] = time.perf_counter() - t0

    @property
    def dynamics(self) -> _Dynamics:
        if self._dyn is None:
            self._dyn = _Dynamics(self)
        return self._dyn

    # -- Formulation interface --------------------------------------------------------------------
    def steady_state(self) -> SteadyState:
        if self._steady is None:
            self._steady = tlf_steady(self.model)
        return self._steady

    def initial_state(self) -> tuple[np.ndarray, np.ndarray]:
        """u = 0, u' = phi'(0) S x0: the undeformed body in rigid rotation (NOTES.md)."""
        d = self.dynamics
        return np.zeros(d.n), self.drive.rate(0.0) * d.Sx0

    def constrain(self, t: float, q: np.ndarray, v: np.ndarray) -> None:
        """Root nodes: u = (A - I) x0 = (cos phi - 1) P x0 + sin phi S x0 and
        u' = phi' S A x0 = phi' (cos phi S x0 - sin phi P x0)."""
        d = self.dynamics
        phi, dphi = self.drive.angle(t), self.drive.rate(t)
        c, s = math.cos(phi), math.sin(phi)
        q[d.root] = d.root_combination(c - 1.0, s)
        v[d.root] = d.root_combination(-dphi * s, dphi * c)

    def _loads(self, t: float, q: np.ndarray) -> tuple[float, float, float, float, float]:
        """d.rhs = Q_e - Q_k(u) [- M_fr u_r'' with the consistent mass] on the free rows (root
        rows hold the reactions); returns (alpha, beta, phi', cos phi, sin phi) with
        u_r'' = alpha P x0 + beta S x0."""
        d = self.dynamics
        phi, dphi, ddphi = self.drive.state(t)
        c, s = math.cos(phi), math.sin(phi)
        d.set_angle(c, s)
        rhs = d.rhs
        np.negative(self.internal_force(q), out=rhs)
        lam = self.scene.load.factor(t)
        _axpy(lam, d.f_line, rhs)
        if d.f_tip:
            np.dot(d.A, d.tip_force, out=d.tip_now)  # fixed in the rotating frame: A F
            for j in range(3):
                _axpy(lam * d.tip_now[j], d.f_tip[j], rhs)
        alpha = -ddphi * s - dphi * dphi * c
        beta = ddphi * c - dphi * dphi * s
        if d.mass != "lumped":
            _axpy(-alpha, d.lift_P, rhs)        # - M_fr u_r''
            _axpy(-beta, d.lift_S, rhs)
        return alpha, beta, dphi, c, s

    def acceleration(self, t: float, q: np.ndarray, v: np.ndarray, out: np.ndarray) -> None:
        """out = M^-1 (Q_e - Q_k(u) - Q_d) on free nodes (Eq. 35); on root nodes the prescribed
        u_r'' = (phi'' S - phi'^2 P) A x0 = alpha P x0 + beta S x0."""
        d = self.dynamics
        alpha, beta, dphi, c, s = self._loads(t, q)
        rhs = d.rhs
        if d.mass == "lumped":
            np.multiply(rhs, d.m_inv, out=out)
        else:
            rhs[d.root] = d.root_combination(alpha, beta)
            for j, (rhs_j, b_arr, x_arr) in enumerate(d.components):
                b_arr[:] = rhs_j
                d.ksp.solve(d.b, d.x)
                out[j::3] = x_arr
        if d.c_rho > 0.0:                        # M^-1 D = c / rho
            if dphi == 0.0:                      # not turning: both models damp u'
                _axpy(-d.c_rho, v, out)
            else:
                d.damped_rate(dphi, c, s, q, v)
                _axpy(-d.c_rho, d.y, out)
        out[d.root] = d.root_combination(alpha, beta)

    # -- implicit integration (formulation.Implicit) ----------------------------------------------
    def force(self, t: float, q: np.ndarray, v: np.ndarray, out: np.ndarray) -> None:
        """F = Q_e - Q_k(u) - Q_d - M_fr u_r'' on the free rows (Eq. 35), 0 on the root. Q_d =
        (c/rho) M y with the damped rate y of ``damped_rate``, which is zero on the root nodes
        (they move rigidly), so M y = M_ff y_f."""
        d = self.dynamics
        _, _, dphi, c, s = self._loads(t, q)
        out[:] = d.rhs
        if d.c_rho > 0.0:
            d.damped_rate(dphi, c, s, q, v)
            self.mass_apply(d.y, d.my)
            _axpy(-d.c_rho, d.my, out)
        out[d.root] = 0.0

    def mass_apply(self, x: np.ndarray, out: np.ndarray) -> None:
        """M_ff x_f: lumped row sums, or the consistent mass per component (M = M_s (x) I_3)."""
        d = self.dynamics
        if d.mass == "lumped":
            np.multiply(x, d.m, out=out)
        else:
            for j, (_, b_arr, x_arr) in enumerate(d.components):
                b_arr[:] = x[j::3]
                b_arr[d.root_nodes] = 0.0              # the scalar mass is 1 on root rows
                d.M.mult(d.b, d.x)
                out[j::3] = x_arr
        out[d.root] = 0.0

    def factorize(self, t: float, q: np.ndarray, v: np.ndarray, m: float, c: float, k: float
                  ) -> "HubTangent":
        """S = m M + c C_t + k K_t factorised in the hub frame (MUMPS LDL^T, see
        :class:`HubTangent`); built (forms compiled, matrix allocated) on the first call."""
        if self._tangent is None:
            self._tangent = HubTangent(self)
        self._tangent.factorize(t, q, m, c, k)
        return self._tangent

    def tip(self, t: float, q: np.ndarray) -> np.ndarray:
        """Free-end deflection in O-XYZ, U = A^T (x0 + u) - x0 of the tip centre (SPEC 2)."""
        return self.model.tip_relative(q, self.drive.angle(t))

    def state_points(self) -> np.ndarray:
        """Undeformed coordinates of the owned nodes, in state order (three entries per node):
        how a checkpoint orders the distributed state independently of the partition."""
        return self.model.node_coordinates()

    def omega_max(self) -> float:
        """Highest circular frequency of the clamped body, sqrt of the largest eigenvalue of
        K_L x = w^2 M x with the mass in use (SLEPc, computed once). Central difference is stable
        for dt < 2 / w_max (SPEC section 4). K_L stands for the tangent: the centrifugal
        prestress moves w_max by about sigma / E (1e-4 at 1000 rpm)."""
        if self._omega_max is None:
            self._omega_max = largest_frequency(self.model, self.mass_kind)
        return self._omega_max

    def memory_bytes(self) -> dict[str, int]:
        """Bytes held by this rank for the internal force route and the mass."""
        d = self.dynamics
        out = {f"force_{k}": v for k, v in d.force.memory_bytes().items()}
        if d.mass == "lumped":
            out["mass_lumped"] = d.m_inv.nbytes
        else:
            # MUMPS INFO(9): real entries of this rank's factor (negative: in millions)
            entries = d.ksp.getPC().getFactorMatrix().getMumpsInfo(9)
            out["mass_factor"] = 8 * (entries if entries >= 0 else -entries * 10**6)
        return out

    def field_writer(self, path: str) -> "FieldWriter":
        """``--fields``: an XDMF series of the displacement for ParaView (rank-collective)."""
        return FieldWriter(self, path)

    def root_stress(self, t: float, q: np.ndarray) -> np.ndarray:
        """sigma_X (Pa) at the four corners of the root section: the resultants of the SVK
        stress (Eq. 30-33) in the root cells on U = A^T (x0 + u) - x0 (the steady state's q is U
        itself, at phi = 0), spread linearly over the section (:mod:`fxflex.solid.section`).
        Collective on ``comm``."""
        if self._root is None:
            self._root = (self.model.root_section("svk"), self.model.node_coordinates())
        section, x0 = self._root
        A = rotation_z(self.drive.angle(t))
        U = ((x0 + q.reshape(-1, 3)) @ A - x0).reshape(-1)
        return self.model.shape.axial_stress(0.0, section.resultants(U))

    def tangent(self, q: np.ndarray) -> PETSc.Mat:
        """The tangent stiffness dQ_k/du at the owned displacements q (o-xyz, no constraints):
        ``ufl.derivative`` of the SVK residual (Eq. 33), assembled."""
        u = fem.Function(self.model.V)
        u.x.array[: q.size] = q
        u.x.scatter_forward()
        R = forms.svk_residual(self.scene.material, u, self.model.u_test, self.model.dx)
        return self.model.matrix(ufl.derivative(R, u, self.model.u_trial), bcs=[])

    # -- linearised motion about the steady state (SPEC section 6) --------------------------------
    def linearise(self, steady: SteadyState | None = None) -> Linearisation:
        """(M, C, K) of the motion about the rotating equilibrium as PETSc matrices on the free
        coordinates, with the mass in use (:mod:`fxflex.solid.rotating`), analysed by SLEPc's
        PEP: the STABILITY_PAIRS lowest roots decide the verdict, a root growing when its real
        part exceeds PEP_STABILITY_RTOL of the largest modulus. Collective."""
        from fxflex.solid.rotating import tlf_linearisation

        st = steady or self.steady_state()
        sc = self.scene
        return tlf_linearisation(self.model, st.q, sc.rotation.omega,
                                 sc.damping.c / sc.material.rho, sc.damping.model == "absolute",
                                 self.mass_kind, min_pairs=STABILITY_PAIRS,
                                 rtol=PEP_STABILITY_RTOL)

    def top_frequency(self) -> float:
        """``omega_max()``: the clamped body at rest, one SLEPc solve, rather than a steady state
        and a linearisation (step limits do not need the rotating state's)."""
        return self.omega_max()

    def mode_tip(self, X: np.ndarray) -> np.ndarray:
        """(6, k) tip translation and section rotation of mode vectors on the free coordinates
        (:meth:`SolidModel.tip_section`). Collective."""
        from fxflex.solid.rotating import free_entries

        full = np.zeros((self.model.n_owned,) + X.shape[1:], dtype=X.dtype)
        full[free_entries(self.model)] = X
        return self.model.tip_section(full)

    # -- pieces -----------------------------------------------------------------------------------
    def internal_force(self, q: np.ndarray) -> np.ndarray:
        """Q_k(u) (Eq. 33, 35) for the owned displacements q, ghosts accumulated: a view of the
        owned part of a work array, valid until the next call. The hub angle is the one last set
        by ``dynamics.set_angle`` (``acceleration`` sets it)."""
        d = self.dynamics
        n = d.n
        d.ul[:n] = q
        d.u_fn.x.scatter_forward()
        if self.hub_frame:
            np.add(d.x0l, d.ul, out=d.work)          # U = A^T (x0 + u) - x0, as rows x^T A
            np.matmul(d.work.reshape(-1, 3), d.A, out=d.Ul.reshape(-1, 3))
            d.Ul -= d.x0l
            d.force.apply(d.Ul, d.fl)
        else:
            d.force.apply(d.ul, d.fl)
        d.f_fn.x.scatter_reverse(cpp.la.ScatterMode.add)
        f = d.fl[:n]
        if self.hub_frame:                           # Q_k(u) = A Q_k(U), rows f^T A^T
            w = d.work[:n]
            w[:] = f
            np.matmul(w.reshape(-1, 3), d.A.T, out=f.reshape(-1, 3))
        return f


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
    columns are the identity (the prescribed coordinates drop out).
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
        if d.mass == "lumped":
            arr = self.diag.getArray()
            np.multiply(self.m_free, mass, out=arr)
            self.A.setDiagonal(self.diag, addv=PETSc.InsertMode.ADD_VALUES)
        self.ksp.getPC().setUp()                 # the numerical factorisation, now (KSPSetUp
        #                                          would leave it to the next solve)

    def solve_hub(self) -> None:
        self.ksp.solve(self.b, self.x)


class FieldWriter:
    """Writes u (o-xyz) and the hub-frame displacement U = A^T (x0 + u) - x0 at each call, to
    one XDMF/HDF5 pair. Every rank must call ``write`` and ``close``."""

    def __init__(self, tlf: TLF, path: str):
        from dolfinx.io import XDMFFile

        m = tlf.model
        self.drive = tlf.drive
        self.file = XDMFFile(tlf.comm, path, "w")
        self.file.write_mesh(m.mesh)
        self.u, self.U = fem.Function(m.V, name="u"), fem.Function(m.V, name="U_hub")
        self.x0 = m.node_coordinates()

    def write(self, t: float, q: np.ndarray) -> None:
        n = q.size
        self.u.x.array[:n] = q
        A = rotation_z(self.drive.angle(t))
        self.U.x.array[:n] = ((self.x0 + q.reshape(-1, 3)) @ A - self.x0).reshape(-1)
        for f in (self.u, self.U):
            f.x.scatter_forward()
            self.file.write_function(f, t)

    def close(self) -> None:
        self.file.close()


class _Dynamics:
    """Everything the time loop touches, built once: forces, mass, loads, root data, buffers."""

    def __init__(self, tlf: TLF):
        model, scene = tlf.model, tlf.scene
        t0 = time.perf_counter()
        V = model.V
        n = model.n_owned
        self.n = n
        self.rhs = np.empty(n)
        self.force = _make_force(tlf.force_eval, model)
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
        self.f_line = _owned(model.line_load_vector(), n)
        self.tip_force = np.asarray(scene.load.tip_force, float)
        self.tip_now = np.empty(3)
        self.f_tip = [_owned(b, n) for b in model.tip_traction_vectors()] \
            if np.any(self.tip_force) else []
        # root nodes (owned)
        self.root = (3 * model.root_owned[:, None] + np.arange(3)).reshape(-1)
        self.Px0_r, self.Sx0_r = self.Px0[self.root], self.Sx0[self.root]
        self._rb, self._rb2 = np.empty(self.root.size), np.empty(self.root.size)
        # mass (Eq. 29)
        t1 = time.perf_counter()
        self.mass = tlf.mass_kind
        if self.mass == "lumped":
            self.m = _owned(model.vector(model.lumped_mass_form(), zero_clamped=False), n)
            self.m_inv = 1.0 / self.m
        else:
            Mf = model.compile(model.mass_form())
            M_full = model.matrix(Mf, bcs=[])
            # M_fr u_r'' = alpha M_fr (P x0)_r + beta M_fr (S x0)_r: two fixed vectors
            self.lift_P = self._lifting(M_full, self.Px0_r)
            self.lift_S = self._lifting(M_full, self.Sx0_r)
            M_full.destroy()
            # M = M_s (x) I_3: factorise the scalar mass once (1/9 of the entries) and solve the
            # three components with it
            self.M = _scalar_mass(model)
            self.ksp = direct_solver(self.M)
            self.ksp.setUp()                               # factorise once, here
            self.b, self.x = self.M.createVecs()
            b_arr, x_arr = self.b.getArray(), self.x.getArray()
            self.components = [(self.rhs[j::3], b_arr, x_arr) for j in range(3)]
        tlf.timings["mass_build"] = time.perf_counter() - t1
        # damping (Eq. 34 relative, Eq. 68 absolute)
        self.c_rho = scene.damping.c / scene.material.rho
        self.relative = scene.damping.model == "relative"
        # step buffers
        self.A = np.eye(3)
        self.y, self.my = np.empty(n), np.empty(n)
        self.root_nodes = model.root_owned

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
            _axpy(dphi, q, y, n=m, offx=1, incx=3, offy=0, incy=3)
            _axpy(-dphi, q, y, n=m, offx=0, incx=3, offy=1, incy=3)
            _axpy(-dphi, self.Sx0, y)
        else:
            _axpy(-dphi * c, self.Sx0, y)
            _axpy(dphi * s, self.Px0, y)


def _axpy(a: float, x: np.ndarray, y: np.ndarray, **strides) -> None:
    """y += a x in place (BLAS daxpy, no temporary); y must be contiguous float64, which is
    checked because f2py would otherwise update a copy silently."""
    if daxpy(x, y, a=a, **strides) is not y:
        raise ValueError("_axpy: y must be a contiguous float64 array")


def _owned(vec: PETSc.Vec, n: int) -> np.ndarray:
    return vec.getArray()[:n].copy()


def _scalar_mass(model: SolidModel) -> PETSc.Mat:
    """The scalar consistent mass int rho N_a N_b (Eq. 29 per component), root rows and columns
    replaced by the identity. Its P1 space numbers the nodes as the vector space does (checked)."""
    V1 = fem.FunctionSpace(model.mesh, ("Lagrange", 1))
    im, imv = V1.dofmap.index_map, model.V.dofmap.index_map
    if not (np.array_equal(V1.dofmap.list.array, model.V.dofmap.list.array)
            and im.size_local == imv.size_local and np.array_equal(im.ghosts, imv.ghosts)):
        raise RuntimeError("scalar and vector P1 spaces number the nodes differently")
    u, v = ufl.TrialFunction(V1), ufl.TestFunction(V1)
    bc = fem.dirichletbc(0.0, model.root_nodes, V1)
    return model.matrix(fem.form(model.rho * u * v * model.dx), bcs=[bc])


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
        owned[:] = 1.0 / np.sqrt(owned)
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


def build(scene: Scene, comm, options: BuildOptions) -> TLF:
    return TLF(scene, comm, options)
