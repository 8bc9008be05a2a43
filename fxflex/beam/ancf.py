"""ANCF: absolute nodal coordinate formulation, second-order beam (paper Sect. 3.3, Eq. 49-57).

Every node carries 21 coordinates (Eq. 50-51, n = 2): position r, the axial gradient dr/dX~ and the
five cross-section gradients of the Pascal triangle (d/dY~, d/dZ~, d2/dY~2, d2/dY~dZ~, d2/dZ~2).
Eq. 52 interpolates the centerline with cubic Hermite functions and the section gradients linearly,
x = N(X~) e. The local coordinates span the straight prism X~ in [0, L], Y~ in [-b0/2, b0/2],
Z~ in [-h0/2, h0/2] (b0, h0 the root sizes); the reference configuration e0 maps it onto the
tapered twisted beam: at node k, r = (R + x_k, 0, 0), dr/dX~ = e_X, dr/dY~ = b(x_k)/b0 (0, cos t,
sin t), dr/dZ~ = h(x_k)/h0 (0, -sin t, cos t), second-order gradients zero (t the twist angle).
Between nodes the linear interpolation of the section gradients is the chord of the twist (a
0.08 % shrink of the section at mid-element with 10 elements).

Green-Lagrange strain on u = N (e - e0) (Eq. 53), St.Venant-Kirchhoff material, 5 x 3 x 3 Gauss
points per element (``mesh.beam_variant = "locking-free"``: uncoupled normal strains, the bending
curvature from the centerline and tied transverse shears, still a Gram form of the slots:
:func:`fxflex.beam.ancf_elements.centerline_strain`, docs/beams.md "Locking-free variants");
elastic force by the invariant tensors of :mod:`fxflex.beam.invariants` (Eq. 55, 57):
``force_eval = "invariant"`` (system invariant matrices) or ``"element"`` (element invariant
matrices, ref. [49]). Mass Eq. 54 (constant), damping Eq. 56 (relative: c/rho M (e' - phi' S e),
because e_r = A e0 moves rigidly) or Eq. 69 (absolute: c/rho M (e' - e_r')), external load on the
centerline. The root node follows the drive: its coordinates are A(phi(t)) e0, except dr/dX~,
which stays free with the default ``mesh.ancf_root = "free-axial"`` (SPEC section 1).
"""

from __future__ import annotations

import math
import time

import numpy as np

from fxflex.beam.ancf_elements import (DPN, QUADRATURE, SLOTS, assemble_blocks,
                                       centerline_strain, elastic_tensors, elasticity_matrix,
                                       gram_tensors, line_load, prism_quadrature,
                                       reference_coordinates, reference_gradients, scalar_mass)
from fxflex.beam.elements import ancf_tables
from fxflex.beam.invariants import GramChain
from fxflex.beam.line import beam_line, twist_check
from fxflex.formulation import FORCE_EVAL, BuildOptions, FormulationBase, SteadyState
from fxflex.numerics.dense import DenseLU, newton, omega_max
from fxflex.numerics.director import Director, FactorUpdate
from fxflex.numerics.hub import HubFrameFactor
from fxflex.numerics.qep import DenseLinearisation
from fxflex.numerics.sparse import SparseAdd
from fxflex.scene import Drive, Scene
from fxflex.scene.kinematics import P3, S3, rotation_z

__all__ = ["build", "dof_count", "ANCF", "constrained_slots", "QUADRATURE", "elasticity_matrix",
           "reference_coordinates", "tip_mass_block", "tip_director"]


def constrained_slots(scene: Scene) -> tuple[int, ...]:
    """Root-node slots prescribed by the drive: all but dr/dX~ ("free-axial") or all ("full")."""
    return tuple(range(SLOTS)) if scene.mesh.ancf_root == "full" else (0, 2, 3, 4, 5, 6)


