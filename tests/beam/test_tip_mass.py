"""[tip_mass] (SPEC section 10, issue 16): the scene table, its checks, and the beams carrying it
against closed forms (frequency equations) and an independent Ritz solution."""

import functools
import math

import numpy as np
import pytest
from scipy.optimize import brentq

from fxflex.errors import SceneError
from fxflex.scene import Scene, load_scene
from fxflex.scene.load import TIP_MASS_METHODS, validate_for


def test_tip_mass_table_reads_and_its_defaults_leave_the_hash():
    plain = load_scene()
    zero = load_scene(overrides=["tip_mass.mass=0", "tip_mass.inertia=[0, 0, 0]"])
    assert "tip_mass" not in plain.stable_dict() and zero.hash == plain.hash
    heavy = load_scene(overrides=["tip_mass.mass=2.5", "tip_mass.inertia=[0.2, 0.1, 0.1]"])
    assert heavy.tip_mass.mass == 2.5 and heavy.tip_mass.inertia == (0.2, 0.1, 0.1)
    assert heavy.stable_dict()["tip_mass"] == {"mass": 2.5, "inertia": [0.2, 0.1, 0.1]}
    assert heavy.hash != plain.hash
    # Pi = tr(J)/2 I - J: J_X = Pi_YY + Pi_ZZ etc.
    pi = heavy.tip_mass.second_moments().diagonal()
    assert list(pi) == pytest.approx([0.0, 0.1, 0.1], abs=1e-15)


@pytest.mark.parametrize("override, words", [
    ("tip_mass.mass=-1", "allowed: >= 0"),
    ("tip_mass.inertia=[0.1, -0.1, 0.1]", "allowed: >= 0"),
    ("tip_mass.inertia=[0.1, 0.1]", "list of 3"),
    ("tip_mass.inertia=[1, 0, 0]", "at most the sum of the other two"),
    ("tip_mass.mass=1e9", "meaningless for an elastic body"),
    ("tip_mass.radius=1", "unknown key"),
])
def test_bad_tip_mass_is_one_line_naming_the_key(override, words):
    with pytest.raises(SceneError) as err:
        load_scene(overrides=[override, "rotation.rpm=10000"])
    text = str(err.value)
    assert text.startswith("tip_mass.") and words in text and "\n" not in text


@pytest.mark.parametrize("method", ["ffrf", "gcms", "tlf", "lebb", "nebb", "ancf"])
def test_every_method_takes_a_point_mass_and_its_inertia(method):
    """All six carry the tip body: its translation and its rotary inertia, a body flat in the
    tip plane (J_X = J_Y + J_Z) and one with extent along X (the solids on the tip face's normal,
    tests/solid/test_tip_mass_solid.py)."""
    assert method in TIP_MASS_METHODS
    validate_for(method, Scene().replace(**{"tip_mass.mass": 1.0}))
    validate_for(method, Scene().replace(**{"tip_mass.mass": 1.0,
                                            "tip_mass.inertia": [0.02, 0.01, 0.01]}))
    validate_for(method, Scene().replace(**{"tip_mass.mass": 1.0,
                                            "tip_mass.inertia": [0.01, 0.01, 0.01]}))


# ---------------------------------------------------------------------------- LEBB and NEBB

def test_point_terms_are_those_of_a_cloud_of_points():
    """point_quadratic / point_linear against the sum over a random cloud of points moving as
    U = W + theta x r (the kinematics of N_c, Eq. 36, with the offset in all three axes)."""
    from fxflex.beam.frame import N0, NY, NZ, point_linear, point_quadratic
    from fxflex.scene.kinematics import P3, S3

    rng = np.random.default_rng(7)
    r = rng.normal(size=(40, 3))
    r -= r.mean(axis=0)
    w = rng.uniform(0.5, 1.5, size=40)
    r -= (w @ r / w.sum())                  # first moments zero about the body's centroid
    Pi, m = np.einsum("p,pi,pj->ij", w, r, r), w.sum()
    Xc = np.array([1.3, 0.0, 0.0])

    def N(p):                               # N0 + p_X N_X + p_Y NY + p_Z NZ
        NX = np.zeros((3, 6))
        NX[1, 5], NX[2, 4] = 1.0, -1.0      # theta x (X, 0, 0)
        return N0 + p[0] * NX + p[1] * NY + p[2] * NZ

    for Q in (np.eye(3), S3, P3):
        quad = sum(wi * N(p).T @ Q @ N(p) for wi, p in zip(w, r))
        lin = sum(wi * N(p).T @ Q @ (Xc + p) for wi, p in zip(w, r))
        scale = np.abs(quad).max()
        np.testing.assert_allclose(point_quadratic(Q, m, Pi), quad, rtol=0, atol=1e-13 * scale)
        np.testing.assert_allclose(point_linear(Q, m, Pi, Xc), lin, rtol=0, atol=1e-13 * scale)


