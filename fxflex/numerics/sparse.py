"""The sparse product of the beam time loops, y += A x, without allocating.

SciPy's public routes allocate: ``A @ x`` and ``A.dot(x)`` return a new array on every call (no
``out=``), which the time loop must not do (STYLE.md habit 4), and cost 1.3 to 2 times as much here. The
compiled kernel behind them, ``scipy.sparse._sparsetools``, accumulates into a given array; it is
the only private SciPy import in fxflex, kept behind this one function. petsc4py's
``Mat.multAdd`` is no faster once the loop's changing buffers are placed in its Vecs
(``placeArray``/``resetArray``: 12.9 against 12.8 us on ANCF's K_L, issue 12), would bring PETSc
into beam runs that need only NumPy and SciPy, and cannot follow GramChain's slot matrix, whose
values change every step, without assembling it or writing into PETSc's borrowed array. Should
SciPy move the kernel, this function is the one place to change.
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
