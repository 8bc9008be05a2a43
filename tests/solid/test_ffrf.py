"""FFRF (Sect. 2.1): inertia invariants against direct quadrature of Eq. 11 and Eq. 17, steady
state against the full-order linear equilibrium, transients (mean, divergence, step size, AB2
growth law), drive torque, damping models, command line and demo."""

import json
import os
import pathlib
import runpy
import subprocess
import sys

import numpy as np
import pytest
import ufl
from dolfinx import fem
from mpi4py import MPI

from fxflex.analysis.signals import growth_fit, hann_mean
from fxflex.solid.family import ReducedFamily
from fxflex.scene import load_scene
from fxflex.scene.kinematics import P3, S3, rotation_z
from fxflex.solid.small_strain import linear_steady
from fxflex.solid.reduction import inner, mat_apply
from fxflex.time import AB2, deviation_growth, diagnose, simulate

COMM = MPI.COMM_WORLD
ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


@pytest.fixture(scope="module")
def tiny():
    """10x2x2 mesh without external load: quadrature checks of the inertia terms."""
    return ReducedFamily(load_scene(overrides=["mesh.solid=[10,2,2]", "load.line_load=0"]),
                         COMM, count=10)


@pytest.fixture(scope="module")
def small():
    return ReducedFamily(load_scene(overrides=["mesh.solid=[20,4,2]"]), COMM)


@pytest.fixture(scope="module")
def paper():
    return ReducedFamily(load_scene(), COMM)


# -- the inertia terms against direct quadrature ---------------------------------------------------

class Quadrature:
    """Eq. 11 integrals at a deformation U = Phi eta by UFL quadrature on the deformed position
    X = X0 + U, independent of the invariants."""

    def __init__(self, form):
        self.form, self.model = form, form.model
        self.Phi = form.modes.vectors[:, : form.dof]
        self.U = fem.Function(self.model.V)
        self.X = self.model.X0 + self.U

    def set(self, eta):
        n = self.model.n_owned
        self.U.x.array[:n] = self.Phi @ eta
        self.U.x.scatter_forward()

    def scalar(self, integrand):
        m = self.model
        return m.comm.allreduce(fem.assemble_scalar(fem.form(m.rho * integrand * m.dx)))

    def projected(self, integrand):
        m = self.model
        b = m.vector(m.rho * integrand * m.dx).getArray(readonly=True)[: m.n_owned]
        return inner(m.comm, self.Phi, b)

    def m_phiphi(self, eta):
        """int rho X^T P X: the phi-phi entry of the mass matrix in (phi, eta)."""
        self.set(eta)
        return self.scalar(ufl.inner(ufl.dot(ufl.as_matrix(P3.tolist()), self.X), self.X))

    def m_phieta(self, eta):
        """int rho (S X)^T Phi: the phi-eta block."""
        self.set(eta)
        v = self.model.u_test
        return self.projected(ufl.inner(ufl.dot(ufl.as_matrix(S3.tolist()), self.X), v))


