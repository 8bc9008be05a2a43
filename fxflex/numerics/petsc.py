"""The quadratic eigenproblem of :mod:`fxflex.numerics.qep` for distributed PETSc matrices.

(lambda^2 M + lambda C + K) x = 0 by SLEPc's PEP solver (TOAR, the Krylov method on the companion
linearisation that never forms it) with shift-and-invert about a target sigma: each Krylov step
solves with P(sigma) = K + sigma C + sigma^2 M, factorised once by MUMPS (LU: K carries the
non-symmetric circulatory term of the absolute damping model), or on the iterative route
(docs/solvers.md) by a GAMG-preconditioned Krylov solve. Around sigma = 0 the roots nearest
in magnitude are the lowest modes, the ones a rotating beam loses stability through (divergence,
where a root passes through 0, or flutter of the low modes). Collective on the matrices'
communicator; the vectors come back as this rank's entries.
"""

from __future__ import annotations

import numpy as np
from petsc4py import PETSc
from slepc4py import SLEPc

from fxflex.numerics.qep import EigenNotConverged

__all__ = ["pep_eigen", "make_direct", "make_iterative", "rigid_body_modes", "inner_rtol", "ROUTES",
           "PetscLinearisation", "TOL", "MAX_IT"]

#: relative residual the PEP converges each root to, by default
TOL = 1e-10
#: restarts of the Krylov iteration before the PEP gives up (SLEPc's max_it)
MAX_IT = 200


def make_direct(ksp: PETSc.KSP, *, symmetric: bool = True) -> PETSc.KSP:
    """Turn ``ksp`` (e.g. a SLEPc spectral transformation's) into one MUMPS factorisation and
    solve: LDL^T (Cholesky) when symmetric, LU otherwise."""
    ksp.setType("preonly")
    pc = ksp.getPC()
    pc.setType("cholesky" if symmetric else "lu")
    pc.setFactorSolverType("mumps")
    return ksp


#: linear solver routes of ``[solver] linear`` once "auto" is resolved (fxflex.memory.check)
ROUTES = ("direct", "iterative")
#: Krylov iterations before an iterative solve gives up (GAMG on these meshes: tens)
KRYLOV_MAX_IT = 2000
#: an eigensolver's shift-and-invert on the iterative route solves to this fraction of the eigen
#: tolerance, so that the inexact inverse leaves the eigenpairs' residuals at the tolerance ...
INNER_FACTOR = 0.1
#: ... but no tighter than this: the true residual of a Krylov solve in double precision stalls
#: near kappa * eps ||x|| / ||b||, above 1e-14 on these meshes
INNER_MIN = 1e-13


def inner_rtol(tol: float) -> float:
    """The relative residual an iterative shift-and-invert solve is converged to for eigenpairs
    converged to ``tol`` (INNER_FACTOR, INNER_MIN)."""
    return max(INNER_MIN, INNER_FACTOR * tol)


def rigid_body_modes(V, entries: np.ndarray | None = None) -> PETSc.NullSpace:
    """The six rigid-body motions of the solid on the nodes of the vector space ``V`` (three
    translations e_i and three rotations e_i x X about the origin, on the undeformed dof
    coordinates X), orthonormalised by modified Gram-Schmidt: the near-nullspace GAMG builds
    its coarse spaces from (dolfinx 0.5 has no helper). ``entries``: this rank's owned entries
    to keep, in order (the free coordinates of a clamped body, whose matrices are numbered
    rank by rank in that order); default all. Collective on V's communicator."""
    from dolfinx import la

    imap, bs = V.dofmap.index_map, V.dofmap.index_map_bs
    owned = imap.size_local
    X = V.tabulate_dof_coordinates()[:owned]
    comm = V.mesh.comm
    if entries is None:
        keep = slice(None)
        vecs = [la.create_petsc_vector(imap, bs) for _ in range(6)]
    else:
        keep, n = entries, entries.size
        vecs = [PETSc.Vec().createMPI((n, comm.allreduce(n)), comm=comm) for _ in range(6)]
    for i in range(6):
        block = np.zeros((owned, 3))
        if i < 3:
            block[:, i] = 1.0
        else:                                   # e_k x X for k = i - 3
            e = np.zeros(3)
            e[i - 3] = 1.0
            block[:] = np.cross(e, X)
        vecs[i].setArray(block.reshape(-1)[keep])
    for i, v in enumerate(vecs):
        for w in vecs[:i]:
            v.axpy(-v.dot(w), w)
        v.normalize()
    return PETSc.NullSpace().create(vectors=vecs, comm=comm)


