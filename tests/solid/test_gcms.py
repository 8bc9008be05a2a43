"""GCMS (Sect. 2.2): global modes and their Gram cut, the nine-matrix stiffness against a direct
projection, the rotating-frame steady state, agreement with FFRF, and the same reduced model on
two ranks as on one."""

import numpy as np
import pytest
from mpi4py import MPI

from fxflex.solid.family import ReducedFamily
from fxflex.scene import load_scene
from fxflex.scene.kinematics import P3, S3, rotation_z
from fxflex.solid.ffrf import FFRF
from fxflex.solid.gcms import G3, GCMS
from fxflex.solid.small_strain import linear_steady
from fxflex.solid.reduction import inner, mat_apply, nodal
from fxflex.time import simulate

COMM = MPI.COMM_WORLD


@pytest.fixture(scope="module")
def small():
    return ReducedFamily(load_scene(overrides=["mesh.solid=[20,4,2]"]), COMM, count=30)


def global_basis(form):
    """Psi (n_owned, 90) and Psi~ = Psi T, built here from the clamped modes."""
    Phi = form.modes.vectors[:, :30]
    Psi = np.hstack([nodal(P3, Phi), nodal(S3, Phi), nodal(G3, Phi)])
    return Psi, Psi @ form.gm.T


def test_gram_matrix_blocks_pairs_and_orthonormal_basis(small):
    g, f = small.build("gcms"), small.build("ffrf")
    Psi, Psit = global_basis(g)
    W = inner(COMM, Psi, mat_apply(g.data.M, Psi))
    Z, I = np.zeros((30, 30)), np.eye(30)
    N, G = f.inv.N, f.inv.G
    # I - N: Phi^T M Phi = I holds to the eigensolver's 1e-12
    assert np.allclose(W, np.block([[N, G, Z], [-G, N, Z], [Z, Z, I - N]]), rtol=0, atol=1e-10)
    # the in-plane block is the real form of the Hermitian N - iG: every eigenvalue twice
    lam_h = np.linalg.eigvalsh(N - 1j * G)
    assert np.allclose(np.linalg.eigvalsh(W[:60, :60]), np.sort(np.repeat(lam_h, 2)), rtol=0,
                       atol=1e-12)
    assert np.allclose(np.sort(np.linalg.eigvalsh(W)), np.sort(g.gm.gram), rtol=0, atol=1e-12)
    assert g.dof == 90 and g.gm.gram.min() > 0
    assert np.allclose(inner(COMM, Psit, mat_apply(g.data.M, Psit)), np.eye(90), rtol=0,
                       atol=1e-9)


def test_nine_matrix_stiffness_is_the_rotated_projection(small):
    """K(phi) from the nine constant K_ij equals Psi~^T A_d K_L A_d^T Psi~ built directly."""
    g = small.build("gcms")
    _, Psit = global_basis(g)
    for phi in (0.0, 0.4, 2.9):
        Y = nodal(rotation_z(phi).T, Psit)
        direct = inner(COMM, Y, mat_apply(g.data.K, Y))
        K = g.stiffness(phi)
        # K(phi) from the nine constant matrices and directly: the same products in another order,
        # round-off
        assert np.allclose(K, direct, rtol=0, atol=1e-10 * np.abs(direct).max())


def test_retained_span_is_closed_under_rotation(small):
    """R(phi) = Psi~^T M A_d Psi~ is orthogonal and K(phi) = R K(0) R^T: the GCMS equations are
    the rotating-frame Galerkin equations on span(Psi~) in disguise."""
    for tol in (1e-6, 1e-3):
        g = small.build("gcms", f"reduction.gcms_gram_tol={tol}")
        R = g.rotation(1.1)
        eye = np.eye(g.dof)
        assert np.allclose(R.T @ R, eye, rtol=0, atol=1e-8)
        K0 = g.stiffness(0.0)
        assert np.allclose(R @ K0 @ R.T, g.stiffness(1.1), rtol=0, atol=1e-8 * np.abs(K0).max())
        assert np.allclose(g.gm.J @ g.gm.J, -g.gm.MP, rtol=0, atol=1e-8)


