"""NEBB (Eq. 45-48): invariant vs per-step element force (Eq. 66), tangent, static checks,
stability at 10000 rpm."""

import numpy as np
import pytest

from fxflex.beam import lebb, nebb


@pytest.fixture
def form(default):
    return nebb.build(default, None)


def random_state(form, scale=1e-3, seed=0):
    rng = np.random.default_rng(seed)
    W = np.zeros(form.n_full)
    W[6:] = scale * rng.standard_normal(form.dof)
    return W


def test_invariant_and_element_forces_agree(form):
    W = random_state(form)
    system, eq66, elem = (np.zeros(form.n_full) for _ in range(3))
    form.engine.add_force_system(W, system)          # system invariant matrices (Eq. 48)
    form.add_force_eq66(W, eq66)                     # Gauss-point integration (Eq. 66)
    form.engine.add_force_element(W, elem)           # element invariant matrices
    scale = np.abs(system).max()
    assert scale > 0
    # the same force by three routes: round-off of the largest cancelling terms
    np.testing.assert_allclose(eq66, system, rtol=0, atol=1e-10 * scale)
    np.testing.assert_allclose(elem, system, rtol=0, atol=1e-10 * scale)


def test_von_karman_force_from_the_strain_energy(form):
    """Q_N is the gradient of 1/2 int N_L w + 1/8 int EA w^2: check against a finite difference
    of that energy computed directly at the Gauss points."""
    tab, dx = form.tab, form.line.dx

    def energy(W):
        ue = form.engine.element_views(W)
        w = (ue @ tab.dY.T) ** 2 + (ue @ tab.dZ.T) ** 2
        NL = np.einsum("eqk,ek->eq", form.e1, ue)
        return np.sum(dx * (0.5 * NL * w + 0.125 * form.EA * w**2))

    W = random_state(form, 1e-2, 1)
    Q = form.engine.force(W)
    rng = np.random.default_rng(2)
    d = np.zeros_like(W)
    d[6:] = rng.standard_normal(form.dof)
    h = 1e-6
    fd = (energy(W + h * d) - energy(W - h * d)) / (2 * h)
    assert fd == pytest.approx(Q @ d, rel=1e-7)


def test_tangent_is_the_derivative_of_the_force(form):
    W = random_state(form, 1e-2)
    K = form.nonlinear_tangent(W)
    d = np.random.default_rng(3).standard_normal(form.n_full)
    h = 1e-7
    fd = (form.engine.force(W + h * d) - form.engine.force(W - h * d)) / (2 * h)
    np.testing.assert_allclose(K @ d, fd, rtol=0, atol=1e-7 * np.abs(K @ d).max())


@pytest.mark.parametrize("force_eval", ["invariant", "element"])
def test_cantilever_linear_range(uniform, force_eval):
    scene = uniform.replace(**{"load.line_load": -800.0})
    st = nebb.NEBB(scene, force_eval).steady_state()
    Iy = 0.12 * 0.06**3 / 12
    ref = -800.0 / (8 * scene.material.E * Iy)
    assert st.converged and st.tip[2] == pytest.approx(ref, rel=1e-2)


def test_spinning_bar_elongation(uniform):
    scene = uniform.replace(**{"rotation.rpm": 1000.0, "load.line_load": 0.0})
    tip = nebb.build(scene, None).steady_state().tip
    ref = scene.material.rho * scene.rotation.omega**2 / (3 * scene.material.E)
    assert tip[0] == pytest.approx(ref, rel=5e-3)


@pytest.mark.parametrize("model", ["relative", "absolute"])
def test_steady_state_is_an_equilibrium_of_the_dynamics(default, model):
    scene = default.replace(**{"damping.model": model, "load.tip_force": (50.0, -30.0, 20.0)})
    form = nebb.build(scene, None)
    st = form.steady_state()
    a = np.zeros(form.dof)
    form.acceleration(1.0, st.q, np.zeros(form.dof), a)     # after the ramp
    a_load = np.abs(form.Mi_fq).max()
    assert np.abs(a).max() < 1e-8 * a_load


def test_stiffening_at_10000_rpm(default):
    """NEBB converges and is stable at 10000 rpm where LEBB is not (Sect. 4.1)."""
    scene = default.replace(**{"rotation.rpm": 10000.0})
    form = nebb.build(scene, None)
    st = form.steady_state()
    assert st.converged
    assert form.growth_rate()[0] < 0
    assert lebb.build(scene, None).growth_rate()[0] > 0
    # transverse deflections shrink with speed for the nonlinear model
    slow = nebb.build(default, None).steady_state().tip
    assert abs(st.tip[2]) < abs(slow[2]) and abs(st.tip[1]) < abs(slow[1])


def _torsion_shift(method, scene, rpm):
    """(omega^2 - omega_0^2) / Omega^2 of the first torsion mode (1/s^2 per (rad/s)^2)."""
    from fxflex.analysis.modes import modes_of
    from fxflex.formulation import BuildOptions, build

    def f(r):
        m = modes_of(build(method, scene.replace(**{"rotation.rpm": r}), None, BuildOptions()), 12)
        return float(m.frequencies_hz[m.labels.index("torsion")]) * 2 * np.pi

    return (f(rpm) ** 2 - f(0.0) ** 2) / (rpm * np.pi / 30) ** 2


