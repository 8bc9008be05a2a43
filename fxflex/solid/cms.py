"""Clamped-root eigenmodes of the solid for component mode synthesis (paper Sect. 2.1).

The reference condition of the floating frame is the clamped root (the paper's [16]), so the
component modes are the lowest eigenpairs of

    K_L x = omega^2 M x,    x = 0 on the root face,

with K_L the linear stiffness (Eq. 14) and M = M_ff the consistent mass (Eq. 11). SLEPc solves the
generalised Hermitian problem by shift-and-invert about 0 (MUMPS Cholesky of K_L), distributed over
the model's communicator; on the iterative route (``[solver] linear``, docs/solvers.md) each
inverse is a CG solve with GAMG and the rigid-body near-nullspace, converged to a tenth of the
eigen tolerance (:func:`fxflex.numerics.petsc.inner_rtol`), so that the inexact inverse leaves
the eigenpairs' residuals at tol. The clamped rows carry 1 on the diagonal of K_L and 0 on that
of M: their eigenvalues are infinite and never reach the target (the iterative route's modes are
set to zero there exactly, as the factorisation's are). Each mode is scaled to x^T M x = 1 and its
sign fixed so that the largest tip-centre component is positive (deterministic across ranks).

Everything the eigenmodes depend on is the scene's geometry, material and mesh, so they are
cached on disk (:mod:`fxflex.cache`, kind ``modes``) keyed by the mesh key, the material, the
quadrature degree, the mode count, the solver tolerance and the source of the producing modules.
An entry is independent of the partition: rank 0 gathers the modes in the mesh file's node order
(gmsh's input numbering, ``mesh.geometry.input_global_indices``) with the node coordinates, and
every rank reads back its owned rows, after checking that its nodes sit where the stored ones
do. A cache written on 1 rank therefore serves 2 and vice versa (the vectors then differ from a
fresh solve on the new partition by the solver's round-off, as two fresh solves do).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from mpi4py import MPI

from fxflex import cache

if TYPE_CHECKING:                   # a cache hit needs neither PETSc nor dolfinx: imported on use
    from petsc4py import PETSc

    from fxflex.solid.model import SolidModel

__all__ = ["ClampedModes", "clamped_modes", "mass_and_stiffness", "modes_key", "CODE_MODULES"]

#: modules whose source decides the modes (with the mesh key): a change makes a new cache entry
CODE_MODULES = ("fxflex.solid.cms", "fxflex.solid.forms", "fxflex.solid.model",
                "fxflex.solid.tip_mass", "fxflex.numerics.director",
                "fxflex.scene.schema", "fxflex.scene.kinematics")


@dataclass(frozen=True)
class ClampedModes:
    """The lowest clamped eigenpairs; ``vectors`` holds this rank's owned entries."""

    omega2: np.ndarray          # (m,) eigenvalues omega^2 (rad^2/s^2), ascending
    vectors: np.ndarray         # (n_owned, m) mass-normalised modes, zero on the clamp
    errors: np.ndarray          # (m,) SLEPc relative residual norms
    timings: dict = field(default_factory=dict)
    from_cache: bool = False

    @property
    def count(self) -> int:
        return self.omega2.size

    @property
    def omega(self) -> np.ndarray:
        """Circular frequencies (rad/s)."""
        return np.sqrt(self.omega2)

    @property
    def frequencies_hz(self) -> np.ndarray:
        return self.omega / (2 * np.pi)


def mass_and_stiffness(model: SolidModel) -> tuple[PETSc.Mat, PETSc.Mat]:
    """(K_L, M) assembled with the root clamp: 1 on K_L's clamped diagonal, 0 on M's. M holds
    the [tip_mass] (:mod:`fxflex.solid.tip_mass`: mu (x) I_3 on the tip nodes, and a body's
    Pi_XX J^T J at the reference, FFRF's linearised director), so the clamped modes are those
    of the solid with its tip body."""
    from fxflex.solid.tip_mass import tip_body

    K = model.matrix(model.compile(model.stiffness_form()))
    M = model.matrix(model.compile(model.mass_form()), diagonal=0.0)
    body = tip_body(model)
    if body is not None:
        body.add_to(M)
        d = body.director
        if d is not None:               # Pi_XX, FFRF's director linearised at the reference
            d.add_to(M, d.mass6(np.zeros(model.n_owned)))
    return K, M


