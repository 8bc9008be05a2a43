"""Floating frame of reference with relative nodal coordinates: what LEBB and NEBB share.

The beam's elastic coordinates W (6 per node: W_X, W_Y, W_Z, theta_X, theta_Y, theta_Z, measured in
the rotating frame O-XYZ, Eq. 36-37) describe the displacement U_f = N_c(X0) N_E(xi) W_fe of every
point. With the rotation prescribed as phi(t), the reference coordinates q_r = (cos phi, sin phi)
of Eq. 3 are known and their rows only carry the drive reaction; the elastic rows of Eq. 44 /
Eq. 58 reduce to (NOTES.md, acceleration in the rotating frame)

    M W'' + (2 phi' G + D) W' + (K_L + phi'' G - phi'^2 N) W + Q_N(W) = Q_e - phi'' g + phi'^2 n

with the inertia shape integrals (derived here, the paper's Appendix is not in the text)

    M = int rho N_f^T N_f dV           (M_ff of Eq. 39)
    G = int rho N_f^T S N_f dV         (skew; the paper's -M_rf3 of Eq. 59, Coriolis)
    N = int rho N_f^T P N_f dV         (the paper's M_rr6: spin softening)
    g = int rho N_f^T S X0 dV,   n = int rho N_f^T P X0 dV    (n is the paper's M_rr2(,1))

N_f = N_c N_E. NEBB adds to N the second-order rotation of its sections and tip body (the
propeller moment, :func:`section_rotation_second_order`, docs/beams.md), and its Euler-force
counterpart GS to phi'' G in the stiffness (the same function with S; the drive torque gains
d/dt (W.GS W')); LEBB, linear, does neither.
Over a section N_c = N0 + Y0 N_Y + Z0 N_Z is linear in Y0, Z0, so each integral
reduces to the section properties A, S_Y, S_Z, I_Y, I_Z, I_YZ of Eq. 41 (see
:func:`section_quadratic`), then to Gauss quadrature along X. Damping (Eq. 42, terms in delta A
ignored as in the paper): D = c/rho M (relative model); the absolute model F_d = -c (U' + phi' S U)
adds the circulatory c/rho phi' G W (SPEC section 5). Q_N is zero for LEBB and the von Karman force
for NEBB. The root node is clamped: the unknowns are the 6 n_el coordinates of the other nodes.

A tip mass (SPEC section 10) is a rigid body at the tip centroid X_c = (R + L, 0, 0) whose
points r (from X_c) move with the tip node as the section's points do, U = W_t + theta_t x r
(N_c of Eq. 36 with the offset r in all three axes, :func:`point_quadratic`): it adds to the tip
node's block of every integral above its point terms, from its mass m and second moments
Pi = int r r^T dm (:meth:`fxflex.scene.schema.TipMass.second_moments`): m Q on the
translations and sum_kl Pi_kl [e_k]x^T Q [e_l]x on the rotations (J on the rotations of M), and
to g, n the vectors m Q X_c and sum_kl Pi_kl [e_k]x Q e_l (n: m Omega^2 (R + L) along X). The
damping D = c/rho M, mass-proportional, acts on it as on the beam.
"""

from __future__ import annotations

import time

import numpy as np

from fxflex.beam.elements import lebb_tables
from fxflex.beam.line import beam_line, twist_check
from fxflex.formulation import FormulationBase, SteadyState
from fxflex.numerics.dense import DenseLU, newton, omega_max
from fxflex.numerics.qep import DenseLinearisation
from fxflex.scene import Drive, Scene
from fxflex.scene.kinematics import P3, S3

__all__ = ["FloatingFrameBeam", "prolongation", "section_quadratic", "section_linear",
           "point_quadratic", "point_linear", "section_rotation_second_order",
           "point_rotation_second_order", "N0", "NY", "NZ", "QUADRATURE_POINTS"]

#: Gauss points per element along X (exact to degree 11: the taper makes the integrands
#: polynomials of degree <= 10 for an untwisted beam; the twist adds smooth trigonometric terms)
QUADRATURE_POINTS = 6

# N_c(X0) = N0 + Y0 NY + Z0 NZ (Eq. 36): small rotation theta x (0, Y0, Z0)
N0 = np.hstack([np.eye(3), np.zeros((3, 3))])
NY = np.zeros((3, 6))
NY[0, 5], NY[2, 3] = -1.0, 1.0
NZ = np.zeros((3, 6))
NZ[0, 4], NZ[1, 3] = 1.0, -1.0
_EX, _EY, _EZ = np.eye(3)


#: the constant matrices of :func:`section_quadratic` / :func:`section_linear` per Q (a beam
#: build uses three Q; recomputing their 6 x 6 products was a tenth of a small build)
_SECTION_TERMS: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}