#: a slender uniform cantilever (L = 1 m): its sections' rotary inertia shifts the flap frequency
#: by about 1e-5, accounted for below to first order
B, H = 0.02, 0.01


def _uniform(n: int, ratio: float = 0.0, rpm: float = 0.0, **keys) -> Scene:
    rho = Scene().material.rho
    return Scene().replace(**{"geometry.root_y": B, "geometry.tip_y": B, "geometry.root_z": H,
                              "geometry.tip_z": H, "geometry.twist_deg": 0.0, "rotation.rpm": rpm,
                              "damping.c": 0.0, "load.line_load": 0.0, "mesh.beam_elements": n,
                              "tip_mass.mass": ratio * rho * B * H * 1.0, **keys})


def _flap_hz(method: str, scene: Scene) -> float:
    from fxflex.analysis.modes import modes_of
    from fxflex.formulation import build

    m = modes_of(build(method, scene, None), 4)
    return float(m.frequencies_hz[m.labels.index("out-of-plane")])


def _tip_mass_root(mu: float) -> float:
    """The lowest root bL of 1 + cos cosh + mu bL (cos sinh - sin cosh) = 0 (mu = M_t / rho A L)."""
    f = lambda x: (1 + math.cos(x) * math.cosh(x)
                   + mu * x * (math.cos(x) * math.sinh(x) - math.sin(x) * math.cosh(x)))
    xs = np.linspace(0.05, 1.9, 200)            # below the no-mass root 1.8751 for every mu
    i = next(i for i in range(len(xs) - 1) if f(xs[i]) * f(xs[i + 1]) < 0)
    return brentq(f, xs[i], xs[i + 1], xtol=1e-15)


def _rotary_shift(bl: float, mu: float) -> float:
    """First-order relative frequency shift of the sections' rotary inertia, Rayleigh:
    -1/2 rho I_Y int phi'^2 / (rho A int phi^2 + M_t phi(L)^2), phi the clamped mode with a tip
    mass (phi''(L) = 0 fixes sigma; the shear condition is the frequency equation)."""
    x, wq = np.polynomial.legendre.leggauss(60)
    x, wq = 0.5 * (x + 1), 0.5 * wq
    s = (math.cosh(bl) + math.cos(bl)) / (math.sinh(bl) + math.sin(bl))
    phi = lambda y: np.cosh(bl * y) - np.cos(bl * y) - s * (np.sinh(bl * y) - np.sin(bl * y))
    dphi = bl * (np.sinh(bl * x) + np.sin(bl * x) - s * (np.cosh(bl * x) - np.cos(bl * x)))
    rot = H**2 / 12.0 * (wq @ dphi**2)          # I_Y / A int phi'^2 (L = 1)
    return -0.5 * rot / (wq @ phi(x) ** 2 + mu * phi(1.0) ** 2)


@pytest.mark.parametrize("method", ["lebb", "nebb"])
@pytest.mark.parametrize("mu", [0.1, 1.0, 5.0])
def test_flap_frequency_with_a_tip_mass_at_rest(method, mu):
    """The first flap frequency against the root of the frequency equation, shifted by the
    sections' rotary inertia (Euler-Bernoulli leaves it out, the beams keep it); the tolerance is
    the discretisation error, estimated by halving the elements (Hermite cubics converge at
    order 4 in the frequency: f_10 - f_exact ~ 16/15 (f_10 - f_20), doubled for safety), plus the
    second-order remainder of the rotary shift."""
    mat = Scene().material
    bl = _tip_mass_root(mu)
    exact = bl**2 * math.sqrt(mat.E * H**2 / 12.0 / mat.rho) / (2 * math.pi)
    shift = _rotary_shift(bl, mu)
    f10, f20 = (_flap_hz(method, _uniform(n, mu)) for n in (10, 20))
    tol = 2.0 * abs(f10 - f20) / exact + 10 * shift**2 + 1e-10
    assert abs(f10 / exact - (1.0 + shift)) < tol
    assert abs(f20 / exact - (1.0 + shift)) < tol