def make_iterative(ksp: PETSc.KSP, *, symmetric: bool = True, rtol: float = 1e-10,
                   nullspace: PETSc.NullSpace | None = None) -> PETSc.KSP:
    """Turn ``ksp`` into a GAMG-preconditioned Krylov solve: CG when symmetric (the tangent of a
    stable steady state and K_L are positive definite), GMRES otherwise (the circulatory term
    of the absolute damping), right-preconditioned. Both stop on the true residual,
    ||b - A x|| <= rtol ||b||, so that ``rtol`` means what a direct solve's round-off would.
    ``nullspace`` (:func:`rigid_body_modes`) is set as the operator's near-nullspace, the coarse
    spaces of smoothed aggregation for elasticity; the KSP must have its operator already (a
    SLEPc spectral transformation's gets it only at set-up: set the near-nullspace on the matrix
    instead). A solve that does not converge raises."""
    if symmetric:
        ksp.setType("cg")
        ksp.setNormType(PETSc.KSP.NormType.UNPRECONDITIONED)
    else:
        ksp.setType("gmres")
        ksp.setGMRESRestart(100)
        ksp.setPCSide(PETSc.PC.Side.RIGHT)
        ksp.setNormType(PETSc.KSP.NormType.UNPRECONDITIONED)
    ksp.setTolerances(rtol=rtol, atol=0.0, max_it=KRYLOV_MAX_IT)
    ksp.setErrorIfNotConverged(True)
    pc = ksp.getPC()
    pc.setType("gamg")
    pc.setGAMGType("agg")
    if not symmetric:
        # smoothed aggregation reads the matrix graph as undirected: symmetrise it
        opts, key = PETSc.Options(), f"{ksp.getOptionsPrefix() or ''}pc_gamg_sym_graph"
        opts[key] = True
        pc.setFromOptions()
        opts.delValue(key)
    if nullspace is not None:
        A, _ = ksp.getOperators()
        if A.getType() is None:
            raise ValueError("make_iterative: the KSP has no operator yet to carry the "
                             "near-nullspace (an eigensolver's, before set-up); set it on the "
                             "matrix itself")
        A.setNearNullSpace(nullspace)
    return ksp


