"""TLF: total Lagrangian solid with Green-Lagrange strain (paper Sect. 2.3, Eq. 25-35).

Transient (Eq. 35), inertial frame, nodal displacements u = x - x0 (Eq. 25) as unknowns:

    M u'' + Q_d + Q_k(u) = Q_e(t).

- Q_k, the St.Venant-Kirchhoff internal force (Eq. 30-33), two ways on the same Gauss rule:
  ``ufl`` assembles the residual form every evaluation (the per-step integration of Eq. 65) and
  ``invariant`` applies the system invariant matrices K_L, K_N1, K_N2, K_N3 (Eq. 33, 35; see
  :mod:`fxflex.solid.tlf_invariants`). Both are evaluated on the displacement seen from the hub,
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

Steady state (SPEC section 6): :mod:`fxflex.solid.tlf_steady`. The pieces the class assembles live
beside it: the UFL force kernel (:mod:`.tlf_force`), the time-loop data and buffers
(:mod:`.tlf_dynamics`), the implicit iteration matrix (:mod:`.tlf_tangent`) and the highest
frequency behind the stable step (:mod:`.tlf_frequency`); the XDMF output is
:class:`fxflex.io.fields.FieldWriter`. A sweep over speeds (the Campbell diagram) is
:mod:`.tlf_sweep`.
"""

from __future__ import annotations

import math
import time
from typing import TYPE_CHECKING

import numpy as np
import ufl
from dolfinx import cpp, fem
from petsc4py import PETSc

from fxflex.formulation import FORCE_EVAL, BuildOptions, FormulationBase, SteadyState
from fxflex.io.fields import FieldWriter
from fxflex.scene import Drive, Scene
from fxflex.scene.kinematics import rotation_z
from fxflex.scene.load import tip_body_is_flat
from fxflex.solid import forms
from fxflex.solid.model import SolidModel, solid_dof_count
from fxflex.solid.tlf_dynamics import Dynamics, axpy
from fxflex.solid.tlf_force import UflForce
from fxflex.solid.tlf_frequency import largest_frequency
from fxflex.solid.tlf_steady import tlf_steady
from fxflex.solid.tlf_tangent import HubTangent

if TYPE_CHECKING:
    from fxflex.solid.rotating import Linearisation
    from fxflex.solid.tlf_sweep import SpeedSweep

__all__ = ["TLF", "UflForce", "FieldWriter", "build", "dof_count", "tlf_steady", "largest_frequency",
           "DEFAULT_MASS"]

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