def test_mass_blocks_equal_direct_quadrature_of_eq11(tiny):
    """M_rr, M_rf, M_ff of Eq. 11 (q_r = (cos phi, sin phi)) at a random phi and deformation."""
    f = tiny.build("ffrf", "reduction.ffrf_modes=10")
    quad, inv = Quadrature(f), f.inv
    rng = np.random.default_rng(7)
    eta, phi = 0.05 * rng.standard_normal(10), 0.7
    quad.set(eta)
    A = ufl.as_matrix(rotation_z(phi).tolist())
    Gs = [ufl.as_matrix(P3.tolist()), ufl.as_matrix(S3.tolist())]
    v = f.model.u_test
    M_rr = np.array([[quad.scalar(ufl.inner(ufl.dot(Gi, quad.X), ufl.dot(Gj, quad.X)))
                      for Gj in Gs] for Gi in Gs])
    M_rf = np.array([quad.projected(ufl.inner(ufl.dot(Gi, quad.X), ufl.dot(A, v))) for Gi in Gs])
    Phi = quad.Phi
    M_ff = inner(COMM, Phi, mat_apply(f.data.M, Phi))
    K_ff = inner(COMM, Phi, mat_apply(f.data.K, Phi))
    # the same blocks from the invariants J0, n, N, g, G (docs/reduced.md)
    m = inv.J0 + 2 * inv.n @ eta + eta @ inv.N @ eta
    a, b = inv.n + inv.N @ eta, inv.g + inv.G @ eta
    c, s = np.cos(phi), np.sin(phi)
    # the same quadrature by two routes (direct UFL and the invariants): round-off relative to the
    # block's size, ~ n eps with n ~ 1e3 terms
    assert np.allclose(M_rr, m * np.eye(2), rtol=0, atol=1e-12 * m)
    ref = np.array([c * a - s * b, c * b + s * a])
    assert np.allclose(M_rf, ref, rtol=0, atol=1e-12 * np.abs(ref).max())
    assert np.allclose(M_ff, np.eye(10), rtol=0, atol=1e-12)
    assert np.allclose(K_ff, inv.Lambda, rtol=0, atol=1e-12 * f.modes.omega2[9])
    # Phi^T K Phi with M-orthonormal modes: off-diagonals are the modes' residuals and round-off,
    # bounded by the certified radii (tests/solid/conftest.py), below 1e-9 omega_10^2 on this mesh
    assert np.allclose(inv.Lambda, np.diag(f.modes.omega2[:10]), rtol=0,
                       atol=1e-9 * f.modes.omega2[9])


def test_quadratic_velocity_and_drive_torque_follow_from_kinetic_energy(tiny):
    """Eq. 17: Q_v = -M' q' + (dT/dq)^T with M(q) by quadrature and exact central differences
    (M is quadratic in eta). The eta rows of Lagrange's equations must give FFRF's acceleration,
    the phi row its drive torque, during a spin-up (phi'' != 0), undamped and unloaded."""
    f = tiny.build("ffrf", "reduction.ffrf_modes=10", "damping.c=0", "rotation.rpm=3000",
                   "rotation.profile=spin-up", "rotation.spinup_time=0.01")
    quad = Quadrature(f)
    rng = np.random.default_rng(3)
    eta, deta = 0.05 * rng.standard_normal(10), 30.0 * rng.standard_normal(10)
    t = 0.004
    _, w, a = f.drive.state(t)
    eps = 1.0                                  # central differences are exact on quadratics
    Mdot_eta = (quad.m_phieta(eta + eps * deta) - quad.m_phieta(eta - eps * deta)) / (2 * eps) * w
    Mdot_phi = ((quad.m_phiphi(eta + eps * deta) - quad.m_phiphi(eta - eps * deta)) * w
                + (quad.m_phieta(eta + eps * deta) - quad.m_phieta(eta - eps * deta)) @ deta
                ) / (2 * eps)
    dTdeta = np.empty(10)
    for k in range(10):
        e = np.zeros(10)
        e[k] = eps
        dTdeta[k] = (0.5 * w * w * (quad.m_phiphi(eta + e) - quad.m_phiphi(eta - e))
                     + w * (quad.m_phieta(eta + e) - quad.m_phieta(eta - e)) @ deta) / (2 * eps)
    Qv = -Mdot_eta + dTdeta                   # dT/dphi = 0: T does not depend on phi
    Lam = inner(COMM, quad.Phi, mat_apply(f.data.K, quad.Phi))
    m_pe = quad.m_phieta(eta)
    acc = np.empty(10)
    f.acceleration(t, eta, deta, acc)
    # eta rows: m_pe phi'' + eta'' = Q_v - Lambda eta
    # the same equations of motion by quadrature and by the invariants: round-off of the largest
    # terms
    assert np.allclose(acc, Qv - Lam @ eta - m_pe * a, rtol=0, atol=1e-10 * np.abs(acc).max())
    # phi row: tau = m_pp phi'' + m_pe . eta'' + (M' q')_phi
    tau = quad.m_phiphi(eta) * a + m_pe @ acc + Mdot_phi
    assert f.drive_torque(t, eta, deta) == pytest.approx(tau, rel=1e-10)


