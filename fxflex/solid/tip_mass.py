"""The [tip_mass] of SPEC section 10 on the solid models (FFRF, GCMS, TLF), through the tip face.

The body is rigid, rigidly attached at the tip section centroid X_c = (R + L, 0, 0): mass m and
second moments Pi = int r r^T dm about X_c (:meth:`fxflex.scene.schema.TipMass.second_moments`,
J = tr(Pi) I - Pi, the same Pi as the beams' point terms in :mod:`fxflex.beam.frame`). Its mass
is written as a scalar matrix mu over the tip face nodes, one 3 x 3 identity per node pair
(isotropic, like the solid's own consistent mass of Eq. 29):

    M_tip = mu (x) I_3,   mu = m w w^T + Pi_YY g_Y g_Y^T + Pi_ZZ g_Z g_Z^T,

- w: the translation weights of the tip face's least-squares rigid fit
  (:meth:`SolidModel.tip_fit`, t = sum_a w_a u_a; sum w_a = 1, sum w_a r_a = 0 with
  r_a = X_a - X_c, checked on build: the section centroid is the face nodes' mean);
- G = [g_Y, g_Z]: gradient rows of the affine least-squares fit u ~ a + (grad u) r over the tip
  face nodes, so that sum_a g_i,a = 0 and sum_a g_i,a r_a = e_i (the face's own rotation).

This mass carries Pi in the tip section plane only (the face has no extent along X): a body
flat in that plane, Pi_XX = 0, i.e. J_X = J_Y + J_Z (a thin disc [2 J, J, J], a rod along Y or
Z; :func:`fxflex.scene.load.tip_body_is_flat`). (A gradient along X would need nodes behind the
face; over the last node layer its weights grow as 1 / h, and Pi_XX then loads that layer's
axial and shear strain rates with an inertia Pi_XX / h^2: local modes whose frequencies fall as
the mesh is refined, measured from 189 to 73 Hz between 40 and 320 layers. A scalar mass per
node pair cannot tell a rotation from a strain there.) The rest, Pi_XX, TLF carries on the
face's unit normal n = g_Y x g_Z / |g_Y x g_Z| (:class:`Director`: a mass that depends on the
configuration, exact for every rigid motion of the face); FFRF and GCMS, whose reductions rest
on the constant isotropic mass below, refuse it with one line
(:func:`fxflex.scene.load.validate_for`).

Then for any rigid motion of the face, v_a = v_c + omega x r_a' (r_a' = A r_a, any rotation A,
not only a small one), the kinetic energy 1/2 sum mu_ab v_a . v_b is
1/2 m |v_c|^2 + 1/2 omega^T (tr(Pi') I - Pi') omega with Pi' = A Pi A^T: the rigid body's,
exactly. Where the face deforms, the body follows its affine fit, which sees the face's in-plane
strain rates besides its rotation (terms of the order of the section's in-plane strain: a rod
along Y, [P, 0, P], and a disc [P, P/2, P/2] give torsion frequencies 0.35 % apart at rest on a
uniform 0.12 x 0.06 m solid with P = rho I_p L, docs/beams.md).

Being isotropic node by node, M_tip commutes with the nodal 3 x 3 operators B = S, P, G3 and with
A_d, so every rotating-frame term that FFRF, GCMS and TLF build from the mass follows by adding
M_tip where they use M (NOTES.md): int rho N^T B N dV gains mu (x) B (Coriolis S, spin softening
P: with Pi, the body's gyroscopic coupling and linear centrifugal terms; TLF's prestress adds the
second-order ones, docs/beams.md), the rigid-rotation loads
int rho N^T B X0 dV gain (mu (x) B) X0, J0 gains X0^T (mu (x) P) X0 = m X_c^T P X_c + tr(P Pi),
and the damping (c/rho) M damps the body as it damps the solid (as for the beams). The row sums
of M_tip are not used: TLF's lumped mass D keeps the body rigid through the Sherman-Morrison-
Woodbury form of (D + M_tip)^-1 (:meth:`TipBody.woodbury`, a capacitance of at most 3 x 3 per
direction).

mu has rank at most 3: mu = V C V^T with V = [w, g_Y, g_Z] and C = diag(m, Pi_YY, Pi_ZZ) (Pi
is diagonal, SPEC section 10); columns with a zero coefficient are dropped.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from mpi4py import MPI

from fxflex.errors import FxflexError
from fxflex.scene import Scene
from fxflex.scene.load import tip_body_is_flat

if TYPE_CHECKING:
    from petsc4py import PETSc

    from fxflex.solid.model import SolidModel

__all__ = ["TipBody", "tip_body", "tip_key", "affine_gradients"]


def tip_key(scene: Scene) -> dict:
    """The cache-key part of the tip mass: empty without one (old entries stay valid)."""
    tip = scene.tip_mass
    return {"tip_mass": {"mass": tip.mass, "inertia": list(tip.inertia)}} if tip.present else {}


def affine_gradients(comm, r: np.ndarray) -> np.ndarray | None:
    """(n, d): the gradient rows of the equal-weight least-squares affine fit u ~ a + g . r over
    the owned points r (n, d) of every rank, sum_a G[a] = 0 and sum_a G[a] r_a^T = I_d; None if
    the points fix no such fit (on every rank alike). Collective."""
    D = np.hstack([np.ones((len(r), 1)), r])
    N = comm.allreduce(D.T @ D)
    ev = np.linalg.eigvalsh(N)
    if not ev[0] > 1e-9 * ev[-1]:
        return None
    return (D @ np.linalg.inv(N))[:, 1:]


class TipBody:
    """The tip body on ``model``'s tip nodes (module docstring). Collective to build."""

    def __init__(self, model: SolidModel):
        tip = model.scene.tip_mass
        self.model, self.mass = model, float(tip.mass)
        self.Xc = np.asarray(model.x0_tip, float)
        comm = model.comm
        T = model.tip_fit().tocsr()                      # (6, n_owned), this rank's columns
        w = np.asarray(T[0, 0::3].todense()).ravel()     # weight of each owned node
        iso = np.kron(w, np.eye(3))                      # T_t = w^T (x) I_3 ?
        err = np.abs(T[:3].toarray() - iso).max() if w.size else 0.0
        err, total = comm.allreduce(err, op=MPI.MAX), comm.allreduce(float(w.sum()))
        if not (err <= 1e-10 and abs(total - 1.0) <= 1e-10):
            raise FxflexError("tip_mass: the tip section's centroid is not the mean of its face "
                              "nodes, so the rigid fit's translation is not one weight per "
                              "node; allowed: a symmetric section and mesh, or lebb, nebb, ancf")
        columns, coefficients = [w], [self.mass]
        Pi = np.diag(tip.second_moments())
        flat = tip_body_is_flat(tip.inertia)
        G = self._face_gradients(model, w) if (np.any(Pi[1:] > 0.0) or not flat) else None
        #: the body's extent along X (Pi_XX > 0): the director g_X = g_Y x g_Z, see Director
        self.director = None if flat else Director(model, G, float(Pi[0]))
        if np.any(Pi[1:] > 0.0):
            for k in (1, 2):
                if Pi[k] > 0.0:
                    columns.append(G[:, k - 1])
                    coefficients.append(float(Pi[k]))
        if self.mass == 0.0:                             # inertia only: no translation column
            columns, coefficients = columns[1:], coefficients[1:]
        self.nodes = np.flatnonzero(w)                   # owned tip-face nodes (all columns)
        self.w = w[self.nodes]
        # (nodes, K); K = 0 for a rod along X without mass (the Director carries it all)
        self.V = (np.column_stack(columns) if columns else np.zeros((w.size, 0)))[self.nodes]
        self.C = np.asarray(coefficients, float)         # (K,)
        self.V_all = np.concatenate(comm.allgather(self.V))
        first = model.V.dofmap.index_map.local_range[0]
        self.global_nodes = first + self.nodes
        X0 = model.node_coordinates().reshape(-1)
        self.X0c = self.coordinates(X0)                  # V^T X0: (K, 3)

    @staticmethod
    def _face_gradients(model: SolidModel, w: np.ndarray) -> np.ndarray:
        """[g_Y, g_Z] (n_owned_nodes, 2) over the tip face (the nodes of w; module docstring).
        Collective."""
        face = w != 0.0
        r = model.node_coordinates()[face] - model.x0_tip
        g = affine_gradients(model.comm, r[:, 1:])
        if g is None:
            raise FxflexError("tip_mass.inertia: the tip face's nodes fix no rotation of the "
                              "tip body; allowed: inertia [0, 0, 0]")
        G = np.zeros((w.size, 2))
        G[face] = g
        return G

    # -- vectors on the owned entries -------------------------------------------------------------
    def coordinates(self, X: np.ndarray) -> np.ndarray:
        """V^T X: (K, 3) or (K, 3, k) for owned-entry arrays X (n_owned,) or (n_owned, k), on
        every rank (row of the translation column: t = sum_a w_a u_a)."""
        part = X.reshape((-1, 3) + X.shape[1:])[self.nodes]
        return self.model.comm.allreduce(np.tensordot(self.V, part, axes=(0, 0)))

    def translation(self, X: np.ndarray) -> np.ndarray:
        """t = sum_a w_a u_a (3,) or (3, k) of owned-entry arrays (n_owned,) or (n_owned, k),
        on every rank."""
        part = X.reshape((-1, 3) + X.shape[1:])[self.nodes]
        return self.model.comm.allreduce(np.tensordot(self.w, part, axes=(0, 0)))

    def spread(self, F: np.ndarray) -> np.ndarray:
        """V F: the owned entries (n_owned,) of the nodal forces for F (K, 3) per column."""
        out = np.zeros(self.model.n_owned)
        out.reshape(-1, 3)[self.nodes] = self.V @ F
        return out

    def load(self, B: np.ndarray) -> np.ndarray:
        """(mu (x) B) X0: the body's share of int rho N^T B X0 dV (B = P: centrifugal per unit
        phi'^2; B = S: Euler per unit phi'')."""
        return self.spread(self.C[:, None] * (self.X0c @ B.T))

    def second_moment(self, B: np.ndarray) -> float:
        """X0^T (mu (x) B) X0 = m X_c^T B X_c + tr(B Pi): the body's share of
        int rho X0^T B X0 dV (B = P: J0)."""
        return float(np.einsum("k,ki,ij,kj->", self.C, self.X0c, B, self.X0c))

    def apply(self, x: np.ndarray, out: np.ndarray) -> None:
        """out += M_tip x on the owned entries. Collective."""
        out.reshape(-1, 3)[self.nodes] += self.V @ (self.C[:, None] * self.coordinates(x))

    def diagonal(self, d: np.ndarray) -> None:
        """Prepare :meth:`woodbury` for the lumped (diagonal) mass D, owned entries d > 0."""
        dv = d.reshape(-1, 3)[self.nodes]                                 # (nodes, 3)
        self._dw = self.V[:, :, None] / dv[:, None, :]                    # D_j^-1 V: (nodes, K, 3)
        cap = self.model.comm.allreduce(np.einsum("ak,alj->jkl", self.V, self._dw))
        cap += np.diag(1.0 / self.C)[None]                                # C^-1 + V^T D_j^-1 V
        self._cap_inv = np.linalg.inv(cap)                                # (3, K, K)

    def woodbury(self, out: np.ndarray) -> None:
        """out = D^-1 r on entry, (D + M_tip)^-1 r on exit (Sherman-Morrison-Woodbury with
        M_tip = (V C V^T) (x) I_3: per direction j a K x K capacitance C^-1 + V^T D_j^-1 V, one
        (K, 3) reduction per call). TLF's central differences keep a diagonal solve with the
        body rigid (row sums would smear it over the nodes and change its inertia).
        Collective."""
        y = self.coordinates(out)                                         # (K, 3)
        z = np.einsum("jkl,lj->kj", self._cap_inv, y)
        out.reshape(-1, 3)[self.nodes] -= np.einsum("akj,kj->aj", self._dw, z)

    # -- matrices ----------------------------------------------------------------------------------
    def add_to(self, A: PETSc.Mat, B: np.ndarray | None = None, scale: float = 1.0, *,
               rows: np.ndarray | None = None, block: int = 3) -> None:
        """A += scale mu (x) B (B = I_3 by default; ``block`` 1: the scalar mu) and assemble A.
        ``rows``: the global row of each owned entry of the model (n_owned,), for a matrix on
        another layout (TLF's free coordinates); default the model's own numbering. Collective
        (every rank adds its owned rows, new nonzeros allowed)."""
        from petsc4py import PETSc

        B = np.eye(block) if B is None else np.asarray(B, float)
        if rows is None:
            g = self.global_nodes
            idx = (block * g[:, None] + np.arange(block)).reshape(-1)
        else:
            idx = rows[(3 * self.nodes[:, None] + np.arange(3)).reshape(-1)]
        cols = np.concatenate(self.model.comm.allgather(idx)).astype(PETSc.IntType)
        values = scale * np.kron((self.V * self.C) @ self.V_all.T, B)
        A.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
        if idx.size:
            A.setValues(idx.astype(PETSc.IntType), cols, values,
                        addv=PETSc.InsertMode.ADD_VALUES)
        A.assemble()


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b of two 3-vectors (np.cross costs ~40 us a call, in a time loop)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                     a[0] * b[1] - a[1] * b[0]])