@pytest.mark.parametrize("body", [False, True])
def test_propeller_moment_of_the_sections_and_the_tip_body(uniform, body):
    """A section (or tip disc) twisted by phi tilts its extent along Y (in the plane of rotation)
    out of that plane and the centrifugal field pulls it back: NEBB carries the second-order
    rotation of its sections (fxflex.beam.frame.section_rotation_second_order), LEBB does not.
    On the uniform untwisted 0.12 x 0.06 beam the torsion's omega^2 gains Omega^2 rho I_Z over
    the torsional inertia rho I_p (I_Z = int Y^2): NEBB's shift (omega^2 - omega_0^2) / Omega^2
    is LEBB's plus I_Z / I_p = 0.8, on the discrete model too (the term is proportional to the
    torsional inertia, on the same shape functions); both shifts also hold the same gyroscopic
    coupling of torsion with the flap rotation (measured: LEBB -0.2034 against the spin
    softening -I_Y / I_p = -0.2, NEBB 0.5970 against the propeller law (I_Z - I_Y) / I_p = 0.6).
    A thin tip disc with second moments in the section's proportions, Pi = c diag(0, I_Z, I_Y)
    (point_rotation_second_order), adds the same 0.8. At 1000 rpm the stretched state's other
    changes are of the order of the root axial strain, rho Omega^2 L^2 / (2 E) = 2.1e-4,
    relative (measured 4e-4 of 0.8; 4e-6 at 100 rpm)."""
    b, h = 0.12, 0.06
    IZ, IY = h * b**3 / 12, b * h**3 / 12
    scene = uniform.replace(**{"damping.c": 0.0, "load.line_load": 0.0,
                               "mesh.beam_elements": 10})
    if body:
        c = 0.5 * scene.material.rho                     # half a metre of the beam's inertia
        scene = scene.replace(**{"tip_mass.inertia": [c * (IZ + IY), c * IY, c * IZ]})
    L = scene.geometry.length
    strain = scene.material.rho * (1000 * np.pi / 30 * L) ** 2 / (2 * scene.material.E)
    nebb_shift, lebb_shift = (_torsion_shift(m, scene, 1000.0) for m in ("nebb", "lebb"))
    assert nebb_shift - lebb_shift == pytest.approx(IZ / (IZ + IY), rel=5 * strain)
    assert lebb_shift == pytest.approx(-IY / (IZ + IY), abs=0.02)


def test_second_order_rotation_matrices_against_an_exact_rotation():
    """section_rotation_second_order with B = P and S (and the tip body's) are the
    Hessians over theta of sum w (B X0) . u2 with B = P (centrifugal) and S (Euler), u2 the
    second-order part of R(theta) s - s for the exact rotation R = exp([theta]x): checked on a
    weighted cloud of section points with non-zero first moments and product of inertia (so
    every entry, X S / 2 and I_YZ / 2 included, is exercised), through the quadratic form at
    eps theta extrapolated from eps = 1e-3 and 5e-4 (its third-order remainder is linear in eps):
    what is left is O(eps^2) = 1e-6 relative, far above round-off and far below any wrong
    entry."""
    from types import SimpleNamespace

    from scipy.spatial.transform import Rotation

    from fxflex.beam.frame import point_rotation_second_order, section_rotation_second_order
    from fxflex.scene.kinematics import P3, S3

    rng = np.random.default_rng(3)
    Xs = 1.7
    pts = np.column_stack([np.zeros(9), rng.normal(0.1, 0.05, 9), rng.normal(-0.03, 0.02, 9)])
    w = rng.uniform(0.5, 2.0, 9)
    Y, Z = pts[:, 1], pts[:, 2]
    sec = SimpleNamespace(A=np.array(w.sum()), S_Z=np.array(w @ Y), S_Y=np.array(w @ Z),
                          I_Z=np.array(w @ Y**2), I_Y=np.array(w @ Z**2),
                          I_YZ=np.array(w @ (Y * Z)))
    Pi = (pts * w[:, None]).T @ pts                       # a cloud about its own origin ...
    centred = pts - (w @ pts) / w.sum()                   # ... and about its centroid (body)
    Pi_c = (centred * w[:, None]).T @ centred
    def quadratic(B, cloud, x0, theta, eps):
        """sum w (B x0) . u2 / eps^2 for the exact rotation by eps theta."""
        R = Rotation.from_rotvec(eps * theta).as_matrix()
        u2 = cloud @ R.T - cloud - np.cross(eps * theta, cloud)          # O(eps^2)
        return np.sum(w * np.einsum("ki,ij,kj->k", x0, B.T, u2)) / eps**2

    I_Z, I_Y, I_YZ, S_Z, S_Y = sec.I_Z, sec.I_Y, sec.I_YZ, sec.S_Z, sec.S_Y
    closed = {0: np.array([[-I_Z, Xs * S_Z / 2, Xs * S_Y / 2], [Xs * S_Z / 2, 0, I_YZ / 2],
                           [Xs * S_Y / 2, I_YZ / 2, -I_Z]]),          # the docstring's, B = P
              1: np.array([[-Xs * S_Z, -I_Z / 2, -I_YZ / 2], [-I_Z / 2, 0, Xs * S_Y / 2],
                           [-I_YZ / 2, Xs * S_Y / 2, -Xs * S_Z]])}    # B = S
    for which, B in enumerate((P3, S3)):
        H = section_rotation_second_order(B, sec, Xs)[3:, 3:]
        Hb = point_rotation_second_order(B, Pi_c)[3:, 3:]
        assert np.allclose(H, closed[which], rtol=0, atol=1e-14 * np.abs(H).max())
        for _ in range(3):
            theta = rng.standard_normal(3)
            for cloud, x0, Hk in ((pts, pts + np.array([Xs, 0.0, 0.0]), H),
                                  (centred, centred, Hb)):
                exact = 2 * quadratic(B, cloud, x0, theta, 5e-4) - quadratic(B, cloud, x0,
                                                                               theta, 1e-3)
                assert exact == pytest.approx(0.5 * theta @ Hk @ theta, rel=1e-5)
    assert np.abs(Pi - Pi_c).max() > 0                     # the cloud's centroid is off its origin
