"""The iterative linear solver route (issue 14 item 6, docs/solvers.md) against the direct one.

TLF steady state: both routes stop on the same Newton test, so each leaves a residual R(u) whose
norm it reports; with J the tangent at the direct solution (symmetric positive definite at a
stable steady state), u_i - u_d = J^-1 (R(u_i) - R(u_d)) to first order, hence
||u_i - u_d|| <= (||R(u_i)|| + ||R(u_d)||) / lambda_min(J) -- a bound each side certifies by its
own residual, not one machine's digits (a factor 2 covers the second-order term, which is of the
size of the squared difference). Clamped modes: each eigenvalue of either route lies within its
certified radius of an exact one (tests/solid/conftest.py), so two of them differ by at most the
sum of the radii. Under ``mpirun -n 2`` the iterative route runs distributed and is compared with
the direct route on one process, each rank gathering the whole field in the node order of the
serial mesh (matched by coordinates), so that every rank asserts the same.
"""

import numpy as np
import pytest
import scipy.linalg as la
import ufl
from dolfinx import fem
from mpi4py import MPI

from fxflex.scene import Scene
from fxflex.solid import forms
from fxflex.solid.cms import clamped_modes
from fxflex.solid.model import SolidModel
from fxflex.solid.tlf_steady import tlf_steady

MESH = (16, 2, 2)


def _scene(**keys):
    return Scene().replace(**{"mesh.solid": MESH, **keys})


def _serial_order(model, local, serial_x0):
    """Rows (node-wise, ``local`` of shape (n_owned_nodes, k)) of a possibly distributed model,
    gathered on every rank and put in the node order of the serial mesh ``serial_x0``."""
    comm = model.comm
    x0 = np.vstack(comm.allgather(model.node_coordinates()))
    rows = np.vstack(comm.allgather(local))
    order = np.lexsort(np.round(x0, 9).T[::-1])
    target = np.lexsort(np.round(serial_x0, 9).T[::-1])
    out = np.empty_like(rows)
    out[target] = rows[order]
    assert np.allclose(x0[order], serial_x0[target], atol=1e-12)
    return out


def _lambda_min_tangent(model, u, omega, dense):
    """Smallest eigenvalue of the TLF steady tangent at u (serial model) on the free unknowns."""
    U = fem.Function(model.V)
    U.x.array[: u.size] = u
    U.x.scatter_forward()
    v, du = model.u_test, model.u_trial
    R = (forms.svk_residual(model.scene.material, U, v, model.dx)
         - omega**2 * forms.centrifugal(model.rho, model.X0 + U, v, model.dx))
    J = dense(model.matrix(model.compile(ufl.derivative(R, U, du))))
    clamped = np.concatenate([3 * model.root_nodes + i for i in range(3)])
    free = np.setdiff1d(np.arange(J.shape[0]), clamped)
    Jf = J[np.ix_(free, free)]
    assert np.allclose(Jf, Jf.T, rtol=0, atol=1e-9 * np.abs(Jf).max())
    return float(np.linalg.eigvalsh(0.5 * (Jf + Jf.T))[0])


@pytest.mark.parametrize("rpm", [1000.0, 5000.0])
def test_tlf_steady_iterative_equals_direct(rpm, eig):
    scene = _scene(**{"rotation.rpm": rpm})
    serial = SolidModel(scene, MPI.COMM_SELF)
    direct = tlf_steady(serial, linear="direct")
    model = SolidModel(scene, MPI.COMM_WORLD)
    iterative = tlf_steady(model, linear="iterative")
    assert direct.converged and iterative.converged
    assert iterative.extra["linear"] == "iterative" and iterative.extra["krylov_iterations"]
    x0 = serial.node_coordinates()
    u_i = _serial_order(model, iterative.q.reshape(-1, 3), x0).reshape(-1)
    u_d = direct.q
    lam = _lambda_min_tangent(serial, u_d, scene.rotation.omega, eig.dense)
    assert lam > 0
    bound = 2.0 * (direct.residuals[-1] + iterative.residuals[-1]) / lam
    diff = np.linalg.norm(u_i - u_d)
    assert diff <= bound, (diff, bound)
    # the bound is a small fraction of the deflection: the test can tell the routes apart
    assert bound < 1e-6 * np.linalg.norm(u_d)


def test_clamped_modes_iterative_equal_direct(eig):
    scene = _scene()
    serial = SolidModel(scene, MPI.COMM_SELF)
    count = 6
    direct = clamped_modes(serial, count, use_cache=False, linear="direct")
    model = SolidModel(scene, MPI.COMM_WORLD)
    iterative = clamped_modes(model, count, use_cache=False, linear="iterative")
    K, M, free = eig.free_pencil(serial)
    chol = la.cho_factor(M)
    x_i = _serial_order(model, iterative.vectors.reshape(-1, 3 * count),
                        serial.node_coordinates()).reshape(-1, count)
    r_d = eig.radii(serial, direct)
    r_i = np.array([eig.radius(K, M, chol, lam, x) for lam, x in zip(iterative.omega2,
                                                                       x_i[free].T)])
    gap = np.abs(iterative.omega2 - direct.omega2)
    assert np.all(gap <= r_d + r_i), (gap, r_d + r_i)
    # the radii are tight: far below the spacing of the modes
    assert np.all(r_d + r_i < 1e-6 * direct.omega2)
