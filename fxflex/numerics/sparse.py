"""The sparse products of the beam time loops, y += A x, in place and without allocating.

SciPy's public routes allocate: ``A @ x`` and ``A.dot(x)`` return a new array on every call (no
``out=``), which the time loop must not do (STYLE.md habit 4), and cost 1.3 to 2 times as much
here. PETSc's sequential AIJ product does accumulate in place (``MatMultAdd(A, x, y, y)``), through
public API only: :class:`SparseAdd` holds the CSR arrays as the matrix's own storage
(``MatCreateSeqAIJWithArrays`` borrows them, it does not copy) and the caller's arrays are placed
in two work vectors for the call (``VecPlaceArray`` / ``VecResetArray``). Its row loop sums in
CSR order as SciPy's does, y's entry first (SciPy adds it last: the sums agree to round-off,
checked in tests/numerics/test_sparse.py). Measured on ANCF's matrices (AMD EPYC, issue 12): K_L
with 10 elements (231 rows, 10782 entries) 8.6 us against 12.0 us for SciPy's compiled kernel,
the scalar mass times three interleaved vectors 3.1 against 3.8 us; with 80 elements 50 against
92 us. ANCF's whole default central-difference step: the same within the noise (127.7-132.0
against 125.9-128.8 us).

Matrices whose values change between products keep their pattern: :attr:`SparseAdd.values` is the
borrowed storage, written in place (e.g. ``np.take(s, m.source, out=m.values)``), and the next
product uses the new values. A product with k interleaved vectors (x, y row-major (n, k),
flattened) is the product with kron(A, I_k), whose entries :attr:`SparseAdd.source` maps to A's.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from petsc4py import PETSc

__all__ = ["SparseAdd"]


class SparseAdd:
    """y += A x for one sparse matrix A of fixed pattern (serial; one per rank under MPI).

    With ``k > 1``, x and y hold k interleaved vectors (row-major (n_cols, k) and (n_rows, k),
    flattened): y[:, j] += A x[:, j] for each j."""

    def __init__(self, matrix, k: int = 1):
        a = sp.csr_matrix(matrix)
        a.sort_indices()
        source = np.arange(a.nnz, dtype=np.int64)
        if k > 1:
            # kron(A, I_k): entry (i, j) of A becomes entries (i k + c, j k + c), c < k; the
            # tags (index + 1: no tag is a zero the product could drop) say which entry
            tagged = sp.csr_matrix((source + 1, a.indices, a.indptr), shape=a.shape)
            kron = sp.kron(tagged, sp.identity(k, dtype=np.int64, format="csr"), format="csr")
            kron.sort_indices()
            source = kron.data - 1
            indptr, indices, shape = kron.indptr, kron.indices, kron.shape
        else:
            indptr, indices, shape = a.indptr, a.indices, a.shape
        #: for each stored entry, the index of the entry of A's CSR data it copies
        self.source = source
        self._indptr = np.ascontiguousarray(indptr, dtype=PETSc.IntType)
        self._indices = np.ascontiguousarray(indices, dtype=PETSc.IntType)
        #: the matrix's values, in its CSR order: PETSc reads them from this array
        self.values = np.ascontiguousarray(a.data[source], dtype=PETSc.ScalarType)
        self._mat = PETSc.Mat().createAIJWithArrays(
            shape, (self._indptr, self._indices, self.values), comm=PETSc.COMM_SELF)
        self._mat.assemble()
        self._x = PETSc.Vec().createWithArray(np.zeros(shape[1]), comm=PETSc.COMM_SELF)
        self._y = PETSc.Vec().createWithArray(np.zeros(shape[0]), comm=PETSc.COMM_SELF)

    def add(self, x: np.ndarray, y: np.ndarray) -> None:
        """y += A x in place (x, y contiguous float64 of the product's sizes: PETSc would work
        on a silent copy of any other y)."""
        if not (y.flags.c_contiguous and y.dtype == np.float64):
            raise ValueError("SparseAdd.add: y must be a C-contiguous float64 array")
        self._x.placeArray(x)
        self._y.placeArray(y)
        try:
            self._mat.multAdd(self._x, self._y, self._y)
        finally:
            self._x.resetArray()
            self._y.resetArray()