def _rotating_flap_ritz(mu: float, rpm: float, terms: int) -> float:
    """An independent reference for the rotating cantilever with a tip mass (hub radius R): flap
    w(x) by Ritz on x^2 .. x^(terms+1), with the axial force T = EA u' of the exact stretched
    equilibrium (EA u'' + rho A Omega^2 (R + x + u) = 0, u(0) = 0, EA u'(L) = M_t Omega^2
    (R + L + u(L))), bending EI, the geometric stiffness T w'^2, the sections' rotary inertia
    rho I_Y w'^2 and its spin softening -Omega^2 rho I_Y w'^2, the tip mass M_t w(L)^2."""
    from scipy.linalg import eigh

    sc = _uniform(1, mu, rpm)
    mat, R, L = sc.material, sc.geometry.hub_radius, sc.geometry.length
    A, I = B * H, B * H**3 / 12.0
    om, m = sc.rotation.omega, sc.tip_mass.mass
    k = om * math.sqrt(mat.rho / mat.E)
    # u = R cos kx + C sin kx - (R + x); the tip condition is linear in C
    u = lambda x, C: R * np.cos(k * x) + C * np.sin(k * x) - (R + x)
    du = lambda x, C: -R * k * np.sin(k * x) + C * k * np.cos(k * x) - 1.0
    r0 = mat.E * A * du(L, 0.0) - m * om**2 * (R + L + u(L, 0.0))
    r1 = mat.E * A * (du(L, 1.0) - du(L, 0.0)) - m * om**2 * (u(L, 1.0) - u(L, 0.0))
    C = -r0 / r1
    x, wq = np.polynomial.legendre.leggauss(80)
    x, wq = 0.5 * L * (x + 1), 0.5 * L * wq
    T = mat.E * A * du(x, C)
    p = np.arange(2, terms + 2)
    f, df, ddf = x[:, None] ** p, p * x[:, None] ** (p - 1), p * (p - 1) * x[:, None] ** (p - 2)
    K = (mat.E * I * ddf.T @ (wq[:, None] * ddf) + df.T @ ((wq * T)[:, None] * df)
         - om**2 * mat.rho * I * df.T @ (wq[:, None] * df))
    M = (mat.rho * A * f.T @ (wq[:, None] * f) + mat.rho * I * df.T @ (wq[:, None] * df)
         + m * np.outer(L**p, L**p))
    return math.sqrt(eigh(K, M, eigvals_only=True)[0]) / (2 * math.pi)


def test_rotating_flap_with_a_tip_mass_stiffens_as_the_ritz_reference():
    """NEBB about its rotating steady state: the tip mass's centrifugal pull stiffens the flap
    mode (von Karman term); against an independent Ritz solution (converged: 8 and 10 terms
    agree to 1e-9) within twice the change from 10 to 20 elements (order >= 1 in the element
    size: the axial force is constant per element). LEBB, linear, has no such stiffening."""
    mu, rpm = 1.0, 600.0
    ref, ref8 = (_rotating_flap_ritz(mu, rpm, n) for n in (10, 8))
    assert abs(ref8 / ref - 1.0) < 1e-9
    f10, f20 = (_flap_hz("nebb", _uniform(n, mu, rpm)) for n in (10, 20))
    at_rest = _flap_hz("nebb", _uniform(10, mu))
    assert ref > 1.5 * at_rest                 # the stiffening is the bulk of the frequency
    tol = 2.0 * abs(f10 - f20) + 1e-9 * ref
    assert abs(f10 - ref) < tol and abs(f20 - ref) < tol
    assert _flap_hz("lebb", _uniform(10, mu, rpm)) == pytest.approx(at_rest, rel=1e-3)


def _torsion_hz(method: str, scene: Scene) -> float:
    from fxflex.analysis.modes import modes_of
    from fxflex.formulation import build

    m = modes_of(build(method, scene, None), 12)
    return float(m.frequencies_hz[m.labels.index("torsion")])