def tip_mass_block(scene: Scene, e0_tip: np.ndarray) -> np.ndarray:
    """The tip mass's share of the scalar mass on the tip node's slots (SLOTS x SLOTS; SPEC
    section 10): a rigid body at the tip centroid r whose point at offset rho (undeformed, O-XYZ)
    follows the tip section's affine motion x = r + [d_X, d_Y~, d_Z~] J0^-1 rho (J0 the same
    gradients at e0), so its kinetic energy 1/2 m |r'|^2 + 1/2 sum_ab K_ab d_a' . d_b' is one of
    the scalar form M_s (x) I_3 with K = J0^-1 Pi' J0^-T (Pi = int rho rho^T dm,
    :meth:`fxflex.scene.schema.TipMass.second_moments`; Pi' without Pi_XX, which
    :func:`tip_director` carries on the section's normal): m on the position slot, K on the
    three first-order gradients; the second-order ones carry none. For a rigid turn of the
    section, J = A J0 with A' = [w]x A, this and the director's share are 1/2 w^T (A J_tip A^T)
    w: the rotary inertia exactly; the Coriolis and centrifugal terms follow from M_s as for the
    beam's own mass."""
    tip = scene.tip_mass
    J0 = e0_tip[1:4].T                                   # columns d_X, d_Y~, d_Z~
    Jinv = np.linalg.inv(J0)
    Pi = tip.second_moments()
    Pi[0, 0] = 0.0                                       # Pi_XX: tip_director
    out = np.zeros((SLOTS, SLOTS))
    out[0, 0] = tip.mass
    out[1:4, 1:4] = Jinv @ Pi @ Jinv.T
    return out


def tip_director(scene: Scene, e0_tip: np.ndarray, free: np.ndarray):
    """The tip body's Pi_XX on the tip section's normal (:class:`fxflex.numerics.director.
    Director`), on the free coordinates, or None for a body flat in the section plane. Its X
    axis is n = g_Y x g_Z / |g_Y x g_Z| with [g_X, g_Y, g_Z] = [d_X, d_Y~, d_Z~] J0^-1 (the
    section's affine motion of :func:`tip_mass_block`), so a shear of the tip element (d_X
    tilting against the section) does not turn the body: Pi_XX on d_X instead, as before,
    made a rod along X [0, J, J] act on the free end's shear strain rate (2nd lead-lag 177.9 Hz
    against 231.4 with the disc [2 J, J, J] of the same J_Z, uniform 0.12 x 0.06 m beam, 10
    elements) and its centrifugal pull, along d_X, stretch the tip (2 % of the steady stretch
    at 3000 rpm). The tip node's slots are the last SLOTS, all free."""
    from mpi4py import MPI

    from fxflex.scene.load import tip_body_is_flat

    tip = scene.tip_mass
    if tip_body_is_flat(tip.inertia):
        return None
    Jinv = np.linalg.inv(e0_tip[1:4].T)
    last = free[-1] - SLOTS + 1                          # the tip node's first slot
    slots = np.searchsorted(free, last + np.arange(1, 4))  # d_X, d_Y~, d_Z~ among the free
    n = 3 * len(free)
    reference = np.zeros(n)
    reference.reshape(-1, 3)[slots] = e0_tip[1:4]         # d_X, d_Y~, d_Z~ of e0
    return Director(MPI.COMM_SELF, n, slots, Jinv[:, 1:3], float(tip.second_moments()[0, 0]),
                    np.zeros(n), reference=reference)