def modes_key(model: SolidModel, count: int, tol: float) -> str:
    """Cache key of the ``count`` clamped modes of ``model`` (module docstring)."""
    from dataclasses import asdict

    from fxflex.solid.tip_mass import tip_key

    return cache.entry_key({
        "kind": "modes", "mesh": model.solid_mesh.key,
        **({"degree": model.degree} if model.degree != 1 else {}),
        "material": asdict(model.scene.material), "quadrature": model.quadrature_degree,
        "count": int(count), "tol": float(tol), **tip_key(model.scene),
        "code": cache.code_version(*CODE_MODULES)})


def clamped_modes(model: SolidModel, count: int, *, K: PETSc.Mat | None = None,
                  M: PETSc.Mat | None = None, tol: float = 1e-12,
                  use_cache: bool = True, linear: str = "direct") -> ClampedModes:
    """The ``count`` lowest clamped eigenmodes of (K_L, M) on ``model.comm``, the inverse of K_L
    applied by the ``linear`` route ("direct" or "iterative"; one cache entry serves both: they
    agree to the eigen tolerance).

    K and M may be passed when the caller has assembled them already (they must carry the clamp
    as :func:`mass_and_stiffness` does); on a cache hit they are not needed. Collective.
    """
    if count < 1:
        raise ValueError(f"count must be >= 1, got {count}")
    key = modes_key(model, count, tol) if use_cache and cache.enabled("modes") else None
    if key is not None:
        t0 = time.perf_counter()
        hit = _read(model, key, count)
        if hit is not None:
            hit.timings["cache_load"] = time.perf_counter() - t0
            return hit
    modes = _solve(model, count, K, M, tol, linear)
    if key is not None:
        _write(model, key, modes)
    return modes


def _solve(model: SolidModel, count: int, K, M, tol: float, linear: str) -> ClampedModes:
    from slepc4py import SLEPc

    from dolfinx.fem.petsc import set_bc

    from fxflex.numerics.petsc import inner_rtol, make_iterative, rigid_body_modes
    from fxflex.solid.solvers import make_direct

    t0 = time.perf_counter()
    if K is None or M is None:
        K, M = mass_and_stiffness(model)
    t1 = time.perf_counter()
    eps = SLEPc.EPS().create(model.comm)
    eps.setOperators(K, M)
    eps.setProblemType(SLEPc.EPS.ProblemType.GHEP)
    eps.setDimensions(nev=count)
    eps.setWhichEigenpairs(SLEPc.EPS.Which.TARGET_MAGNITUDE)
    eps.setTarget(0.0)
    st = eps.getST()
    st.setType(SLEPc.ST.Type.SINVERT)
    st.setShift(0.0)
    if linear == "iterative":
        # on K itself: SLEPc hands its KSP the operator only at set-up (at shift 0, K)
        K.setNearNullSpace(rigid_body_modes(model.V))
        make_iterative(st.getKSP(), rtol=inner_rtol(tol))
    else:
        make_direct(st.getKSP())
    eps.setTolerances(tol, 500)
    eps.solve()
    nconv = eps.getConverged()
    if nconv < count:
        raise RuntimeError(f"SLEPc converged {nconv} of {count} clamped eigenmodes")
    x = K.createVecRight()
    Mx = M.createVecLeft()
    pairs = []
    for i in range(nconv):
        lam = eps.getEigenpair(i, x).real
        pairs.append((lam, i))
    pairs.sort()
    n_owned = x.getLocalSize()
    vectors = np.empty((n_owned, count))
    omega2 = np.empty(count)
    errors = np.empty(count)
    for j, (lam, i) in enumerate(pairs[:count]):
        eps.getEigenpair(i, x)
        if linear == "iterative":      # exactly zero on the clamp, as the direct route's are
            set_bc(x, [model.bc])
        M.mult(x, Mx)
        x.scale(1.0 / np.sqrt(x.dot(Mx)))
        omega2[j] = lam
        errors[j] = eps.computeError(i)
        vectors[:, j] = x.getArray(readonly=True)
    eps.destroy()
    _fix_signs(model, vectors)
    t2 = time.perf_counter()
    return ClampedModes(omega2=omega2, vectors=vectors, errors=errors,
                        timings={"assemble_KM": t1 - t0, "eigensolve": t2 - t1})


