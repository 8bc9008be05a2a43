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
face's unit normal n = g_Y x g_Z / |g_Y x g_Z| (:class:`fxflex.numerics.director.Director`, on
the columns G below: a mass that depends on the configuration, exact for every rigid motion of
the face) and FFRF on that normal linearised at the reference (a constant, non-isotropic mass:
:func:`fxflex.solid.reduction.director_corrections`); GCMS on the same linearised normal, kept
apart from its Gram matrix (in its absolute coordinates that mass turns with the hub:
:class:`fxflex.solid.gcms.TipDirector`).

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
from fxflex.numerics.director import Director
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
        #: the body's extent along X (Pi_XX > 0): its X axis the face's normal (Director)
        self.director = None if flat else Director.on_face(model, G, float(Pi[0]))
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
