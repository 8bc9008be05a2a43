"""TLF transients (Sect. 2.3, Eq. 25-35): internal force two ways, mass, damping, root
conditions, the transient against the steady state, CD stability and energy.

Coarse meshes only except the ``paper`` tier; every test runs on one rank (the two-rank check
is in test_tlf_mpi.py).
"""

import math
import pathlib

import numpy as np
import pytest
from dolfinx import fem
from mpi4py import MPI

from fxflex.formulation import BuildOptions, build
from fxflex.scene import load_scene
from fxflex.scene.kinematics import S3, rotation_z
from fxflex.solid import forms
from fxflex.solid.tlf_invariants import InvariantForce
from fxflex.solid.tlf import TLF, UflForce
from fxflex.time import diagnose, simulate
from fxflex.time.explicit import CentralDifference

COMM = MPI.COMM_WORLD
COARSE = "mesh.solid=[10,2,2]"


def tlf(*sets, force_eval="ufl", mass="lumped", hub_frame=True) -> TLF:
    scene = load_scene(overrides=[COARSE, *sets])
    return TLF(scene, COMM, BuildOptions(force_eval=force_eval, mass=mass, need_steady=False),
               hub_frame=hub_frame)


def rotation(axis, angle):
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


@pytest.fixture(scope="module")
def coarse():
    form = tlf("mesh.solid=[6,2,2]")
    model = form.model
    return model, UflForce(model), InvariantForce(model), model.V.tabulate_dof_coordinates()


# -- internal force ---------------------------------------------------------------------------------
@pytest.mark.parametrize("amplitude", [1e-5, 1e-2, 0.3])
def test_invariant_force_equals_ufl(coarse, amplitude):
    """Eq. 33-35 with the system invariant matrices = the assembled SVK residual, at random
    displacements up to 0.3 m on a 1 m beam (strains of order 10)."""
    model, ufl_force, inv_force, X = coarse
    u = amplitude * np.random.default_rng(7).standard_normal(X.size)
    f_ufl, f_inv = np.empty_like(u), np.empty_like(u)
    ufl_force.apply(u, f_ufl)
    inv_force.apply(u, f_inv)
    # the same polynomial of u by two routes (quadrature of the UFL form, invariant matrices): their
    # difference is round-off, ~ nnz-per-row eps x the largest term, 1e-10 leaving 1e4 for terms up
    # to strains of order 10
    assert np.linalg.norm(f_inv - f_ufl) <= 1e-10 * np.linalg.norm(f_ufl)


@pytest.mark.serial
def test_ufl_tangent_matches_finite_difference(coarse):
    """K_T du = d/de Q_k(u + e du). Q_k is cubic in u, so the central difference is
    D(e) = K_T du + e^2/6 Q'''[du, du, du] exactly and the Richardson value (4 D(e/2) - D(e)) / 3
    removes the error to round-off."""
    model, ufl_force, _, X = coarse
    form = tlf("mesh.solid=[6,2,2]")
    rng = np.random.default_rng(3)
    n = model.n_owned
    u = 1e-3 * rng.standard_normal(n)
    du = 1e-3 * rng.standard_normal(n)
    K = form.tangent(u)
    Kdu = K.createVecLeft()
    x = K.createVecRight()
    x.getArray()[:] = du
    K.mult(x, Kdu)
    ref = Kdu.getArray()[:n]

    def force(arr):
        loc = np.zeros(X.size)
        loc[:n] = arr
        out = np.empty_like(loc)
        ufl_force.apply(loc, out)
        return out[:n]

    def central(e):
        return (force(u + e * du) - force(u - e * du)) / (2 * e)

    e = 1.0
    richardson = (4 * central(e / 2) - central(e)) / 3
    assert np.linalg.norm(richardson - ref) <= 1e-9 * np.linalg.norm(ref)
    # and the plain difference has the expected O(e^2) error, so the test can see a wrong K_T
    assert np.linalg.norm(central(e) - ref) > 1e3 * np.linalg.norm(richardson - ref)


