"""numerics.sparse.SparseAdd: y += A x in place through PETSc's AIJ product (issue 12)."""

import numpy as np
import pytest
import scipy.sparse as sp

from fxflex.numerics.sparse import SparseAdd


def _matrix(rows=37, cols=29, seed=3):
    return sp.random(rows, cols, density=0.25, random_state=seed, format="csr")


def _bound(A, x, y0, k):
    """How far two evaluations of y_i + sum_j a_ij x_j may differ in any summation order: each is
    within gamma_n (sum |a_ij x_j| + |y_i|), gamma_n ~ n eps for the n = nnz(row) + 1 terms
    (Higham, Accuracy and Stability of Numerical Algorithms, 3.1), so twice that."""
    absx = np.abs(x).reshape(-1, k)
    terms = np.repeat(np.diff(A.indptr) + 1, k)
    return 2 * terms * np.finfo(float).eps * ((abs(A) @ absx).reshape(-1) + np.abs(y0))


@pytest.mark.parametrize("k", [1, 3])
def test_accumulates_like_the_product(k):
    A = _matrix()
    rng = np.random.default_rng(0)
    x, y = rng.standard_normal(A.shape[1] * k), rng.standard_normal(A.shape[0] * k)
    y0 = y.copy()
    SparseAdd(A, k).add(x, y)
    expected = y0 + (A @ x.reshape(-1, k)).reshape(-1)
    assert np.all(np.abs(y - expected) <= _bound(A, x, y0, k))
    assert not np.array_equal(y, y0)


@pytest.mark.parametrize("k", [1, 4])
def test_new_values_in_place_are_used(k):
    """Writing :attr:`values` through :attr:`source` changes the matrix, pattern kept (the
    ANCF invariant route's slot matrix, whose values change every step)."""
    A = _matrix(seed=5)
    product = SparseAdd(A, k)
    rng = np.random.default_rng(1)
    data = rng.standard_normal(A.nnz)
    np.take(data, product.source, out=product.values)
    B = sp.csr_matrix((data, A.indices, A.indptr), shape=A.shape)
    x, y = rng.standard_normal(A.shape[1] * k), np.zeros(A.shape[0] * k)
    product.add(x, y)
    expected = (B @ x.reshape(-1, k)).reshape(-1)
    assert np.all(np.abs(y - expected) <= _bound(B, x, np.zeros_like(y), k))


def test_refuses_an_output_it_would_copy():
    """PETSc would work on a copy of a strided y and the sum would be lost: refused."""
    A = _matrix()
    y = np.zeros((A.shape[0], 2))[:, 0]
    with pytest.raises(ValueError, match="C-contiguous float64"):
        SparseAdd(A).add(np.ones(A.shape[1]), y)