@pytest.mark.parametrize("method", ["lebb", "nebb"])
@pytest.mark.parametrize("ratio", [0.3, 3.0])
def test_torsion_frequency_with_a_tip_inertia(method, ratio):
    """A thin disc (inertia [2 J, J, J], J_X = ratio rho I_p L) on the uniform shaft at rest:
    theta = sin(beta x) with the tip condition G J_t theta'(L) = J_X omega^2 theta(L) gives
    beta L tan(beta L) = rho I_p L / J_X, omega = beta sqrt(G J_t / (rho I_p)) (J_t = I_p, the
    polar torsion of ``section.torsion``'s default); for small J_X this is omega_0 (1 + J_X /
    (rho I_p L / 3))^(-1/2) to first order. Linear torsion elements: order 2 in the element
    size, so the tolerance is twice the change from 10 to 20 elements."""
    mat = Scene().material
    Ip = B * H * (B**2 + H**2) / 12.0
    Jx = ratio * mat.rho * Ip * 1.0
    bl = brentq(lambda x: x * math.tan(x) - 1.0 / ratio, 1e-9, math.pi / 2 - 1e-12, xtol=1e-15)
    exact = bl * math.sqrt(mat.G / mat.rho) / (2 * math.pi)
    keys = {"tip_mass.mass": 0.0, "tip_mass.inertia": [Jx, Jx / 2, Jx / 2]}
    f10, f20 = (_torsion_hz(method, _uniform(n, **keys)) for n in (10, 20))
    tol = 2.0 * abs(f10 - f20) + 1e-9 * exact
    assert abs(f10 - exact) < tol and abs(f20 - exact) < tol
    bare = math.pi / 2 * math.sqrt(mat.G / mat.rho) / (2 * math.pi)
    assert exact < 0.9 * bare                  # the inertia matters at these ratios


# ---------------------------------------------------------------------------- ANCF

#: ANCF's locking-free variant: Euler-Bernoulli up to its transverse shear (docs/beams.md)
_LF = {"mesh.beam_variant": "locking-free"}


@functools.cache
def _bare_flap_deviation() -> float:
    """ANCF's own deviation from Euler-Bernoulli on the bare cantilever (shear, rotary inertia,
    Poisson), 20 elements: the bound of its share with a tip mass, which only lowers the shear's
    part of the strain energy (3 EI / (k G A L^2) against 20/3 of it under distributed inertia)."""
    mat = Scene().material
    exact = 1.8751040687119611**2 * math.sqrt(mat.E * H**2 / 12.0 / mat.rho) / (2 * math.pi)
    return abs(_flap_hz("ancf", _uniform(20, 0.0, **_LF)) / exact - 1.0)


@pytest.mark.parametrize("mu", [0.1, 1.0, 5.0])
def test_ancf_flap_frequency_with_a_tip_mass_at_rest(mu):
    """The tip mass on ANCF's position slot: the frequency equation's root within ANCF's own
    (bare-beam) deviation from Euler-Bernoulli and its discretisation error (10 and 20
    elements)."""
    mat = Scene().material
    bl = _tip_mass_root(mu)
    exact = bl**2 * math.sqrt(mat.E * H**2 / 12.0 / mat.rho) / (2 * math.pi)
    f10, f20 = (_flap_hz("ancf", _uniform(n, mu, **_LF)) for n in (10, 20))
    tol = 2.0 * abs(f10 - f20) / exact + _bare_flap_deviation()
    assert abs(f20 / exact - 1.0) < tol and abs(f10 / exact - 1.0) < tol
    assert tol < 2e-4                           # against a 10 % to 55 % drop from the mass


@functools.cache
def _bare_torsion_hz(n: int) -> float:
    return _torsion_hz("ancf", _uniform(n, **_LF))


@pytest.mark.parametrize("ratio", [0.3, 3.0])
def test_ancf_torsion_with_a_tip_inertia_through_the_gradients(ratio):
    """The disc's rotary inertia through the section gradients: ANCF's torsion stiffness (not the
    polar one; its section gradients carry their own) taken from its bare shaft, c = (2 L f_0)^2
    for f_0 = sqrt(c) / (4 L), the disc's frequency follows from beta L tan(beta L) =
    rho I_p L / J_X, f = beta sqrt(c) / (2 pi), at each element count; tolerance twice the
    change of the ratio from 10 to 20 elements (both converge at order >= 1)."""
    mat = Scene().material
    Ip = B * H * (B**2 + H**2) / 12.0
    Jx = ratio * mat.rho * Ip * 1.0
    bl = brentq(lambda x: x * math.tan(x) - 1.0 / ratio, 1e-9, math.pi / 2 - 1e-12, xtol=1e-15)
    keys = {"tip_mass.inertia": [Jx, Jx / 2, Jx / 2], **_LF}
    err = []
    for n in (10, 20):
        bare = _bare_torsion_hz(n)
        err.append(_torsion_hz("ancf", _uniform(n, **keys)) / (bare * bl / (math.pi / 2)) - 1.0)
    assert abs(err[1]) < 2.0 * abs(err[0] - err[1]) + 1e-9
    assert abs(err[1]) < 0.01                   # against the disc's 30 % to 70 % drop