# -- steady state ----------------------------------------------------------------------------------

def _convergence_table(family, rpms, counts):
    rows = {}
    for rpm in rpms:
        ref = linear_steady(family.model, rpm * np.pi / 30).tip
        for m in counts:
            tip = family.build("ffrf", f"rotation.rpm={rpm}",
                               f"reduction.ffrf_modes={m}").steady_state().tip
            rows[rpm, m] = (ref, tip, np.abs(tip - ref) / np.abs(ref))
    if COMM.rank == 0:
        print("\nFFRF steady state vs full-order linear (K_L - Omega^2 M_P) U = F + Omega^2 f_c")
        print(f"{'rpm':>6} {'modes':>5} | {'long mm':>10} {'orth mm':>10} {'load mm':>10} | "
              f"relative difference long / orth / load")
        for (rpm, m), (ref, tip, rel) in rows.items():
            print(f"{rpm:6.0f} {m:5d} | {tip[0] * 1e3:10.6f} {tip[1] * 1e3:10.6f} "
                  f"{tip[2] * 1e3:10.6f} | {rel[0]:.2e} {rel[1]:.2e} {rel[2]:.2e}")
        for rpm in rpms:
            print(f"{rpm:6.0f} {'full':>5} | " + " ".join(f"{x * 1e3:10.6f}"
                                                          for x in rows[rpm, counts[0]][0]))
    return rows


def test_steady_state_approaches_full_order_linear(small):
    rows = _convergence_table(small, (1000.0, 5000.0), (10, 30))
    for rpm in (1000.0, 5000.0):
        assert np.all(rows[rpm, 30][2] <= 0.02)
        assert np.linalg.norm(rows[rpm, 30][2]) < np.linalg.norm(rows[rpm, 10][2])


@pytest.mark.paper
def test_steady_state_approaches_full_order_linear_default_mesh(paper):
    rows = _convergence_table(paper, (1000.0, 5000.0), (10, 30, 60))
    for rpm in (1000.0, 5000.0):
        assert np.all(rows[rpm, 30][2] <= 0.02)
        errs = [np.linalg.norm(rows[rpm, m][2]) for m in (10, 30, 60)]
        assert errs[2] < errs[1] < errs[0]


def test_relative_damping_does_not_move_the_steady_state_absolute_does(small):
    """Sect. 4.3: the absolute model's circulatory term (c/rho) Omega G shifts the convergent
    deflection in proportion to c (at 1000 rpm by about 1e-5 of the orthogonal one)."""
    tips = {(model, c): small.build("ffrf", f"damping.model={model}", f"damping.c={c}")
            .steady_state().tip for model in ("relative", "absolute") for c in (100.0, 1000.0)}
    base = tips["relative", 1000.0]
    assert np.array_equal(tips["relative", 100.0], base)
    shift = {c: tips["absolute", c] - base for c in (100.0, 1000.0)}
    if COMM.rank == 0:
        print(f"\nabsolute damping, 1000 rpm: shift / |steady| = {shift[1000.0] / np.abs(base)} "
              f"at c = 1000, {shift[100.0] / np.abs(base)} at c = 100")
    assert abs(shift[1000.0][1]) > 1e-6 * abs(base[1])
    assert np.allclose(shift[1000.0], 10 * shift[100.0], rtol=1e-3, atol=0)


@pytest.mark.parametrize("method, dt", [("ffrf", 1e-6), ("gcms", 0.3e-6)])
@pytest.mark.parametrize("model", ["relative", "absolute"])
def test_heavily_damped_transient_settles_on_the_steady_state(small, method, dt, model):
    """c/rho = 870 1/s (about critical for the lowest mode): after 30 ms the transient has
    settled, and on the steady state, circulatory term of the absolute model included."""
    f = small.build(method, f"damping.model={model}", "damping.c=6.83e6")
    res = simulate(f, "ab2", dt, 0.03)
    st = f.steady_state().tip
    assert res.diverged is None
    assert np.allclose(res.tip, st, rtol=1e-3, atol=0)


# -- transients ------------------------------------------------------------------------------------

