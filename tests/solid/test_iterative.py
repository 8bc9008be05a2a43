"""The iterative linear solver route (issue 14 item 6, docs/solvers.md) against the direct one.

TLF steady state: both routes stop on the same Newton test, so each leaves a residual R(u) whose
norm it reports; with J the tangent at the direct solution (symmetric positive definite at a
stable steady state), u_i - u_d = J^-1 (R(u_i) - R(u_d)) to first order, hence
||u_i - u_d|| <= (||R(u_i)|| + ||R(u_d)||) / lambda_min(J) -- a bound each side certifies by its
own residual, not one machine's digits (a factor 2 covers the second-order term, which is of the
size of the squared difference). Clamped modes: each eigenvalue of either route lies within its
certified radius of an exact one (tests/solid/conftest.py), so two of them differ by at most the
sum of the radii. TLF's stability PEP (lambda^2 M + lambda C + K) x = 0: to first order a computed
pair (lambda, x) with residual r = P(lambda) x lies at -y^H r / y^H P'(lambda) x from an exact
root (y its left eigenvector, from the dense matrices); both routes solve the same matrices, so
their roots differ by at most the sum of these radii (twice, for the second-order term), y^H r
taken as computed plus the bound on its round-off (Higham's gamma_k, tests/solid/conftest.py).
(||y|| ||r|| instead would be 1e4 times looser: the residual's large entries sit where the low
modes' left vectors are small.) Under ``mpirun -n 2`` the iterative route runs distributed and
is compared with the direct route on one process (the PEP: both routes distributed, every rank
gathering the matrices and vectors), each rank gathering the whole field in the node order of the
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
from fxflex.formulation import BuildOptions
from fxflex.numerics.petsc import TOL
from fxflex.solid.cms import clamped_modes
from fxflex.solid.model import SolidModel
from fxflex.solid.rotating import tlf_matrices
from fxflex.solid.tlf import PEP_STABILITY_RTOL, STABILITY_PAIRS, TLF
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


def _pep_radius(M, C, K, lam, x, y, gamma):
    """(|y^H r| + |y|^T (r's round-off)) / |y^H P'(lambda) x|, r = P(lambda) x: how far the pair
    (lambda, x) lies from the root whose left eigenvector is y, to first order (module
    docstring)."""
    k = max(np.count_nonzero(A, axis=1).max() for A in (M, C, K)) + 2
    r = lam**2 * (M @ x) + lam * (C @ x) + K @ x
    slack = gamma(k) * (np.abs(K) @ np.abs(x) + abs(lam) * (np.abs(C) @ np.abs(x))
                        + abs(lam) ** 2 * (np.abs(M) @ np.abs(x)))
    return ((abs(np.vdot(y, r)) + np.abs(y) @ slack)
            / abs(np.vdot(y, (2.0 * lam * M + C) @ x)))


def _left_vector(M, C, K, lam):
    """The left eigenvector of the root nearest ``lam``: inverse iteration on P(lambda)^H."""
    PH = (lam**2 * M + lam * C + K).conj().T
    y = np.random.default_rng(0).standard_normal(K.shape[0]) + 0j
    for _ in range(3):
        y = np.linalg.solve(PH, y)
        y /= np.linalg.norm(y)
    return y


@pytest.mark.parametrize("rpm, damping", [(1000.0, "relative"), (5000.0, "relative"),
                                          (5000.0, "absolute")])
def test_tlf_stability_pep_iterative_equals_direct(rpm, damping, eig, gathered_dense):
    """The verdict's PEP about one steady state, its shift-and-invert by MUMPS and by GAMG + CG
    (GMRES for the absolute damping's non-symmetric K): the same roots within the radii each
    route's residuals certify, the same verdict."""
    scene = _scene(**{"rotation.rpm": rpm, "damping.model": damping})
    comm = MPI.COMM_WORLD
    model = SolidModel(scene, comm)
    st = tlf_steady(model, linear="direct")
    assert st.converged
    roots, vectors, verdicts = {}, {}, {}
    for route in ("direct", "iterative"):
        form = TLF(scene, comm, BuildOptions(linear=route), model=model)
        lin = form.linearise(st)
        assert lin.linear == route
        lam, X = lin.modes(STABILITY_PAIRS)
        verdicts[route] = lin.stable()
        roots[route] = lam
        vectors[route] = np.vstack(comm.allgather(X))
    args = (model, st.q, scene.rotation.omega, scene.damping.c / scene.material.rho,
            scene.damping.model == "absolute", form.mass_kind)
    M, C, K = (gathered_dense(A, comm) for A in tlf_matrices(*args))
    radii = {route: [] for route in roots}
    for j, lam_d in enumerate(roots["direct"]):
        y = _left_vector(M, C, K, lam_d)
        for route in roots:
            radii[route].append(_pep_radius(M, C, K, roots[route][j], vectors[route][:, j], y,
                                            eig.gamma))
    r_d, r_i = np.array(radii["direct"]), np.array(radii["iterative"])
    lam_d, lam_i = roots["direct"], roots["iterative"]
    bound = 2.0 * (r_d + r_i)
    gap = np.abs(lam_i - lam_d)
    assert np.all(gap <= bound), (gap, bound)
    # the bound resolves the frequencies to 1e-6 and the growth rates (damping: Re lambda about
    # -c / (2 rho)) to 1 %, and no root within it of the direct one could cross the verdict's
    # threshold (a root grows when Re lambda > PEP_STABILITY_RTOL max |lambda|)
    assert np.all(bound < 1e-6 * np.abs(lam_d)), (bound, lam_d)
    assert np.all(bound < 1e-2 * np.abs(lam_d.real)), (bound, lam_d.real)
    assert np.all(lam_d.real + bound < PEP_STABILITY_RTOL * np.abs(lam_d).max())
    # the inexact inverse leaves the eigenpairs' residuals at the PEP's tolerance: normwise
    # backward errors (||K|| + |lambda| ||C|| + |lambda|^2 ||M||) within TOL, as the direct ones
    norms = [np.linalg.norm(A, 2) for A in (K, C, M)]
    for lam, X in ((lam_d, vectors["direct"]), (lam_i, vectors["iterative"])):
        for mu, x in zip(lam, X.T):
            r = mu**2 * (M @ x) + mu * (C @ x) + K @ x
            scale = (norms[0] + abs(mu) * norms[1] + abs(mu) ** 2 * norms[2]) * np.linalg.norm(x)
            assert np.linalg.norm(r) <= TOL * scale, (np.linalg.norm(r) / scale, mu)
    assert verdicts["direct"] is True and verdicts["iterative"] is True


@pytest.mark.serial     # the CLI prints on rank 0 only
@pytest.mark.parametrize("command", ["steady", "modes"])
@pytest.mark.parametrize("route", ["direct", "iterative"])
def test_cli_verdict_without_factorisation(command, route, folder, monkeypatch, capsys):
    """``fxflex steady`` (``modes``) ``--method tlf --set solver.linear=iterative`` reports the
    verdict (and the modes), and no MUMPS factor is made on the way: every one goes through
    ``make_direct``, spied on here wherever it is imported. The direct route, which factorises,
    shows that the spy sees them."""
    import json

    import fxflex.numerics.petsc
    import fxflex.solid.solvers
    import fxflex.solid.tlf_frequency
    from fxflex.cli import main

    made = []
    for module in (fxflex.numerics.petsc, fxflex.solid.solvers, fxflex.solid.tlf_frequency):
        real = module.make_direct

        def spy(ksp, *args, real=real, **kwargs):
            made.append(ksp)
            return real(ksp, *args, **kwargs)

        monkeypatch.setattr(module, "make_direct", spy)
    assert main([command, "--method", "tlf", "--set", f"mesh.solid={list(MESH)}", "--set",
                 f"solver.linear={route}", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["stable"] is True
    if command == "steady":
        assert out["converged"] and out["linear"] == route
    else:
        assert len(out["frequencies_hz"]) == out["n"] > 0
    assert (len(made) == 0) == (route == "iterative"), made


def test_near_nullspace_needs_the_operator():
    """A SLEPc spectral transformation's KSP gets its operator only at set-up: a near-nullspace
    given to it before would sit on a placeholder matrix that GAMG never sees (the clamped
    modes' iterative route lost its rigid-body modes so), so make_iterative refuses it."""
    from petsc4py import PETSc

    from fxflex.numerics.petsc import make_iterative, rigid_body_modes

    model = SolidModel(_scene(), MPI.COMM_WORLD)
    ksp = PETSc.KSP().create(model.comm)
    with pytest.raises(ValueError, match="no operator"):
        make_iterative(ksp, nullspace=rigid_body_modes(model.V))
    ksp.destroy()