# ---------------------------------------------------------------------------- ANCF: extent along X

def _stubby(inertia, rpm: float = 0.0, mu: float = 1.0, **keys) -> Scene:
    """The uniform 0.12 x 0.06 x 1 m beam (the solids' test beam, stubby enough for the tip
    element's shear to matter), 10 locking-free elements, a tip body of mass mu rho A L."""
    rho = Scene().material.rho
    return Scene().replace(**{
        "geometry.root_y": 0.12, "geometry.tip_y": 0.12, "geometry.root_z": 0.06,
        "geometry.tip_z": 0.06, "geometry.twist_deg": 0.0, "rotation.rpm": rpm,
        "damping.c": 0.0, "load.line_load": 0.0, "mesh.beam_elements": 10, **_LF,
        "tip_mass.mass": mu * rho * 0.12 * 0.06, "tip_mass.inertia": list(inertia), **keys})


def _bending_hz(method: str, scene: Scene) -> np.ndarray:
    """The first two out-of-plane and in-plane frequencies (Hz)."""
    from fxflex.analysis.modes import modes_of
    from fxflex.formulation import build

    m = modes_of(build(method, scene, None), 8)
    f = np.asarray(m.frequencies_hz)
    return np.array([f[[i for i, lab in enumerate(m.labels) if lab == fam][:2]]
                     for fam in ("out-of-plane", "in-plane")]).ravel()


@pytest.mark.parametrize("j", [0.05, 0.1])
def test_ancf_rod_along_x_turns_with_the_section_not_the_centerline(j):
    """ANCF carries Pi_XX on the tip section's normal n = g_Y x g_Z / |.| (ancf.tip_director):
    a rod along X [0, J, J] has the bending rotary inertia of the disc [2 J, J, J] (same J_Y,
    J_Z; J = j rho A L^3), so at rest their first two flap and lead-lag frequencies agree to
    1e-6 (measured: equal to 1e-12; the flat part's section gradients and the normal see the
    same rotation). Before, on d_X (the centerline's tangent, which the tip element's shear
    tilts against the section), the rod's 2nd lead-lag was 177.9 Hz against the disc's 231.4."""
    J = j * Scene().material.rho * 0.12 * 0.06
    rod, disc = (_bending_hz("ancf", _stubby(b)) for b in ((0.0, J, J), (2 * J, J, J)))
    print(f"\nrod {rod}, disc {disc}")
    np.testing.assert_allclose(rod, disc, rtol=1e-6)


