"""System invariant matrices of the TLF internal force (paper Eq. 31-35), built once.

With Q1 shape-function gradients g_a = grad N_a (reference configuration) and nodal displacements
u_a, the displacement gradient is H = sum_a u_a (x) g_a and the Green-Lagrange strain (Eq. 30)

    E = sym(H) + 1/2 H^T H,    H^T H = sum_ab (u_a . u_b) g_a (x) g_b.

The quadratic part depends on u only through the node-pair products w_ab = u_a . u_b, which is
what the paper's block matrix u_ds does: B_N u = B_N5 u_ds u (Eq. 31), and (u_ds u)_ab = u_a . u_b.
Because w_ab = w_ba we keep one entry per unordered pair p = {a, b} of nodes sharing a cell (the
paper keeps the m^2 ordered pairs per element; this halves the pair space without changing the
algebra) with Gamma_p = g_a (x) g_b + g_b (x) g_a (a != b), g_a (x) g_a (a = b), so that
H^T H = sum_p w_p Gamma_p. The SVK internal force Q_k = dW/du, W = 1/2 int E : C : E, is then
(Eq. 33, 35)

    Q_k = K_L u + K_N1 w + u_ds^T (K_N2 u + K_N3 w),

    K_N1 = 1/2 int B_L^T C B_N5 = 1/2 K_N2^T,   K_N2 = int B_N5^T C B_L,
    K_N3 = 1/2 int B_N5^T C B_N5,

in tensor form K_N2[p, (b,l)] = int lambda tr(Gamma_p) g_b,l + 2 mu (Gamma_p g_b)_l and
K_N3[p, q] = 1/2 int lambda tr(Gamma_p) tr(Gamma_q) + 2 mu Gamma_p : Gamma_q, and the last
product u_ds^T z adds z_p u_b / 2 to node a and z_p u_a / 2 to node b (dw_p/du_a = u_b, or 2 u_a
when a = b). K_N1 is not stored: it is half the transpose of K_N2.

Every matrix is integrated with the same quadrature rule as the UFL residual (Gauss, degree set
on the model) over the cells this rank owns, in the rank's local node numbering (owned and ghost
nodes): the "system" of one process. Ghost contributions are accumulated afterwards exactly as
for an assembled UFL vector, so on one process these are the paper's system matrices and on
several their subdomain parts. Products use PETSc sequential AIJ matrices on arrays allocated
once; nothing is allocated per evaluation.

Building the matrices takes seconds on the default mesh (6.7 s serial), so they are cached on disk
(:mod:`fxflex.cache`, kind ``tlf-invariants``), one entry per rank: a rank's matrices are its
subdomain's, so the key hashes that rank's node coordinates and cell-node lists in its local
numbering (with the material, the quadrature degree and this module's source). The same mesh on
the same number of ranks partitions the same way and hits; any other partition misses and builds.
"""

from __future__ import annotations

import hashlib
import time

import basix
import numpy as np
import scipy.sparse as sp
from petsc4py import PETSc

from fxflex import cache

__all__ = ["CellGradients", "cell_gradients", "InvariantForce", "invariant_key",
           "assemble_invariants", "refuse_degree", "q2_bytes"]

#: unordered node pairs (a <= b) of a Q1 hexahedron: 36 of the paper's 64 ordered ones
_IA, _IB = np.triu_indices(8)