@pytest.mark.parametrize("route", ["ufl", "invariant"])
def test_rigid_rotation_gives_zero_force(coarse, route):
    """Green-Lagrange strain is invariant under rigid motion: u = (R - I) x0 with a 1.3 rad
    rotation about a skew axis gives Q_k = 0 to round-off, measured against the force the linear
    part alone would give, |K_L u|."""
    model, ufl_force, inv_force, X = coarse
    R = rotation([0.3, -1.0, 0.6], 1.3)
    u = (X @ R.T - X).reshape(-1)
    f = np.empty_like(u)
    (ufl_force if route == "ufl" else inv_force).apply(u, f)
    x, y = inv_force.KL.createVecs()
    x.getArray()[:] = u
    inv_force.KL.mult(x, y)
    linear = y.getArray()
    assert np.linalg.norm(linear) > 1e9
    assert np.linalg.norm(f) <= 1e-10 * np.linalg.norm(linear)


@pytest.mark.parametrize("route", ["ufl", "invariant"])
def test_hub_frame_evaluation_is_objective(route):
    """Q_k(A (x0 + U) - x0) = A Q_k(U) at a 0.8 rad hub angle, which TLF uses to evaluate the force
    on the small hub-frame displacement. U = A^T (x0 + u) - x0 is recovered from u with an absolute
    round-off of eps |x| ~ 2e-16 m, 2e-12 of |U| = 1e-4 m, so the force is exact to about that
    (bound 1e-10); the direct evaluation on u is printed for comparison."""
    form = tlf(force_eval=route)
    d = form.dynamics
    n = d.n
    x0 = d.x0l[:n].reshape(-1, 3)
    U = 1e-4 * np.sin(3 * x0 + 0.2)
    A = rotation_z(0.8)
    u = ((x0 + U) @ A.T - x0).reshape(-1)
    d.set_angle(1.0, 0.0)
    ref = (form.internal_force(U.reshape(-1)).reshape(-1, 3) @ A.T).reshape(-1)
    d.set_angle(math.cos(0.8), math.sin(0.8))
    hub = form.internal_force(u).copy()
    form.hub_frame = False
    direct = form.internal_force(u).copy()
    err = np.linalg.norm(hub - ref) / np.linalg.norm(ref)
    print(f"\n{route}: hub frame {err:.1e}, direct "
          f"{np.linalg.norm(direct - ref) / np.linalg.norm(ref):.1e}")
    assert err <= 1e-10


# -- mass, damping, root ---------------------------------------------------------------------------
def test_lumped_mass_sums_to_body_mass():
    form = tlf(mass="lumped")
    d = form.dynamics
    m = 1.0 / d.m_inv
    volume = COMM.allreduce(fem.assemble_scalar(fem.form(1.0 * form.model.dx)))
    total = COMM.allreduce(np.sum(m[0::3]))
    # row sums of the same quadrature as the volume: a sum of ~1e3 positive terms, round-off ~ n eps
    assert total == pytest.approx(form.scene.material.rho * volume, rel=1e-12)


def mass_times(form, a):
    """(M a) on the owned coordinates, M the mass the formulation uses, without constraints."""
    d = form.dynamics
    if d.mass == "lumped":
        return a / d.m_inv
    M = form.model.matrix(form.model.compile(form.model.mass_form()), bcs=[])
    x, y = M.createVecs()
    x.getArray()[:] = a
    M.mult(x, y)
    return y.getArray().copy()


@pytest.mark.parametrize("mass", ["lumped", "consistent"])
@pytest.mark.parametrize("model", ["relative", "absolute"])
def test_rigid_rotation_state_has_no_internal_or_damping_force(mass, model):
    """Body in rigid rotation, no load: Q_k = 0 and both damping models give Q_d = 0 (Eq. 34, 68),
    so (M u'')_free = 0 (with the consistent mass the free nodes next to the root are dragged by
    M_fr u_r''); the root gets the exact u_r'' = (phi'' S - phi'^2 P) A x0. Spin-up profile so
    that phi'' != 0."""
    form = tlf("load.line_load=0", "rotation.profile=\"spin-up\"", "rotation.spinup_time=0.01",
               f"damping.model=\"{model}\"", "damping.c=1e5", mass=mass)
    d = form.dynamics
    t = 0.004
    phi, dphi, ddphi = form.drive.state(t)
    A = rotation_z(phi)
    x0 = d.x0l[: d.n].reshape(-1, 3)
    q = (x0 @ A.T - x0).reshape(-1)
    v = (dphi * x0 @ (S3 @ A).T).reshape(-1)
    a = np.empty_like(q)
    form.acceleration(t, q, v, a)
    a_rigid = (x0 @ ((ddphi * S3 - dphi**2 * np.diag([1, 1, 0])) @ A).T).reshape(-1)
    free = np.setdiff1d(np.arange(d.n), d.root)
    def largest(x):                  # over every rank (a rank may own no root node)
        return COMM.allreduce(np.abs(x).max(initial=0.0), op=MPI.MAX)

    scale = largest(mass_times(form, a_rigid))
    # zero up to the round-off of the cancelling rigid-motion forces (~ eps x element forces x
    # cond(M) ~ 1e-13) and of the solve with M (direct; cond(M) ~ 1e2): 1e-9 leaves room for the
    # sums over ranks
    assert largest(mass_times(form, a)[free]) <= 1e-9 * scale
    assert largest(a[d.root] - a_rigid[d.root]) <= 1e-12 * largest(a_rigid)