def skew(a: np.ndarray) -> np.ndarray:
    """[a]x: the 3 x 3 matrix of a x ."""
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


class Director:
    """The tip body's extent along X (Pi_XX > 0) on the tip face: the unit normal n of its fit.

    With g_Y, g_Z the face's affine-fit gradients applied to the nodal positions y (any frame:
    the hub frame's X0 + U, the inertial x0 + u), (g_Y, g_Z) = W y, W = [G_Y (x) I_3; G_Z (x) I_3]
    (6 x 3n, the same G as TipBody's columns; W X0 = (e_Y, e_Z)), the body's X axis is the unit
    normal of the plane they span,

        n = c / |c|,  c = g_Y x g_Z,

    its rotation is [n, g_Y, g_Z] for every rigid motion of the face (any rotation), and with
    T = 1/2 sum_k Pi_kk |g_k'|^2 (g_X = n) the body's kinetic energy is exact there; TipBody
    carries Pi_YY, Pi_ZZ as a constant (isotropic) mass, this class the rest, Pi_XX |n'|^2 / 2,
    whose mass depends on the configuration. n is normalised: the face's in-plane area change
    (Poisson, or a load on it) moves no inertia and takes no load from the body (unnormalised,
    c's length follows the area and the centrifugal pull on Pi_XX, Omega^2 Pi_XX along X, would
    stretch the face in its plane: 1.1 % on the 0.12 x 0.06 m uniform solid with Pi_XX = 1 kg m^2
    at 3000 rpm). With B(g) = [-[g_Z]x, [g_Y]x] (3 x 6, c' = B W y') and P_n = I - n n^T:

        n' = J y',  J = B_n W,  B_n = P_n B / |c|,
        n'' = J y'' + k,  k = (P_n (2 g_Y' x g_Z') - 2 n' (n . c')) / |c| - n |n'|^2,

    and the generalized inertia force is exactly Pi_XX J^T n'' (n a function of y alone); J^T n
    = 0, so the force is Pi_XX W^T B_n^T (B_n W y'' + k). Seen from the hub turning at Omega
    about z, n'' becomes n'' + 2 Omega S n' - Omega^2 P n (NOTES.md: a material point's
    kinematics), so:

    - steady state: Pi_XX J^T f with f = -Omega^2 P n [+ (c/rho) Omega S (n - e_X), the absolute
      damping of the director's rate relative to the rigidly turning e_X]; its derivative
      Pi_XX W^T (B_n^T K3 B_n + B^T Hc(f) B + H6(P_n f / |c|)) W, K3 = df/dn, with the second
      derivatives of f . c / |c| in c, Hc(f) = -(n f^T P_n + P_n f n^T + (f . n) P_n) / |c|^2,
      and of the bilinear c in y, H6(a) = [[0, -[a]x], [[a]x, 0]] (d(B^T a)/dy = W^T H6(a) W);
    - linearised about it: M += Pi_XX J^T J, C += Pi_XX (2 Omega J^T S J + (c/rho) J^T J),
      K += the steady derivative above: the terms the solid's M_B gives an isotropic mass;
    - in time (inertial frame): the mass Pi_XX J^T J (rank 2 in the fixed 6-column space of W^T:
      a Woodbury update of any mass the solid has) and the force Pi_XX W^T B_n^T k.

    Relative damping, (c/rho) times the whole mass: J y with y = u' - phi' S (x0 + u) is n' -
    phi' S n (the director's rate seen from the hub), since S (a x b) = S a x b + a x S b and
    P_n S n = S n.
    """

    def __init__(self, model: SolidModel, G: np.ndarray, pi_xx: float):
        comm = model.comm
        self.model, self.pi = model, pi_xx
        self.nodes = np.flatnonzero(np.any(G != 0.0, axis=1))   # owned face nodes
        self.G = G[self.nodes]                                   # (nodes, 2): G_Y, G_Z
        self.G_all = np.concatenate(comm.allgather(self.G))
        first = model.V.dofmap.index_map.local_range[0]
        self.global_nodes = first + self.nodes
        self.x0 = model.node_coordinates().reshape(-1)           # owned X0
        self._C = self.mass6(np.zeros(model.n_owned))           # until the first moving()
        self._Ct = np.zeros((6, 6))

    # -- the director -----------------------------------------------------------------------------
    def gradients(self, y: np.ndarray) -> np.ndarray:
        """W y: (2, 3) rows g_Y, g_Z of the owned-entry array y (positions or rates), on every
        rank. Collective."""
        part = y.reshape(-1, 3)[self.nodes]
        return self.model.comm.allreduce(self.G.T @ part)

    @staticmethod
    def B(g: np.ndarray) -> np.ndarray:
        """B(g) (3 x 6) for g = W y (2, 3): c' = B W y'."""
        return np.hstack([-skew(g[1]), skew(g[0])])

    @classmethod
    def normal(cls, g: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, np.ndarray,
                                             np.ndarray]:
        """(B, n, |c|, P_n, B_n) at g = W y (class docstring)."""
        B = cls.B(g)
        c = cross(g[0], g[1])
        size = float(np.linalg.norm(c))
        n = c / size
        Pn = np.eye(3) - np.outer(n, n)
        return B, n, size, Pn, Pn @ B / size

    @staticmethod
    def H6(a: np.ndarray) -> np.ndarray:
        """H6(a) (6 x 6): d(B(g)^T a)/dy = W^T H6(a) W at fixed a (symmetric)."""
        F = skew(a)
        Z = np.zeros((3, 3))
        return np.block([[Z, -F], [F, Z]])

    def spread(self, f6: np.ndarray) -> np.ndarray:
        """W^T f6: the owned entries (n_owned,) for f6 (6,)."""
        out = np.zeros(self.model.n_owned)
        self.add_spread(f6, out)
        return out

    def add_spread(self, f6: np.ndarray, out: np.ndarray, scale: float = 1.0) -> None:
        """out += scale W^T f6 on the owned entries."""
        out.reshape(-1, 3)[self.nodes] += scale * (self.G[:, :1] * f6[:3]
                                                   + self.G[:, 1:] * f6[3:])

    # -- the rotating frame -------------------------------------------------------------------------
    def rotating(self, U: np.ndarray, w2: float, circulatory: float = 0.0
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """At the hub-frame displacement U (owned entries), speed^2 w2 and circulatory
        coefficient (c/rho) Omega (absolute damping; else 0): (B_n, f6, K6) with the steady force
        Pi_XX J^T f = W^T f6 and its derivative W^T K6 W (class docstring). Collective."""
        from fxflex.scene.kinematics import P3, S3

        B, n, size, Pn, Bn = self.normal(self.gradients(self.x0 + U))
        K3 = -w2 * P3 + circulatory * S3
        f = -w2 * (P3 @ n) + circulatory * (S3 @ (n - np.array([1.0, 0.0, 0.0])))
        pf = Pn @ f
        Hc = -(np.outer(n, pf) + np.outer(pf, n) + float(f @ n) * Pn) / size**2
        K6 = Bn.T @ K3 @ Bn + B.T @ Hc @ B + self.H6(pf / size)
        return Bn, self.pi * (Bn.T @ f), self.pi * K6

    # -- the inertial frame (TLF's time loop) -------------------------------------------------------
    def mass6(self, q: np.ndarray) -> np.ndarray:
        """Pi_XX B_n^T B_n (6 x 6) at the owned displacement q from X0 (positions X0 + q, either
        frame): the director's mass W^T (.) W. Collective."""
        Bn = self.normal(self.gradients(self.x0 + q))[4]
        return self.pi * (Bn.T @ Bn)

    def moving(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Take the configuration (q, v) (inertial, owned entries): its mass for
        :meth:`mass_apply` and :meth:`woodbury`; returns the velocity part of the inertia
        force, Pi_XX B_n^T k (6,), which the equations carry on the left. Collective."""
        part = np.stack([(self.x0 + q).reshape(-1, 3)[self.nodes],
                         v.reshape(-1, 3)[self.nodes]], axis=1)          # (nodes, 2, 3)
        both = self.model.comm.allreduce(np.tensordot(self.G, part, axes=(0, 0)))  # (2, 2, 3)
        g, rate = both[:, 0], both[:, 1]
        B, n, size, Pn, Bn = self.normal(g)
        cdot = B @ rate.reshape(-1)
        ndot = Pn @ cdot / size
        k = (2.0 * cross(rate[0], rate[1]) - 2.0 * ndot * float(n @ cdot)) / size
        self._C = self.pi * (Bn.T @ Bn)
        # d(B_n^T k)/d(W v), for implicit iteration matrices (HubTangent)
        self._Ct = self.pi * (Bn.T @ (2.0 * self.B(rate) - 2.0 * float(n @ cdot) * Bn
                                      - 2.0 * np.outer(ndot, n @ B))) / size
        return self.pi * (Bn.T @ k)                    # B_n^T P_n = B_n^T, B_n^T n = 0

    def mass_apply(self, x: np.ndarray, out: np.ndarray) -> None:
        """out += Pi_XX J^T J x at the configuration of the last :meth:`moving`. Collective."""
        self.add_spread(self._C @ self.gradients(x).reshape(-1), out)

    def prepare(self, solve) -> None:
        """Store Y = M0^-1 W^T (n_owned, 6) and W Y for :meth:`woodbury`; ``solve(x)`` replaces
        an owned-entry array x by M0^-1 x (the solid's mass with TipBody's). Collective."""
        cols = []
        for k in range(6):
            e = np.zeros(6)
            e[k] = 1.0
            x = self.spread(e)
            solve(x)
            cols.append(x)
        Y = np.column_stack(cols)
        self._WY = np.column_stack([self.gradients(c).reshape(-1) for c in cols])
        self._rows = np.flatnonzero(np.any(Y != 0.0, axis=1))   # the face's, with a lumped M0
        self._Y = Y[self._rows]

    def woodbury(self, out: np.ndarray) -> None:
        """out = M0^-1 r on entry, (M0 + W^T C W)^-1 r on exit, C = Pi_XX B_n^T B_n of the last
        :meth:`moving` (push-through form, C singular allowed: x - Y (I + C W Y)^-1 C W x).
        Collective."""
        C = self._C
        s = np.linalg.solve(np.eye(6) + C @ self._WY, C @ self.gradients(out).reshape(-1))
        out[self._rows] -= self._Y @ s

    # -- matrices ------------------------------------------------------------------------------------
    def add_to(self, A: PETSc.Mat, C6: np.ndarray, *, rows: np.ndarray | None = None) -> None:
        """A += W^T C6 W (C6 6 x 6) and assemble A; ``rows`` as in :meth:`TipBody.add_to`.
        Collective (new nonzeros allowed)."""
        from petsc4py import PETSc

        if rows is None:
            idx = (3 * self.global_nodes[:, None] + np.arange(3)).reshape(-1)
        else:
            idx = rows[(3 * self.nodes[:, None] + np.arange(3)).reshape(-1)]
        cols = np.concatenate(self.model.comm.allgather(idx)).astype(PETSc.IntType)
        values = sum(np.kron(np.outer(self.G[:, k], self.G_all[:, l]),
                             C6[3 * k: 3 * k + 3, 3 * l: 3 * l + 3])
                     for k in (0, 1) for l in (0, 1))
        A.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
        if idx.size:
            A.setValues(idx.astype(PETSc.IntType), cols, values,
                        addv=PETSc.InsertMode.ADD_VALUES)
        A.assemble()


def tip_body(model: SolidModel) -> TipBody | None:
    """The model's tip body, or None without a [tip_mass] (every operator as it was)."""
    return TipBody(model) if model.scene.tip_mass.present else None


class SteadyTerms:
    """The body's share of TLF's rotating-frame equilibrium (:mod:`fxflex.solid.tlf_steady`),
    for :func:`fxflex.solid.solvers.newton`: the centrifugal load on its deformed position and,
    with the absolute damping model, its circulatory term,

        r_tip(U) = -Omega^2 (mu (x) P) (X0 + U) [+ (c/rho) Omega (mu (x) S) U],

    and their derivative -Omega^2 mu (x) P [+ (c/rho) Omega mu (x) S]. ``w2`` and ``w1`` hold
    Omega^2 and Omega (``.value``, the continuation's current stage)."""

    def __init__(self, body: TipBody, w2, w1=None, c_rho: float = 0.0):
        from fxflex.scene.kinematics import P3, S3

        self.body, self.w2, self.w1, self.c_rho = body, w2, w1, c_rho
        self.P, self.S = P3, S3

    def _circulatory(self) -> float:
        return float(self.w1.value) * self.c_rho if self.w1 is not None else 0.0

    def residual(self, u, b) -> None:
        body = self.body
        U = u.x.array[: body.model.n_owned]
        t = body.coordinates(U)                                           # V^T U: (K, 3)
        force = -float(self.w2.value) * (body.X0c + t) @ self.P.T + self._circulatory() * (
            t @ self.S.T)
        out = b.getArray()[: body.model.n_owned]
        out += body.spread(body.C[:, None] * force)
        if body.director is not None:                    # Pi_XX J^T f (Director)
            _, f6, self._K6 = body.director.rotating(U, float(self.w2.value),
                                                     self._circulatory())
            body.director.add_spread(f6, out)

    def jacobian(self, A) -> None:
        """Called after :meth:`residual` at the same U (fxflex.solid.solvers.newton)."""
        self.body.add_to(A, -float(self.w2.value) * self.P + self._circulatory() * self.S)
        if self.body.director is not None:
            self.body.director.add_to(A, self._K6)