def _mean_vs_steady(form, dt, t_end):
    res = simulate(form, "ab2", dt, t_end, sample_every=max(1, int(round(1e-5 / dt))),
                   keep_history=True)
    h = np.array(res.history)
    st = form.steady_state().tip
    mean = hann_mean(h[:, 0], h[:, 1:4])
    rel = np.abs(mean - st) / np.abs(st)
    if COMM.rank == 0:
        print(f"\n{form.method} {t_end * 1e3:.0f} ms at 1000 rpm: Hann-weighted mean / steady - 1 ="
              f" {rel}; plain mean: {np.abs(h[:, 1:4].mean(axis=0) - st) / np.abs(st)}; "
              f"peak / steady = {np.abs(h[:, 1:4]).max(axis=0) / np.abs(st)}")
    return res, rel


def test_transient_oscillates_about_the_steady_state(small):
    res, rel = _mean_vs_steady(small.build("ffrf"), 1e-6, 0.1)
    assert res.diverged is None and np.all(rel <= 0.02)


@pytest.mark.paper
def test_transient_oscillates_about_the_steady_state_default_mesh(paper):
    res, rel = _mean_vs_steady(paper.build("ffrf"), 0.5e-6, 0.12)
    assert res.diverged is None and np.all(rel <= 0.02)


@pytest.mark.parametrize("method, dt", [("ffrf", 0.5e-6), ("gcms", 0.3e-6)])
def test_bounded_at_1000_and_5000_rpm_divergent_at_10000(small, method, dt):
    """The paper's Omega3 divergence is physical: the measured growth of the deviation from the
    (unstable) equilibrium equals the eigenvalue of the linearised rotating system."""
    for rpm in (1000.0, 5000.0):
        f = small.build(method, f"rotation.rpm={rpm}")
        res = simulate(f, "ab2", dt, 0.02, sample_every=20, keep_history=True)
        h = np.array(res.history)
        st = f.steady_state().tip
        ratio = np.linalg.norm(h[:, 1:4] - st, axis=1).max() / np.linalg.norm(st)
        if COMM.rank == 0:
            print(f"\n{method} {rpm:.0f} rpm: max |deflection - steady| / |steady| = {ratio:.2f}"
                  f" over 20 ms")
        assert res.diverged is None and f.stable()
        assert ratio < 5
    f = small.build(method, "rotation.rpm=10000")
    res = simulate(f, "ab2", dt, 0.03, sample_every=20, keep_history=True, limit=100.0)
    measured, _ = deviation_growth(res.history, f.steady_state().tip)
    rate, _ = f.growth_rate()
    if COMM.rank == 0:
        print(f"\n{method} 10000 rpm: diverged at {res.diverged['time_s'] * 1e3:.2f} ms, measured "
              f"growth {measured:.2f} 1/s, eigenvalue {rate:.2f} 1/s")
    assert res.diverged is not None and not f.stable()
    assert measured == pytest.approx(rate, rel=2e-3)
    assert diagnose(f, "ab2", dt, res)["cause"] == "physical"


@pytest.mark.paper
def test_paper_step_sizes_agree_default_mesh(paper):
    """Fig. 5: FFRF-AB at 0.5 us and 0.25 us give the same deflections (to 0.1 % of the peak;
    measured 2e-4 longitudinal, the AB2 phase error of the axial mode, 3e-6 orthogonal)."""
    f = paper.build("ffrf")
    runs = [np.array(simulate(f, "ab2", dt, 0.005, sample_every=k, keep_history=True).history)
            for dt, k in ((0.5e-6, 2), (0.25e-6, 4))]
    assert np.array_equal(runs[0][:, 0].round(12), runs[1][:, 0].round(12))
    peak = np.abs(runs[1][:, 1:4]).max(axis=0)
    diff = np.abs(runs[0][:, 1:4] - runs[1][:, 1:4]).max(axis=0) / peak
    if COMM.rank == 0:
        print(f"\nFFRF-AB 0.5 us vs 0.25 us over 5 ms: max difference / peak = {diff}")
    assert np.all(diff < 1e-3)