@pytest.mark.parametrize("model", ["relative", "absolute"])
def test_damping_of_a_deformed_body_rotating_rigidly(model):
    """A fixed deformation U carried round by the hub: the relative model (Eq. 34) sees no
    deformation rate; the absolute one (Eq. 68) damps the velocity phi' S A U of the deformation:
    the accelerations of the two runs differ by exactly -(c / rho) phi' S A U on free nodes."""
    c = 1e5
    forms_ = {m: tlf("load.line_load=0", f"damping.model=\"{m}\"", f"damping.c={c}")
              for m in ("relative", "absolute")}
    nodamp = tlf("load.line_load=0", "damping.c=0")
    d = nodamp.dynamics
    x0 = d.x0l[: d.n].reshape(-1, 3)
    U = 1e-4 * x0[:, [0]] ** 2 * np.array([0.2, 0.5, 1.0])
    t = 0.002
    phi, dphi = nodamp.drive.angle(t), nodamp.drive.rate(t)
    A = rotation_z(phi)
    q = ((x0 + U) @ A.T - x0).reshape(-1)
    v = (dphi * (x0 + U) @ (S3 @ A).T).reshape(-1)
    base, a = np.empty_like(q), np.empty_like(q)
    nodamp.acceleration(t, q.copy(), v.copy(), base)
    forms_[model].acceleration(t, q.copy(), v.copy(), a)
    free = np.setdiff1d(np.arange(d.n), d.root)
    expected = 0.0 if model == "relative" else \
        -(c / 7850.0) * dphi * (U @ (S3 @ A).T).reshape(-1)[free]
    scale = (c / 7850.0) * dphi * np.abs(U).max()
    assert np.abs(a[free] - base[free] - expected).max() <= 1e-6 * scale


def test_initial_state_and_constraint():
    form = tlf("rotation.rpm=1000")
    d = form.dynamics
    q, v = form.initial_state()
    x0 = d.x0l[: d.n].reshape(-1, 3)
    omega = form.scene.rotation.omega
    assert np.all(q == 0.0)
    # closed forms evaluated on the same coordinates (|x| <= 1.2 m, omega ~ 1e2): round-off ~ 1e-14
    np.testing.assert_allclose(v.reshape(-1, 3), omega * x0 @ S3.T, atol=1e-14)
    t = 0.003
    form.constrain(t, q, v)
    A = rotation_z(form.drive.angle(t))
    r = d.root
    np.testing.assert_allclose(q[r], (x0 @ A.T - x0).reshape(-1)[r], atol=1e-15)
    np.testing.assert_allclose(v[r], (omega * x0 @ (S3 @ A).T).reshape(-1)[r], atol=1e-12)
    spin = tlf("rotation.profile=\"spin-up\"", "rotation.spinup_time=0.01")
    assert np.all(spin.initial_state()[1] == 0.0)


# -- the transient against the steady state ---------------------------------------------------------
def hann_mean(history, t0, t1):
    h = np.asarray(history)
    t = h[:, 0]
    w = (t >= t0) & (t <= t1)
    weight = np.sin(np.pi * (t[w] - t0) / (t1 - t0)) ** 2
    return (h[w, 1:4] * weight[:, None]).sum(0) / weight.sum()


