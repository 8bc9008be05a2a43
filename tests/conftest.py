"""Shared test set-up: quiet JIT logs; MPI-marked tests need >= 2 ranks (the MPI suite)."""

import logging
import math

import numpy as np
import pytest

for _name in ("ffcx", "UFL", "ufl", "dolfinx"):
    logging.getLogger(_name).setLevel(logging.WARNING)

# PetscInitialize is collective on MPI_COMM_WORLD: done here, on every rank at once, it cannot
# fall inside a test's rank-0-only work (writing a mesh file) while the other rank waits in a
# barrier, which deadlocked tests/mesh/test_imported.py when it ran first under mpirun -n 2
from petsc4py import PETSc  # noqa: E402,F401


def pytest_collection_modifyitems(config, items):
    from mpi4py import MPI

    size = MPI.COMM_WORLD.size
    skip_mpi = pytest.mark.skip(reason="needs mpirun -n 2 (the MPI suite)")
    skip_serial = pytest.mark.skip(reason="serial-only test")
    for item in items:
        if "mpi" in item.keywords and size < 2:
            item.add_marker(skip_mpi)
        if "serial" in item.keywords and size > 1:
            item.add_marker(skip_serial)


@pytest.fixture
def folder(tmp_path, monkeypatch):
    """An empty fxflex cache folder of the test's own (FXFLEX_CACHE), not bypassed."""
    monkeypatch.setenv("FXFLEX_CACHE", str(tmp_path))
    monkeypatch.delenv("FXFLEX_NO_CACHE", raising=False)
    return tmp_path


EPS = np.finfo(float).eps


def _distributed_rtol(form, steady) -> float:
    """How far two equal solves of ``form``'s steady state may differ, relative to it: 0 where
    the solve is repeatable (one rank), otherwise the forward-error bound cond(K) eps of the
    distributed direct solve (MUMPS schedules its work across ranks dynamically, so its sums run
    in a different order from one run to the next), times 10 for the few Newton steps that
    carry it. cond(K) of the tangent about ``steady``, from the dense matrix (small meshes only).
    Collective."""
    if form.comm.size == 1:
        return 0.0
    lin = form.linearise(steady)
    try:
        dense = _gathered_dense(lin.K, form.comm)
    finally:
        lin.destroy()
    return 10.0 * np.linalg.cond(dense) * EPS


def _gathered_dense(K, comm) -> np.ndarray:
    """A distributed PETSc matrix as the whole dense array on every rank (small meshes only).
    Collective."""
    indptr, indices, data = K.getValuesCSR()
    first, last = K.getOwnershipRange()
    n = K.getSize()[0]
    local = np.zeros((last - first, n))
    for i in range(last - first):
        local[i, indices[indptr[i]:indptr[i + 1]]] = data[indptr[i]:indptr[i + 1]]
    return np.vstack(comm.allgather(local))


@pytest.fixture
def gathered_dense():
    """:func:`_gathered_dense`: a distributed PETSc matrix, dense on every rank."""
    return _gathered_dense


@pytest.fixture
def distributed_rtol():
    """:func:`_distributed_rtol`: the accuracy of a steady state solved on several ranks."""
    return _distributed_rtol


def tip_body_root(mu: float, j: float) -> float:
    """The lowest root bL of the Euler-Bernoulli cantilever with a tip mass mu = M_t / (rho A L)
    and rotary inertia j = J_t / (rho A L^3): 1 + cos cosh + mu bL (cos sinh - sin cosh)
    - j bL^3 (cosh sin + sinh cos) + mu j bL^4 (1 - cos cosh) = 0, the determinant of the
    clamp w = w_x = 0 and the tip conditions EI w_xx = J_t omega^2 w_x, EI w_xxx = -M_t omega^2 w
    (checked against that determinant when written)."""
    def f(x):
        c, s, ch, sh = math.cos(x), math.sin(x), math.cosh(x), math.sinh(x)
        return (1 + c * ch + mu * x * (c * sh - s * ch) - j * x**3 * (ch * s + sh * c)
                + mu * j * x**4 * (1 - c * ch))
    from scipy.optimize import brentq

    grid = np.linspace(0.05, 1.8752, 400)
    k = next(i for i in range(grid.size - 1) if f(grid[i]) * f(grid[i + 1]) < 0)
    return brentq(f, grid[k], grid[k + 1], xtol=1e-15)


def iteration_matrix_error(form, t1: float, t2: float = 0.002) -> float:
    """|S^-1 (dr/dx dx) - dx| / |dx| for generalized-alpha's iteration matrix S of ``form``
    (TLF or ANCF: hub-frame factors) made at t1 of its scene's run (step 10 us) and Newton's
    residual r(x) = M(q(x)) x - F(q(x), v(x)) at t2 by central differences, dt = 2 us, a
    random dx zero on the prescribed coordinates; the velocities are the rigid rotation's. The
    same value on every rank."""
    from mpi4py import MPI

    from fxflex.scene.kinematics import S3
    from fxflex.time import simulate
    from fxflex.time.generalized_alpha import DEFAULT_RHO_INF, parameters

    comm = form.comm
    states = {}
    simulate(form, "generalized-alpha", 1e-5, t2, sample_every=50,
             on_sample=lambda t, tip, ex, q: states.setdefault(round(t, 6), q.copy()))
    am, af, beta, gamma = parameters(DEFAULT_RHO_INF)
    h = 2e-6
    kappa = (1 - af) / (1 - am)
    cq, cv = h * h * beta * kappa, h * gamma * kappa
    origin = form.state_points().reshape(-1) if form.method == "tlf" else 0.0

    def rigid_rate(t, q):
        return form.drive.rate(t) * ((origin + q).reshape(-1, 3) @ S3.T).reshape(-1)

    def largest(x):
        return comm.allreduce(float(np.abs(x).max(initial=0.0)), op=MPI.MAX)

    q1, q2 = states[t1], states[t2]
    tangent = form.factorize(t1, q1, rigid_rate(t1, q1), 1.0, cv, cq)
    v2, a2 = rigid_rate(t2, q2), np.zeros_like(q2)
    form.acceleration(t2, q2, v2, a2)

    def residual(x):
        q, v = q2 + cq * x, v2 + cv * x
        form.constrain(t2, q, v)
        f, r = np.zeros_like(q), np.zeros_like(q)
        form.force(t2, q, v, f)
        form.mass_apply(x, r)
        return r - f

    dx = np.random.default_rng(5 + comm.rank).standard_normal(q2.size)
    probe = np.zeros_like(q2)
    form.mass_apply(np.ones_like(q2), probe)      # zero on the prescribed coordinates
    dx[probe == 0.0] = 0.0
    eps = 1e-3 * largest(a2) / largest(dx)
    fd = (residual(a2 + eps * dx) - residual(a2 - eps * dx)) / (2 * eps)
    y = np.zeros_like(q2)
    residual(a2)                                  # the state of the last force(): x = a2
    tangent.solve(t2, fd, y)
    return largest(y - dx) / largest(dx)