@pytest.mark.parametrize("rpm", [1000.0, 5000.0])
def test_steady_state_is_the_galerkin_equilibrium_on_the_global_span(small, rpm):
    g, f = small.build("gcms", f"rotation.rpm={rpm}"), small.build("ffrf", f"rotation.rpm={rpm}")
    _, Psit = global_basis(g)
    w = rpm * np.pi / 30
    KP = inner(COMM, Psit, mat_apply(g.data.K, Psit) - w * w * mat_apply(g.data.M,
                                                                          nodal(P3, Psit)))
    rhs = inner(COMM, Psit, g.data.F + w * w * g.data.f_c)
    zeta = np.linalg.solve(KP, rhs)
    st = g.steady_state()
    # two direct solves of the same 90 x 90 Galerkin system: each within n eps cond(KP) (1.3e6
    # here) of the exact solution, relative
    rtol = 2 * KP.shape[0] * np.finfo(float).eps * np.linalg.cond(KP)
    assert np.allclose(st.tip, g.gm.tip @ zeta, rtol=rtol, atol=0)
    # Galerkin on a larger space than FFRF's: closer to the full-order equilibrium in the energy
    # norm of K_L - Omega^2 M_P (positive definite at these speeds)
    full = linear_steady(g.model, w).q
    err = {"gcms": Psit @ st.q - full,
           "ffrf": f.modes.vectors[:, :30] @ f.steady_state().q - full}

    def energy(e):
        return inner(COMM, e, mat_apply(g.data.K, e[:, None])[:, 0]
                     - w * w * mat_apply(g.data.M, nodal(P3, e)[:, None])[:, 0])

    norms = {k: energy(e) for k, e in err.items()}
    if COMM.rank == 0:
        print(f"\n{rpm:.0f} rpm energy norm^2 of the error: GCMS {norms['gcms']:.3e}, "
              f"FFRF {norms['ffrf']:.3e}")
    assert 0 < norms["gcms"] <= norms["ffrf"]


def test_gram_cut_dependence(small):
    """The cut acts on relative M-norms: 1e-3 drops directions; what it drops carries stiffness
    that the clamped modes need, so the deflection moves (the study is in the bench)."""
    base = small.build("gcms")
    rows = []
    for tol in (1e-6, 1e-4, 3e-4, 1e-3):
        g = small.build("gcms", f"reduction.gcms_gram_tol={tol}")
        rows.append((tol, g.dof, g.omega_max(), g.steady_state().tip))
    if COMM.rank == 0:
        print("\ngcms_gram_tol  kept  w_max (rad/s)  steady tip (mm)")
        for tol, n, wmax, tip in rows:
            print(f"{tol:12.0e} {n:5d} {wmax:14.5g}  {np.round(tip * 1e3, 6)}")
    counts = [r[1] for r in rows]
    assert counts[0] == 90 and counts == sorted(counts, reverse=True) and counts[-1] < 90
    rel_norm = np.sqrt(base.gm.gram / base.gm.gram.max())
    assert counts == [int(np.sum(rel_norm >= tol)) for tol, *_ in rows]
    assert not np.allclose(rows[-1][3], rows[0][3], rtol=1e-3, atol=0)


def test_spin_up_matches_ffrf_in_the_rotating_frame(small):
    """phi(t) general: a 3 ms spin-up to 1000 rpm, deflections and drive torque."""
    over = ("rotation.profile=spin-up", "rotation.spinup_time=0.003")
    runs = {}
    for method in ("ffrf", "gcms"):
        res = simulate(small.build(method, *over), "ab2", 0.3e-6, 0.004, sample_every=10,
                       keep_history=True)
        runs[method] = np.array(res.history)
    a, b = runs["ffrf"], runs["gcms"]
    diff = np.abs(a[:, 1:] - b[:, 1:]).max(axis=0) / np.abs(a[:, 1:]).max(axis=0)
    if COMM.rank == 0:
        print(f"\nspin-up: max |FFRF - GCMS| / peak (long, orth, load, torque) = {diff}")
    assert np.all(diff < 5e-3)