@pytest.fixture(scope="module")
def transients():
    """1000 rpm, c3, [10,2,2]: 0.12 s with each mass at the same step, 1.7 us (2 / w_max: lumped
    3.6 us, consistent 1.9 us); 7 s (lumped) and 17 s (consistent). The flap and lag modes keep
    their full amplitude (c / rho = 0.13 1/s), so the mean is taken with a Hann window over
    0.02-0.12 s, whose leakage from a mode at f is about 1 / (pi f T (f T)^2) ~ 1e-4 of its
    amplitude at f T ~ 7. On [20,4,2] (not run here, 3 us, 15 s) the same check gives orthogonal
    and load within 0.1 % and longitudinal 1.1 % low: the mean foreshortening of the ~2 mm flap
    oscillation, which the steady state does not have (with c = 2e6 the transient settles within
    0.2 % of it)."""
    out = {}
    for mass in ("lumped", "consistent"):
        form = tlf(mass=mass)
        res = simulate(form, "cd", 1.7e-6, 0.12, sample_every=10, keep_history=True)
        assert res.diverged is None
        out[mass] = (form, np.array(res.history))
    out["steady"] = out["lumped"][0].steady_state().tip
    return out


@pytest.mark.parametrize("mass", ["lumped", "consistent"])
def test_transient_oscillates_about_steady_state(transients, mass):
    """The window mean of the 1000 rpm transient = the TLF steady state of the same mesh within
    2 % per component. Measured: lumped +0.2 / -0.02 / -0.004 %, consistent -0.45 / +0.04 /
    +0.03 % (longitudinal / orthogonal / load)."""
    mean = hann_mean(transients[mass][1], 0.02, 0.12)
    steady = transients["steady"]
    rel = np.abs(mean - steady) / np.abs(steady)
    print(f"\n{mass}: mean {mean * 1e3} mm, steady {steady * 1e3} mm, rel {rel}")
    assert np.all(rel <= 0.02), (mean, steady)


def test_consistent_and_lumped_mass_agree(transients):
    """Window means of the two masses within 1 % of each other (measured 0.65 % longitudinal,
    0.06 % orthogonal, 0.03 % load); the trajectories themselves drift apart in phase (the lumped
    mass lowers the frequencies), printed for the first 5 ms."""
    a = hann_mean(transients["lumped"][1], 0.02, 0.12)
    b = hann_mean(transients["consistent"][1], 0.02, 0.12)
    ha, hb = transients["lumped"][1], transients["consistent"][1]
    early = ha[:, 0] <= 0.005
    traj = np.abs(ha[early, 1:4] - hb[early, 1:4]).max(0) / np.abs(hb[early, 1:4]).max(0)
    rel = np.abs(a - b) / np.abs(b)
    print(f"\nlumped vs consistent: window means differ by {rel}; first 5 ms trajectories by "
          f"{traj} of their peak")
    assert np.all(rel <= 0.01)


def test_damped_transient_with_rotating_tip_force_settles_on_steady_state():
    """A 300 N tip force along the rotating Y axis (it turns with the hub: A(phi) F in o-xyz) and
    heavy relative damping, c = 2e6 (decay rate c / 2 rho = 127 1/s): by 40-60 ms the oscillation
    is down to e^-5 ~ 0.6 % of its start, at most the static deflection, and the Hann mean over that
    window must equal the steady state (which has the same force in O-XYZ) within 0.5 %. Measured:
    1e-6 / 8e-5 / 7e-5 (relative) with the consistent mass. With the lumped mass the transient settles on a
    slightly different equilibrium, +0.6 % longitudinal on this mesh: the steady state's
    centrifugal load int rho P (X0 + U) . v is the consistent one, the lumped inertia is not.
    A force that stayed fixed in o-xyz would have turned 6 rad away by then."""
    form = tlf("damping.c=2e6", "load.tip_force=[0.0, 300.0, 0.0]", mass="consistent")
    res = simulate(form, "cd", 1.7e-6, 0.06, sample_every=10, keep_history=True)
    mean = hann_mean(res.history, 0.04, 0.06)
    steady = form.steady_state().tip
    without = tlf("damping.c=2e6", mass="consistent").steady_state().tip
    assert abs(steady[1] - without[1]) > 0.3 * abs(without[1])     # the force matters
    assert np.all(np.abs(mean - steady) <= 0.005 * np.abs(steady)), (mean, steady)


