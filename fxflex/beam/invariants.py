"""Invariant-matrix evaluation of the geometrically nonlinear elastic forces of NEBB and ANCF.

Both strain measures are quadratic in the coordinates through a Gram matrix only. Group the
element coordinates into "slots" (ANCF: the 14 shape functions of Eq. 52, each carrying a 3-vector
of e - e0; NEBB: the four Hermite functions of W_Y and W_Z, each carrying the pair (W_Y, W_Z) of
values or slopes) and write B for the slot matrix (slots x components, B = R u) and P = B B^T.
Then the Green-Lagrange / von Karman strain energy is

    V = 1/2 u^T K_L u + 1/2 sum_k u_k T1[k] : P + 1/8 P : T4 : P

with T1 (cubic) and T4 (quartic) constant element tensors, and the elastic force is

    Q = K_L u + 1/2 T1 : P + R^T (S1 + 1/2 S4) B,   S1 = sum_k u_k T1[k],   S4 = T4 : P.

This is the paper's Q = (K_L + K_N) u with K_N = K_N1 u_d + u_d^T K_N2 + u_d^T K_N3 u_d (Eq. 33,
48, 55, 57): u_d u is the vector of the products P_ab, so K_N1 = T1/2, K_N2 = T1^T and
K_N3 = T4/2. Two evaluations are offered:

- ``system`` (system invariant matrices): T1 and T4 assembled once into sparse system matrices over
  the pairs of slots that share an element; per step the products p_ab, three sparse products and
  one sparse slot-matrix product. No element loop, no assembly in the time loop.
- ``element`` (element invariant matrices, the paper's ref. [49]): per step every element stiffness
  matrix K_Le + K_Ne(u_e) is computed from the element tensors, applied to u_e and assembled.

The elements form a chain (element e joins nodes e and e + 1); node k owns ``dpn`` coordinates and
``spn`` slots.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numpy.lib.stride_tricks import as_strided

from fxflex.numerics.sparse import SparseAdd

__all__ = ["GramChain"]


def _csr(rows, cols, vals, shape) -> sp.csr_matrix:
    m = sp.coo_matrix((vals, (rows, cols)), shape=shape).tocsr()
    m.sum_duplicates()
    m.eliminate_zeros()
    m.sort_indices()
    return m


class ChainBlocks:
    """A system matrix of a chain whose row group k (r rows) couples only the column groups
    k - 1, k, k + 1 (c columns each), stored as one dense block row per group so that y = A x is
    a single batched product over overlapping windows of x (no per-step assembly)."""

    def __init__(self, A: sp.csr_matrix, r: int, c: int, n_groups: int):
        dense = np.zeros((n_groups * r, n_groups * c))
        dense[:A.shape[0], :A.shape[1]] = A.toarray()
        self.blocks = np.zeros((n_groups, r, 3 * c))
        padded = np.zeros((n_groups * r, (n_groups + 2) * c))
        padded[:, c:-c] = dense
        for k in range(n_groups):
            self.blocks[k] = padded[k * r:(k + 1) * r, k * c:(k + 3) * c]
        if not np.isclose(np.abs(self.blocks).sum(), np.abs(dense).sum(), rtol=1e-12, atol=0):
            raise ValueError("matrix couples groups that are not neighbours")
        # trailing columns that no block uses (e.g. the pairs of node k + 1 with node k + 2)
        used = np.nonzero(np.any(self.blocks != 0.0, axis=(0, 1)))[0]
        width = int(used[-1]) + 1 if used.size else 1
        self.blocks = np.ascontiguousarray(self.blocks[:, :, :width])
        self.shape, self.c, self.n_groups = A.shape, c, n_groups
        self.xpad = np.zeros((n_groups + 2) * c)
        self.windows = as_strided(self.xpad, shape=(n_groups, width, 1),
                                  strides=(c * 8, 8, 8), writeable=False)

    def matvec(self, x: np.ndarray, y: np.ndarray) -> None:
        """y = A x (y of length n_groups r, overwritten)."""
        self.xpad[self.c:self.c + x.size] = x
        np.matmul(self.blocks, self.windows, out=y.reshape(self.n_groups, -1, 1))


class GramChain:
    """Nonlinear elastic force of a chain of two-node elements from the invariant tensors.

    T1e: (n_el, 2 dpn, ms, ms), T4e: (n_el, ms, ms, ms, ms) with ms = 2 spn slots per element;
    emap, esign: (ms, nc) element coordinate index and sign of slot s, component i (B = R u_e).
    """

    def __init__(self, T1e: np.ndarray, T4e: np.ndarray, dpn: int, spn: int,
                 emap: np.ndarray, esign: np.ndarray, *, system: bool = True):
        self.n_el = T1e.shape[0]
        self.dpn, self.spn = dpn, spn
        self.ms, self.nc = emap.shape
        self.ne = 2 * dpn
        n_nodes = self.n_el + 1
        self.n_dof, self.n_slots = dpn * n_nodes, spn * n_nodes
        # symmetrise (round-off) so that the formulas may use T1[k,p,q] = T1[k,q,p] etc.
        self.T1e = 0.5 * (T1e + T1e.transpose(0, 1, 3, 2))
        T4 = 0.5 * (T4e + T4e.transpose(0, 2, 1, 3, 4))
        T4 = 0.5 * (T4 + T4.transpose(0, 1, 2, 4, 3))
        self.T4e = 0.5 * (T4 + T4.transpose(0, 3, 4, 1, 2))
        self.emap, self.esign = np.asarray(emap), np.asarray(esign, float)
        R = np.zeros((self.ms * self.nc, self.ne))
        R[np.arange(self.ms * self.nc), self.emap.ravel()] = self.esign.ravel()
        self.R = R                                           # element: vec(B) = R u_e
        # the slot matrix is a plain reshape of u when every coordinate is one slot component
        self.identity_slots = (dpn == spn * self.nc and np.array_equal(
            self.emap.ravel(), np.arange(self.ms * self.nc)) and np.all(self.esign == 1))
        # the system matrices only serve the ``system`` route (half of ANCF's build time): built
        # here when asked for, else on the first system evaluation (checks, not the time loop)
        self.K1h = None
        if system:
            self._build_system()
        self._alloc_element()

    # ------------------------------------------------------------------ system invariant route
    def prepare_system(self) -> None:
        """Build the system invariant matrices now if not yet built (before a time loop's clock;
        a steady state or modes analysis uses the element route and never needs them)."""
        if self.K1h is None:
            self._build_system()

    def _build_system(self) -> None:
        ms, spn, dpn = self.ms, self.spn, self.dpn
        n_nodes = self.n_el + 1
        # pairs of slots sharing an element, grouped by node: group k = the pairs within node k,
        # then the pairs (node k, node k + 1); element e's pairs are then contiguous and every
        # system matrix below couples only neighbouring groups
        index: dict[tuple[int, int], int] = {}
        for k in range(n_nodes):
            for s in range(spn):
                for t in range(s, spn):
                    index[(spn * k + s, spn * k + t)] = len(index)
            if k < self.n_el:
                for s in range(spn):
                    for t in range(spn):
                        index[(spn * k + s, spn * (k + 1) + t)] = len(index)
        self.group = spn * (spn + 1) // 2 + spn * spn
        epairs = np.zeros((self.n_el, ms, ms), dtype=np.int64)
        for e in range(self.n_el):
            for s in range(ms):
                for t in range(s, ms):
                    epairs[e, s, t] = epairs[e, t, s] = index[(spn * e + s, spn * e + t)]
        pairs = np.array(list(index), dtype=np.int64)
        self.n_pairs = len(pairs)
        n_pad = self.group * n_nodes
        self.I, self.J = pairs[:, 0].copy(), pairs[:, 1].copy()
        iu, ju = np.triu_indices(ms)
        off = iu != ju
        r1, c1, v1, r2, c2, v2, r4, c4, v4 = ([] for _ in range(9))
        for e in range(self.n_el):
            T1, T4 = self.T1e[e], self.T4e[e]
            gdof = dpn * e + np.arange(self.ne)
            pe = epairs[e, iu, ju]
            w1 = T1[:, iu, ju] * np.where(off, 2.0, 1.0)            # sum over ordered pairs
            r1.append(np.repeat(gdof, len(pe))), c1.append(np.tile(pe, self.ne))
            v1.append(0.5 * w1.ravel())
            r2.append(np.repeat(pe, self.ne)), c2.append(np.tile(gdof, len(pe)))
            v2.append(T1[:, iu, ju].T.ravel())
            w4 = T4[iu, ju][:, iu, ju] * np.where(off, 2.0, 1.0)[None, :]
            r4.append(np.repeat(pe, len(pe))), c4.append(np.tile(pe, len(pe)))
            v4.append(0.5 * w4.ravel())
        cat = np.concatenate
        K1h = _csr(cat(r1), cat(c1), cat(v1), (self.n_dof, n_pad))       # K_N1 = T1 / 2
        K2 = _csr(cat(r2), cat(c2), cat(v2), (n_pad, self.n_dof))        # K_N2 = T1^T
        K3h = _csr(cat(r4), cat(c4), cat(v4), (n_pad, n_pad))            # K_N3 = T4 / 2
        self.K1h = ChainBlocks(K1h, dpn, self.group, n_nodes)
        self.K2 = ChainBlocks(K2, self.group, dpn, n_nodes)
        self.K3h = ChainBlocks(K3h, self.group, self.group, n_nodes)
        # symmetric slot matrix S (both triangles) whose entries are read from the pair vector
        rows = np.concatenate([self.I, self.J[self.I != self.J]])
        cols = np.concatenate([self.J, self.I[self.I != self.J]])
        tag = np.concatenate([np.arange(self.n_pairs), np.nonzero(self.I != self.J)[0]])
        smat = sp.coo_matrix((tag.astype(float) + 1.0, (rows, cols)),
                             shape=(self.n_slots, self.n_slots)).tocsr()
        smat.sort_indices()
        smap = smat.data.astype(np.int64) - 1
        smat.data = np.zeros_like(smat.data)
        self.S = SparseAdd(smat, self.nc)     # S (x) I_nc acting on the (slot, component) field
        self.smap = smap[self.S.source]       # pair-vector entry behind each stored value
        # global slot map (slot, component) -> coordinate, with sign
        node = np.arange(self.n_slots) // spn
        local = np.arange(self.n_slots) % spn
        self.gmap = (dpn * node[:, None] + self.emap[local]).ravel()
        self.gsign = self.esign[local].ravel()
        Rt = np.zeros((self.n_dof, self.n_slots * self.nc))
        Rt[self.gmap, np.arange(self.n_slots * self.nc)] = self.gsign
        self.Rt = Rt
        self.B = np.zeros((self.n_slots, self.nc))
        self.BI = np.zeros((self.n_pairs, self.nc))
        self.BJ = np.zeros((self.n_pairs, self.nc))
        self.p = np.zeros(n_pad)
        self.s = np.zeros(n_pad)
        self.s3 = np.zeros(n_pad)
        self.q1 = np.zeros(self.n_dof)
        self.SB = np.zeros((self.n_slots, self.nc))
        self.tmp = np.zeros(self.n_dof)

    def slots(self, u: np.ndarray) -> np.ndarray:
        """The slot matrix B = R u (a view of u when possible)."""
        if self.identity_slots:
            return u.reshape(self.n_slots, self.nc)
        np.take(u, self.gmap, out=self.B.reshape(-1), mode="clip")
        self.B.reshape(-1)[:] *= self.gsign
        return self.B

    def add_force_system(self, u: np.ndarray, out: np.ndarray) -> None:
        """out += K_N(u) u with the system invariant matrices (no element loop)."""
        if self.K1h is None:
            self._build_system()
        B = self.slots(u)
        np.take(B, self.I, axis=0, out=self.BI, mode="clip")
        np.take(B, self.J, axis=0, out=self.BJ, mode="clip")
        np.einsum("ij,ij->i", self.BI, self.BJ, out=self.p[:self.n_pairs])   # p = u_d u
        self.K2.matvec(u, self.s)                                # S1 on the pairs
        self.K3h.matvec(self.p, self.s3)                         # S4 / 2
        self.s += self.s3
        self.K1h.matvec(self.p, self.q1)                         # K_N1 u_d u
        out += self.q1
        np.take(self.s, self.smap, out=self.S.values, mode="clip")
        if self.identity_slots:
            self.S.add(B.reshape(-1), out.reshape(-1))
        else:
            self.SB.fill(0.0)
            self.S.add(B.reshape(-1), self.SB.reshape(-1))
            np.dot(self.Rt, self.SB.reshape(-1), out=self.tmp)
            out += self.tmp

    # ------------------------------------------------------------------ element invariant route
    def _alloc_element(self) -> None:
        n, ms, nc, ne = self.n_el, self.ms, self.nc, self.ne
        self.eB = np.zeros((n, ms, nc))
        self.eX = np.zeros((n, ne * ms, nc))
        self.eY = np.zeros((n, ms**3, nc))
        self.eC = np.zeros((n, ms, nc, ms, nc))
        self.eYB = np.zeros((n, ms * ms * nc, nc))
        self.eCR = np.zeros((n, ms * nc, ne))
        self.eK = np.zeros((n, ne, ne))
        self.eW = np.zeros((n, ne, ne))
        self.ef = np.zeros((n, ne))

    def element_views(self, u: np.ndarray) -> np.ndarray:
        """(n_el, 2 dpn) view of the element coordinate vectors of a chain (no copy)."""
        u = np.ascontiguousarray(u)
        return as_strided(u, shape=(self.n_el, self.ne), strides=(self.dpn * u.itemsize,
                                                                   u.itemsize), writeable=False)

    def element_stiffness(self, u: np.ndarray) -> np.ndarray:
        """K_Ne(u_e) of every element (n_el, 2 dpn, 2 dpn): the paper's
        K_N1e u_de + u_de^T K_N2e + u_de^T K_N3e u_de, computed component by component from the
        element invariant tensors (ref. [49])."""
        n, ms, nc, ne = self.n_el, self.ms, self.nc, self.ne
        ue = self.element_views(u)
        B = self.eB
        np.take(ue, self.emap.ravel(), axis=1, out=B.reshape(n, ms * nc), mode="clip")
        B *= self.esign
        # X[e, k, q, i] = sum_p T1[e, k, p, q] B[e, p, i]
        np.matmul(self.T1e.reshape(n, ne * ms, ms), B, out=self.eX)
        X = self.eX.reshape(n, ne, ms * nc)
        # K_N1e u_de (= X R / 2) and u_de^T K_N2e (= R^T X^T)
        np.matmul(X, self.R, out=self.eK)
        self.eK *= 0.5
        np.matmul(self.R.T, X.transpose(0, 2, 1), out=self.eW)
        self.eK += self.eW
        # u_de^T K_N3e u_de = R^T C R, C[(p,i),(s,j)] = 1/2 sum_qr T4[p,q,r,s] B[q,i] B[r,j]
        # (eC holds the sum without the 1/2)
        np.matmul(self.T4e.reshape(n, ms**3, ms), B, out=self.eY)      # Y[r,s,p,i]
        # C[p,i,s,j] = sum_r Y[r,s,p,i] B[r,j]: a batched product, then the axes in place (the
        # five-index einsum: 2.5-6x slower on 2-40 elements)
        np.matmul(self.eY.reshape(n, ms, ms * ms * nc).transpose(0, 2, 1), B, out=self.eYB)
        self.eC[...] = self.eYB.reshape(n, ms, ms, nc, nc).transpose(0, 2, 3, 1, 4)
        np.matmul(self.eC.reshape(n, ms * nc, ms * nc), self.R, out=self.eCR)
        np.matmul(self.R.T, self.eCR, out=self.eW)
        self.eW *= 0.5
        self.eK += self.eW
        return self.eK

    def add_force_element(self, u: np.ndarray, out: np.ndarray) -> None:
        """out += sum_e K_Ne(u_e) u_e: the nonlinear element stiffness matrices computed element by
        element, applied and assembled (K_L u stays a system product, as in the paper)."""
        K = self.element_stiffness(u)
        ue = self.element_views(u)
        np.matmul(K, ue[..., None], out=self.ef[..., None])
        nodes = out.reshape(-1, self.dpn)
        nodes[:-1] += self.ef[:, :self.dpn]
        nodes[1:] += self.ef[:, self.dpn:]

    # ------------------------------------------------------------------ tangent (outside the loop)
    def tangent(self, u: np.ndarray) -> np.ndarray:
        """Dense d(K_N(u) u)/du (n_dof x n_dof): the nonlinear part of the tangent stiffness,
        X R + R^T X^T + R^T (S1 x I) R + 2 R^T C R + 1/2 R^T (S4 x I) R per element."""
        n, ms, nc, ne = self.n_el, self.ms, self.nc, self.ne
        self.element_stiffness(u)              # fills eB, eX, eC for this u
        B = self.eB
        ue = self.element_views(u)
        X = self.eX.reshape(n, ne, ms * nc)
        C2 = self.eC.reshape(n, ms * nc, ms * nc)            # 2 C (not halved)
        S1 = ue[:, None, :] @ self.T1e.reshape(n, ne, ms * ms)           # (n, 1, ms ms)
        P = np.matmul(B, B.transpose(0, 2, 1))
        S4 = self.T4e.reshape(n, ms * ms, ms * ms) @ P.reshape(n, ms * ms, 1)
        S = (S1[:, 0, :] + 0.5 * S4[..., 0]).reshape(n, ms, ms)
        diag = np.zeros((n, ms, nc, ms, nc))                              # S x I (Kronecker)
        for i in range(nc):
            diag[:, :, i, :, i] = S
        inner = C2 + diag.reshape(n, ms * nc, ms * nc)
        Ke = X @ self.R + self.R.T @ X.transpose(0, 2, 1) + self.R.T @ inner @ self.R
        K = np.zeros((self.n_dof, self.n_dof))
        for e in range(n):
            sl = slice(self.dpn * e, self.dpn * e + ne)
            K[sl, sl] += Ke[e]
        return K

    def force(self, u: np.ndarray) -> np.ndarray:
        """K_N(u) u (allocating; for checks and Newton)."""
        out = np.zeros(self.n_dof)
        self.add_force_system(np.ascontiguousarray(u, dtype=float), out)
        return out