class ANCF(FormulationBase):
    """Second-order ANCF beam in the inertial frame; see the module docstring."""

    method = "ancf"
    extra_columns: tuple[str, ...] = ()
    #: absolute nodal coordinates: they turn with the beam at the steady state
    steady_at_rest = False
    #: geometrically exact (absolute coordinates, Green-Lagrange strain): a run stops only beyond
    #: 2 L of deflection (fxflex.time.driver.divergence_limit)
    deflection_range = 2.0

    def __init__(self, scene: Scene, force_eval: str | None = None):
        from mpi4py import MPI

        t0 = time.perf_counter()
        self.scene, self.comm = scene, MPI.COMM_SELF
        self.force_eval = force_eval or FORCE_EVAL["ancf"][0]
        self.drive = Drive(scene.rotation)
        rho = scene.material.rho
        self.c_rho = scene.damping.c / rho
        self.absolute = scene.damping.model == "absolute"
        self.warnings = twist_check(scene, "ancf")
        line = self.line = beam_line(scene, QUADRATURE[0])
        n_el, n_nodes, le = line.n_el, line.n_nodes, line.le
        self.n_slots, self.n_full = SLOTS * n_nodes, DPN * n_nodes
        self.e0n = reference_coordinates(scene)
        self.e0 = self.e0n.reshape(-1).copy()
        # element arrays (fxflex.beam.ancf_elements): Gauss rule on the prism, reference
        # Jacobian, Green-strain tensors of the elastic force, scalar mass, line load
        X, Y, Z, wq = prism_quadrature(scene, le)
        tab = self.tab = ancf_tables(X, Y, Z, le)
        self.detJ, nx = reference_gradients(self.e0n, tab)
        dV = self.detJ * wq
        self.quad = {"nx": nx, "dV": dV}                               # for checks
        C = self.C = elasticity_matrix(scene)
        if scene.mesh.beam_variant == "paper":
            self.KLe, T1, T4 = elastic_tensors(C, nx, dV)
        else:
            BL, W = centerline_strain(self.e0n, tab, X, Y, Z, le)
            self.KLe, T1, T4 = gram_tensors(C, BL, W, dV)
        emap = np.arange(2 * DPN).reshape(2 * SLOTS, 3)
        # the system matrices serve the time loop's invariant route only: built at its
        # initial_state (a steady state or modes analysis never needs them: a third of a build)
        self.engine = GramChain(T1, T4, dpn=DPN, spn=SLOTS, emap=emap, esign=np.ones(emap.shape),
                                system=False)
        # linear stiffness and scalar mass (Eq. 54: M = Ms x I_3), assembled
        KL = assemble_blocks(self.KLe, DPN, self.n_full)
        Ms = assemble_blocks(scalar_mass(rho, dV, tab.N), SLOTS, self.n_slots)
        if scene.tip_mass.present:
            Ms[-SLOTS:, -SLOTS:] += tip_mass_block(scene, self.e0n[-1])
        self.KL_dense, self.Ms = KL, Ms
        self.KL_add = SparseAdd(KL)                      # out += K_L u in the time loop
        self.Ms_add = SparseAdd(Ms, 3)                   # M_s times the (n, 3) node field
        self.fq = line_load(scene, le, n_nodes)
        self.tip_dofs = slice(self.n_full - DPN, self.n_full - DPN + 3)
        self.Ftip = np.asarray(scene.load.tip_force, float)
        # root constraint: constrained slots follow the drive
        self.con = np.array(constrained_slots(scene))
        self.free = np.array([s for s in range(self.n_slots) if s not in set(self.con)])
        self.root_free = self.free[self.free < SLOTS]
        self.dof = 3 * len(self.free)
        self.free_dofs = (3 * self.free[:, None] + np.arange(3)).ravel()
        self.con_dofs = (3 * self.con[:, None] + np.arange(3)).ravel()
        self.timings = {"assemble": time.perf_counter() - t0}
        t1 = time.perf_counter()
        self.Mff = Mff = Ms[np.ix_(self.free, self.free)]
        Minv = np.linalg.inv(Mff)
        self.Minv = 0.5 * (Minv + Minv.T)
        self.Mfc = Ms[np.ix_(self.free, self.con)]
        self.director = tip_director(scene, self.e0n[-1], self.free)
        if self.director is not None:            # Pi_XX: a Woodbury update of M_ff^-1
            self.director.prepare(self._minv_solve)
        self.timings["factorise"] = time.perf_counter() - t1
        # work arrays (the time loop allocates nothing)
        n = self.n_full
        self._u, self._F, self._Ku, self._d, self._Md = (np.zeros(n) for _ in range(5))
        self._Ae0 = np.zeros((self.n_slots, 3))
        self._acon = np.zeros((len(self.con), 3))
        self._Ae0c = np.zeros((len(self.con), 3))
        self._mfa = np.zeros((len(self.free), 3))
        self._rhs = np.zeros((len(self.free), 3))
        self._xf, self._mfx = np.zeros((len(self.free), 3)), np.zeros((len(self.free), 3))
        self._factor: HubFrameLU | None = None
        self._qf, self._vf, self._df = (np.zeros(len(self.free_dofs)) for _ in range(3))
        self._afree = np.zeros((len(self.free), 3))
        self._col = np.zeros(self.n_slots)
        self._A = np.eye(3)
        self._Kacc = np.zeros((3, 3))
        # at rest (0 rpm) A = I and the root does not move: the per-step rotation of e0, the
        # rotating part of the damping and the root's inertia load are skipped
        self.at_rest = self.drive.at_rest
        self._rotate(0.0)
        self._steady: SteadyState | None = None
        self._omega_max: float | None = None

    def _minv_solve(self, x: np.ndarray) -> None:
        """x <- M_ff^-1 x on the free coordinates (M_s (x) I_3 with the flat tip block)."""
        x[:] = (self.Minv @ x.reshape(-1, 3)).reshape(-1)

    # ------------------------------------------------------------------ drive
    def _rotate(self, phi: float) -> np.ndarray:
        """A(phi) e0 for every slot into self._Ae0; returns A."""
        A = rotation_z(phi, self._A)
        np.matmul(self.e0n.reshape(-1, 3), A.T, out=self._Ae0)
        return A

    def initial_state(self) -> tuple[np.ndarray, np.ndarray]:
        """Undeformed beam in rigid rotation (NOTES.md): e = A(phi0) e0, e' = phi'(0) S e. A time
        loop follows: the invariant route's system matrices are built here, before its clock."""
        if self.force_eval == "invariant":
            self.engine.prepare_system()
        phi, rate, _ = self.drive.state(0.0)
        self._rotate(phi)
        q = self._Ae0.reshape(-1).copy()
        v = (rate * self._Ae0 @ S3.T).reshape(-1)
        return q, v

    def constrain(self, t: float, q: np.ndarray, v: np.ndarray) -> None:
        """Root slots: e = A(phi) e0, e' = phi' S A e0."""
        phi, rate, _ = self.drive.state(t)
        self._rotate(phi)
        q3, v3 = q.reshape(-1, 3), v.reshape(-1, 3)
        for s in self.con:
            x, y, z = self._Ae0[s]
            q3[s, 0], q3[s, 1], q3[s, 2] = x, y, z
            v3[s, 0], v3[s, 1], v3[s, 2] = -rate * y, rate * x, 0.0

    # ------------------------------------------------------------------ forces
    def add_elastic_force(self, u: np.ndarray, out: np.ndarray, route: str | None = None
                          ) -> None:
        """out += Q_k = (K_L + K_N) (e - e0) (Eq. 55/57) by ``route`` (default ``force_eval``)."""
        self.KL_add.add(u, out)
        if (route or self.force_eval) == "invariant":
            self.engine.add_force_system(u, out)
        else:
            self.engine.add_force_element(u, out)

    def elastic_force(self, e: np.ndarray, route: str | None = None) -> np.ndarray:
        """Q_k at coordinates e (allocating) by ``route`` (default ``force_eval``). The steady
        Newton's residual and the root stress take "element": the same force to round-off,
        without the system matrices that only the time loop needs."""
        out = np.zeros(self.n_full)
        self.add_elastic_force(np.ascontiguousarray(e - self.e0), out, route)
        return out

    def acceleration(self, t: float, q: np.ndarray, v: np.ndarray, out: np.ndarray) -> None:
        """out = M^-1 (Q_e - Q_d - Q_k) on the free coordinates (Eq. 57), the exact prescribed
        acceleration (phi'' S - phi'^2 P) A e0 on the root's constrained ones."""
        rhs = self._free_force(t, q, v)
        np.matmul(self.Minv, rhs, out=self._afree)
        if self.director is not None:            # its mass J^T J at q: Woodbury
            self.director.woodbury(self._afree.reshape(-1))
        out3 = out.reshape(-1, 3)
        nr = len(self.root_free)
        out3[self.con] = self._acon
        out3[self.root_free] = self._afree[:nr]
        out3[SLOTS:] = self._afree[nr:]

    def _free_force(self, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """F = Q_e - Q_d - Q_k - M_fc e_c'' on the free slots, (free slots, 3), in the work array
        ``_rhs``; leaves the prescribed acceleration e_c'' of the constrained slots in ``_acon``."""
        phi, rate, accel = self.drive.state(t)
        A = self._A if self.at_rest else self._rotate(phi)
        u, F, Ku, d = self._u, self._F, self._Ku, self._d
        np.subtract(q, self.e0, out=u)
        Ku.fill(0.0)
        self.add_elastic_force(u, Ku)
        lam = self.scene.load.factor(t)
        np.multiply(self.fq, lam, out=F)
        if self.Ftip.any():
            F[self.tip_dofs] += lam * (A @ self.Ftip)
        F -= Ku
        if self.c_rho:
            # Eq. 56: e' - e_r' - phi' S (e - e_r) = e' - phi' S e; Eq. 69: e' - phi' S A e0
            d3, src = d.reshape(-1, 3), (self._Ae0 if self.absolute else q.reshape(-1, 3))
            d[:] = v
            if not self.at_rest:
                np.multiply(src[:, 1], rate, out=self._col)
                d3[:, 0] += self._col
                np.multiply(src[:, 0], rate, out=self._col)
                d3[:, 1] -= self._col
            self._Md.fill(0.0)
            self.Ms_add.add(d, self._Md)
            self._Md *= self.c_rho
            F -= self._Md
        if not self.at_rest:                     # root acceleration (phi'' S - phi'^2 P) A e0
            K = self._Kacc
            np.multiply(S3, accel, out=K)
            K -= (rate * rate) * P3
            np.take(self._Ae0, self.con, axis=0, out=self._Ae0c, mode="clip")
            np.matmul(self._Ae0c, K.T, out=self._acon)
        F3 = F.reshape(-1, 3)
        nr = len(self.root_free)
        rhs = self._rhs
        np.take(F3, self.root_free, axis=0, out=rhs[:nr], mode="clip")
        rhs[nr:] = F3[SLOTS:]
        if not self.at_rest:                     # its inertia load on the free coordinates
            np.matmul(self.Mfc, self._acon, out=self._mfa)
            rhs -= self._mfa
        if self.director is not None:            # Pi_XX: velocity force, mass at q, damping
            director = self.director
            np.take(q, self.free_dofs, out=self._qf, mode="clip")
            np.take(v, self.free_dofs, out=self._vf, mode="clip")
            flat = rhs.reshape(-1)
            director.add_spread(director.moving(self._qf, self._vf), flat, -1.0)
            if self.c_rho:
                np.take(d, self.free_dofs, out=self._df, mode="clip")
                director.mass_apply(self._df, flat, -self.c_rho)
                if self.absolute and not self.at_rest:   # its own rate against e_X's
                    director.add_spread(director.absolute_damping(rate, A), flat, -self.c_rho)
        return rhs

    # ------------------------------------------------------------------ implicit integration
    def force(self, t: float, q: np.ndarray, v: np.ndarray, out: np.ndarray) -> None:
        """F = Q_e - Q_d - Q_k - M_fc e_c'' on the free coordinates (Eq. 57), 0 on the root's
        constrained ones."""
        rhs = self._free_force(t, q, v)
        out[self.con_dofs] = 0.0               # flat indices: 2-D row indexing allocates
        out[self.free_dofs] = rhs.reshape(-1)

    def mass_apply(self, x: np.ndarray, out: np.ndarray) -> None:
        """M_ff x_f with M = M_s (x) I_3 (Eq. 54); a tip body's Pi_XX adds its J^T J at the q of
        the last ``force`` call."""
        np.take(x, self.free_dofs, out=self._xf.reshape(-1), mode="clip")
        np.matmul(self.Mff, self._xf, out=self._mfx)
        if self.director is not None:            # J^T J at the q of the last force()
            self.director.mass_apply(self._xf.reshape(-1), self._mfx.reshape(-1))
        out[self.con_dofs] = 0.0
        out[self.free_dofs] = self._mfx.reshape(-1)

    def factorize(self, t: float, q: np.ndarray, v: np.ndarray, m: float, c: float, k: float
                  ) -> "HubFrameLU":
        """S = m M + c C_t + k K_t on the free coordinates, factorised in the hub frame.

        K_t = dQ_k/de + dQ_d/de with the exact tangent of the invariant-tensor force and, for the
        relative damping (Eq. 56), dQ_d/de = -c/rho phi' M_s (x) S; C_t = c/rho M_s (x) I_3. The
        elastic energy does not change under a rigid rotation of every slot, so K_t(A e) =
        A_d K_t(e) A_d^T, and M_s (x) I_3 and M_s (x) S commute with A_d = I (x) A: S(e) = A_d
        S(A^T e) A_d^T. The factor is made of S(A^T e) and solves rotate by A(phi(t)) at the time
        asked, so that it stays the tangent while the beam turns."""
        phi, rate, _ = self.drive.state(t)
        A = rotation_z(phi)
        e_hub = (q.reshape(-1, 3) @ A).reshape(-1)
        K = self.tangent_stiffness(e_hub)
        if self.c_rho and not self.absolute:
            K -= self.c_rho * rate * np.kron(self.Ms, S3)
        K *= k
        K += (m + c * self.c_rho) * np.kron(self.Ms, np.eye(3))
        if self._factor is None:
            self._factor = HubFrameLU(self.free_dofs, self.n_full, self.drive)
        lu = self._factor.lu
        lu.matrix[...] = K[np.ix_(self.free_dofs, self.free_dofs)]
        director = self.director
        if director is not None:                 # Pi_XX J^T J at the hub-frame coordinates
            C6 = (m + c * self.c_rho) * director.mass6(e_hub[self.free_dofs])
            director.add_dense(lu.matrix, C6)
        lu.factor()
        if director is not None:                 # kept current while the factor serves
            self._factor.update = FactorUpdate(director, self._lu_solve, C6,
                                               m + c * self.c_rho, c)
        return self._factor

    def _lu_solve(self, b: np.ndarray) -> np.ndarray:
        x = np.zeros_like(b)
        self._factor.lu.solve_into(b, x)
        return x

    def tip(self, t: float, q: np.ndarray) -> np.ndarray:
        """U = A^T x_tip - x0_tip: the rigid rotation removed (SPEC section 2)."""
        A = self.drive.A(t)
        x = np.asarray(q[self.tip_dofs], float)
        return A.T @ x - self.e0[self.tip_dofs]

    def rotating_state(self, t: float, q: np.ndarray, v: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray]:
        """(z, z') on the free coordinates in the rotating frame, as :meth:`linearise` and
        ``steady_state().q`` use them: each slot turned back, A^T e, and A^T (e' - phi' S e)."""
        phi, rate, _ = self.drive.state(t)
        A = rotation_z(phi)
        e3, v3 = q.reshape(-1, 3), v.reshape(-1, 3)
        z = (e3 @ A).reshape(-1)                         # rows e^T A = (A^T e)^T
        zd = ((v3 - rate * e3 @ S3.T) @ A).reshape(-1)
        return z[self.free_dofs], zd[self.free_dofs]

    def root_stress(self, t: float, q: np.ndarray) -> np.ndarray:
        """sigma_X (Pa) at the four corners of the root section from the section forces there:
        the elastic force on the root node's coordinates (Eq. 55) minus the line load's share,
        turned to O-XYZ with A^T, gives the force F = Q_r and, about the root centre, the moment
        M = sum_s r_s x Q_s over the gradient slots (a rigid rotation d theta moves each gradient
        by d theta x r_s); then N = -F_X, int Y sigma dA = M_Z, int Z sigma dA = -M_Y, spread
        linearly over the section as in beam theory."""
        Q = self.elastic_force(q, "element")
        Q -= self.scene.load.factor(t) * self.fq
        A = self.drive.A(t)
        Qr = Q[:DPN].reshape(SLOTS, 3) @ A               # rows (A^T Q_s)^T
        er = q[:DPN].reshape(SLOTS, 3) @ A
        F = Qr[0]
        M = np.cross(er[1:], Qr[1:]).sum(axis=0)
        return self.line.shape.axial_stress(0.0, (-F[0], M[2], -M[1]))

    # ------------------------------------------------------------------ rotating-frame statics
    def _full(self, x_free: np.ndarray) -> np.ndarray:
        e = self.e0.copy()
        e[self.free_dofs] = x_free
        return e

    def _static_residual(self, x: np.ndarray, s: float) -> np.ndarray:
        """Rotating frame at speed sqrt(s) Omega, loads x s: Q_k(e) - Omega^2 M P e
        [+ c/rho Omega M S (e - e0)] - Q_e (NOTES.md), on the free coordinates."""
        e = self._full(x)
        rate = math.sqrt(s) * self.scene.rotation.omega
        e3 = e.reshape(-1, 3)
        r = self.elastic_force(e, "element")
        r -= rate**2 * (self.Ms @ (e3 @ P3.T)).reshape(-1)
        if self.absolute:
            r += self.c_rho * rate * (self.Ms @ ((e3 - self.e0n.reshape(-1, 3)) @ S3.T)).reshape(-1)
        r -= s * self.fq
        r[self.tip_dofs] -= s * self.Ftip
        r = r[self.free_dofs]
        if self.director is not None:            # -Omega^2 Pi_XX J^T P n [+ circulatory]
            self.director.add_spread(self._director_terms(x, rate)[1], r)
        return r

    def _director_terms(self, x: np.ndarray, rate: float):
        """(B_n, f6, K6) of the tip body's Pi_XX at the free coordinates x and speed ``rate``
        (:meth:`fxflex.numerics.director.Director.rotating`)."""
        return self.director.rotating(x, rate**2, self.c_rho * rate if self.absolute else 0.0)

    def tangent_stiffness(self, e: np.ndarray) -> np.ndarray:
        """dQ_k/de (dense, all coordinates)."""
        return self.KL_dense + self.engine.tangent(np.ascontiguousarray(e - self.e0))

    def _effective_stiffness(self, e: np.ndarray, rate: float) -> np.ndarray:
        K = self.tangent_stiffness(e) - rate**2 * np.kron(self.Ms, P3)
        if self.absolute:
            K += self.c_rho * rate * np.kron(self.Ms, S3)
        K = K[np.ix_(self.free_dofs, self.free_dofs)]
        if self.director is not None:
            self.director.add_dense(K, self._director_terms(e[self.free_dofs], rate)[2])
        return K

    def steady_state(self) -> SteadyState:
        """Rotating-frame equilibrium at the final speed by Newton (speed continuation if the
        direct iteration fails); tip and coordinates expressed at phi = 0."""
        if self._steady is not None:
            return self._steady
        t0 = time.perf_counter()
        omega = self.scene.rotation.omega
        tangent = lambda x, s: self._effective_stiffness(self._full(x), math.sqrt(s) * omega)
        x0 = self.e0[self.free_dofs]
        x, its, hist, ok = newton(self._static_residual, tangent, x0, rtol=self.steady_rtol)
        if not ok:
            x, its, hist, ok = newton(self._static_residual, tangent, x0, rtol=self.steady_rtol,
                                      steps=tuple(np.linspace(0.1, 1.0, 10)))
        e = self._full(x)
        self._steady = SteadyState(tip=e[self.tip_dofs] - self.e0[self.tip_dofs], q=e,
                                   iterations=its, residuals=hist, converged=ok,
                                   timings={"steady": time.perf_counter() - t0})
        return self._steady

    def linearise(self, steady: SteadyState | None = None) -> DenseLinearisation:
        """(M, C, K) about the steady state in the rotating frame, free coordinates: C = 2 Omega
        M S + c/rho M, K = K_T(e*) - Omega^2 M P [+ c/rho Omega M S, absolute model]; a tip
        body's Pi_XX adds J^T J to M, 2 Omega J^T S J to C and its steady derivative to K."""
        e = (steady or self.steady_state()).q
        omega = self.scene.rotation.omega
        f = np.ix_(self.free_dofs, self.free_dofs)
        M = np.kron(self.Ms, np.eye(3))[f]
        C = 2 * omega * np.kron(self.Ms, S3)[f]
        if self.director is not None:            # J^T J, 2 Omega J^T S J at the equilibrium
            Bn = self._director_terms(e[self.free_dofs], omega)[0]
            pi = self.director.pi
            self.director.add_dense(M, pi * (Bn.T @ Bn))
            self.director.add_dense(C, 2 * omega * pi * (Bn.T @ S3 @ Bn))
        C += self.c_rho * M
        return DenseLinearisation(M, C, self._effective_stiffness(e, omega))

    def mode_tip(self, X: np.ndarray) -> np.ndarray:
        """(6, k) tip translation and small section rotation of rotating-frame mode vectors X
        (free coordinates, k columns). The translation is the tip node's position r; the rotation
        theta follows from the gradients' changes, delta d = theta x d for a rigid section: the
        axial gradient d_X = e_X gives theta_Y = -delta d_X,z and theta_Z = delta d_X,y, the two
        section gradients d_Y, d_Z (orthogonal, in the section plane) give
        theta_X = 1/2 sum_k (d_k x delta d_k)_X / |d_k|^2."""
        tip = X[-DPN:].reshape(SLOTS, 3, -1)             # the free end: every slot is free
        d = self.e0n[-1]
        out = np.empty((6, tip.shape[2]), dtype=X.dtype)
        out[:3] = tip[0]
        out[3] = 0.5 * sum((d[k, 1] * tip[k, 2] - d[k, 2] * tip[k, 1]) / (d[k] @ d[k])
                           for k in (2, 3))
        out[4] = -tip[1, 2]
        out[5] = tip[1, 1]
        return out

    def mode_span(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(x, S) of rotating-frame mode vectors X (free coordinates, k columns): the nodes'
        distances from the root (s,) and S (4, s, k) each node's position change r (the
        centerline, on the section centroid) and theta_X from its section gradients as in
        :meth:`mode_tip`; the prescribed root coordinates are zero (SPEC section 10)."""
        X2 = X.reshape(X.shape[0], -1)
        full = np.zeros((self.n_full, X2.shape[1]), dtype=X.dtype)
        full[self.free_dofs] = X2
        nodes = full.reshape(-1, SLOTS, 3, X2.shape[1])
        d = self.e0n                                          # (n_nodes, SLOTS, 3)
        S = np.empty((4, nodes.shape[0], X2.shape[1]), dtype=X.dtype)
        S[:3] = nodes[:, 0].transpose(1, 0, 2)
        S[3] = 0.5 * sum((d[:, k, 1, None] * nodes[:, k, 2] - d[:, k, 2, None] * nodes[:, k, 1])
                         / np.einsum("ni,ni->n", d[:, k], d[:, k])[:, None] for k in (2, 3))
        return self.line.x_nodes.copy(), S

    def omega_max(self) -> float:
        """Highest circular frequency of the clamped beam at rest (K_L, M on the free
        coordinates): the central-difference limit is dt < 2 / omega_max."""
        if self._omega_max is None:
            f = np.ix_(self.free_dofs, self.free_dofs)
            self._omega_max = omega_max(self.KL_dense[f], np.kron(self.Ms, np.eye(3))[f])
        return self._omega_max

    def field_writer(self, path: str, comm=None):
        """``--fields``: the beam line with U_hub, u and the polar rotation of the gradients
        (XDMF from rank 0 of ``comm``; :func:`fxflex.beam.beam_fields.ancf_field_writer`)."""
        from fxflex.beam.beam_fields import ancf_field_writer
        return ancf_field_writer(self, path, comm)


class HubFrameLU(HubFrameFactor):
    """Dense LU of the iteration matrix in the hub frame, S_hub = A_d^T S A_d on the free
    coordinates: solve(t, r) = A_d S_hub^-1 A_d^T r with A = A(phi(t)) per 3-vector slot."""

    def __init__(self, free_dofs: np.ndarray, n_full: int, drive: Drive):
        self._w = np.zeros(n_full)
        super().__init__(drive, self._w, self._w)
        self.free_dofs = free_dofs
        self.lu = DenseLU(len(free_dofs))
        self.update = None                       # fxflex.numerics.director.FactorUpdate
        self._b, self._x = np.zeros(len(free_dofs)), np.zeros(len(free_dofs))

    def solve_hub(self) -> None:
        w = self._w
        np.take(w, self.free_dofs, out=self._b, mode="clip")
        self.lu.solve_into(self._b, self._x)
        if self.update is not None:              # a tip body's Pi_XX, at the last force()
            self.update.correct(self._x, self._rotation)
        w.fill(0.0)
        w[self.free_dofs] = self._x


def build(scene: Scene, comm, options: BuildOptions | None = None) -> ANCF:
    """Replicated on every rank: ``form.comm`` is COMM_SELF."""
    options = options or BuildOptions()
    return ANCF(scene, options.force_eval)


def dof_count(scene: Scene) -> int:
    """21 coordinates per node, minus the root's prescribed ones."""
    return DPN * (scene.mesh.beam_elements + 1) - 3 * len(constrained_slots(scene))