def pep_eigen(M: PETSc.Mat, C: PETSc.Mat, K: PETSc.Mat, pairs: int, *, target: float = 0.0,
              tol: float | None = None, vectors: bool = True, symmetric: bool = False,
              initial: np.ndarray | None = None, errors: bool = True,
              linear: str = "direct", nullspace: PETSc.NullSpace | None = None
              ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """The ``pairs`` roots nearest ``target`` with Im >= 0 (one per conjugate pair), as
    (lambda (k,), X (n_local, k) complex or None, backward errors (k,)), unsorted.

    SLEPc returns a complex pair as two consecutive roots; ``nev`` asks for both members of each
    pair plus a margin, so that at least ``pairs`` roots with Im >= 0 converge, and never more
    than the 2n roots there are (n the size of the matrices). Fewer converged roots raise
    :class:`~fxflex.numerics.qep.EigenNotConverged` carrying those that did.

    ``symmetric``: P(target) is symmetric (no circulatory term; at target 0 it is K), so MUMPS
    factorises it as LDL^T, half the entries of LU. ``initial`` (n_local, m) real: the Krylov
    search starts from these vectors (SLEPc's initial space), e.g. the mode vectors of a nearby
    speed; the roots it converges are the same, to ``tol``. Without ``errors`` the backward
    errors are not computed (None).

    ``linear`` (:data:`ROUTES`): "direct" factorises P(target) with MUMPS; "iterative" applies
    its inverse by a GAMG-preconditioned Krylov solve (:func:`make_iterative`; CG when
    ``symmetric``, else GMRES) converged to :func:`inner_rtol` of the PEP tolerance, the
    ``nullspace`` (:func:`rigid_body_modes` on the matrices' layout) as GAMG's near-nullspace.
    That route needs ``target`` 0, where SLEPc's shift-and-invert operator is K itself, which
    carries the near-nullspace (set on a KSP before SLEPc gives it its operator, it would be
    lost). A symmetric K that is not positive definite (past a divergence, where the iterative
    steady state's CG steps fail first) stops CG with an error."""
    if linear not in ROUTES:
        raise ValueError(f"linear solver route {linear!r}; allowed: {', '.join(ROUTES)}")
    if linear == "iterative" and target != 0.0:
        raise ValueError("the iterative route of the PEP needs target 0 (its operator is K)")
    tol = TOL if tol is None else tol
    pep = SLEPc.PEP().create(K.getComm())
    pep.setOperators([K, C, M])
    pep.setProblemType(SLEPc.PEP.ProblemType.GENERAL)
    pep.setType(SLEPc.PEP.Type.TOAR)
    pep.setScale(SLEPc.PEP.Scale.SCALAR)
    size = 2 * K.getSize()[0]
    nev = min(2 * pairs + 4, size)
    pep.setDimensions(nev=nev, ncv=min(max(2 * nev, nev + 32), size))
    pep.setTarget(target)
    pep.setWhichEigenpairs(SLEPc.PEP.Which.TARGET_MAGNITUDE)
    st = pep.getST()
    st.setType(SLEPc.ST.Type.SINVERT)
    if linear == "iterative":
        if nullspace is not None:
            K.setNearNullSpace(nullspace)
        make_iterative(st.getKSP(), symmetric=symmetric, rtol=inner_rtol(tol))
    else:
        make_direct(st.getKSP(), symmetric=symmetric)
    pep.setTolerances(tol, MAX_IT)
    space = []
    if initial is not None and initial.shape[1]:
        for col in initial.T:
            v = K.createVecRight()
            v.setArray(np.ascontiguousarray(col))
            space.append(v)
        pep.setInitialSpace(space)
    pep.solve()
    for v in space:
        v.destroy()
    nconv = pep.getConverged()
    xr, xi = K.createVecRight(), K.createVecRight()
    lam, cols = [], []
    backward = [] if errors else None
    for i in range(nconv):
        value = pep.getEigenpair(i, xr, xi)
        if value.imag < 0.0:
            continue
        lam.append(complex(value))
        if backward is not None:
            backward.append(pep.computeError(i, SLEPc.PEP.ErrorType.BACKWARD))
        if vectors:
            cols.append(xr.getArray(readonly=True) + 1j * xi.getArray(readonly=True))
    pep.destroy()
    xr.destroy()
    xi.destroy()
    X = np.column_stack(cols) if vectors and cols else None
    if len(lam) < pairs:
        raise EigenNotConverged(f"SLEPc PEP converged {len(lam)} of {pairs} eigenvalue pairs",
                                np.array(lam, dtype=complex), X)
    return np.array(lam), X, None if backward is None else np.array(backward)


class PetscLinearisation:
    """The linearised motion M x'' + C x' + K x = 0 as distributed PETSc matrices, and what follows
    from it by SLEPc's PEP (:func:`pep_eigen`): the same methods as
    :class:`fxflex.numerics.qep.DenseLinearisation`, so callers never ask which. Only the lowest
    roots are computed -- a rotating beam loses stability through its low modes (a root through
    zero, or low modes merging); the high ones are damped at about -c/(2 rho) and hardly moved by
    the rotation -- at least ``min_pairs`` of them, kept, so that the verdict after a modal
    analysis costs nothing. Collective on the matrices' communicator.

    With ``reassemble`` (a callable giving (M, C, K) afresh) the matrices are freed after each
    eigensolve, as a distributed model's memory asks, and assembled again only for a later solve
    that wants more roots. ``symmetric``, ``initial`` and ``linear`` are passed to
    :func:`pep_eigen` (a symmetric K; a starting space, e.g. a nearby speed's modes; the linear
    solver route of its shift-and-invert); ``nullspace``, a callable, gives the iterative
    route's near-nullspace on the matrices' layout."""

    kind = "petsc"

    def __init__(self, M: PETSc.Mat, C: PETSc.Mat, K: PETSc.Mat, *, min_pairs: int = 8,
                 rtol: float = 1e-8, reassemble=None, symmetric: bool = False,
                 initial: np.ndarray | None = None, linear: str = "direct", nullspace=None):
        self.M, self.C, self.K = M, C, K
        self._reassemble = reassemble
        self.dof = K.getSize()[0]
        self.min_pairs = min_pairs      # lowest pairs behind eigenvalues(), stable(), growth_rate()
        self.rtol = rtol                # a root grows when Re > rtol max|lambda| (PEP residual)
        self.note: str | None = None
        self.symmetric, self.initial = symmetric, initial
        self.linear, self._nullspace = linear, nullspace
        self._modes: tuple[np.ndarray, np.ndarray | None, int] | None = None

    def modes(self, pairs: int) -> tuple[np.ndarray, np.ndarray]:
        """The ``pairs`` lowest roots, one per conjugate pair, lowest frequency first, and their
        mode vectors on this rank's entries; at most ``dof``. When the PEP converges fewer, the
        ones it has are kept and :class:`~fxflex.numerics.qep.EigenNotConverged` is raised with
        them, now and on each later call that asks for more."""
        from fxflex.numerics.qep import conjugate_pairs

        pairs = min(pairs, self.dof)
        if self._modes is None or self._modes[2] < pairs:
            count = min(max(pairs, self.min_pairs), self.dof)
            if self.K is None:
                self.M, self.C, self.K = self._reassemble()
            iterative = {}
            if self.linear != "direct":
                iterative = {"linear": self.linear, "nullspace": (
                    self._nullspace() if self._nullspace is not None else None)}
            try:
                lam, X, _ = pep_eigen(self.M, self.C, self.K, count, symmetric=self.symmetric,
                                      initial=self.initial, errors=False, **iterative)
            except EigenNotConverged as exc:
                lam, X = exc.eigenvalues, exc.vectors
            finally:
                if self._reassemble is not None:
                    self.destroy()
            keep = conjugate_pairs(lam)[:count]
            self._modes = (lam[keep], X[:, keep] if X is not None else None, count)
        lam, X, _ = self._modes
        if lam.size < pairs:
            raise EigenNotConverged(f"SLEPc PEP converged {lam.size} of {pairs} eigenvalue "
                                    "pairs", lam, X)
        return lam[:pairs], X[:, :pairs]

    def eigenvalues(self) -> np.ndarray:
        """The ``min_pairs`` lowest roots."""
        return self.modes(self.min_pairs)[0]

    def growth_rate(self) -> tuple[float, float]:
        """(Re lambda, |Im lambda|) of the rightmost of the lowest roots (1/s, rad/s)."""
        from fxflex.numerics.qep import rightmost
        return rightmost(self.eigenvalues())

    def stable(self) -> bool | None:
        """No growing root among the lowest (:func:`fxflex.numerics.qep.unstable`, with the
        PEP's own tolerance). When the PEP converged only some of them, a growing one among
        those still decides (False); otherwise None, undecided, the reason in ``note``."""
        from fxflex.numerics.qep import unstable
        try:
            lam = self.eigenvalues()
        except EigenNotConverged as exc:
            if exc.eigenvalues.size and unstable(exc.eigenvalues, rtol=self.rtol):
                return False
            self.note = f"stability not decided: {exc}"
            return None
        return not unstable(lam, rtol=self.rtol)

    def top_frequency(self) -> float | None:
        """Not computed from these matrices (a SLEPc solve of its own): None, and callers use
        the formulation's ``omega_max()``."""
        return None

    def destroy(self) -> None:
        for A in (self.M, self.C, self.K):
            if A is not None:
                A.destroy()
        self.M = self.C = self.K = None