@pytest.mark.parametrize("dt", [4e-6, 6e-6])
def test_ab2_growth_of_the_fastest_mode(small, dt):
    """Numerical divergence: the coordinate of the worst eigenvector grows by AB2's principal
    root, exactly; the small-step law w^4 h^3 / 4 of NOTES.md underestimates it at h w ~ 0.3-0.4."""
    import scipy.linalg as la

    f = small.build("ffrf")
    lin = f.linearise()
    M, C, K = lin.M, lin.C, lin.K
    n = f.dof
    lam, left = la.eig(np.block([[np.zeros((n, n)), np.eye(n)], [-K, -C]]), left=True,
                       right=False)
    predicted, wk = f.ab2_growth_rate(dt)
    k = int(np.argmin(np.abs(np.abs(lam) - wk)))
    q, v = f.initial_state()
    scheme = AB2()
    scheme.start(f, 0.0, dt, q, v)
    ts, amp = [], []
    for i in range(1, int(0.02 / dt)):
        scheme.step(f, i * dt, dt, q, v)
        ts.append((i + 1) * dt)
        amp.append(abs(left[:n, k].conj() @ q + left[n:, k].conj() @ v))
    ts, amp = np.array(ts), np.array(amp)
    late = ts > 0.01
    measured = growth_fit(ts[late], amp[late])
    law = wk**4 * dt**3 / 4
    if COMM.rank == 0:
        print(f"\nAB2 dt={dt * 1e6:.0f} us, w={wk:.4g} rad/s (h w = {dt * wk:.3f}): measured "
              f"{measured:.2f} 1/s, principal root {predicted:.2f} 1/s, w^4 h^3/4 = {law:.2f} 1/s")
    assert measured == pytest.approx(predicted, rel=1e-3)
    assert law < predicted < 2 * law


# -- drive torque ----------------------------------------------------------------------------------

def march(form, dt, t_end):
    """AB2 by hand, yielding (t, q, v) (the live arrays) after every step."""
    q, v = form.initial_state()
    scheme = AB2()
    scheme.start(form, 0.0, dt, q, v)
    yield dt, q, v
    for i in range(1, int(round(t_end / dt))):
        scheme.step(form, i * dt, dt, q, v)
        yield (i + 1) * dt, q, v


def work_and_energy(form, J0: float, t_end: float = 0.003) -> tuple[np.ndarray, np.ndarray]:
    """(work, energy) over an AB2 march at 0.2 us: int (tau - J0 phi'') phi' dt (trapezoidal) and
    T + V - J0 phi'^2 / 2, at every step."""
    t_, p_, e_ = [0.0], [0.0], [0.0]
    for t, q, v in march(form, 0.2e-6, t_end):
        _, w, a = form.drive.state(t)
        t_.append(t)
        p_.append((form.drive_torque(t, q, v) - J0 * a) * w)
        e_.append(form.kinetic_energy(t, q, v) - 0.5 * J0 * w * w + form.strain_energy(t, q))
    t_, p_, e_ = map(np.array, (t_, p_, e_))
    return np.concatenate([[0.0], np.cumsum(0.5 * (p_[1:] + p_[:-1]) * np.diff(t_))]), e_


@pytest.mark.parametrize("method", ["ffrf", "gcms"])
def test_drive_torque_does_the_work_of_the_deformation_energy(tiny, method):
    """Undamped, unloaded spin-up: the work of the torque beyond the rigid part,
    int (tau - J0 phi'') phi' dt, equals the energy T + V - J0 phi'^2 / 2 put into deformation."""
    f = tiny.build(method, "reduction.ffrf_modes=10", "reduction.gcms_modes=30", "damping.c=0",
                   "rotation.profile=spin-up", "rotation.spinup_time=0.003", "rotation.rpm=1000")
    work, e_ = work_and_energy(f, f.data.J0)
    if COMM.rank == 0:
        print(f"\n{method}: deformation energy at 3 ms {e_[-1]:.6e} J, drive work beyond the "
              f"rigid part {work[-1]:.6e} J, max deviation / max energy "
              f"{np.abs(work - e_).max() / np.abs(e_).max():.2e}")
    assert np.abs(e_).max() > 0
    assert np.abs(work - e_).max() <= 1e-4 * np.abs(e_).max()