def test_ancf_steady_and_rotating_rod_along_x_as_nebb():
    """At 3000 rpm, the rod along X [0, P, P] (P = 0.02 rho A L^3): its centrifugal pull runs
    along its own axis, so it adds no stretch to the steady tip (to 1e-8 of it; before, on d_X,
    2 % of it); under a line load it moves the tilted tip back (its restoring moment Omega^2 P
    theta_Y) as NEBB's second-order point rotation does, within twice the pair's own gap in that
    deflection without the body (their flap compliance; measured 0.47 % against 0.71 %; TLF on
    the solid: between them); and its share of the rotating flap frequency (propeller
    stiffening against the rest's added J_Y): the stiffening itself, share - 1 (4 %), as NEBB's
    within the pair's flap gap at rest, in frequency or in the static deflection, the larger
    (J_X + J_Y - J_Z = 0: the rod couples flap to torsion in neither; measured 0.6 % against
    0.71 %). Also the
    steady Newton tangent against central differences of the residual, with the absolute
    damping's circulatory term (h = 1e-7 on coordinates of order 1: 1e-6 of it)."""
    rho = Scene().material.rho
    P = 0.02 * rho * 0.12 * 0.06
    from fxflex.formulation import build

    sv = {"section.torsion": "saint-venant"}
    tips = {}
    for m in ("ancf", "nebb"):
        for J in ((0, 0, 0), (0, P, P)):
            sc = _stubby(J, 3000.0, **{"load.line_load": 100.0}, **(sv if m == "nebb" else {}))
            tips[m, J] = build(m, sc, None).steady_state().tip
    moved = {m: tips[m, (0, P, P)] - tips[m, (0, 0, 0)] for m in ("ancf", "nebb")}
    flap = {m: _bending_hz(m, _stubby((0, 0, 0), **(sv if m == "nebb" else {})))[0]
            for m in ("ancf", "nebb")}
    flap_gap = abs(flap["ancf"] / flap["nebb"] - 1.0)
    print(f"\nrod moves the tip: ancf {moved['ancf']}, nebb {moved['nebb']}, gap {flap_gap:.2e}")
    assert abs(moved["ancf"][0]) < 1e-8 * abs(tips["ancf", (0, 0, 0)][0])
    static_gap = abs(tips["ancf", (0, 0, 0)][2] / tips["nebb", (0, 0, 0)][2] - 1.0)
    assert abs(moved["ancf"][2] / moved["nebb"][2] - 1.0) < 2.0 * static_gap

    def share(m: str) -> float:
        f = {(J, rpm): _bending_hz(m, _stubby(J, rpm, 0.0, **(sv if m == "nebb" else {})))[0]
             for J in ((0, 0, 0), (0, P, P)) for rpm in (0.0, 3000.0)}
        return (f[(0, P, P), 3000.0] / f[(0, 0, 0), 3000.0]) / (f[(0, P, P), 0.0]
                                                                 / f[(0, 0, 0), 0.0])

    ours, ref = share("ancf"), share("nebb")
    print(f"rod: flap share {ours:.5f} vs {ref:.5f}, gaps {flap_gap:.2e} {static_gap:.2e}")
    assert ours > 1.03                                    # the propeller moment stiffens, 4 %
    assert abs((ours - 1.0) / (ref - 1.0) - 1.0) < max(flap_gap, static_gap)
    form = build("ancf", _stubby((0.1, 0.2, 0.2), 3000.0, **{"damping.c": 1000.0,
                                                              "damping.model": "absolute"}),
                 None)
    x = form.steady_state().q[form.free_dofs] + 1e-3 * np.random.default_rng(2).standard_normal(
        len(form.free_dofs))
    dx = np.random.default_rng(3).standard_normal(x.size)
    h = 1e-7
    fd = (form._static_residual(x + h * dx, 1.0) - form._static_residual(x - h * dx, 1.0)) / (2 * h)
    K = form._effective_stiffness(form._full(x), form.scene.rotation.omega)
    assert np.abs(fd - K @ dx).max() < 1e-6 * np.abs(fd).max()


def test_ancf_rod_along_x_in_time():
    """ANCF's time loop with the rod along X [0, 1, 1] (its mass a Woodbury update of M_ff^-1,
    the velocity force): at rest under a sudden tip force, central differences and
    generalized-alpha against generalized-alpha with the disc [2, 1, 1] (same J_Y, J_Z): within
    1e-4 of the peak over 30 ms (measured 4.7e-5, central differences' own gap; generalized-
    alpha 4e-13). In a spin-up to 3000 rpm generalized-alpha's reused hub factor keeps the rod's
    mass current (FactorUpdate; tests/conftest.py iteration_matrix_error): made at the state
    itself, the iteration matrix is Newton's Jacobian to 1e-4 (measured 4.2e-5; 6e-4 without the
    update), made 0.5 ms earlier its age (the stiffness's: 8 % without a tip inertia) dominates
    and the rod's error stays within 1.2 times the disc's (measured 12.6 % and 11.4 %; 349 %
    without the update)."""
    from fxflex.formulation import build
    from fxflex.time import simulate

    from ..conftest import iteration_matrix_error

    def tip_z(inertia, integrator):
        form = build("ancf", _stubby(inertia, 0.0, 1.0, **{"load.tip_force": [0.0, 0.0, 100.0]}),
                     None)
        dt = 0.9 * 2.0 / form.omega_max() if integrator == "cd" else 1e-5
        dt = 0.03 / round(0.03 / dt)
        rows = []
        simulate(form, integrator, dt, 0.03, sample_every=max(1, round(2.5e-4 / dt)),
                 on_sample=lambda t, tip, extras, q: rows.append((t, tip[2])))
        return np.array(rows)

    ref = tip_z((2.0, 1.0, 1.0), "generalized-alpha")
    peak = np.abs(ref[:, 1]).max()
    for integrator in ("generalized-alpha", "cd"):
        z = tip_z((0.0, 1.0, 1.0), integrator)
        gap = np.abs(np.interp(ref[:, 0], z[:, 0], z[:, 1]) - ref[:, 1]).max() / peak
        print(f"\nancf rod {integrator}: {gap:.2e} of the peak")
        assert gap < 1e-4
    def error(inertia, t1):
        return iteration_matrix_error(build("ancf", _stubby(
            inertia, 3000.0, 1.0, **{"load.tip_force": [0.0, 100.0, 100.0]}), None), t1)

    fresh = error((0.0, 1.0, 1.0), 0.002)
    stale, disc = (error(J, 0.0015) for J in ((0.0, 1.0, 1.0), (2.0, 1.0, 1.0)))
    print(f"ancf rod: fresh factor {fresh:.2e}, 0.5 ms old {stale:.2e} (disc {disc:.2e})")
    assert fresh < 1e-4
    assert stale < 1.2 * disc


