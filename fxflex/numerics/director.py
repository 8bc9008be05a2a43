"""A rigid body's X axis carried by two gradients of the body it is attached to: n = g_Y x g_Z /
|g_Y x g_Z|, with its configuration-dependent mass (SPEC section 10's [tip_mass], issue 16).

Used where a tip body has extent along X (Pi_XX > 0) but the attachment only fixes the
gradients across the section: TLF's tip face (g_Y, g_Z of the face's affine fit,
:mod:`fxflex.solid.tip_mass`) and ANCF's tip node (g_Y, g_Z from the section gradients d_Y~, d_Z~,
:mod:`fxflex.beam.ancf`). In both the state holds positions (or displacements from them) as
3-vector slots and (g_Y, g_Z) = W y is linear in them; what follows depends on nothing else.
:class:`FactorUpdate` keeps a reused iteration matrix's share of the director current.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from petsc4py import PETSc

__all__ = ["Director", "FactorUpdate", "cross", "skew"]


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b of two 3-vectors (np.cross costs ~40 us a call, in a time loop)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                     a[0] * b[1] - a[1] * b[0]])


def skew(a: np.ndarray) -> np.ndarray:
    """[a]x: the 3 x 3 matrix of a x ."""
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


class Director:
    """A tip body's extent along X (Pi_XX > 0): its X axis, the unit normal n of two gradients.

    With g_Y, g_Z linear in the state's positions y (any frame: the hub frame's X0 + U, the
    inertial x0 + u, ANCF's coordinates), (g_Y, g_Z) = W y, W = [G_Y (x) I_3; G_Z (x) I_3]
    (6 x n; the solid: the tip face's affine-fit gradient rows, W X0 = (e_Y, e_Z); ANCF: the
    section gradients' columns of J0^-1), the body's X axis is the unit normal of the plane they
    span,

        n = c / |c|,  c = g_Y x g_Z,

    its rotation is [n, g_Y, g_Z] for every rigid motion of the section (any rotation), and with
    T = 1/2 sum_k Pi_kk |g_k'|^2 (g_X = n) the body's kinetic energy is exact there; a constant
    (isotropic) mass carries Pi_YY, Pi_ZZ (the solid's TipBody, ANCF's tip block), this class
    the rest, Pi_XX |n'|^2 / 2, whose mass depends on the configuration. n is normalised: the face's in-plane area change
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
      a Woodbury update of the rest of the mass) and the force Pi_XX W^T B_n^T k.

    Relative damping, (c/rho) times the whole mass: J y with y = u' - phi' S (x0 + u) is n' -
    phi' S n (the director's rate seen from the hub), since S (a x b) = S a x b + a x S b and
    P_n S n = S n. Absolute damping damps n' - phi' S A e_X, the rate relative to the rigidly
    turning e_X (steady state, linearisation); the time loops' whole-mass form damps J (q' -
    phi' S A x0) instead, and :meth:`absolute_damping` is the difference they add.
    """

    def __init__(self, comm, n: int, slots: np.ndarray, G: np.ndarray, pi_xx: float,
                 x0: np.ndarray, first: int = 0, reference: np.ndarray | None = None):
        """``n`` entries in this rank's state arrays, 3 per slot; ``slots`` (k,) the slots that
        carry ``G`` (k, 2) = the weights of g_Y, g_Z; ``x0`` (n,) what is added to a state
        array to make positions (the solid's X0 for displacements; 0 for coordinates that are
        positions); ``first``: this rank's first global slot (matrices on the global
        numbering); ``reference`` the state of the undeformed body (default 0: x0 itself).
        Collective."""
        keep = np.any(G != 0.0, axis=1)
        self.comm, self.n, self.pi = comm, int(n), float(pi_xx)
        self.nodes = np.asarray(slots)[keep]
        self.G = np.asarray(G, float)[keep]                   # (nodes, 2): G_Y, G_Z
        self.G_all = np.concatenate(comm.allgather(self.G))
        self.global_nodes = first + self.nodes
        self.x0 = np.asarray(x0, float)
        ref = np.zeros(self.n) if reference is None else np.asarray(reference, float)
        self.g0 = self.gradients(self.x0 + ref)                # (e_Y, e_Z) of the reference
        self._C = self.mass6(ref)                              # until the first moving()
        self._Ct = np.zeros((6, 6))
        self._Bn = self.normal(self.g0)[4]

    @classmethod
    def on_face(cls, model, G: np.ndarray, pi_xx: float) -> "Director":
        """On a solid's tip face: G (n_owned_nodes, 2) the face's affine-fit gradient rows."""
        return cls(model.comm, model.n_owned, np.arange(len(G)), G, pi_xx,
                   model.node_coordinates().reshape(-1),
                   first=model.V.dofmap.index_map.local_range[0])

    # -- the director -----------------------------------------------------------------------------
    def gradients(self, y: np.ndarray) -> np.ndarray:
        """W y: (2, 3) rows g_Y, g_Z of the owned-entry array y (positions or rates), or
        (2, 3, k) for k columns y (n, k), on every rank. Collective."""
        part = y.reshape((-1, 3) + y.shape[1:])[self.nodes]
        return self.comm.allreduce(np.tensordot(self.G, part, axes=(0, 0)))

    def reference_rows(self, y: np.ndarray) -> np.ndarray:
        """J y = B_n0 W y at the reference (3, k) for columns y (n, k): the normal's change per
        column, linearised about the undeformed body (FFRF, GCMS: n = e_X + J u). Collective."""
        return self.normal(self.g0)[4] @ self.gradients(y).reshape(6, -1)

    @staticmethod
    def B(g: np.ndarray) -> np.ndarray:
        """B(g) (3 x 6) for g = W y (2, 3): c' = B W y'."""
        return np.hstack([-skew(g[1]), skew(g[0])])

    @classmethod
    def normal(cls, g: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, np.ndarray,
                                             np.ndarray]:
        """(B, n, |c|, P_n, B_n) at g = W y (class docstring); n = 0 and B_n = 0 where g_Y, g_Z
        span no plane (c = 0: a state of all-zero coordinates, which Newton's scale asks for)."""
        B = cls.B(g)
        c = cross(g[0], g[1])
        size = float(np.linalg.norm(c))
        if size == 0.0:                  # no plane (ANCF's all-zero coordinates): no director
            return B, np.zeros(3), 1.0, np.eye(3), np.zeros((3, 6))
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
        out = np.zeros(self.n)
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

    # -- the inertial frame (the time loop) ----------------------------------------------------------
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
        both = self.comm.allreduce(np.tensordot(self.G, part, axes=(0, 0)))  # (2, 2, 3)
        g, rate = both[:, 0], both[:, 1]
        B, n, size, Pn, Bn = self.normal(g)
        cdot = B @ rate.reshape(-1)
        ndot = Pn @ cdot / size
        k = (2.0 * cross(rate[0], rate[1]) - 2.0 * ndot * float(n @ cdot)) / size
        self._C = self.pi * (Bn.T @ Bn)
        self._Bn = Bn
        # d(B_n^T k)/d(W v), for implicit iteration matrices (HubTangent)
        self._Ct = self.pi * (Bn.T @ (2.0 * self.B(rate) - 2.0 * float(n @ cdot) * Bn
                                      - 2.0 * np.outer(ndot, n @ B))) / size
        return self.pi * (Bn.T @ k)                    # B_n^T P_n = B_n^T, B_n^T n = 0

    def absolute_damping(self, rate: float, A: np.ndarray) -> np.ndarray:
        """(6,): W^T of it is what turns the time loops' absolute damping of the director,
        (c/rho) Pi_XX J^T J (q' - phi' S A x0) (the whole mass times the nodes' rate relative to
        the rigidly turning reference, as for the rest of the body), into the director's own,
        (c/rho) Pi_XX J^T (n' - phi' S A e_X) (its rate relative to the rigidly turning e_X,
        what the steady state and the linearisation damp): the difference per unit c/rho,
        phi' Pi_XX B_n^T (J S A x0 - S A e_X), at the configuration of the last :meth:`moving`
        (zero for a rigid motion of the reference; J S_d != S J elsewhere). Add it times
        -c/rho to the force."""
        from fxflex.scene.kinematics import S3

        SA = S3 @ A
        turned = np.concatenate([SA @ self.g0[0], SA @ self.g0[1]])    # W (S A x0)
        return rate * self.pi * (self._Bn.T @ (self._Bn @ turned - SA[:, 0]))

    def mass_apply(self, x: np.ndarray, out: np.ndarray, scale: float = 1.0) -> None:
        """out += scale Pi_XX J^T J x at the configuration of the last :meth:`moving`.
        Collective."""
        self.add_spread(self._C @ self.gradients(x).reshape(-1), out, scale)

    def prepare(self, solve) -> None:
        """Make :meth:`woodbury` ready for the mass M0 (the rest of the mass: the solid's with
        TipBody's flat part, ANCF's M_s (x) I_3 with its flat part); ``solve(x)`` replaces a
        state array x by M0^-1 x. Collective."""
        def copy(b: np.ndarray) -> np.ndarray:
            solve(b)
            return b

        self._time_loop = FactorUpdate(self, copy, np.zeros((6, 6)), 1.0, 0.0)

    def woodbury(self, out: np.ndarray) -> None:
        """out = M0^-1 r on entry, (M0 + W^T C W)^-1 r on exit, C = Pi_XX B_n^T B_n of the last
        :meth:`moving`: :class:`FactorUpdate` of M0, which holds none of it. Collective."""
        self._time_loop.correct(out)

    # -- matrices ------------------------------------------------------------------------------------
    def _block(self, C6: np.ndarray, G_cols: np.ndarray) -> np.ndarray:
        """W^T C6 W on (this rank's slots) x (the slots of G_cols), 3 x 3 blocks."""
        return sum(np.kron(np.outer(self.G[:, k], G_cols[:, l]),
                           C6[3 * k: 3 * k + 3, 3 * l: 3 * l + 3])
                   for k in (0, 1) for l in (0, 1))

    def add_dense(self, A: np.ndarray, C6: np.ndarray) -> None:
        """A += W^T C6 W for a dense A on the state's layout (one rank)."""
        idx = (3 * self.nodes[:, None] + np.arange(3)).reshape(-1)
        A[np.ix_(idx, idx)] += self._block(C6, self.G)

    def add_to(self, A: PETSc.Mat, C6: np.ndarray, *, rows: np.ndarray | None = None) -> None:
        """A += W^T C6 W (C6 6 x 6) and assemble A: ``rows`` the global row of each entry of the
        state (a matrix on another layout, TLF's free coordinates), default 3 * global slot +
        component. Collective (new nonzeros allowed)."""
        from petsc4py import PETSc

        if rows is None:
            idx = (3 * self.global_nodes[:, None] + np.arange(3)).reshape(-1)
        else:
            idx = rows[(3 * self.nodes[:, None] + np.arange(3)).reshape(-1)]
        cols = np.concatenate(self.comm.allgather(idx)).astype(PETSc.IntType)
        values = self._block(C6, self.G_all)
        A.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
        if idx.size:
            A.setValues(idx.astype(PETSc.IntType), cols, values,
                        addv=PETSc.InsertMode.ADD_VALUES)
        A.assemble()


class FactorUpdate:
    """A factorised iteration matrix S = ... + m W^T C6 W (the director's mass at the state it
    was made at, ``C6``) reused while the director's mass changes: :meth:`correct` swaps in
    m C + c C_t of the director's last :meth:`Director.moving` (its mass and c times the
    derivative of its velocity force by the rates), turned into the factor's frame by the
    rotation R (hub-frame factors: B_n(A g) = A B_n(g) diag(A, A)^T), by Woodbury on the six
    columns S^-1 W^T stored here: x -= Y (I + dC W Y)^-1 dC W x (push-through form, dC
    singular allowed). With C6 = 0, m = 1, c = 0 it is the time loop's (M0 + Pi_XX J^T J)^-1
    (:meth:`Director.woodbury`)."""

    def __init__(self, director: Director, solve, C6: np.ndarray, m: float, c: float):
        """``solve(b) -> x``: S^-1 on a state array (a copy); ``C6`` the director's part the
        factor holds; (m, c) the iteration matrix's mass and damping coefficients. Collective."""
        self.director, self.C6, self.m, self.c = director, C6, m, c
        cols = []
        for k in range(6):
            e = np.zeros(6)
            e[k] = 1.0
            cols.append(solve(director.spread(e)))
        Y = np.column_stack(cols)
        self.WY = director.gradients(Y).reshape(6, 6)
        self.rows = np.flatnonzero(np.any(Y != 0.0, axis=1))   # the face's, with a lumped M0
        self.Y = Y[self.rows]

    def correct(self, x: np.ndarray, rotation: np.ndarray | None = None) -> None:
        """x = S^-1 r on entry (the factor's frame), the updated matrix's solve on exit.
        Collective."""
        d = self.director
        now = self.m * d._C + self.c * d._Ct
        if rotation is not None:
            R6 = np.kron(np.eye(2), rotation)
            now = R6.T @ now @ R6
        dC = now - self.C6
        w = d.gradients(x).reshape(-1)
        x[self.rows] -= self.Y @ np.linalg.solve(np.eye(6) + dC @ self.WY, dC @ w)