def _section_terms(Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(6, 36) and (8, 6): the matrices that multiply A, S_Z, S_Y, I_Z, I_Y, I_YZ in
    :func:`section_quadratic` and A X, S_Z X, S_Z, S_Y X, S_Y, I_Z, I_Y, I_YZ in
    :func:`section_linear`."""
    Q = np.asarray(Q, float)
    key = Q.tobytes()
    if key not in _SECTION_TERMS:
        def sym(a, b):
            return a.T @ Q @ b + b.T @ Q @ a
        quad = np.array([N0.T @ Q @ N0, sym(N0, NY), sym(N0, NZ), NY.T @ Q @ NY, NZ.T @ Q @ NZ,
                         sym(NY, NZ)]).reshape(6, 36)
        lin = np.array([N0.T @ Q @ _EX, NY.T @ Q @ _EX, N0.T @ Q @ _EY, NZ.T @ Q @ _EX,
                        N0.T @ Q @ _EZ, NY.T @ Q @ _EY, NZ.T @ Q @ _EZ,
                        NY.T @ Q @ _EZ + NZ.T @ Q @ _EY])
        _SECTION_TERMS[key] = (quad, lin)
    return _SECTION_TERMS[key]


def section_quadratic(Q: np.ndarray, sec) -> np.ndarray:
    """int_A N_c^T Q N_c dA (6 x 6 at every station) for a constant 3 x 3 matrix Q:
    A N0^T Q N0 + S_Z sym(N0, NY) + S_Y sym(N0, NZ) + I_Z NY^T Q NY + I_Y NZ^T Q NZ
    + I_YZ sym(NY, NZ), sym(a, b) = a^T Q b + b^T Q a."""
    quad, _ = _section_terms(Q)
    c = np.stack([sec.A, sec.S_Z, sec.S_Y, sec.I_Z, sec.I_Y, sec.I_YZ], axis=-1)
    return (c @ quad).reshape(c.shape[:-1] + (6, 6))


def section_linear(Q: np.ndarray, sec, X: np.ndarray) -> np.ndarray:
    """int_A N_c^T Q X0 dA (6-vector at every station), X0 = (X, Y0, Z0), X = R + x:
    A X N0^T Q e_X + S_Z (X NY^T Q e_X + N0^T Q e_Y) + S_Y (X NZ^T Q e_X + N0^T Q e_Z)
    + I_Z NY^T Q e_Y + I_Y NZ^T Q e_Z + I_YZ (NY^T Q e_Z + NZ^T Q e_Y)."""
    _, lin = _section_terms(Q)
    X = np.asarray(X)
    c = np.stack([sec.A * X, sec.S_Z * X, sec.S_Z, sec.S_Y * X, sec.S_Y, sec.I_Z, sec.I_Y,
                  sec.I_YZ], axis=-1)
    return c @ lin


#: [e_k]x, the cross-product matrices of the axes: theta x r = -sum_k r_k [e_k]x theta
_CROSS = np.array([[[0.0, 0, 0], [0, 0, -1], [0, 1, 0]], [[0.0, 0, 1], [0, 0, 0], [-1, 0, 0]],
                   [[0.0, -1, 0], [1, 0, 0], [0, 0, 0]]])


def point_quadratic(Q: np.ndarray, mass: float, Pi: np.ndarray) -> np.ndarray:
    """int N_r^T Q N_r dm (6 x 6) over a rigid body of mass m and second moments Pi about its
    centroid, N_r = [I, -[r]x] (U = W + theta x r): the point analogue of
    :func:`section_quadratic`; the cross terms vanish (first moments zero about the centroid)."""
    out = np.zeros((6, 6))
    out[:3, :3] = mass * Q
    out[3:, 3:] = np.einsum("kl,kab,bc,lcd->ad", Pi, _CROSS, Q, _CROSS)
    out[3:, 3:] *= -1.0                                  # [e_k]x^T = -[e_k]x
    return out


def point_linear(Q: np.ndarray, mass: float, Pi: np.ndarray, Xc: np.ndarray) -> np.ndarray:
    """int N_r^T Q (X_c + r) dm (6-vector), the point analogue of :func:`section_linear`:
    m Q X_c on the translations, sum_kl Pi_kl [e_k]x Q e_l on the rotations."""
    out = np.zeros(6)
    out[:3] = mass * Q @ Xc
    out[3:] = np.einsum("kl,kab,bl->a", Pi, _CROSS, Q)
    return out


def section_rotation_second_order(B: np.ndarray, sec, X: np.ndarray) -> np.ndarray:
    """The second-order rotation's share of the rotating-frame matrix of B (6 x 6 at every
    station, docs/beams.md "NEBB: the propeller moment"): the Hessian over theta of
    int (B X0) . u2 dA, where u2 = ((theta . s) theta - |theta|^2 s) / 2 is the second-order
    displacement of the section point s = (0, Y0, Z0) under the small rotation theta and
    X0 = (X, Y0, Z0), X = R + x:

        sym(int s (B X0)^T dA) - (int s . B X0 dA) I
          = sym(X F (B e_X)^T + Q B^T) - (X F . B e_X + tr(B Q)) I

    on the rotations (zero on the translations), F = int s dA = (0, S_Z, S_Y), Q = int s s^T dA.
    B = P (centrifugal, added to N): [[-I_Z, X S_Z / 2, X S_Y / 2], [., 0, I_YZ / 2],
    [., ., -I_Z]], so torsion and the in-plane slope gain +Omega^2 rho I_Z under -phi'^2 N; B = S
    (Euler, joining phi'' G): [[-X S_Z, -I_Z / 2, -I_YZ / 2], [., 0, X S_Y / 2], [., ., -X S_Z]]."""
    X = np.asarray(X)
    F = np.zeros(np.shape(sec.A) + (3,))
    F[..., 1], F[..., 2] = sec.S_Z, sec.S_Y
    Q = np.zeros(np.shape(sec.A) + (3, 3))
    Q[..., 1, 1], Q[..., 2, 2] = sec.I_Z, sec.I_Y
    Q[..., 1, 2] = Q[..., 2, 1] = sec.I_YZ
    Be = B @ _EX
    A = X[..., None, None] * F[..., :, None] * Be + Q @ B.T       # int s (B X0)^T dA
    trace = X * (F @ Be) + np.einsum("ij,...ji->...", B, Q)       # int s . B X0 dA
    out = np.zeros(np.shape(sec.A) + (6, 6))
    out[..., 3:, 3:] = 0.5 * (A + np.swapaxes(A, -1, -2)) - trace[..., None, None] * np.eye(3)
    return out


def point_rotation_second_order(B: np.ndarray, Pi: np.ndarray) -> np.ndarray:
    """:func:`section_rotation_second_order` for the rigid tip body (6 x 6): its first moments
    vanish about X_c, so sym(Pi B^T) - tr(B Pi) I on the rotations (B = P: (Pi P + P Pi) / 2 -
    tr(P Pi) I; B = S: (S Pi - Pi S) / 2)."""
    out = np.zeros((6, 6))
    out[3:, 3:] = 0.5 * (Pi @ B.T + B @ Pi) - np.trace(B @ Pi) * np.eye(3)
    return out


def section_stiffness(scene: Scene, sec) -> np.ndarray:
    """Cross-section stiffness matrix of Eq. 41 (4 x 4 at every station), generalized strains
    (W_X', W_Z'', W_Y'', theta_X'); J_X per ``section.torsion``."""
    E, G = scene.material.E, scene.material.G
    out = np.zeros(sec.A.shape + (4, 4))
    out[..., 0, 0] = E * sec.A
    out[..., 0, 1] = out[..., 1, 0] = -E * sec.S_Y
    out[..., 0, 2] = out[..., 2, 0] = -E * sec.S_Z
    out[..., 1, 1] = E * sec.I_Y
    out[..., 1, 2] = out[..., 2, 1] = E * sec.I_YZ
    out[..., 2, 2] = E * sec.I_Z
    out[..., 3, 3] = G * sec.J_X(scene.section.torsion)
    return out


def _assemble(blocks: np.ndarray, n_full: int, dpn: int) -> np.ndarray:
    """Dense assembly of element matrices (n_el, 2 dpn, 2 dpn) or vectors of a chain."""
    out = np.zeros((n_full,) * (blocks.ndim - 1))
    for e, b in enumerate(blocks):
        sl = slice(dpn * e, dpn * e + b.shape[0])
        if b.ndim == 2:
            out[sl, sl] += b
        else:
            out[sl] += b
    return out


def element_integral(dx: np.ndarray, N1: np.ndarray, A: np.ndarray, N2: np.ndarray
                     ) -> np.ndarray:
    """sum_q dx[e, q] N1[q]^T A[e, q] N2[q] (e, i, j): the element matrices of a section
    operator A (e, q, a, b) between shape-function tables N1 (q, a, i), N2 (q, b, j), by two
    batched matrix products and a sum over the points (one four-operand einsum loops over all
    six indices at once: 18x slower on 40 elements; two pairwise einsums: 3-6x slower than the
    products on 2-40 elements, a third of a beam level's build)."""
    T = (dx[:, :, None, None] * A) @ N2
    return (np.swapaxes(N1, -1, -2) @ T).sum(axis=1)


def _prolongation_parts(n_el: int, le: float, x_nodes: np.ndarray):
    """(e, N): per node of ``x_nodes`` after the root, the element of a beam of ``n_el`` elements
    of length ``le`` it lies in and the element's shape matrix N_E (Eq. 37) there (n, 6, 12)."""
    x = np.asarray(x_nodes, float)[1:]
    e = np.minimum((x / le).astype(int), n_el - 1)
    return e, lebb_tables(x / le - e, le).N


def prolongation(n_el: int, le: float, x_nodes: np.ndarray) -> np.ndarray:
    """(6 (len(x_nodes) - 1), 6 n_el): the coordinates of a beam of ``n_el`` elements of length
    ``le`` (root clamped) interpolated at the nodes ``x_nodes`` of another mesh of the same line
    (root first, left out): the element's shape matrix N_E (Eq. 37) at each node gives its six
    coordinates (values and rotations). Exact for every field of the coarse space at nodes of a
    mesh that refines it (nested Hermite spaces). As a dense matrix (the restricted solve);
    :meth:`FloatingFrameBeam.prolongate` applies it to a vector without forming it."""
    e, N = _prolongation_parts(n_el, le, x_nodes)
    P = np.zeros((e.size, 6, 6 * (n_el + 1)))
    rows = np.arange(e.size)[:, None, None]
    P[rows, np.arange(6)[None, :, None], (6 * e[:, None] + np.arange(12))[:, None, :]] = N
    return P.reshape(6 * e.size, -1)[:, 6:]                    # the clamped root's columns out


class FloatingFrameBeam(FormulationBase):
    """LEBB (and, with a nonlinear force, NEBB) in the floating frame; see the module docstring."""

    extra_columns = ("drive_torque_Nm",)
    force_eval: str | None = None

    def __init__(self, scene: Scene, method: str):
        from mpi4py import MPI

        t0 = time.perf_counter()
        self.method, self.scene, self.comm = method, scene, MPI.COMM_SELF
        self.drive = Drive(scene.rotation)
        rho = scene.material.rho
        self.c_rho = scene.damping.c / rho
        self.absolute = scene.damping.model == "absolute"
        self.warnings = twist_check(scene, method)
        line = self.line = beam_line(scene, QUADRATURE_POINTS)
        tab = self.tab = lebb_tables(line.xi, line.le)
        n_full = 6 * line.n_nodes
        self.n_full, self.dof = n_full, 6 * line.n_el
        sec, dx = line.sec, line.dx
        X = line.hub_radius + line.xq
        # element matrices by quadrature of the section integrals (Eq. 39, 41)
        Ne = tab.N
        integral = lambda A6: rho * element_integral(dx, Ne, A6, Ne)
        mass = lambda Q: integral(section_quadratic(Q, sec))
        NeF = Ne.reshape(-1, Ne.shape[-1])                     # (q a, i)
        vec = lambda Q: rho * ((dx[..., None] * section_linear(Q, sec, X)).reshape(
            dx.shape[0], -1) @ NeF)                            # sum_qa dx N^T (int N_c^T Q X0)
        self.Me, Ge, Nme = mass(np.eye(3)), mass(S3), mass(P3)
        second = method == "nebb"            # the propeller moment (module docstring)
        if second:
            Nme = Nme + integral(section_rotation_second_order(P3, sec, X))
            GSe = integral(section_rotation_second_order(S3, sec, X))
        self.KLe = element_integral(dx, tab.B, section_stiffness(scene, sec), tab.B)
        fq_e = scene.load.line_load * np.einsum("eq,qi->ei", dx, Ne[:, 2, :])
        full = {"M": _assemble(self.Me, n_full, 6), "G": _assemble(Ge, n_full, 6),
                "N": _assemble(Nme, n_full, 6), "K": _assemble(self.KLe, n_full, 6),
                "g": _assemble(vec(S3), n_full, 6), "n": _assemble(vec(P3), n_full, 6),
                "fq": _assemble(fq_e, n_full, 6)}
        if second:
            full["GS"] = _assemble(GSe, n_full, 6)
        # int rho X0^T P X0 dV: the undeformed beam's moment of inertia about the axis
        self.I0 = float(rho * np.sum(dx * (sec.A * X**2 + 2 * X * sec.S_Z + sec.I_Z)))
        tip = scene.tip_mass
        if tip.present:                     # the tip body's point terms (module docstring)
            m, Pi = tip.mass, tip.second_moments()
            Xc = np.array([line.hub_radius + line.length, 0.0, 0.0])
            t = slice(n_full - 6, n_full)
            for key, Q in (("M", np.eye(3)), ("G", S3), ("N", P3)):
                full[key][t, t] += point_quadratic(Q, m, Pi)
            if second:
                full["N"][t, t] += point_rotation_second_order(P3, Pi)
                full["GS"][t, t] += point_rotation_second_order(S3, Pi)
            for key, Q in (("g", S3), ("n", P3)):
                full[key][t] += point_linear(Q, m, Pi, Xc)
            self.I0 += m * Xc @ P3 @ Xc + float(np.trace(P3 @ Pi))
        # root rows, for the section forces the beam transmits to the clamp (root_stress)
        self.K_root, self.fq_root = full["K"][:6].copy(), full["fq"][:6].copy()
        f = slice(6, None)                                   # root node clamped
        # contiguous copies: np.dot(view, x, out=) would copy a strided view at every call
        self.M, self.G, self.N, self.K = (np.ascontiguousarray(full[k][f, f]) for k in "MGNK")
        self.g, self.n, self.fq = full["g"][f], full["n"][f], full["fq"][f]
        self.ftip = np.zeros(self.dof)
        self.ftip[-6:-3] = scene.load.tip_force
        self.timings = {"assemble": time.perf_counter() - t0}
        # NEBB: the Euler force's share of the second-order rotation, with phi'' (symmetric)
        self.GS = np.ascontiguousarray(full["GS"][f, f]) if second else None
        self.load = self.fq + self.ftip
        self.at_rest = self.drive.at_rest                # no Coriolis, no inertia loads
        n = self.dof
        self._Kq, self._Cv, self._nn = np.zeros((n, n)), np.zeros((n, n)), np.zeros((n, n))
        self._f = np.zeros(n)
        self._w1, self._w2 = np.zeros(n), np.zeros(n)
        self._Wfull, self._QN = np.zeros(n_full), np.zeros(n_full)
        self._a_extra = np.zeros(n)
        # the acceleration that extras() computed, reused when the next step asks for the same
        # (t, q, v): the driver samples right before the step that starts from that state
        self._memo_t: float | None = None
        self._memo_q, self._memo_v, self._memo_d = np.zeros(n), np.zeros(n), np.zeros(n)
        self._key = None
        # implicit integration: the same coefficients without M^-1 (built when first asked for)
        self._Keff, self._Ceff, self._feff = np.zeros((n, n)), np.zeros((n, n)), np.zeros(n)
        self._fkey = None
        self._lu: DenseLU | None = None
        self._steady: SteadyState | None = None
        self._omega_max: float | None = None

    #: the explicit time loop's M^-1 products (:meth:`_explicit_matrices`)
    _EXPLICIT = frozenset({"Minv", "MiK", "MiG", "MiN", "MiGS", "Mi_fq", "Mi_tip", "Mi_load",
                           "Mi_g", "Mi_n"})

    def __getattr__(self, name: str):
        """The M^-1 products on first use (a steady state or modes analysis never needs them:
        a tenth to a fifth of a small build; a time loop makes them at :meth:`initial_state`)."""
        if name in type(self)._EXPLICIT and "M" in self.__dict__:
            self._explicit_matrices()
            return self.__dict__[name]
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    def _explicit_matrices(self) -> None:
        """M^-1 (symmetrised) and its products with K, G, N, GS and the load vectors: what
        :meth:`acceleration` multiplies (timed as ``factorise``)."""
        if "Minv" in self.__dict__:
            return
        t1 = time.perf_counter()
        Minv = np.linalg.inv(self.M)
        Minv = 0.5 * (Minv + Minv.T)
        self.MiK, self.MiG, self.MiN = Minv @ self.K, Minv @ self.G, Minv @ self.N
        self.MiGS = Minv @ self.GS if self.GS is not None else None
        self.Mi_fq, self.Mi_tip = Minv @ self.fq, Minv @ self.ftip
        self.Mi_load = self.Mi_fq + self.Mi_tip          # both follow the load ramp
        self.Mi_g, self.Mi_n = Minv @ self.g, Minv @ self.n
        self.Minv = Minv
        self.timings["factorise"] = time.perf_counter() - t1

    # ------------------------------------------------------------------ nonlinear hooks (NEBB)
    nonlinear = False

    def add_static_force(self, Wfull: np.ndarray, out: np.ndarray) -> None:
        """The nonlinear force of the steady Newton and the root stress (no time loop): NEBB's
        element route, which needs none of the time loop's system matrices."""
        self.add_nonlinear_force(Wfull, out)

    def add_nonlinear_force(self, Wfull: np.ndarray, out: np.ndarray) -> None:
        """out += Q_N(W) on the full coordinate vector (root included); LEBB: nothing."""

    def nonlinear_tangent(self, Wfull: np.ndarray) -> np.ndarray:
        return np.zeros((self.n_full, self.n_full))

    # ------------------------------------------------------------------ protocol
    def initial_state(self) -> tuple[np.ndarray, np.ndarray]:
        """Undeformed and at rest relative to the frame: W = 0, W' = 0. A time loop follows:
        the M^-1 products are made here, before its clock starts."""
        self._explicit_matrices()
        return np.zeros(self.dof), np.zeros(self.dof)

    def constrain(self, t: float, q: np.ndarray, v: np.ndarray) -> None:
        """The clamp is built into the unknowns: nothing to do."""

    def _coefficients(self, rate: float, accel: float) -> None:
        """M^-1 (K_L + phi'' G - phi'^2 N [+ c/rho phi' G]) and M^-1 (2 phi' G + D), rebuilt only
        when phi' or phi'' change (never at constant speed)."""
        Kq, Cv, nn = self._Kq, self._Cv, self._nn
        np.multiply(self.MiG, accel + (self.c_rho * rate if self.absolute else 0.0), out=Kq)
        Kq += self.MiK
        if self.GS is not None and accel:
            np.multiply(self.MiGS, accel, out=nn)
            Kq += nn
        np.multiply(self.MiN, rate * rate, out=nn)
        Kq -= nn
        np.multiply(self.MiG, 2.0 * rate, out=Cv)
        Cv.flat[::self.dof + 1] += self.c_rho
        np.multiply(self.Mi_g, -accel, out=self._f)
        np.multiply(self.Mi_n, rate * rate, out=self._w1)
        self._f += self._w1
        self._key = (rate, accel)

    def acceleration(self, t: float, q: np.ndarray, v: np.ndarray, out: np.ndarray) -> None:
        """out = M^-1 [Q_e - (2 phi' G + D) W' - (K_L + phi'' G - phi'^2 N) W - Q_N(W)
        - phi'' g + phi'^2 n] (Eq. 44/58 with the reference coordinates eliminated)."""
        if t == self._memo_t and self._same(q, self._memo_q) and self._same(v, self._memo_v):
            out[:] = self._a_extra
            return
        rate, accel = self.drive.rate(t), self.drive.accel(t)
        if self._key != (rate, accel):
            self._coefficients(rate, accel)
        rest = self.at_rest
        self._combine(t, q, v, out, self._Kq, None if rest else self._Cv,
                      None if rest else self._f, self.Mi_load, self.Minv)

    def _combine(self, t: float, q: np.ndarray, v: np.ndarray, out: np.ndarray, K, C, f, load,
                 Minv) -> None:
        """out = -K W - C W' + f + r(t) load - [Minv] Q_N(W): the right-hand side with the
        matrices of ``acceleration`` (M^-1 applied) or of ``force`` (Minv None). C None stands
        for c/rho I (M^-1 D at rest), f None for no inertia loads (at rest)."""
        w1 = self._w1
        np.dot(K, q, out=out)
        if C is None:                                      # at rest: M^-1 (2 phi' G + D) = c/rho I
            np.multiply(v, self.c_rho, out=w1)
        else:
            np.dot(C, v, out=w1)
        out += w1
        np.negative(out, out=out)
        if f is not None:                                  # - phi'' g + phi'^2 n
            out += f
        np.multiply(load, self.scene.load.factor(t), out=w1)
        out += w1
        if self.nonlinear:
            self._Wfull[6:] = q
            self._QN.fill(0.0)
            self.add_nonlinear_force(self._Wfull, self._QN)
            if Minv is None:
                out -= self._QN[6:]
            else:
                np.dot(Minv, self._QN[6:], out=w1)
                out -= w1

    # ------------------------------------------------------------------ implicit integration
    def _force_coefficients(self, rate: float, accel: float) -> None:
        """K_eff = K_L + phi'' G - phi'^2 N [+ c/rho phi' G], C_eff = 2 phi' G + D and
        f = -phi'' g + phi'^2 n: ``_coefficients`` without M^-1."""
        Keff, Ceff = self._Keff, self._Ceff
        np.multiply(self.G, accel + (self.c_rho * rate if self.absolute else 0.0), out=Keff)
        Keff += self.K
        if self.GS is not None and accel:
            np.multiply(self.GS, accel, out=self._nn)
            Keff += self._nn
        np.multiply(self.N, rate * rate, out=self._nn)
        Keff -= self._nn
        np.multiply(self.G, 2.0 * rate, out=Ceff)
        np.multiply(self.M, self.c_rho, out=self._nn)
        Ceff += self._nn
        np.multiply(self.g, -accel, out=self._feff)
        np.multiply(self.n, rate * rate, out=self._w2)
        self._feff += self._w2
        self._fkey = (rate, accel)

    def force(self, t: float, q: np.ndarray, v: np.ndarray, out: np.ndarray) -> None:
        """F = Q_e - C_eff W' - K_eff W - Q_N(W) + f (Eq. 44/58, the right-hand side of
        ``acceleration`` before M^-1)."""
        rate, accel = self.drive.rate(t), self.drive.accel(t)
        if self._fkey != (rate, accel):
            self._force_coefficients(rate, accel)
        self._combine(t, q, v, out, self._Keff, self._Ceff, None if self.at_rest else self._feff,
                      self.load, None)

    def mass_apply(self, x: np.ndarray, out: np.ndarray) -> None:
        np.dot(self.M, x, out=out)

    def factorize(self, t: float, q: np.ndarray, v: np.ndarray, m: float, c: float, k: float
                  ) -> DenseLU:
        """S = m M + c C_eff + k (K_eff + K_N,T(W)): exact tangents (K_N,T from the invariant
        tensors, :meth:`~fxflex.beam.invariants.GramChain.tangent`)."""
        rate, accel = self.drive.rate(t), self.drive.accel(t)
        if self._fkey != (rate, accel):
            self._force_coefficients(rate, accel)
        if self._lu is None:
            self._lu = DenseLU(self.dof)
        S = self._lu.matrix
        S[...] = self._Keff
        if self.nonlinear:
            self._Wfull[6:] = q
            S += self.nonlinear_tangent(self._Wfull)[6:, 6:]
        S *= k
        S += c * self._Ceff
        S += m * self.M
        return self._lu.factor()

    def _same(self, a: np.ndarray, b: np.ndarray) -> bool:
        np.subtract(a, b, out=self._memo_d)
        return not self._memo_d.any()

    def tip(self, t: float, q: np.ndarray) -> np.ndarray:
        """W_X, W_Y, W_Z of the free-end node: already relative and in O-XYZ."""
        return np.array(q[-6:-3], dtype=float)

    def rotating_state(self, t: float, q: np.ndarray, v: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray]:
        """(W, W') in the coordinates of :meth:`linearise`: the relative coordinates themselves."""
        return q, v

    def extras(self, t: float, q: np.ndarray, v: np.ndarray) -> tuple[float]:
        """Drive torque about z (N m) from the eliminated reference rows: d/dt of the angular
        momentum about the axis minus the moments of the loads and of the damping force.

        T = g.W'' - W.G W'' + 2 phi' (n.W' + W.N W') + phi'' (I0 + 2 n.W + W.N W) - M_z(F_tip)
            - M_z(F_d), with M_z(F_d) = c/rho (W.G W' - g.W') [- c/rho phi' (n.W + W.N W)]."""
        rate, accel = self.drive.rate(t), self.drive.accel(t)
        a = self._a_extra
        self._memo_t = None
        self.acceleration(t, q, v, a)
        self._memo_t = t
        self._memo_q[:] = q
        self._memo_v[:] = v
        torque = (self.g @ a - q @ (self.G @ a) + 2 * rate * (self.n @ v + q @ (self.N @ v))
                  + accel * (self.I0 + 2 * self.n @ q + q @ (self.N @ q)))
        if self.GS is not None:             # d/dt of the second-order relative momentum
            torque += v @ (self.GS @ v) + q @ (self.GS @ a)
        Fx, Fy, _ = np.asarray(self.scene.load.tip_force) * self.scene.load.factor(t)
        x_tip = self.line.hub_radius + self.line.length + q[-6]
        torque -= x_tip * Fy - q[-5] * Fx
        m_damp = self.c_rho * (q @ (self.G @ v) - self.g @ v)
        if self.absolute:
            m_damp -= self.c_rho * rate * (self.n @ q + q @ (self.N @ q))
        return (float(torque - m_damp),)

    def root_stress(self, t: float, q: np.ndarray) -> np.ndarray:
        """sigma_X (Pa) at the four corners of the root section from the section forces there:
        the elastic force on the clamped root node, (K_L W + Q_N(W)) minus the line load's share
        of it (exact in equilibrium: the support reaction), gives N = -Q_X, int Y sigma dA =
        Q_thetaZ and int Z sigma dA = -Q_thetaY (U_X = W_X - Y theta_Z + Z theta_Y, Eq. 36);
        beam theory spreads them linearly over the section (Eq. 40-41)."""
        Wf = np.zeros(self.n_full)
        Wf[6:] = q
        Q = self.K_root @ Wf
        if self.nonlinear:
            QN = np.zeros(self.n_full)
            self.add_static_force(Wf, QN)
            Q += QN[:6]
        Q -= self.scene.load.factor(t) * self.fq_root
        return self.line.shape.axial_stress(0.0, (-Q[0], Q[5], -Q[4]))

    def field_writer(self, path: str, comm=None):
        """``--fields``: the beam line with U_hub, u and the nodal rotation theta (XDMF, written
        by rank 0 of ``comm``, default COMM_WORLD; :mod:`fxflex.beam.beam_fields`)."""
        from fxflex.beam.beam_fields import frame_field_writer
        return frame_field_writer(self, path, comm)

    # ------------------------------------------------------------------ steady state and stability
    def _stiffness(self, W: np.ndarray, rate: float) -> np.ndarray:
        """Effective tangent K_L + K_N,T(W) - phi'^2 N [+ c/rho phi' G]."""
        K = self.K - rate**2 * self.N
        if self.absolute:
            K = K + self.c_rho * rate * self.G
        if self.nonlinear:
            Wf = np.zeros(self.n_full)
            Wf[6:] = W
            K = K + self.nonlinear_tangent(Wf)[6:, 6:]
        return K

    def _static_residual(self, W: np.ndarray, s: float) -> np.ndarray:
        rate = np.sqrt(s) * self.scene.rotation.omega
        r = (self.K - rate**2 * self.N) @ W - s * (self.fq + self.ftip) - rate**2 * self.n
        if self.absolute:
            r += self.c_rho * rate * self.G @ W
        if self.nonlinear and W.any():          # Q_N(0) = 0 (Newton's reference residual)
            Wf, QN = np.zeros(self.n_full), np.zeros(self.n_full)
            Wf[6:] = W
            self.add_static_force(Wf, QN)
            r += QN[6:]
        return r

    def steady_state(self) -> SteadyState:
        """Rotating-frame equilibrium at the scene's final speed: LEBB solves Eq. 59 with the time
        derivatives set to zero, (K_L - Omega^2 M_rr6) W = Q_e + Omega^2 M_rr2(,1) (one Newton
        step); NEBB adds the von Karman force and iterates (Newton, speed continuation if needed)."""
        if self._steady is not None:
            return self._steady
        t0 = time.perf_counter()
        omega = self.scene.rotation.omega
        tangent = lambda W, s: self._stiffness(W, np.sqrt(s) * omega)
        start, extra = self.steady_start, {}
        rtol = self.steady_rtol
        if start is not None:                     # a guess (nested iteration): else from rest
            W, its, hist, ok = newton(self._static_residual, tangent, start, rtol=rtol)
            if not ok:
                start, extra = None, {"cold_fallback": True}
        if start is None:
            W, its, hist, ok = newton(self._static_residual, tangent, np.zeros(self.dof),
                                      rtol=rtol)
        if not ok and self.nonlinear:
            W, its, hist, ok = newton(self._static_residual, tangent, np.zeros(self.dof),
                                      steps=tuple(np.linspace(0.1, 1.0, 10)), rtol=rtol)
        self._steady = SteadyState(tip=self.tip(0.0, W), q=W, iterations=its, residuals=hist,
                                   converged=ok, timings={"steady": time.perf_counter() - t0},
                                   extra=extra)
        return self._steady

    #: a first guess of the steady state's W (the ``--tol`` ladder's coarser level, prolongated)
    steady_start: np.ndarray | None = None

    def prolongate(self, W: np.ndarray, x_nodes: np.ndarray) -> np.ndarray:
        """This beam's coordinates W (root clamped) interpolated at the nodes ``x_nodes`` of
        another mesh of the same line (:func:`prolongation`, applied node by node)."""
        e, N = _prolongation_parts(self.line.n_el, self.line.le, x_nodes)
        ends = np.concatenate([np.zeros(6), W])[6 * e[:, None] + np.arange(12)]   # (n, 12)
        return np.einsum("nij,nj->ni", N, ends).reshape(-1)

    def restricted_steady(self, n_coarse: int) -> SteadyState:
        """LEBB: the steady state on ``n_coarse`` equal elements, whose Hermite space is a
        subspace of this mesh's when this mesh refines it (n_el a multiple of n_coarse): the
        Galerkin solution there, P^T (K_L - Omega^2 N [+ c/rho Omega G, absolute damping]) P u
        = P^T (Q_e + Omega^2 n) with P the coarse space's :func:`prolongation` to these nodes.
        It is the ``n_coarse``-element discretisation integrated at this mesh's Gauss points:
        where the section properties are polynomial or smooth along the span (the paper's
        rectangle, tapered and twisted) the tip agrees with a ``n_coarse``-element build to
        1e-13 of |tip|; station tables and hollow walls, sampled more densely here, differ by
        their quadrature (2.9e-5 for a tapered hollow wall), which is why the ladder uses it
        only for the paper's shape. Costs no build (the ``--tol`` ladder's first level,
        :meth:`fxflex.analysis.tolerance.Refiner.nested`)."""
        if self.nonlinear:
            raise ValueError("restricted_steady: only a linear beam (LEBB)")
        if self.line.n_el % n_coarse:
            raise ValueError(f"restricted_steady: {self.line.n_el} elements do not refine "
                             f"{n_coarse}")
        t0 = time.perf_counter()
        P = prolongation(n_coarse, self.line.length / n_coarse, self.line.x_nodes)
        zero = np.zeros(self.dof)
        A = self._stiffness(zero, self.scene.rotation.omega)
        r0 = self._static_residual(zero, 1.0)
        Ac, rc = P.T @ A @ P, P.T @ r0
        u = np.linalg.solve(Ac, -rc)
        hist = [float(np.linalg.norm(rc)), float(np.linalg.norm(Ac @ u + rc))]
        return SteadyState(tip=self.tip(0.0, u), q=u, iterations=1, residuals=hist,
                           converged=True, timings={"steady": time.perf_counter() - t0},
                           extra={"restricted_from_elements": self.line.n_el})

    def linearise(self, steady: SteadyState | None = None) -> DenseLinearisation:
        """(M, C, K) of the motion about the steady state (SPEC section 6): C = 2 Omega G + D,
        K = K_L + K_N,T(W*) - Omega^2 N [+ c/rho Omega G for the absolute damping model]."""
        W = (steady or self.steady_state()).q
        omega = self.scene.rotation.omega
        C = 2 * omega * self.G + self.c_rho * self.M
        return DenseLinearisation(self.M.copy(), C, self._stiffness(W, omega))

    def mode_tip(self, X: np.ndarray) -> np.ndarray:
        """(6, k) tip translation and rotation of mode vectors X (dof, k): the free-end node's
        W_X, W_Y, W_Z, theta_X, theta_Y, theta_Z (O-XYZ)."""
        return X[-6:]

    def mode_span(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(x, S) of mode vectors X (dof, k): the nodes' distances from the root (s,) and
        S (4, s, k) their W_X, W_Y, W_Z, theta_X (O-XYZ; the section centroid lies on the
        reference line, SPEC section 9), zero at the clamped root (SPEC section 10)."""
        X2 = X.reshape(X.shape[0], -1)
        S = np.zeros((4, self.line.n_nodes, X2.shape[1]), dtype=X.dtype)
        S[:, 1:] = X2.reshape(self.line.n_el, 6, -1)[:, :4].transpose(1, 0, 2)
        return self.line.x_nodes.copy(), S

    def omega_max(self) -> float:
        """Highest circular frequency of the clamped beam at rest, sqrt(max eig(K_L, M))."""
        if self._omega_max is None:
            self._omega_max = omega_max(self.K, self.M)
        return self._omega_max