# -- stability of central difference ----------------------------------------------------------------
def cd_stable(form, dt, steps=1000):
    """True when CD runs ``steps`` steps without growth: the initial state gets a 1e-6 m/s random
    velocity so that every mode, the highest included, starts from a finite level."""
    q, v = form.initial_state()
    v += 1e-6 * np.random.default_rng(0).standard_normal(v.size)
    with np.errstate(all="ignore"):          # a divergent trial overflows before it is caught
        res = simulate(form, "cd", dt, steps * dt, sample_every=10, limit=0.01, state=(q, v))
    return res.diverged is None


@pytest.mark.parametrize("mass", ["lumped", "consistent"])
def test_cd_critical_step_matches_two_over_omega_max(mass):
    """Bisection of the CD step between stable and divergent until the bracket is 5 % wide; its
    centre within 10 % of 2 / w_max (SLEPc, same mass)."""
    form = tlf(mass=mass)
    bound = 2.0 / form.omega_max()
    lo, hi = 0.5 * bound, 2.0 * bound
    assert cd_stable(form, lo) and not cd_stable(form, hi)
    while hi / lo > 1.05:
        mid = math.sqrt(lo * hi)
        lo, hi = (mid, hi) if cd_stable(form, mid) else (lo, mid)
    critical = math.sqrt(lo * hi)
    print(f"\n{mass}: bisection {critical * 1e6:.4f} us, 2/w_max {bound * 1e6:.4f} us")
    assert abs(critical / bound - 1) <= 0.10


def test_divergence_is_diagnosed_as_numerical():
    form = tlf()
    dt = 1.3 * 2.0 / form.omega_max()
    with np.errstate(all="ignore"):
        res = simulate(form, "cd", dt, 2000 * dt, sample_every=10)
    assert res.diverged is not None
    out = diagnose(form, "cd", dt, res)
    assert out["cause"] == "numerical" and "2/w_max" in out["detail"]


@pytest.mark.paper
@pytest.mark.parametrize("mass", ["lumped", "consistent"])
def test_paper_step_is_stable_on_default_mesh(mass):
    """The paper's 0.5 us: below 2 / w_max on the 100 x 12 x 6 mesh, and 400 steps stay bounded
    (a mode above the limit would grow by 1.09 per step or more at w h = 2.0004, 1e15 by then).
    Measured 2 / w_max: lumped 1.14 us, consistent 0.55 us."""
    scene = load_scene()
    form = TLF(scene, COMM, BuildOptions(mass=mass, need_steady=False))
    assert 0.5e-6 * form.omega_max() < 2.0
    res = simulate(form, "cd", 0.5e-6, 400 * 0.5e-6, sample_every=100)
    assert res.diverged is None


# -- energy ----------------------------------------------------------------------------------------
@pytest.mark.serial
def test_cd_energy_stays_within_the_derived_bound():
    """No load, damping or rotation; an initial velocity field. For a linear system leapfrog
    conserves H = E_n - h^2/8 |f_n|^2_{M^-1} exactly (E_n: kinetic energy at the synchronised
    velocity v_n = (v_{n-1/2} + v_{n+1/2}) / 2 plus strain energy, f_n the internal force), and
    per mode 0 <= E_n - H <= delta E_n with delta = (w_max h)^2 / 4, so over any number of steps

        1 - delta <= E_n / E_0 <= 1 / (1 - delta).

    The SVK force is linear to within the strain (~1e-3 here); the test checks this bound over
    1e4 steps at w_max h = 1.8 (delta = 0.81), and that H itself stays constant to delta times the
    largest strain, the size of the nonlinear correction."""
    form = tlf("rotation.rpm=0", "load.line_load=0", "damping.c=0")
    d = form.dynamics
    h = 0.9 * 2.0 / form.omega_max()
    delta = (form.omega_max() * h) ** 2 / 4
    m = 1.0 / d.m_inv
    minv = d.m_inv.copy()
    minv[d.root] = 0.0
    x0 = d.x0l[: d.n].reshape(-1, 3)
    q, v = form.initial_state()
    v[:] = np.column_stack([0 * x0[:, 0], 0.3 * x0[:, 0] ** 2, x0[:, 0] ** 2]).reshape(-1)
    u = fem.Function(form.model.V)
    W = fem.form(forms.svk_energy(form.scene.material, u, form.model.dx))
    cd = CentralDifference()
    cd.start(form, 0.0, h, q, v)
    E, H, strain = [], [], 0.0
    for k in range(10000):
        vs = cd.v_half - 0.5 * h * cd.a
        f = form.internal_force(q)
        u.x.array[: q.size] = q
        u.x.scatter_forward()
        e = 0.5 * np.sum(m * vs * vs) + fem.assemble_scalar(W)
        E.append(e)
        H.append(e - h * h / 8 * np.sum(f * f * minv))
        if k % 100 == 0:
            strain = max(strain, np.abs(np.diff(q.reshape(-1, 3), axis=0)).max() / 0.03)
        cd.step(form, (k + 1) * h, h, q, v)
    E, H = np.array(E), np.array(H)
    print(f"\ndelta {delta:.3f}: E/E0 in [{E.min() / E[0]:.3e}, {E.max() / E[0]:.3e}], "
          f"|H - H0|/H0 <= {np.abs(H / H[0] - 1).max():.2e}, strain ~ {strain:.1e}")
    assert E.min() / E[0] >= 1 - delta and E.max() / E[0] <= 1 / (1 - delta)
    assert np.abs(H / H[0] - 1).max() <= delta * strain