def _fix_signs(model: SolidModel, vectors: np.ndarray) -> None:
    """Flip each mode so that its largest tip-centre component is positive."""
    local = np.zeros((3, vectors.shape[1]))
    if model.tip_node is not None:
        local[:] = vectors[3 * model.tip_node: 3 * model.tip_node + 3]
    tip = model.comm.allreduce(local)
    idx = np.argmax(np.abs(tip), axis=0)
    signs = np.sign(tip[idx, np.arange(tip.shape[1])])
    signs[signs == 0] = 1.0
    vectors *= signs


# -- the partition-independent cache entry ---------------------------------------------------------

def _input_numbers(model: SolidModel) -> np.ndarray:
    """Mesh-file (gmsh input) number of each owned node of ``model.V``. The Lagrange space and
    the geometry share degree and cell layout (P1 on Q1 cells, P2 on 27-node cells), so a node's
    dof and geometry index meet cell by cell."""
    geo = model.mesh.geometry
    imap = model.V.dofmap.index_map
    node_of_dof = np.full(imap.size_local + imap.num_ghosts, -1, dtype=np.int64)
    node_of_dof[model.V.dofmap.list.array] = geo.dofmap.array      # owned and ghost cells
    owned = node_of_dof[: model.n_owned_nodes]
    if np.any(owned < 0):
        raise RuntimeError("clamped modes cache: an owned node lies in no local cell")
    return np.asarray(geo.input_global_indices, dtype=np.int64)[owned]


def _write(model: SolidModel, key: str, modes: ClampedModes) -> None:
    """Gather the modes on rank 0 in mesh-file node order and store them there."""
    comm = model.comm
    parts = comm.gather((_input_numbers(model), model.node_coordinates(), modes.vectors), root=0)
    if comm.rank == 0:
        n_nodes = sum(p[0].size for p in parts)
        coords = np.empty((n_nodes, 3))
        vectors = np.empty((n_nodes, 3, modes.count))
        for numbers, xyz, vec in parts:
            coords[numbers] = xyz
            vectors[numbers] = vec.reshape(-1, 3, modes.count)
        cache.save("modes", key, {"omega2": modes.omega2, "errors": modes.errors,
                                  "coords": coords, "vectors": vectors.reshape(-1, modes.count)})
    comm.Barrier()          # the entry (inside a build: its pending file) exists once this returns


def _read(model: SolidModel, key: str, count: int) -> ClampedModes | None:
    """This rank's rows of a stored entry, or None on every rank unless every rank has them."""
    data = cache.load("modes", key)
    local = None
    if data is not None and data["omega2"].shape == (count,):
        numbers = _input_numbers(model)
        coords, stored = data["coords"], data["vectors"]
        xyz = model.node_coordinates()
        scale = model.scene.geometry.length + model.scene.geometry.hub_radius
        if (numbers.size == 0 or numbers.max() < coords.shape[0]) and stored.shape == (
                3 * coords.shape[0], count) and np.allclose(
                coords[numbers], xyz, rtol=0, atol=1e-12 * scale):
            rows = (3 * numbers[:, None] + np.arange(3)).reshape(-1)
            local = ClampedModes(omega2=data["omega2"], vectors=np.ascontiguousarray(
                stored[rows]), errors=data["errors"], from_cache=True)
    if not model.comm.allreduce(local is not None, op=MPI.LAND):
        return None
    return local
