"""The sparse product of the beam time loops, y += A x, without allocating.

SciPy's public routes allocate: ``A @ x`` and ``A.dot(x)`` return a new array on every call (there
is no ``out=``), which the time loop must not do (STYLE.md habit 4). The compiled kernel behind
them, ``scipy.sparse._sparsetools``, accumulates into a given array, and is the only private SciPy
import in fxflex: kept here, behind one function, because no public route was as fast (petsc4py's
``Mat.multAdd`` on Vecs wrapping the same numpy buffers: figures in the issue-12 layering commit).
Should SciPy move it, this function is the one place to change.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse import _sparsetools

__all__ = ["csr_matvec_add"]


def csr_matvec_add(m: sp.csr_matrix, x: np.ndarray, y: np.ndarray, k: int = 1) -> None:
    """y += m x in place. With k > 1, x and y hold k interleaved vectors (row-major
    (n_cols, k) and (n_rows, k), flattened): y[:, j] += m x[:, j] for each j."""
    if k == 1:
        _sparsetools.csr_matvec(m.shape[0], m.shape[1], m.indptr, m.indices, m.data, x, y)
    else:
        _sparsetools.csr_matvecs(m.shape[0], m.shape[1], k, m.indptr, m.indices, m.data, x, y)