# -- integrators, outputs ---------------------------------------------------------------------------
def test_ab2_and_cd_agree():
    """Both generic integrators on the same problem: the tip history (every 5 us) up to 1 ms
    within 1 % of its peak."""
    tips = {}
    for integrator, dt, every in (("cd", 0.5e-6, 10), ("ab2", 0.1e-6, 50)):
        form = tlf()
        res = simulate(form, integrator, dt, 1e-3, sample_every=every, keep_history=True)
        tips[integrator] = np.array(res.history)[:, 1:4]
    diff = np.abs(tips["cd"] - tips["ab2"]).max(0)
    assert np.all(diff <= 0.01 * np.abs(tips["cd"]).max(0))


def test_field_writer_writes_every_call(tmp_path):
    form = tlf()
    # one file for every rank: the XDMF/HDF5 writer is collective, and each rank has its own
    # tmp_path (different names on the ranks left the collective open waiting)
    path = pathlib.Path(COMM.bcast(str(tmp_path), root=0)) / "u.xdmf"
    writer = form.field_writer(str(path))
    q, v = form.initial_state()
    for t in (0.0, 1e-4, 2e-4):
        form.constrain(t, q, v)
        writer.write(t, q)
    writer.close()
    text = path.read_text()
    assert text.count('Attribute Name="u"') == 3 and text.count('Attribute Name="U_hub"') == 3


def test_build_through_registry_and_memory_report():
    scene = load_scene(overrides=[COARSE])
    for fe in ("ufl", "invariant"):
        for mass in ("lumped", "consistent"):
            form = build("tlf", scene, COMM, BuildOptions(force_eval=fe, mass=mass,
                                                          need_steady=False))
            mem = form.memory_bytes()
            assert all(v > 0 for v in mem.values())
            assert (fe == "invariant") == ("force_K_N3" in mem)


@pytest.mark.parametrize("route,mass", [("ufl", "lumped"), ("invariant", "consistent")])
def test_time_loop_allocates_no_arrays(route, mass):
    """After the first step, CD steps allocate no array: tracemalloc (which sees numpy buffers)
    records a peak below one state vector (7.6 kB on [20,4,2]) over 50 steps, with a tip force
    and damping switched on."""
    import tracemalloc

    form = tlf("mesh.solid=[20,4,2]", "load.tip_force=[10.0, 20.0, 30.0]", force_eval=route,
               mass=mass)
    q, v = form.initial_state()
    cd = CentralDifference()
    cd.start(form, 0.0, 1e-6, q, v)
    cd.step(form, 1e-6, 1e-6, q, v)
    tracemalloc.start()
    base = tracemalloc.get_traced_memory()[0]
    for k in range(2, 52):
        cd.step(form, k * 1e-6, 1e-6, q, v)
    peak = tracemalloc.get_traced_memory()[1] - base
    tracemalloc.stop()
    assert peak < q.nbytes, peak