class TLF(FormulationBase):
    """The TLF formulation behind the :class:`~fxflex.formulation.Formulation` interface.

    The transient operators are built on the first call of ``initial_state`` (eagerly when the
    options say no steady state is needed, as ``fxflex run`` does), never inside the time loop.
    A member of a speed sweep (``model`` and ``sweep`` given, :mod:`fxflex.solid.tlf_sweep`)
    shares the sweep's SolidModel and continues its steady states and eigensolves.
    """

    method = "tlf"
    #: a distributed mesh field whose nodal displacements turn with the hub; the SLEPc PEP gives
    #: the lowest roots only
    distributed, steady_at_rest, all_roots = True, False, False
    mesh_key = "mesh.solid"
    #: geometrically exact (Green-Lagrange strain): a run stops only beyond 2 L of deflection
    #: (fxflex.time.driver.divergence_limit)
    deflection_range = 2.0

    def __init__(self, scene: Scene, comm, options: BuildOptions, *, hub_frame: bool = True,
                 model: SolidModel | None = None, sweep: SpeedSweep | None = None):
        t0 = time.perf_counter()
        self.scene, self.options = scene, options
        self.model = SolidModel(scene, comm) if model is None else model
        self.sweep = sweep
        self.comm = comm
        self.dof = self.model.dof
        self.force_eval = options.force_eval or FORCE_EVAL["tlf"][0]
        self.mass_kind = options.mass or DEFAULT_MASS
        self.drive = Drive(scene.rotation)
        # at rest A = I: the hub-frame turn of the force (below) would multiply by identities
        self.hub_frame = hub_frame and not self.drive.at_rest
        self.timings = dict(self.model.timings)
        self._dyn: Dynamics | None = None
        self._tangent: HubTangent | None = None
        self._omega_max: float | None = None
        self._root: tuple | None = None
        self._steady: SteadyState | None = None
        if not options.need_steady:
            self._dyn = Dynamics(self)
        self.timings["build"] = time.perf_counter() - t0

    @property
    def dynamics(self) -> Dynamics:
        if self._dyn is None:
            self._dyn = Dynamics(self)
            if self._dyn.director is not None and self._mac_q is not None:
                self._dyn.director.moving(self._mac_q, np.zeros_like(self._mac_q))
        return self._dyn

    #: the equilibrium of the last linearisation: where a tip body's director mass is taken for
    #: ``mass_apply`` outside a time loop (the MAC weights of fxflex.analysis.tracking)
    _mac_q = None

    # -- Formulation interface --------------------------------------------------------------------
    #: (omega, owned U0): a starting guess for :meth:`steady_state` (one Newton continuation from
    #: it instead of the stages from the undeformed body; the ``--tol`` ladder sets it from the
    #: coarser level, :func:`fxflex.solid.tlf_steady.prolongate`)
    steady_start: tuple[float, np.ndarray] | None = None

    def steady_state(self) -> SteadyState:
        if self._steady is None:
            linear = self.options.linear or "direct"
            if self.sweep is not None:
                self._steady = self.sweep.steady(self, linear)
            else:
                rtol = self.steady_rtol
                st = tlf_steady(self.model, linear=linear, start=self.steady_start, rtol=rtol)
                if not st.converged and self.steady_start is not None:
                    st = tlf_steady(self.model, linear=linear, rtol=rtol)   # the guess failed
                    st.extra["cold_fallback"] = True
                self._steady = st
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
        axpy(lam, d.f_line, rhs)
        if d.f_tip:
            np.dot(d.A, d.tip_force, out=d.tip_now)  # fixed in the rotating frame: A F
            for j in range(3):
                axpy(lam * d.tip_now[j], d.f_tip[j], rhs)
        alpha = -ddphi * s - dphi * dphi * c
        beta = ddphi * c - dphi * dphi * s
        if d.mass != "lumped":
            axpy(-alpha, d.lift_P, rhs)        # - M_fr u_r''
            axpy(-beta, d.lift_S, rhs)
        return alpha, beta, dphi, c, s

    def acceleration(self, t: float, q: np.ndarray, v: np.ndarray, out: np.ndarray) -> None:
        """out = M^-1 (Q_e - Q_k(u) - Q_d) on free nodes (Eq. 35); on root nodes the prescribed
        u_r'' = (phi'' S - phi'^2 P) A x0 = alpha P x0 + beta S x0."""
        d = self.dynamics
        alpha, beta, dphi, c, s = self._loads(t, q)
        rhs = d.rhs
        if d.director is not None:               # Pi_XX's quadratic-velocity force
            self._director_force(dphi, q, v, rhs)
        if d.mass == "lumped":
            np.multiply(rhs, d.m_inv, out=out)
            if d.body is not None:               # (D + M_tip)^-1 (fxflex.solid.tip_mass)
                d.body.woodbury(out)
        else:
            rhs[d.root] = d.root_combination(alpha, beta)
            for j, (rhs_j, b_arr, x_arr) in enumerate(d.components):
                b_arr[:] = rhs_j
                d.ksp.solve(d.b, d.x)
                out[j::3] = x_arr
        if d.director is not None:               # and its mass, J^T J at q: Woodbury
            d.director.woodbury(out)
        if d.c_rho > 0.0:                        # M^-1 D = c / rho
            if dphi == 0.0:                      # not turning: both models damp u'
                axpy(-d.c_rho, v, out)
            else:
                d.damped_rate(dphi, c, s, q, v)
                axpy(-d.c_rho, d.y, out)
        out[d.root] = d.root_combination(alpha, beta)

    def _director_force(self, dphi: float, q: np.ndarray, v: np.ndarray, out: np.ndarray) -> None:
        """out -= a tip body's Pi_XX velocity force at (q, v) (it takes that configuration), and
        with the absolute damping model the director's own damping against the whole-mass one
        the loop applies (:meth:`fxflex.numerics.director.Director.absolute_damping`)."""
        d = self.dynamics
        director = d.director
        director.add_spread(director.moving(q, v), out, -1.0)
        if d.c_rho > 0.0 and not d.relative and dphi != 0.0:
            director.add_spread(director.absolute_damping(dphi, d.A), out, -d.c_rho)

    # -- implicit integration (formulation.Implicit) ----------------------------------------------
    def force(self, t: float, q: np.ndarray, v: np.ndarray, out: np.ndarray) -> None:
        """F = Q_e - Q_k(u) - Q_d - M_fr u_r'' on the free rows (Eq. 35), 0 on the root. Q_d =
        (c/rho) M y with the damped rate y of ``damped_rate``, which is zero on the root nodes
        (they move rigidly), so M y = M_ff y_f."""
        d = self.dynamics
        _, _, dphi, c, s = self._loads(t, q)
        out[:] = d.rhs
        if d.director is not None:               # takes (q, v): mass_apply's M(q) from here
            self._director_force(dphi, q, v, out)
        if d.c_rho > 0.0:
            d.damped_rate(dphi, c, s, q, v)
            self.mass_apply(d.y, d.my)
            axpy(-d.c_rho, d.my, out)
        out[d.root] = 0.0

    def mass_apply(self, x: np.ndarray, out: np.ndarray) -> None:
        """M_ff x_f: lumped row sums, or the consistent mass per component (M = M_s (x) I_3); a
        tip body's Pi_XX adds its J^T J at the q of the last ``force`` call."""
        d = self.dynamics
        if d.mass == "lumped":
            np.multiply(x, d.m, out=out)
            if d.body is not None:
                d.body.apply(x, out)
        else:
            for j, (_, b_arr, x_arr) in enumerate(d.components):
                b_arr[:] = x[j::3]
                b_arr[d.root_nodes] = 0.0              # the scalar mass is 1 on root rows
                d.M.mult(d.b, d.x)
                out[j::3] = x_arr
        if d.director is not None:                     # M(q) at the last force()'s q
            d.director.mass_apply(x, out)
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

    def field_writer(self, path: str) -> FieldWriter:
        """``--fields``: an XDMF series for ParaView of u (o-xyz) and the hub-frame displacement
        U = A^T (x0 + u) - x0 at each ``write`` (rank-collective)."""
        x0, drive = self.model.node_coordinates(), self.drive

        def displacement(t: float, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            A = rotation_z(drive.angle(t))
            return q, ((x0 + q.reshape(-1, 3)) @ A - x0).reshape(-1)

        return FieldWriter(self.comm, self.model.V, path, displacement)

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
        part exceeds PEP_STABILITY_RTOL of the largest modulus. Its shift-and-invert takes the
        build's linear solver route (``options.linear``, docs/solvers.md): a MUMPS factor of K,
        or CG (GMRES when K is not symmetric) with GAMG. Collective."""
        from fxflex.solid.rotating import k_symmetric, tlf_linearisation

        st = steady or self.steady_state()
        sc = self.scene
        if not tip_body_is_flat(sc.tip_mass.inertia):   # mass_apply's director mass (the
            self._mac_q = np.asarray(st.q, float)        # MAC weights): at this equilibrium,
            if self._dyn is not None:                    # now or when the loop data are built
                self._dyn.director.moving(self._mac_q, np.zeros_like(self._mac_q))
        absolute = sc.damping.model == "absolute"
        start = {} if self.sweep is None else self.sweep.eigen_start(self, absolute)
        if self.options.linear == "iterative":
            start = {"symmetric": k_symmetric(sc), **start, "linear": "iterative"}
        return tlf_linearisation(self.model, st.q, sc.rotation.omega,
                                 sc.damping.c / sc.material.rho, absolute,
                                 self.mass_kind, min_pairs=STABILITY_PAIRS,
                                 rtol=PEP_STABILITY_RTOL, **start)

    def rotating_modes(self, pairs: int, steady: SteadyState | None = None
                       ) -> tuple[np.ndarray, np.ndarray]:
        """As every formulation's; a sweep member also hands its mode vectors to the sweep (the
        next speed's initial space)."""
        lam, X = super().rotating_modes(pairs, steady)
        if self.sweep is not None:
            self.sweep.record_modes(self, X)
        return lam, X

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

    def mode_span(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(x, S) of mode vectors on the free coordinates: every node layer's section centroid
        translation and rotation about X (:meth:`SolidModel.span_sections`, SPEC section 10).
        Collective: every rank gets the same result."""
        from fxflex.solid.rotating import free_entries

        full = np.zeros((self.model.n_owned,) + X.shape[1:], dtype=X.dtype)
        full[free_entries(self.model)] = X
        return self.model.span_sections(full)

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


def build(scene: Scene, comm, options: BuildOptions) -> TLF:
    return TLF(scene, comm, options)