@pytest.mark.parametrize("model", ["relative", "absolute"])
@pytest.mark.parametrize("inertia", [(0.0, 0.01, 0.01), (0.01, 0.01, 0.01)])
def test_ancf_linearisation_is_the_time_loop_about_the_steady_state(model, inertia):
    """ANCF with a tip body of extent along X at 3000 rpm, damped (c = 1000): the time loop's
    acceleration seen from the hub, z'' = a(A z, A (Omega S z + z')) - 2 Omega S z' + Omega^2 P z
    (at phi = 0, A = I), vanishes at the steady state to 5e-8 of the centripetal scale
    Omega^2 |e| (measured 5e-9 to 1.3e-8, the Newton tolerance's share; with the absolute model
    and a rod, 1.5e-7 to 3e-7 without Director.absolute_damping, which makes the time loop damp
    the director's rate relative to the rigidly turning e_X as the steady state does), and its
    derivatives by central differences are the linearisation's -M^-1 K and -M^-1 C to 1e-6 (K:
    h = 1e-7 on coordinates of order 1, measured 1e-9; C: exact differences of a quadratic)."""
    from fxflex.formulation import build
    from fxflex.scene.kinematics import P3, S3

    sc = Scene().replace(**{"load.line_load": 0.0, "rotation.rpm": 3000.0, "tip_mass.mass": 1.0,
                            "tip_mass.inertia": list(inertia), "damping.model": model,
                            "damping.c": 1000.0, "mesh.beam_elements": 6})
    form = build("ancf", sc, None)
    st = form.steady_state()
    lin = form.linearise(st)
    w, free = sc.rotation.omega, form.free_dofs
    x0 = np.asarray(st.q, float)[free]

    def hub_acceleration(x, dz):
        q = form._full(x)
        zdot = np.zeros_like(q)
        zdot[free] = dz
        v = (w * q.reshape(-1, 3) @ S3.T).reshape(-1) + zdot
        a = np.zeros_like(q)
        form.acceleration(0.0, q, v, a)
        a = a - 2 * w * (zdot.reshape(-1, 3) @ S3.T).reshape(-1)
        return (a + w * w * (q.reshape(-1, 3) @ P3.T).reshape(-1))[free]

    rest = np.zeros(x0.size)
    scale = w * w * np.abs(x0).max()
    assert np.abs(hub_acceleration(x0, rest)).max() < 5e-8 * scale
    rng = np.random.default_rng(1)
    # in z' the acceleration is at most quadratic (damping, Coriolis, the director's velocity
    # force), so a central difference is exact there at any step: a large one keeps the round-off
    # of accelerations of 1e9 (the stiff gradient slots) out
    for matrix, h, perturb in ((lin.K, 1e-7, lambda d: (x0 + d, rest)),
                               (lin.C, 1.0, lambda d: (x0, d))):
        d = rng.standard_normal(x0.size)
        fd = (hub_acceleration(*perturb(h * d)) - hub_acceleration(*perturb(-h * d))) / (2 * h)
        want = -np.linalg.solve(lin.M, matrix @ d)
        assert np.abs(fd - want).max() < 1e-6 * np.abs(want).max()