# -- command line and demo -------------------------------------------------------------------------

def fxflex(*args, cwd=None):
    r = subprocess.run([sys.executable, "-m", "fxflex", *args, "--set", "mesh.solid=[20,4,2]"],
                       capture_output=True, text=True, cwd=cwd)
    assert r.returncode == 0, r.stderr
    return r


@pytest.mark.serial
@pytest.mark.parametrize("method", ["ffrf", "gcms"])
def test_cli_steady(small, method):
    d = json.loads(fxflex("steady", "--method", method, "--json").stdout)
    form = small.build(method)
    assert d["dof"] == form.dof and d["stable"] is True and d["converged"] is True
    tip = np.array([d["tip_mm"][k] for k in ("longitudinal", "orthogonal", "load")]) / 1e3
    # the same linear solve in another process; JSON carries every digit
    assert np.allclose(tip, form.steady_state().tip, rtol=1e-9, atol=0)


@pytest.mark.serial
def test_cli_run_writes_the_drive_torque_and_diagnoses_divergence(small, tmp_path):
    out = tmp_path / "gcms.csv"
    d = json.loads(fxflex("run", "--method", "gcms", "--t-end", "3e-4", "--out", str(out),
                          "--json").stdout)
    assert d["diverged"] is None and d["series"] == str(out) and d["integrator"] == "ab2"
    lines = out.read_text().splitlines()
    header = [ln for ln in lines if not ln.startswith("#")]
    assert header[0] == "t_s,longitudinal_m,orthogonal_m,load_m,drive_torque_Nm"
    last = np.array(header[-1].split(","), float)
    assert last[0] == pytest.approx(3e-4, rel=1e-3)
    f = small.build("gcms")
    res = simulate(f, "ab2", 0.3e-6, 3e-4)
    # the same AB2 run in another process; the CSV carries 12 significant digits
    assert np.allclose(last[1:4], res.tip, rtol=1e-9, atol=1e-15)
    d = json.loads(fxflex("run", "--method", "ffrf", "--rpm", "10000", "--t-end", "0.03",
                          "--json").stdout)
    assert d["diverged"]["cause"] == "physical" and d["diverged"]["time_s"] < 0.03


DEMOS = sorted((pathlib.Path(ROOT) / "demos").glob("ffrf_*.py"))


@pytest.mark.serial
@pytest.mark.parametrize("path", DEMOS, ids=[p.name for p in DEMOS])
def test_demo_runs(path, capsys):
    runpy.run_path(str(path), run_name="__main__")
    assert "load-direction steady deflection" in capsys.readouterr().out


def test_demos_found():
    assert DEMOS


@pytest.mark.parallel
@pytest.mark.parametrize("method", ["ffrf", "gcms"])
def test_field_writer_rebuilds_the_deflection(tiny, method, tmp_path):
    """--fields: the written U_hub at the tip centre is the reported deflection, u = A U_hub."""
    f = tiny.build(method, "reduction.ffrf_modes=10", "reduction.gcms_modes=30")
    q = np.random.default_rng(5).standard_normal(f.dof) * 1e-3
    path = tmp_path / "fields.xdmf" if COMM.size == 1 else \
        pathlib.Path(COMM.bcast(str(tmp_path) if COMM.rank == 0 else None)) / "fields.xdmf"
    w = f.field_writer(str(path))
    t = 0.0123
    w.write(t, q)
    w.close()
    m = f.model
    # the same modal sum on the nodes and at the probe: round-off
    assert np.allclose(m.tip_displacement(w.U.x.array), f.tip(t, q), rtol=1e-12, atol=1e-18)
    assert np.allclose(m.tip_displacement(w.u.x.array),
                       rotation_z(f.drive.angle(t)) @ f.tip(t, q), rtol=1e-12, atol=1e-18)
    assert path.exists() and path.with_suffix(".h5").exists()
