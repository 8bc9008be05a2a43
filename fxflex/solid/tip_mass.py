"""The [tip_mass] of SPEC section 10 on the solid models (FFRF, GCMS, TLF), through the tip surface.

The body is a point mass m rigidly attached at the tip section centroid X_c = (R + L, 0, 0). Its
position is X_c + t(u), t the translation of the least-squares rigid fit of the tip-face nodal
displacements (:meth:`SolidModel.tip_fit`, the tip layer of :meth:`SolidModel.span_sections`'
fit; exact for every rigid motion of the face, so also for TLF's large hub rotation). With the
section centroid at the face nodes' mean (the sections of SPEC sections 1 and 9, meshed
symmetrically), the translation rows of that fit are t = sum_a w_a u_a with scalar weights w_a
(sum w_a = 1, sum w_a r_a = 0): T_t = w^T (x) I_3, checked on build. Hence the body's kinetic
energy 1/2 m |t'|^2 in any frame is the quadratic form of the mass

    M_tip = m (w w^T) (x) I_3,

which is isotropic node by node like the solid's own consistent mass (Eq. 29): it commutes with
the nodal 3 x 3 operators B = S, P, G3 and with A_d. So every rotating-frame term that FFRF, GCMS
and TLF build from the mass follows by adding M_tip where they use M (NOTES.md):
int rho N^T B N dV gains m (w w^T) (x) B (Coriolis S, spin softening P), the rigid-rotation loads
int rho N^T B X0 dV gain m w (x) B X_c (centrifugal P, Euler S), J0 gains m X_c^T P X_c, and the
damping (c/rho) M damps the body as it damps the solid (as for the beams). The row sums of
M_tip are not used: TLF's lumped mass D keeps the body a point through the Sherman-Morrison-
Woodbury form of (D + M_tip)^-1 (:meth:`TipBody.woodbury`).

Rotary inertia (``tip_mass.inertia``) is not carried by the solids yet: the small-rotation rows
of the fit are not isotropic, so they would not commute with A_d (GCMS's global modes, TLF's hub-
frame factor, the scalar mass M_s (x) I_3); :func:`fxflex.scene.load.validate_for` refuses it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from mpi4py import MPI

from fxflex.errors import FxflexError
from fxflex.scene import Scene

if TYPE_CHECKING:
    from petsc4py import PETSc

    from fxflex.solid.model import SolidModel

__all__ = ["TipBody", "tip_body", "tip_key"]


def tip_key(scene: Scene) -> dict:
    """The cache-key part of the tip mass: empty without one (old entries stay valid)."""
    tip = scene.tip_mass
    return {"tip_mass": {"mass": tip.mass, "inertia": list(tip.inertia)}} if tip.present else {}


class TipBody:
    """The tip point mass on ``model``'s tip face (module docstring). Collective to build."""

    def __init__(self, model: SolidModel):
        tip = model.scene.tip_mass
        if any(j > 0.0 for j in tip.inertia):
            raise FxflexError("tip_mass.inertia: the solid methods carry the tip mass's "
                              "translation only; allowed: inertia [0, 0, 0], or lebb, nebb, ancf")
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
        self.nodes = np.flatnonzero(w)                   # owned tip-face nodes
        self.w = w[self.nodes]
        self.w_all = np.concatenate(comm.allgather(self.w))
        first = model.V.dofmap.index_map.local_range[0]
        self.global_nodes = first + self.nodes

    # -- vectors on the owned entries -------------------------------------------------------------
    def translation(self, X: np.ndarray) -> np.ndarray:
        """t = sum_a w_a u_a (3,) or (3, k) of owned-entry arrays (n_owned,) or (n_owned, k),
        on every rank."""
        part = X.reshape((-1, 3) + X.shape[1:])[self.nodes]
        return self.model.comm.allreduce(np.tensordot(self.w, part, axes=(0, 0)))

    def nodal(self, vector3: np.ndarray) -> np.ndarray:
        """m w (x) v: the owned entries (n_owned,) of the body's force m v spread with w."""
        out = np.zeros(self.model.n_owned)
        out.reshape(-1, 3)[self.nodes] = self.mass * self.w[:, None] * np.asarray(vector3)
        return out

    def load(self, B: np.ndarray) -> np.ndarray:
        """m w (x) B X_c: the body's share of int rho N^T B X0 dV (B = P: centrifugal per unit
        phi'^2; B = S: Euler per unit phi'')."""
        return self.nodal(B @ self.Xc)

    def second_moment(self, B: np.ndarray) -> float:
        """m X_c^T B X_c: the body's share of int rho X0^T B X0 dV (B = P: J0)."""
        return self.mass * float(self.Xc @ B @ self.Xc)

    def apply(self, x: np.ndarray, out: np.ndarray) -> None:
        """out += M_tip x = m w (x) t(x) on the owned entries. Collective."""
        out.reshape(-1, 3)[self.nodes] += self.mass * self.w[:, None] * self.translation(x)

    def diagonal(self, d: np.ndarray) -> None:
        """Prepare :meth:`woodbury` for the lumped (diagonal) mass D, owned entries d > 0."""
        self._dw = self.w[:, None] / d.reshape(-1, 3)[self.nodes]          # D^-1 W, (k, 3)
        self._cap = 1.0 / self.mass + self.model.comm.allreduce(
            np.sum(self.w[:, None] * self._dw, axis=0))                    # 1/m + W^T D^-1 W

    def woodbury(self, out: np.ndarray) -> None:
        """out = D^-1 r on entry, (D + M_tip)^-1 r on exit (Sherman-Morrison-Woodbury: M_tip =
        m W W^T, W = w (x) I_3, so the capacitance 1/m I + W^T D^-1 W is diagonal, one
        3-vector reduced per call). TLF's central differences keep a diagonal solve with the
        body a point (spreading it over the face as row sums would give it the face's rotary
        inertia m <y^2 + z^2>). Collective."""
        c = self.translation(out) / self._cap
        out.reshape(-1, 3)[self.nodes] -= self._dw * c

    # -- matrices ----------------------------------------------------------------------------------
    def add_to(self, A: PETSc.Mat, B: np.ndarray | None = None, scale: float = 1.0, *,
               rows: np.ndarray | None = None, block: int = 3) -> None:
        """A += scale m (w w^T) (x) B (B = I_3 by default; ``block`` 1: the scalar m w w^T) and
        assemble A. ``rows``: the global row of each owned entry of the model (n_owned,), for a
        matrix on another layout (TLF's free coordinates); default the model's own numbering.
        Collective (every rank adds its owned rows, new nonzeros allowed)."""
        from petsc4py import PETSc

        B = np.eye(block) if B is None else np.asarray(B, float)
        if rows is None:
            g = self.global_nodes
            idx = (block * g[:, None] + np.arange(block)).reshape(-1)
        else:
            idx = rows[(3 * self.nodes[:, None] + np.arange(3)).reshape(-1)]
        cols = np.concatenate(self.model.comm.allgather(idx)).astype(PETSc.IntType)
        values = scale * self.mass * np.kron(np.outer(self.w, self.w_all), B)
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

        r_tip(U) = -Omega^2 m w (x) P (X_c + t(U)) [+ (c/rho) Omega m w (x) S t(U)],

    and their derivative -Omega^2 m (w w^T) (x) P [+ (c/rho) Omega m (w w^T) (x) S]. ``w2`` and
    ``w1`` hold Omega^2 and Omega (``.value``, the continuation's current stage)."""

    def __init__(self, body: TipBody, w2, w1=None, c_rho: float = 0.0):
        from fxflex.scene.kinematics import P3, S3

        self.body, self.w2, self.w1, self.c_rho = body, w2, w1, c_rho
        self.P, self.S = P3, S3

    def _circulatory(self) -> float:
        return float(self.w1.value) * self.c_rho if self.w1 is not None else 0.0

    def residual(self, u, b) -> None:
        n = self.body.model.n_owned
        t = self.body.translation(u.x.array[:n])
        force = -float(self.w2.value) * self.P @ (self.body.Xc + t) + self._circulatory() * (
            self.S @ t)
        b.getArray()[:n] += self.body.nodal(force)

    def jacobian(self, A) -> None:
        self.body.add_to(A, -float(self.w2.value) * self.P + self._circulatory() * self.S)