def q2_bytes(cells: int) -> float:
    """Bytes the invariant matrices would take on ``cells`` 27-node hexahedra: per cell 378 node
    pairs (27 x 28 / 2, against 36 on Q1), so the upper half of K_N3 holds 378 x 379 / 2 and K_N2
    378 x 81 entries per cell, 12 bytes each (value and column index), before the entries of
    cells sharing nodes merge (at most a factor 2 less on these meshes): 1.2 MB per cell, about
    50 kB per unknown (a Q2 cell adds about 8 nodes), against 1530 entries per cell and the
    measured 12 kB per unknown of Q1. Assembly holds a further 24 bytes per cell entry of a
    1024-cell chunk, and an evaluation streams the whole of K_N3 (slower than the UFL kernel)."""
    pairs = 27 * 28 // 2
    return float(cells) * (pairs * (pairs + 1) // 2 + pairs * 81) * 12.0


def refuse_degree(model) -> None:
    """The invariant route is built for Q1 (8-node cells, 36 node pairs): refuse any other degree
    with one line giving the memory it would need (:func:`q2_bytes`). Collective."""
    from fxflex.errors import FxflexError

    if model.degree == 1:
        return
    cells = model.mesh.topology.index_map(3).size_global
    raise FxflexError(f"--force-eval invariant: not built for mesh.solid_degree = {model.degree} "
                      f"(its K_N3 and K_N2 would need about {q2_bytes(cells) / 1e6:.3g} MB on "
                      f"mesh.solid {list(model.divisions)}, "
                      f"{q2_bytes(cells) / model.dof / 1e3:.3g} kB per unknown against 12 kB on "
                      f"Q1); allowed: --force-eval ufl, or mesh.solid_degree = 1")


class CellGradients:
    """Physical shape-function gradients g (cells, points, 8, 3), weights w |det J| (cells,
    points) and local node indices (cells, 8) of the cells a rank owns."""

    def __init__(self, nodes: np.ndarray, grads: np.ndarray, weights: np.ndarray):
        self.nodes, self.grads, self.weights = nodes, grads, weights


def cell_gradients(model, cells: slice | None = None) -> CellGradients:
    """Gradients of the Q1 basis at the Gauss points of ``model.quadrature_degree`` (the rule
    FFCx uses for the UFL forms), from the isoparametric map of each owned cell."""
    V = model.V
    n_cells = model.mesh.topology.index_map(3).size_local
    nodes = V.dofmap.list.array.reshape(-1, 8)[:n_cells]
    if cells is not None:
        nodes = nodes[cells]
    X = V.tabulate_dof_coordinates()
    points, wq = basix.make_quadrature(basix.CellType.hexahedron, model.quadrature_degree)
    element = basix.create_element(basix.ElementFamily.P, basix.CellType.hexahedron, 1,
                                   basix.LagrangeVariant.equispaced)
    dN = np.moveaxis(element.tabulate(1, points)[1:, :, :, 0], 0, -1)   # (points, 8, 3)
    J = np.einsum("cai,qaj->cqij", X[nodes], dN)
    detJ = np.linalg.det(J)
    invJ = np.linalg.inv(J)
    grads = np.einsum("qaj,cqji->cqai", dN, invJ)
    return CellGradients(nodes, grads, wq[None, :] * np.abs(detJ))


def _element_matrices(cg: CellGradients, lmbda: float, mu: float):
    """K_L (cells, 24, 24), K_N2 (cells, 36, 24) and K_N3 (cells, 36, 36) of Eq. 33."""
    g, wd = cg.grads, cg.weights
    ga, gb = g[:, :, _IA, :], g[:, :, _IB, :]
    gamma = ga[..., :, None] * gb[..., None, :]
    gamma = gamma + np.swapaxes(gamma, -1, -2)
    gamma[:, :, _IA == _IB] *= 0.5
    tr = np.einsum("cqpii->cqp", gamma)
    # K_L: lambda g_a,k g_b,l + mu (g_a . g_b) delta_kl + mu g_a,l g_b,k
    gg = np.einsum("cqak,cqbl,cq->cakbl", g, g, wd)
    dot = np.einsum("cakbk->cab", gg)
    KL = lmbda * gg + mu * np.swapaxes(gg, 2, 4)
    KL += mu * np.einsum("cab,kl->cakbl", dot, np.eye(3))
    nc = g.shape[0]
    KL = KL.reshape(nc, 24, 24)
    # K_N2: lambda tr(Gamma_p) g_b,l + 2 mu (Gamma_p g_b)_l
    KN2 = lmbda * np.einsum("cqp,cqbl,cq->cpbl", tr, g, wd)
    KN2 += 2.0 * mu * np.einsum("cqplm,cqbm,cq->cpbl", gamma, g, wd)
    KN2 = KN2.reshape(nc, 36, 24)
    # K_N3: 1/2 (lambda tr(Gamma_p) tr(Gamma_q) + 2 mu Gamma_p : Gamma_q)
    KN3 = 0.5 * lmbda * np.einsum("cqp,cqr,cq->cpr", tr, tr, wd)
    KN3 += mu * np.einsum("cqpij,cqrij,cq->cpr", gamma, gamma, wd)
    return KL, KN2, KN3


def _coo(rows, cols, values, shape) -> sp.csr_matrix:
    return sp.coo_matrix((values.ravel(), (rows.ravel(), cols.ravel())), shape=shape).tocsr()


def _csr(a, kind: str = "aij") -> PETSc.Mat:
    """A sequential PETSc matrix from scipy CSR: ``aij``, ``baij`` (3 x 3 nodal blocks) or
    ``sbaij`` (upper triangle of a symmetric matrix only: half the storage and traffic)."""
    it = PETSc.IntType
    if kind == "baij":
        b = a.tobsr(blocksize=(3, 3))
        b.sort_indices()
        return PETSc.Mat().createBAIJ(a.shape, 3, csr=(b.indptr.astype(it), b.indices.astype(it),
                                                       b.data.reshape(-1)), comm=PETSc.COMM_SELF)
    if kind == "sbaij":
        a = sp.triu(a, format="csr")
    a.sum_duplicates()
    a.sort_indices()
    csr = (a.indptr.astype(it), a.indices.astype(it), a.data)
    if kind == "sbaij":
        return PETSc.Mat().createSBAIJ(a.shape, 1, csr=csr, comm=PETSc.COMM_SELF)
    return PETSc.Mat().createAIJ(a.shape, csr=csr, comm=PETSc.COMM_SELF)


def _vec(array: np.ndarray) -> PETSc.Vec:
    return PETSc.Vec().createWithArray(array, comm=PETSc.COMM_SELF)


def invariant_key(model) -> str:
    """Cache key of this rank's invariant matrices (module docstring)."""
    n_cells = model.mesh.topology.index_map(3).size_local
    local = hashlib.sha256()
    local.update(np.ascontiguousarray(model.V.tabulate_dof_coordinates()).tobytes())
    local.update(np.ascontiguousarray(
        model.V.dofmap.list.array.reshape(-1, 8)[:n_cells], dtype=np.int64).tobytes())
    return cache.entry_key({"kind": "tlf-invariants", "lame": list(model.scene.material.lame),
                            "quadrature": model.quadrature_degree, "local": local.hexdigest(),
                            **({"degree": model.degree} if model.degree != 1 else {}),
                            "code": cache.code_version(__name__)})


def _csr_arrays(name: str, a: sp.csr_matrix) -> dict[str, np.ndarray]:
    a.sum_duplicates()
    a.sort_indices()
    return {f"{name}_indptr": a.indptr, f"{name}_indices": a.indices, f"{name}_data": a.data,
            f"{name}_shape": np.array(a.shape)}


def _from_arrays(name: str, arrays: dict) -> sp.csr_matrix:
    return sp.csr_matrix((arrays[f"{name}_data"], arrays[f"{name}_indices"],
                          arrays[f"{name}_indptr"]), shape=tuple(arrays[f"{name}_shape"]))


def assemble_invariants(model, *, chunk: int = 1024) -> dict[str, np.ndarray]:
    """This rank's K_L, K_N2, K_N3 (upper half) as CSR arrays and the node pairs (pa, pb): the
    expensive part, integrated cell chunk by cell chunk."""
    lmbda, mu = model.scene.material.lame
    n_cells = model.mesh.topology.index_map(3).size_local
    imap = model.V.dofmap.index_map
    n_nodes = imap.size_local + imap.num_ghosts
    n = 3 * n_nodes
    nodes = model.V.dofmap.list.array.reshape(-1, 8)[:n_cells]
    a, b = nodes[:, _IA], nodes[:, _IB]
    keys = np.minimum(a, b).astype(np.int64) * n_nodes + np.maximum(a, b)
    unique, pair_of = np.unique(keys, return_inverse=True)
    pair_of = pair_of.reshape(n_cells, 36)
    P = unique.size
    KL = sp.csr_matrix((n, n))
    KN2 = sp.csr_matrix((P, n))
    KN3 = sp.csr_matrix((P, P))
    for start in range(0, n_cells, chunk):
        sl = slice(start, min(start + chunk, n_cells))
        cg = cell_gradients(model, sl)
        kl, kn2, kn3 = _element_matrices(cg, lmbda, mu)
        dofs = (3 * cg.nodes[:, :, None] + np.arange(3)).reshape(-1, 24)
        pairs = pair_of[sl]
        KL += _coo(np.repeat(dofs, 24, axis=1), np.tile(dofs, (1, 24)), kl, (n, n))
        KN2 += _coo(np.repeat(pairs, 24, axis=1), np.tile(dofs, (1, 36)), kn2, (P, n))
        KN3 += _coo(np.repeat(pairs, 36, axis=1), np.tile(pairs, (1, 36)), kn3, (P, P))
    for m in (KL, KN2, KN3):
        m.sum_duplicates()
    return {"pa": (unique // n_nodes).astype(np.intp), "pb": (unique % n_nodes).astype(np.intp),
            "nnz_full": np.array([KL.nnz, KN2.nnz, KN2.nnz, KN3.nnz]),
            **_csr_arrays("KL", KL), **_csr_arrays("KN2", KN2),
            **_csr_arrays("KN3", sp.triu(KN3, format="csr"))}


class InvariantForce:
    """Q_k(u) of Eq. 35 from the system invariant matrices K_L, K_N2 (K_N1 = K_N2^T / 2), K_N3.

    ``apply(u, out)`` works on the local (owned + ghost) arrays of the model's function space and
    leaves ghost contributions unaccumulated, like a UFL vector assembly. The matrices come from
    the disk cache when this rank built them before (``from_cache``), else they are assembled
    and stored.
    """

    def __init__(self, model, *, chunk: int = 1024, use_cache: bool = True):
        t0 = time.perf_counter()
        refuse_degree(model)                     # Q1 only (8-node cells, 36 node pairs)
        key = invariant_key(model) if use_cache and cache.enabled("tlf-invariants") else None
        arrays = cache.load("tlf-invariants", key) if key else None
        self.from_cache = arrays is not None
        if arrays is None:
            arrays = assemble_invariants(model, chunk=chunk)
            if key:
                cache.save("tlf-invariants", key, arrays)
        self.pa, self.pb = arrays["pa"].astype(np.intp), arrays["pb"].astype(np.intp)
        self.n_pairs = P = self.pa.size
        KL, KN2, KN3 = (_from_arrays(k, arrays) for k in ("KL", "KN2", "KN3"))
        n = KL.shape[0]
        # u_ds^T z as a fixed 0/1 matrix R (n x 6P): node a collects z_p u_b / 2, node b z_p u_a / 2
        comp = np.arange(3)
        rows = np.concatenate([3 * self.pa[:, None] + comp, 3 * self.pb[:, None] + comp])
        R = sp.csr_matrix((np.full(6 * P, 0.5), (rows.ravel(), np.arange(6 * P))),
                          shape=(n, 6 * P))
        # stored: K_L in 3 x 3 blocks, K_N3 symmetric (upper half), K_N2 and R plain CSR
        self.nnz_full = dict(zip(("K_L", "K_N1", "K_N2", "K_N3"),
                                 (int(x) for x in arrays["nnz_full"])))
        self.KL, self.KN2 = _csr(KL, "baij"), _csr(KN2)
        self.KN3, self.R = _csr(KN3, "sbaij"), _csr(R)
        self.nnz = {k: int(m.getInfo()["nz_used"]) for k, m in
                    (("K_L", self.KL), ("K_N2", self.KN2), ("K_N3", self.KN3), ("R", self.R))}
        # work arrays, allocated once
        self.n = n
        self._u = np.zeros(n)
        self._f = np.zeros(n)
        self._ua, self._ub = np.empty((P, 3)), np.empty((P, 3))
        self._w, self._hw, self._z = np.empty(P), np.empty(P), np.empty(P)
        self._y = np.empty((2, P, 3))
        # (numpy 1.24 buffers a broadcast multiply into ``out``; per-column views do not)
        self._columns = [(x[:, j], y[:, j]) for x, y in ((self._ub, self._y[0]),
                                                         (self._ua, self._y[1]))
                         for j in range(3)]
        self._uv, self._fv = _vec(self._u), _vec(self._f)
        self._wv, self._hwv, self._zv = _vec(self._w), _vec(self._hw), _vec(self._z)
        self._yv = _vec(self._y.reshape(-1))
        self.build_time = time.perf_counter() - t0

    def pair_products(self, u: np.ndarray, out: np.ndarray) -> None:
        """w_p = u_a . u_b for every pair (the paper's u_ds u, Eq. 31)."""
        u3 = u.reshape(-1, 3)
        np.take(u3, self.pa, axis=0, out=self._ua, mode="clip")   # "raise" buffers
        np.take(u3, self.pb, axis=0, out=self._ub, mode="clip")
        np.einsum("pi,pi->p", self._ua, self._ub, out=out)

    def apply(self, u: np.ndarray, out: np.ndarray) -> None:
        """out = Q_k(u) (Eq. 35) on local arrays; ghost entries hold partial sums."""
        self._u[:] = u
        self.pair_products(self._u, self._w)
        np.multiply(self._w, 0.5, out=self._hw)
        self.KL.mult(self._uv, self._fv)                       # K_L u
        self.KN2.multTransposeAdd(self._hwv, self._fv, self._fv)   # + K_N1 w
        self.KN2.mult(self._uv, self._zv)                      # z = K_N2 u
        self.KN3.multAdd(self._wv, self._zv, self._zv)         #   + K_N3 w
        for src, dst in self._columns:                        # y = z u_b, z u_a per component
            np.multiply(src, self._z, out=dst)
        self.R.multAdd(self._yv, self._fv, self._fv)           # + u_ds^T z
        out[:] = self._f

    def memory_bytes(self) -> dict[str, int]:
        """Bytes held: the invariant matrices as stored (8-byte values, PETSc integer indices;
        K_N1 is not stored) and the per-pair index and work arrays."""
        isz = np.dtype(PETSc.IntType).itemsize
        rows = {"K_L": self.n // 3, "K_N2": self.n_pairs, "K_N3": self.n_pairs, "R": self.n}
        out = {k: nnz * 8 + (rows[k] + 1) * isz for k, nnz in self.nnz.items()}
        out["K_L"] += self.nnz["K_L"] // 9 * isz            # one column index per 3 x 3 block
        for k in ("K_N2", "K_N3", "R"):
            out[k] += self.nnz[k] * isz
        out["pair_arrays"] = (2 * np.dtype(np.intp).itemsize + 8 * 3 + 6 * 8) * self.n_pairs
        return out