@pytest.mark.paper
def test_ffrf_and_gcms_agree_over_5_ms_default_mesh():
    """Sect. 4.1 'almost the same': 1000 rpm, c3, paper steps (FFRF 0.5 us, GCMS 0.3 us),
    compared on the common 1.5 us grid in the rotating frame, within 0.5 % of the peak."""
    fam = ReducedFamily(load_scene(), COMM, count=30)
    g = fam.build("gcms")
    assert g.dof == 90                          # nothing falls under the default Gram cut
    a = np.array(simulate(fam.build("ffrf"), "ab2", 0.5e-6, 0.005, sample_every=3,
                          keep_history=True).history)
    b = np.array(simulate(g, "ab2", 0.3e-6, 0.005, sample_every=5, keep_history=True).history)
    common, ia, ib = np.intersect1d(a[:, 0].round(12), b[:, 0].round(12), return_indices=True)
    assert len(common) >= 3334                  # every 1.5 us from 0 to 5 ms
    a, b = a[ia], b[ib]
    diff = np.abs(a[:, 1:] - b[:, 1:]).max(axis=0) / np.abs(a[:, 1:]).max(axis=0)
    if COMM.rank == 0:
        print(f"\nFFRF vs GCMS, 5 ms at 1000 rpm: max difference / peak (long, orth, load, "
              f"torque) = {diff}")
    assert np.all(diff[:3] <= 0.005)


@pytest.mark.mpi
def test_reduced_models_on_two_ranks_equal_serial():
    """Distributed preprocessing, replicated reduced system: same numbers as a COMM_SELF build."""
    if MPI.COMM_WORLD.size < 2:
        pytest.skip("needs mpirun -n 2")
    s = load_scene(overrides=["mesh.solid=[20,4,2]"])
    par = [FFRF(s, COMM), GCMS(s, COMM)]
    ser = [FFRF(s, MPI.COMM_SELF), GCMS(s, MPI.COMM_SELF)]
    for p, q in zip(par, ser):
        assert p.comm is MPI.COMM_SELF and p.dof == q.dof
        assert np.allclose(p.steady_state().tip, q.steady_state().tip, rtol=1e-8, atol=0)
        assert np.allclose(np.sort(np.abs(p.eigenvalues())), np.sort(np.abs(q.eigenvalues())),
                           rtol=1e-8, atol=0)
    assert np.allclose(par[0].inv.G, ser[0].inv.G, rtol=0, atol=1e-8)
    lam = ser[0].inv.Lambda
    # modal stiffness matrices of two eigensolves (1 and 2 ranks): the diagonals omega^2 each to
    # its certified radius (tests/solid/conftest.py; relative to omega^2, largest for the lowest
    # mode), the off-diagonals residuals; 1e-12 of the largest is 2.5e-8 of the lowest here
    assert np.allclose(par[0].inv.Lambda, lam, rtol=0, atol=1e-12 * np.abs(lam).max())


@pytest.mark.serial
def test_bench_quick_runs(tmp_path):
    """``fxflex bench reduced --quick``: every study runs and the report is written."""
    import json
    import subprocess
    import sys

    r = subprocess.run([sys.executable, "-m", "fxflex", "bench", "reduced", "--quick", "--json",
                        "--out", str(tmp_path)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["quick"] is True and [s["method"] for s in d["speed"]] == ["ffrf", "gcms"]
    assert all(x["cause"] == "physical" for x in d["divergence"])
    assert max(d["ffrf_vs_gcms"]["max_diff_over_peak"][:3]) < 5e-3
    report = (tmp_path / "reduced" / "reduced.md").read_text()
    assert "Gram cut" in report and "step-size study" in report
