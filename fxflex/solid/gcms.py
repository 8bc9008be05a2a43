"""GCMS: floating frame, absolute elastic coordinates, global modes (paper Sect. 2.2).

The elastic displacement is measured in the inertial frame, u_f = A U_f (Eq. 18). With rotation
about z, A = cos(phi) G1 + sin(phi) G2 + G3 (G1 = P, G2 = S, G3 = e_z e_z^T), so every rotated FFRF
displacement A_d Phi eta lies in the span of the 3m global modes (SPEC section 3)

    Psi = [G1d Phi, G2d Phi, G3d Phi].

They are nearly dependent. Their Gram matrix W = Psi^T M Psi has the block form
[[N, G, 0], [-G, N, 0], [0, 0, I - N]] with the FFRF invariants N, G; its upper part is the real
form of the Hermitian N - iG, so its eigenvalues come in equal pairs whose eigenvectors
[a; b], [-b; a] span planes that the rotation maps onto themselves. Eigen-decomposing N - iG
and I - N and dropping the directions whose M-norm (the square root of the eigenvalue) is below
``reduction.gcms_gram_tol`` times the largest gives the M-orthonormal basis Psi~ = Psi T; the cut
removes whole pairs, so span(Psi~) is still closed under A and the method stays exactly
equivalent to a Galerkin FFRF on span(Psi~) (docs/reduced.md). A dropped direction has little
mass but not little stiffness, and the clamped modes themselves need it: a cut is only harmless
while the dropped eigenvalues stay far below (omega_1 / omega_max)^2.

With u_f = Psi~ xi the mass is constant (Eq. 20: I), there is no quadratic velocity vector, and

    xi'' + (c/rho) (xi' - [phi' J xi]) + K(phi) xi
        = r(t) Psi~^T A_d F - phi'' w(phi) - phi'^2 w'(phi)                      (Eq. 24)

- K(phi) = Psi~^T A_d K_L A_d^T Psi~ = sum_ij a_i a_j K_ij (a = (cos, sin, 1)) with the nine
  constant K_ij = Psi~^T G_id K_L G_jd^T Psi~ (Eq. 21), evaluated per step in the equivalent
  Fourier form K0 + cos K_c1 + sin K_s1 + cos2 K_c2 + sin2 K_s2;
- w(phi) = Psi~^T int rho N^T A S X0 = cos w_S - sin w_P (w_S, w_P: the projected f_S, f_c): the
  rigid-rotation inertia load M_rf^T q_r'' of Eq. 24;
- damping Eq. 22-23 (relative): (c/rho) Psi~^T M (u_f' - phi' S u_f), J = Psi~^T M S_d Psi~;
  the absolute model (Eq. 67) drops the J term.

Rotating frame. Substituting xi = R(phi) zeta with R(phi) = Psi~^T M A_d Psi~ (orthogonal, R' =
phi' J R) turns Eq. 24 at constant speed into the rotating-frame system of
:mod:`fxflex.solid.reduction` with K_r = K(0), G_r = J, N_r = -J^2, n_r = w_P; its equilibrium zeta
is the steady state (SPEC section 6), its eigenvalues the stability, and the deflection is
U = A^T u_f (SPEC section 2).

Drive torque: the phi row, tau = phi'' J0 + w(phi).xi'' + 1/2 xi^T K'(phi) xi - r(t) s0 - Q_phi^d
with Q_phi^d = -(c/rho) (w.xi' [+ phi' w'.xi]) (Eq. 23, D_rf = c/rho M_rf).

Tip body. A [tip_mass] flat in the tip section plane is isotropic node by node and enters M like
the solid's own mass. Its Pi_XX (extent along X) rides on the tip face's normal linearised at the
reference, as in FFRF (:mod:`fxflex.solid.tip_mass`): a mass Pi_XX J^T J that does not commute
with the G_id, so the Gram matrix, the global modes, w and J0 above are made from the isotropic
part alone and the director is added in the rotating-frame coordinates zeta, where it is FFRF's
(:class:`TipDirector`); the xi rows then have the mass I + R M_d R^T.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from fxflex.errors import FxflexError
from fxflex.numerics.dense import DenseLU
from fxflex.formulation import BuildOptions
from fxflex.scene import Scene
from fxflex.scene.kinematics import P3, S3, rotation_z
from fxflex.solid.reduction import (AffineStack, MeshData, ReducedFormulation, RotatingSystem,
                                  inner, mat_apply, nodal, reduced_key, rotation_weights, tip_rows)

if TYPE_CHECKING:                   # a cache hit needs neither dolfinx nor SLEPc: imported on use
    from fxflex.solid.cms import ClampedModes
    from fxflex.solid.model import SolidModel

__all__ = ["GCMS", "GlobalModes", "global_basis", "global_modes", "gram_cut", "build",
           "dof_count"]

G3 = np.diag([0.0, 0.0, 1.0])


def dof_count(scene: Scene) -> None:
    """Not known before the eigenmodes: the Gram cut decides how many global modes remain."""
    return None


def gram_cut(N: np.ndarray, G: np.ndarray, W33: np.ndarray, tol: float
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """M-orthonormalise the global modes from the blocks of W (module docstring).

    A direction is kept when its relative M-norm sqrt(mu / mu_max) is at least ``tol``. Returns
    (T, mu, kept): T (3m, r) with Psi~ = Psi T, the Gram eigenvalues mu (all 3m, descending) and
    the boolean mask of the kept ones.
    """
    m = N.shape[0]
    lam_h, Z = np.linalg.eigh(N - 1j * G)          # each eigenvalue twice in W: [a;b], [-b;a]
    lam_z, U = np.linalg.eigh(W33)
    top = max(lam_h.max(), lam_z.max())
    cols, mus = [], []
    for lam, z in zip(lam_h, Z.T):
        a, b = z.real, z.imag
        for vec in (np.concatenate([a, b, np.zeros(m)]), np.concatenate([-b, a, np.zeros(m)])):
            cols.append(vec)
            mus.append(lam)
    for lam, u in zip(lam_z, U.T):
        cols.append(np.concatenate([np.zeros(2 * m), u]))
        mus.append(lam)
    mus = np.array(mus)
    V = np.column_stack(cols)
    order = np.argsort(-mus, kind="stable")
    mus, V = mus[order], V[:, order]
    kept = np.sqrt(np.maximum(mus, 0.0) / top) >= tol
    T = V[:, kept] / np.sqrt(mus[kept])
    return T, mus, kept


def global_basis(Phi: np.ndarray) -> np.ndarray:
    """Psi = [G1d Phi, G2d Phi, G3d Phi] = [P_d Phi, S_d Phi, G3_d Phi] (n_owned, 3m)."""
    return np.hstack([nodal(P3, Phi), nodal(S3, Phi), nodal(G3, Phi)])


def _block_maps(m: int) -> dict[str, np.ndarray]:
    """Coefficient maps C_B with B_d Psi = Psi C_B for B = G1^T, G2^T, G3^T, S, P, G3."""
    Z, I = np.zeros((m, m)), np.eye(m)
    C1 = np.block([[I, Z, Z], [Z, I, Z], [Z, Z, Z]])        # P Psi = [Psi1, Psi2, 0]
    C2 = np.block([[Z, I, Z], [-I, Z, Z], [Z, Z, Z]])       # -S Psi = [-Psi2, Psi1, 0]
    C3 = np.block([[Z, Z, Z], [Z, Z, Z], [Z, Z, I]])        # G3 Psi = [0, 0, Psi3]
    return {"G1T": C1, "G2T": C2, "G3T": C3, "S": -C2, "P": C1, "G3": C3}


@dataclass
class GlobalModes:
    """The constant matrices and vectors of Eq. 24 on the M-orthonormal global modes."""

    T: np.ndarray               # (3m, r): Psi~ = Psi T
    gram: np.ndarray            # Gram eigenvalues (3m, descending)
    kept: np.ndarray            # mask of the retained ones
    K9: np.ndarray              # (3, 3, r, r): K_ij = Psi~^T G_id K_L G_jd^T Psi~
    J: np.ndarray               # Psi~^T M S_d Psi~ (skew)
    MP: np.ndarray              # Psi~^T M P_d Psi~
    MG3: np.ndarray             # Psi~^T M G3_d Psi~
    wS: np.ndarray              # Psi~^T f_S
    wP: np.ndarray              # Psi~^T f_c
    QP: np.ndarray              # Psi~^T P_d F
    QS: np.ndarray              # Psi~^T S_d F
    Q3: np.ndarray              # Psi~^T G3_d F
    tip: np.ndarray             # (3, r): inertial tip displacement per unit xi
    section: np.ndarray         # (6, r): tip translation and tip-section rotation per unit xi
    J0: float
    s0: float
    #: a tip body's Pi_XX on the director linearised at the reference, n = e_X + b zeta in the
    #: rotating frame (zero rows and 0 without one); wS, wP, J0 and the Gram blocks above are
    #: the isotropic mass's alone (module docstring, "Tip body")
    b: np.ndarray               # (3, r): dn per unit zeta
    pi: float                   # Pi_XX

    @property
    def count(self) -> int:
        return self.T.shape[1]


def global_modes(model: SolidModel, data: MeshData, Phi: np.ndarray, tol: float) -> GlobalModes:
    """Build Psi from Phi, cut its Gram matrix at ``tol`` and project (collective on model.comm)."""
    comm, m = model.comm, Phi.shape[1]
    Psi = global_basis(Phi)
    MPsi = mat_apply(data.M, Psi)
    W = inner(comm, Psi, MPsi)
    d, pi = data.director, 0.0
    JPsi = np.zeros((3, 3 * m))
    if d is not None:           # M holds Pi_XX J^T J (not isotropic): the Gram of the rest
        pi = d.pi
        JPsi = d.reference_rows(Psi)
        W = W - pi * JPsi.T @ JPsi
    Kb = inner(comm, Psi, mat_apply(data.K, Psi))
    Kb = 0.5 * (Kb + Kb.T)
    s1, s2, s3 = slice(0, m), slice(m, 2 * m), slice(2 * m, 3 * m)
    N = 0.5 * (W[s1, s1] + W[s2, s2])
    G = 0.5 * (W[s1, s2] - W[s2, s1])
    W33 = 0.5 * (W[s3, s3] + W[s3, s3].T)
    T, mus, kept = gram_cut(N, 0.5 * (G - G.T), W33, tol)
    C = _block_maps(m)
    Y = [C[k] @ T for k in ("G1T", "G2T", "G3T")]
    K9 = np.array([[Yi.T @ Kb @ Yj for Yj in Y] for Yi in Y])
    Wt = T.T @ W

    def proj(vec):
        return T.T @ inner(comm, Psi, vec)

    J = Wt @ C["S"] @ T
    b = JPsi @ T
    e_x = np.array([1.0, 0.0, 0.0])             # the director's own loads leave wS, wP and J0
    return GlobalModes(
        T=T, gram=mus, kept=kept, K9=K9, J=0.5 * (J - J.T), MP=Wt @ C["P"] @ T,
        MG3=Wt @ C["G3"] @ T, wS=proj(data.f_S) - pi * b.T @ S3 @ e_x,
        wP=proj(data.f_c) - pi * b.T @ P3 @ e_x, QP=proj(nodal(P3, data.F)),
        QS=proj(nodal(S3, data.F)), Q3=proj(nodal(G3, data.F)), tip=tip_rows(model, Psi) @ T,
        section=model.tip_section(Psi) @ T,
        J0=data.J0 - pi * P3[0, 0], s0=data.load_torque, b=b, pi=float(pi))


class GCMS(ReducedFormulation):
    """GCMS on the global modes of ``reduction.gcms_modes / 3`` clamped modes.

    ``model``, ``data`` and ``modes`` may be passed to share them with other builds; the first
    ``gcms_modes / 3`` modes are used.
    """

    method = "gcms"
    #: absolute coordinates: at the steady state xi = R(phi) zeta moves, xi' = Omega J xi
    steady_at_rest = False

    def __init__(self, scene: Scene, comm, options: BuildOptions | None = None, *,
                 modes: ClampedModes | None = None, model: SolidModel | None = None,
                 data: MeshData | None = None):
        super().__init__(scene, comm, options)
        n_global = scene.reduction.gcms_modes
        if n_global % 3:
            raise FxflexError(f"reduction.gcms_modes: must be a multiple of 3 (the global modes "
                              f"are [G1d Phi, G2d Phi, G3d Phi]), got {n_global}")
        t0 = time.perf_counter()
        tol = scene.reduction.gcms_gram_tol
        cached = self._use(n_global // 3, model, data, modes)
        key = reduced_key(scene, "gcms", n_global // 3, gram_tol=tol) if cached else None
        self.gm = gm = self._projections(key, GlobalModes,
                                         lambda m, d, Phi: global_modes(m, d, Phi, tol))
        self.dof = gm.count
        K = gm.K9
        self.K0 = 0.5 * (K[0, 0] + K[1, 1]) + K[2, 2]
        self.Kc1, self.Ks1 = K[0, 2] + K[2, 0], K[1, 2] + K[2, 1]
        self.Kc2, self.Ks2 = 0.5 * (K[0, 0] - K[1, 1]), 0.5 * (K[0, 1] + K[1, 0])
        self.tip_director = td = (TipDirector(gm, self.c_rho, self.absolute) if gm.pi > 0.0
                                  else None)
        if td is None:
            self.rot = RotatingSystem(K=self.stiffness(0.0), G=gm.J, N=-gm.J @ gm.J,
                                      f=gm.QP + gm.Q3, n=gm.wP, tip=gm.tip, section=gm.section)
        else:
            self.rot = RotatingSystem(K=self.stiffness(0.0), G=gm.J + td.G, N=-gm.J @ gm.J + td.N,
                                      f=gm.QP + gm.Q3, n=gm.wP + td.n, tip=gm.tip,
                                      section=gm.section, M=np.eye(self.dof) + td.M)
        # relative damping's (c/rho) phi' J xi: one more weighted block, folded into K0 at
        # constant speed
        self._J_block = not self.absolute and not self.constant_speed
        J_const = 0.0 if self.absolute or self._J_block else self.c_rho * self.omega_s
        self._at_rest = self.drive.at_rest
        if self._at_rest:
            # phi = 0 for all t: K(0), the load A F = F and no inertia load, one matrix each
            self._setup_operators([-self.stiffness(0.0)], [-self.c_rho * np.eye(self.dof)],
                                  [gm.QP + gm.Q3])
        else:
            kmats = [-self.K0 + J_const * gm.J, -self.Kc1, -self.Ks1, -self.Kc2, -self.Ks2]
            if self._J_block:
                kmats.append(gm.J)
            self._setup_operators(kmats, [-self.c_rho * np.eye(self.dof)],
                                  [gm.QP, gm.QS, gm.Q3, gm.wS, gm.wP])
        self._dK = AffineStack([self.Kc1, self.Ks1, self.Kc2, self.Ks2])
        self._rotated: RotatedLU | None = None
        self._phi_force = 0.0                     # the angle of the last force(): mass_apply's
        self._R, self._R_work = np.empty((self.dof, self.dof)), np.empty((self.dof, self.dof))
        self._R_phi: float | None = None          # the angle _R holds
        self.timings["build"] = time.perf_counter() - t0

    def stiffness(self, phi: float) -> np.ndarray:
        """K(phi) = Psi~^T A_d K_L A_d^T Psi~ (Eq. 21) from the nine constant matrices."""
        c, s, c2, s2 = rotation_weights(phi)
        return self.K0 + c * self.Kc1 + s * self.Ks1 + c2 * self.Kc2 + s2 * self.Ks2

    def rotation(self, phi: float, out: np.ndarray | None = None) -> np.ndarray:
        """R(phi) = Psi~^T M A_d Psi~: A_d Psi~ = Psi~ R on the retained span; written into
        ``out`` when given (no allocation: the time loops)."""
        c, s, _, _ = rotation_weights(phi)
        gm = self.gm
        if out is None:
            return c * gm.MP + s * gm.J + gm.MG3
        np.multiply(gm.MP, c, out=out)
        np.multiply(gm.J, s, out=self._R_work)
        out += self._R_work
        out += gm.MG3
        return out

    def _weights(self, t: float) -> None:
        if self._at_rest:
            self.fw[0] = self.ramp(t)
            return
        phi, w, a = self.drive.state(t)
        c, s, c2, s2 = rotation_weights(phi)
        kw, fw = self.kstack.w, self.fw
        kw[1], kw[2], kw[3], kw[4] = c, s, c2, s2
        if self._J_block:
            kw[5] = self.c_rho * w
        r = self.ramp(t)
        fw[0], fw[1], fw[2] = r * c, r * s, r
        fw[3] = -a * c + w * w * s
        fw[4] = a * s + w * w * c

    def factorize(self, t: float, q: np.ndarray, v: np.ndarray, m: float, c: float, k: float
                  ) -> "RotatedLU":
        """S = m I + c C_t + k K_t, factorised once for every hub angle.

        C_t = (c/rho) I and K_t = K(phi) [- (c/rho) phi' J for the relative damping]; since
        K(phi) = R(phi) K(0) R(phi)^T (A_d Psi~ = Psi~ R, module docstring) and J commutes with
        R, S(phi) = R(phi) S(0) R(phi)^T. A factor of S(0) therefore solves at any angle by
        rotating with R(phi(t)) (to the Gram cut's round-off, 4e-10 on a coarse mesh), where a
        factor of S(phi) itself would go stale within a step: the rotation mixes stiff and soft
        global modes."""
        _, rate, _ = self.drive.state(t)
        if self._rotated is None:
            self._rotated = RotatedLU(self)
        S = self._rotated.lu.matrix
        S[...] = self.stiffness(0.0)
        if not self.absolute and self.c_rho:
            S -= (self.c_rho * rate) * self.gm.J
        S *= k
        S.flat[::self.dof + 1] += m + c * self.c_rho
        if self.tip_director is not None:      # its terms are R (...) R^T as well
            S += self.tip_director.iteration_matrix(self.drive.state(t), m, c, k)
        self._rotated.lu.factor()
        return self._rotated

    # -- the tip body's director: a mass that turns with the hub ----------------------------------
    def acceleration(self, t: float, q: np.ndarray, v: np.ndarray, out: np.ndarray) -> None:
        """xi'' of Eq. 24; with a tip director (I + R M_d R^T) xi'' = f + R h (TipDirector),
        solved as R ((I + M_d)^-1 R^T f + (I + M_d)^-1 h)."""
        super().acceleration(t, q, v, out)
        td = self.tip_director
        if td is not None:
            state = self.drive.state(t)
            R = self._turn(state[0])
            z, Rv, Rf = (R.T @ np.column_stack((q, v, out))).T
            y = td.solved(state, z, Rv)
            y += td.Minv @ Rf
            np.dot(R, y, out=out)

    def force(self, t: float, q: np.ndarray, v: np.ndarray, out: np.ndarray) -> None:
        """F of M(phi) xi'' = F: Eq. 24's right side [+ R h of the tip director, whose mass
        I + R M_d R^T :meth:`mass_apply` then applies at this call's angle]."""
        super().acceleration(t, q, v, out)
        td = self.tip_director
        if td is not None:
            state = self.drive.state(t)
            R = self._turn(state[0])
            z, Rv = (R.T @ np.column_stack((q, v))).T
            y = td.solved(state, z, Rv)
            out += R @ (y + td.M @ y)
            self._phi_force = state[0]

    def mass_apply(self, x: np.ndarray, out: np.ndarray) -> None:
        out[:] = x
        if self.tip_director is not None:
            R = self._turn(self._phi_force)
            out += R @ (self.tip_director.M @ (R.T @ x))

    def _turn(self, phi: float) -> np.ndarray:
        """R(phi) in a buffer of this build, kept for the next call at the same angle
        (mass_apply after force)."""
        if phi != self._R_phi:
            self.rotation(phi, self._R)
            self._R_phi = phi
        return self._R

    def tip(self, t: float, q: np.ndarray) -> np.ndarray:
        """U_tip = A^T u_f,tip: the rigid rotation removed (SPEC section 2)."""
        return rotation_z(self.drive.angle(t)).T @ (self.gm.tip @ q)

    def rotating_state(self, t: float, q: np.ndarray, v: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray]:
        """(zeta, zeta') of the rotating frame (module docstring): xi = R zeta with R' = phi' J R,
        so zeta = R^T xi and zeta' = R^T (xi' - phi' J xi)."""
        phi, w, _ = self.drive.state(t)
        RT = self.rotation(phi).T
        return RT @ q, RT @ (v - w * (self.gm.J @ q))

    def rotating_coordinates(self, t: float, q: np.ndarray) -> np.ndarray:
        """zeta = R(phi)^T xi: U = A^T u_f = Psi~ R^T xi, since A_d Psi~ = Psi~ R."""
        return self.rotation(self.drive.angle(t)).T @ q

    def nodal_basis(self) -> tuple[np.ndarray, bool]:
        """Psi~ = [P_d Phi, S_d Phi, G3_d Phi] T, rebuilt on demand (n_owned x r)."""
        Phi = self.modes.vectors[:, : self.scene.reduction.gcms_modes // 3]
        return global_basis(Phi) @ self.gm.T, True

    # -- reference-coordinate row and energies ---------------------------------------------------
    def _w(self, phi: float) -> tuple[np.ndarray, np.ndarray]:
        c, s, _, _ = rotation_weights(phi)
        gm = self.gm
        return c * gm.wS - s * gm.wP, -s * gm.wS - c * gm.wP

    def drive_torque(self, t: float, q: np.ndarray, v: np.ndarray) -> float:
        """Torque (N m) about z that holds the prescribed rotation (module docstring)."""
        phi, w, a = self.drive.state(t)
        acc = self._acc
        self.acceleration(t, q, v, acc)
        wv, wd = self._w(phi)
        c, s, c2, s2 = rotation_weights(phi)
        dK = self._dK
        dK.w[:] = (-s, c, -2.0 * s2, 2.0 * c2)
        dKq = np.empty(self.dof)
        dK.apply(q, dKq)
        tau = a * self.gm.J0 + wv @ acc + 0.5 * q @ dKq - self.ramp(t) * self.gm.s0
        rel = 0.0 if self.absolute else 1.0
        tau += self.c_rho * (wv @ v + rel * w * (wd @ q))
        if self.tip_director is not None:
            tau += self.tip_director.torque((phi, w, a), self.rotation(phi), q, v, acc)
        return float(tau)

    def kinetic_energy(self, t: float, q: np.ndarray, v: np.ndarray) -> float:
        """T = 1/2 phi'^2 J0 + phi' w(phi).xi' + 1/2 xi'.xi' (Eq. 20) [+ the tip director's]."""
        phi, w, _ = self.drive.state(t)
        wv, _ = self._w(phi)
        T = 0.5 * w * w * self.gm.J0 + w * wv @ v + 0.5 * v @ v
        if self.tip_director is not None:
            T += self.tip_director.energy(w, self.rotation(phi), q, v)
        return float(T)

    def strain_energy(self, t: float, q: np.ndarray) -> float:
        """V_e = xi^T K(phi) xi / 2 (Eq. 21)."""
        return float(0.5 * q @ self.stiffness(self.drive.angle(t)) @ q)


class TipDirector:
    """A tip body's Pi_XX on GCMS (module docstring, "Tip body"): its director linearised at the
    reference in the rotating frame, n = A (e_X + b zeta), zeta = R(phi)^T xi.

    Its kinetic energy Pi_XX / 2 |b zeta' + phi' S (e_X + b zeta)|^2 adds, in zeta,

        M_d zeta'' + 2 phi' G_d zeta' + phi'' (G_d zeta + g_d) - phi'^2 (N_d zeta + n_d)

    (M_d = Pi b^T b, G_d = Pi b^T S b, N_d = Pi b^T P b, g_d = Pi b^T S e_X, n_d = Pi b^T P e_X:
    FFRF's director terms on span(Psi~)), and the damping (c/rho) (M_d zeta' [+ phi' G_d zeta,
    absolute]) (its rate relative to the frame, or to the rigidly turning e_X). With zeta' =
    R^T (xi' - phi' J xi) and zeta'' = R^T (xi'' - 2 phi' J xi' - phi'' J xi + phi'^2 J^2 xi)
    the xi rows read (I + R M_d R^T) xi'' = f + R h(zeta, zeta'): every added matrix is
    R (...) R^T, so the mass and the iteration matrix keep GCMS's rotated factor. The
    linearised normal has no X component (b's first row is zero), so G_d and n_d vanish to
    round-off: kept as written, the general form of the terms."""

    def __init__(self, gm: GlobalModes, c_rho: float, absolute: bool):
        b, pi, e_x = gm.b, gm.pi, np.array([1.0, 0.0, 0.0])
        self.J, self.c_rho, self.ab = gm.J, c_rho, 1.0 if absolute else 0.0
        self.b, self.pi, self.e_x = b, pi, e_x
        self.M = pi * b.T @ b
        G = pi * b.T @ S3 @ b
        self.G = 0.5 * (G - G.T)
        N = pi * b.T @ P3 @ b
        self.N = 0.5 * (N + N.T)
        self.g, self.n = pi * b.T @ (S3 @ e_x), pi * b.T @ (P3 @ e_x)
        r = gm.count
        self.Minv = np.linalg.inv(np.eye(r) + self.M)
        self.C = self.G - self.M @ self.J                # the zeta' and phi'' couplings
        self.NJ = self.N + self.M @ self.J @ self.J
        # (I + M_d)^-1 h = (weighted [C; NJ; G; CJ; MJ]) zeta + (weighted [C; M]) R^T xi' +
        # loads, all premultiplied, zeta' = R^T xi' - phi' J zeta folded in: two products a step
        Mi = self.Minv
        self._on_z = AffineStack([Mi @ A for A in (self.C, self.NJ, self.G, self.C @ self.J,
                                                   self.M @ self.J)])
        self._on_v = AffineStack([Mi @ self.C, Mi @ self.M])
        self._n, self._g = Mi @ self.n, Mi @ self.g
        self._tmp = np.empty(gm.count)

    def _zeta(self, R: np.ndarray, w: float, q: np.ndarray, v: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
        z = R.T @ q
        return z, R.T @ v - w * (self.J @ z)             # J commutes with R

    def solved(self, state, z: np.ndarray, Rv: np.ndarray) -> np.ndarray:
        """(I + M_d)^-1 h, h the director's rows moved to the right side, in zeta (class
        docstring), from zeta = R^T xi and R^T xi'."""
        _, w, a = state
        cr, ww = self.c_rho, w * w
        self._on_z.w[:] = (-a, ww, -self.ab * cr * w, 2.0 * ww, cr * w)
        self._on_v.w[:] = (-2.0 * w, -cr)
        y, tmp = np.empty(len(z)), self._tmp
        self._on_z.apply(z, y)
        self._on_v.apply(Rv, tmp)
        y += tmp
        y += ww * self._n - a * self._g
        return y

    def iteration_matrix(self, state, m: float, c: float, k: float) -> np.ndarray:
        """The director's share of m M + c C_t + k K_t at phi = 0 (R S R^T at any angle)."""
        _, w, a = state
        Cd = 2.0 * w * self.C + self.c_rho * self.M
        Kd = -w * (Cd @ self.J) + a * self.C - w * w * self.NJ + self.ab * self.c_rho * w * self.G
        return m * self.M + c * Cd + k * Kd

    def _velocity(self, w: float, z: np.ndarray, zd: np.ndarray) -> np.ndarray:
        return self.b @ zd + w * (S3 @ (self.e_x + self.b @ z))

    def energy(self, w: float, R: np.ndarray, q: np.ndarray, v: np.ndarray) -> float:
        """Pi_XX |n'|^2 / 2 (the whole of it: GCMS's J0 leaves Pi_XX out)."""
        z, zd = self._zeta(R, w, q, v)
        nd = self._velocity(w, z, zd)
        return 0.5 * self.pi * float(nd @ nd)

    def torque(self, state, R: np.ndarray, q: np.ndarray, v: np.ndarray, acc: np.ndarray
               ) -> float:
        """The director's share of the phi row at fixed xi: d/dt (dT_d/dphi') - dT_d/dphi
        - Q_phi^d, with dn'/dphi' = S e_X + (S b - b J) zeta and, since zeta = R^T xi turns
        with phi, d zeta / d phi = -J zeta; the damping's linear part."""
        _, w, a = state
        b, J, S = self.b, self.J, S3
        z, zd = self._zeta(R, w, q, v)
        zdd = R.T @ acc - 2.0 * w * (J @ zd) - (w * w) * (J @ (J @ z)) - a * (J @ z)
        nd = self._velocity(w, z, zd)
        ndd = b @ zdd + a * (S @ (self.e_x + b @ z)) + w * (S @ (b @ zd))
        lever = S @ self.e_x + S @ (b @ z) - b @ (J @ z)
        tau = ndd @ lever + nd @ (S @ (b @ zd) - b @ (J @ zd))
        tau += nd @ (b @ (J @ zd) + w * (S @ (b @ (J @ z))))
        damping = self.c_rho * (self.g @ zd + self.ab * w * (self.n @ z))
        return float(self.pi * tau + damping)


class RotatedLU:
    """LU of S(0) solving S(phi) x = r as x = R S(0)^-1 R^T r with R = R(phi(t))
    (:meth:`GCMS.factorize`)."""

    def __init__(self, gcms: GCMS):
        n = gcms.dof
        self.gcms, self.drive = gcms, gcms.drive
        self.lu = DenseLU(n)
        self._R = np.zeros((n, n))
        self._b, self._x = np.zeros(n), np.zeros(n)

    def solve(self, t: float, r: np.ndarray, out: np.ndarray) -> None:
        R = self.gcms.rotation(self.drive.angle(t), self._R)
        np.dot(R.T, r, out=self._b)
        self.lu.solve_into(self._b, self._x)
        np.dot(R, self._x, out=out)


def build(scene: Scene, comm, options: BuildOptions) -> GCMS:
    return GCMS(scene, comm, options)
