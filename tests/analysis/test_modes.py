"""Modes and stability about the rotating steady state, every method (SPEC section 6, issue 6):
the paper's verdicts at the three speeds, growth rate against a divergent transient, frequency
trends and closed forms on a uniform beam, the damping models' steady states, TLF's PEP against a
dense solve."""

import math

import numpy as np
import pytest
from mpi4py import MPI

from fxflex.numerics.qep import conjugate_pairs, quadratic_eigen
from fxflex.analysis.modes import LABELS, modes_of
from fxflex.bench.reduced import ReducedFamily
from fxflex.formulation import BuildOptions, build
from fxflex.scene import PAPER_RPM, load_scene
from fxflex.time import deviation_growth, diagnose, simulate

COMM = MPI.COMM_WORLD
EPS = np.finfo(float).eps
COARSE = "mesh.solid=[20,4,2]"
LINEAR = ("ffrf", "gcms", "lebb")
#: a uniform untwisted 0.12 x 0.06 beam without load
UNIFORM = ["geometry.tip_y=0.12", "geometry.tip_z=0.06", "geometry.twist_deg=0",
           "load.line_load=0"]


def scene(*overrides):
    return load_scene(overrides=list(overrides))


@pytest.fixture(scope="module")
def small():
    return ReducedFamily(scene(COARSE), COMM, count=30)


def expected_stable(method, rpm):
    """The paper (Sect. 4.1): the linear methods diverge at 10000 rpm, the nonlinear ones not."""
    return not (method in LINEAR and rpm == 10000.0)


def check_verdicts(build_at, method):
    for rpm in PAPER_RPM:
        form = build_at(rpm)
        modes = modes_of(form, 6)
        rate, _ = form.growth_rate()
        assert modes.stable == form.stable() == expected_stable(method, rpm), (method, rpm)
        assert (rate > 0) == (not expected_stable(method, rpm))
        if not modes.stable:
            # divergence: a real root through zero, the in-plane bending mode softened away
            assert modes.frequencies_hz[0] == 0.0
            # the same roots (rotating_modes and growth_rate share the eigensolve), so round-off at
            # most
            assert modes.growth_rates[0] == pytest.approx(rate, rel=1e-9)
            assert modes.labels[0] == "in-plane"


@pytest.mark.parametrize("method", ["lebb", "nebb", "ancf"])
def test_verdicts_beams_default_scene(method):
    check_verdicts(lambda rpm: build(method, scene(f"rotation.rpm={rpm}"), COMM), method)


@pytest.mark.parametrize("method", ["ffrf", "gcms", "tlf"])
def test_verdicts_solids_coarse_mesh(small, method):
    if method == "tlf":
        check_verdicts(lambda rpm: build("tlf", scene(COARSE, f"rotation.rpm={rpm}"), COMM),
                       method)
    else:
        check_verdicts(lambda rpm: small.build(method, f"rotation.rpm={rpm}"), method)


@pytest.mark.paper
def test_verdicts_solids_default_mesh():
    family = ReducedFamily(scene(), COMM, count=30)
    for method in ("ffrf", "gcms"):
        check_verdicts(lambda rpm: family.build(method, f"rotation.rpm={rpm}"), method)
    check_verdicts(lambda rpm: build("tlf", scene(f"rotation.rpm={rpm}"), COMM), "tlf")


def test_lebb_growth_rate_matches_the_divergent_transient():
    """LEBB-AB at 10000 rpm on the default scene: the deviation from the (unstable) equilibrium
    grows at the eigenvalue's rate (FFRF and GCMS: tests/solid/test_ffrf.py)."""
    form = build("lebb", scene("rotation.rpm=10000"), COMM)
    res = simulate(form, "ab2", 0.4e-6, 0.03, sample_every=25, keep_history=True, limit=100.0)
    measured, samples = deviation_growth(res.history, form.steady_state().tip)
    rate, _ = form.growth_rate()
    print(f"\nlebb 10000 rpm: measured growth {measured:.2f} 1/s, eigenvalue {rate:.2f} 1/s")
    assert res.diverged is not None and samples > 20
    assert measured == pytest.approx(rate, rel=0.01)
    assert diagnose(form, "ab2", 0.4e-6, res)["cause"] == "physical"


def lowest(modes, label):
    return [f for f, lab in zip(modes.frequencies_hz, modes.labels) if lab == label]


def uniform_modes(method, rpm, family=None):
    if family is not None:
        return modes_of(family.build(method, f"rotation.rpm={rpm}"), 8)
    options = BuildOptions(mass="consistent") if method == "tlf" else None
    return modes_of(build(method, scene(*UNIFORM, COARSE, f"rotation.rpm={rpm}"), COMM,
                          options), 8)


@pytest.fixture(scope="module")
def uniform_small():
    return ReducedFamily(scene(*UNIFORM, COARSE), COMM, count=30)


@pytest.mark.parametrize("method", ["lebb", "nebb", "ancf", "ffrf", "gcms", "tlf"])
def test_uniform_beam_stiffening_and_softening(uniform_small, method):
    """Centrifugal stiffening raises the nonlinear methods' out-of-plane frequencies with speed,
    by Southwell's omega^2 = omega_0^2 + K Omega^2 with K = 1.193 for the first flap mode of a
    uniform cantilever at small speed; spin softening lowers the linear methods' in-plane ones
    (their out-of-plane ones only feel the rotary inertia's softening)."""
    family = uniform_small if method in ("ffrf", "gcms") else None
    modes = {rpm: uniform_modes(method, rpm, family) for rpm in (0.0, 1000.0, 5000.0)}
    out = [lowest(modes[r], "out-of-plane")[0] for r in (0.0, 1000.0, 5000.0)]
    inp = [lowest(modes[r], "in-plane")[0] for r in (0.0, 1000.0, 5000.0)]
    w0, w1 = 2 * math.pi * out[0], 2 * math.pi * out[1]
    southwell = (w1**2 - w0**2) / (1000.0 * math.pi / 30) ** 2
    print(f"\n{method}: out-of-plane {out} Hz, in-plane {inp} Hz, Southwell K {southwell:.4f}")
    if method in LINEAR:
        assert inp[0] > inp[1] > inp[2]
        assert -0.01 < southwell < 0
    else:
        assert out[0] < out[1] < out[2] and inp[0] < inp[2]
        assert southwell == pytest.approx(1.193, rel=0.01)


@pytest.mark.parametrize("method, tol", [("lebb", 3e-3), ("nebb", 3e-3), ("ancf", 2e-2)])
def test_uniform_beam_at_rest_against_euler_bernoulli(method, tol):
    """f_k = (beta_k L)^2 / (2 pi) sqrt(E I / (rho A L^4)), beta L = 1.8751, 4.6941. LEBB/NEBB
    carry the rotary inertia (Rayleigh beam), lower by (r/L)^2-terms: 0.07 % (first flap),
    0.28 % (first lead-lag), 0.48 % (second flap); ANCF's continuum section adds about 1.5 %."""
    modes = uniform_modes(method, 0.0)
    E, rho = 210e9, 7850.0
    A, Iy, Iz = 0.12 * 0.06, 0.12 * 0.06**3 / 12, 0.06 * 0.12**3 / 12
    eb = [b**2 / (2 * math.pi) * math.sqrt(E * I / (rho * A))
          for b, I in ((1.875104069, Iy), (4.694091133, Iy), (1.875104069, Iz))]
    ours = lowest(modes, "out-of-plane")[:2] + lowest(modes, "in-plane")[:1]
    print(f"\n{method}: {ours} Hz, Euler-Bernoulli {eb} Hz")
    np.testing.assert_allclose(ours, eb, rtol=tol if method == "ancf" else 5e-3)
    if method != "ancf":
        assert ours[0] == pytest.approx(eb[0], rel=tol)


def test_tlf_at_rest_equals_the_clamped_modes(uniform_small):
    """Without speed and load TLF's tangent is K_L: its PEP roots (consistent mass) are the
    clamped eigenfrequencies that FFRF is built on, i.e. SLEPc PEP against SLEPc EPS."""
    tlf = uniform_modes("tlf", 0.0)
    f_cms = uniform_small.modes.frequencies_hz[: len(tlf.labels)]
    # |lambda| = omega exactly under mass-proportional damping
    # PEP (tol 1e-10) against EPS (tol 1e-12), each relative to the root on the shift-inverted
    # problem, where these lowest roots are the largest and well separated: 10 x the looser
    # tolerance
    np.testing.assert_allclose(np.abs(tlf.eigenvalues) / (2 * math.pi), f_cms, rtol=1e-9)


@pytest.mark.parametrize("method", ["lebb", "nebb", "ancf", "ffrf", "gcms", "tlf"])
def test_damping_models_steady_state(method):
    """Sect. 4.3: the relative model's convergent deflection does not depend on c, the absolute
    model's does, through its circulatory term (c/rho) Omega M_S, in proportion to c; at 10000 rpm
    it makes the nonlinear methods' |orthogonal| deflection grow with c."""
    def tip(model, c, rpm):
        return build(method, scene(COARSE, f"rotation.rpm={rpm}", f"damping.model=\"{model}\"",
                                   f"damping.c={c}"), COMM).steady_state().tip
    for rpm in (1000.0, 10000.0):
        base = tip("relative", 1000.0, rpm)
        # c does not enter the relative model's equilibrium: the same solve, bit for bit on one
        # rank; on several, MUMPS and the reductions may sum in another order, and the steady
        # state is then equal to ~ eps cond(K_T) (cond(K_L) = 2.3e6 on this mesh: 5e-10)
        np.testing.assert_allclose(tip("relative", 100.0, rpm), base,
                                   rtol=0 if COMM.size == 1 else 1e-9)
        shift = {c: tip("absolute", c, rpm) - base for c in (100.0, 1000.0)}
        assert abs(shift[1000.0][1]) > 1e-6 * abs(base[1])
        np.testing.assert_allclose(shift[1000.0], 10 * shift[100.0], rtol=2e-3,
                                   atol=1e-9 * np.abs(base).max())
        if rpm == 10000.0 and method not in LINEAR:
            assert abs(base[1] + shift[1000.0][1]) > abs(base[1] + shift[100.0][1]) > abs(base[1])


def _weights(M, C, K, lam):
    return abs(lam) ** 2 * np.linalg.norm(M, 2) + abs(lam) * np.linalg.norm(C, 2) \
        + np.linalg.norm(K, 2)


def backward_error(M, C, K, lam, x):
    """||P(lambda) x|| / ((|lambda|^2 ||M|| + |lambda| ||C|| + ||K||) ||x||): the relative
    backward error of an eigenpair of P(lambda) = lambda^2 M + lambda C + K (Tisseur, Linear
    Algebra Appl. 309, 2000, Thm 1)."""
    return np.linalg.norm((lam * lam * M + lam * C + K) @ x) / (_weights(M, C, K, lam)
                                                                 * np.linalg.norm(x))


def condition(M, C, K, lam):
    """The relative condition number of a simple eigenvalue of P in the same norms (Tisseur
    2000, Thm 5): (|lambda|^2 ||M|| + |lambda| ||C|| + ||K||) ||x|| ||y|| / (|lambda|
    |y* P'(lambda) x|), x and y the right and left singular vectors of P(lambda) that belong
    to its smallest singular value."""
    U, _, Vh = np.linalg.svd(lam * lam * M + lam * C + K)
    x, y = Vh[-1].conj(), U[:, -1]
    return _weights(M, C, K, lam) / (abs(lam) * abs(y.conj() @ (2 * lam * M + C) @ x))


@pytest.mark.parametrize("mass", ["lumped", "consistent"])
@pytest.mark.parametrize("model", ["relative", "absolute"])
def test_tlf_pep_against_dense_solve(mass, model):
    """SLEPc PEP on the assembled (M, C, K) against the dense companion form, tiny mesh, 10000
    rpm (geometric stiffness, spin softening, Coriolis, circulatory term all present)."""
    form = build("tlf", scene("mesh.solid=[6,2,2]", "rotation.rpm=10000",
                              f"damping.model=\"{model}\""), MPI.COMM_SELF,
                 BuildOptions(mass=mass))
    lam, X = form.rotating_modes(6)
    lin = form.linearise()
    M, C, K = (A.convert("dense").getDenseArray().copy() for A in (lin.M, lin.C, lin.K))
    assert not np.allclose(K, K.T) if model == "absolute" else np.allclose(K, K.T, rtol=1e-12)
    ld, Xd = quadratic_eigen(M, C, K)
    keep = conjugate_pairs(ld)[:6]
    # each side to first order in its own backward error (Tisseur 2000): |d lambda| / |lambda| <=
    # kappa (eta_SLEPc + eta_dense + the round-off of forming P(lambda) x)
    k = max(np.count_nonzero(A, axis=1).max() for A in (M, C, K))
    for j, i in enumerate(keep):
        err = backward_error(M, C, K, lam[j], X[:, j]) + backward_error(M, C, K, ld[i], Xd[:, i])
        assert abs(lam[j] - ld[i]) <= condition(M, C, K, ld[i]) * (err + 3 * k * EPS) \
            * abs(ld[i]), j
    # same mode shapes up to a complex factor
    for j, k in enumerate(keep):
        a, b = X[:, j], Xd[:, k]
        assert abs(np.vdot(a, b)) == pytest.approx(np.linalg.norm(a) * np.linalg.norm(b),
                                                   rel=1e-7)
    assert set(modes_of(form, 6).labels) <= set(LABELS)


def test_damping_ratios_are_minus_re_over_modulus():
    """SPEC section 10: ``damping_ratios`` = -Re lambda / |lambda| per mode; with the relative
    damping every mode of the rotating beam decays at about Re lambda = -c / (2 rho)
    (docs/stability.md), so the ratio is about c / (2 rho |lambda|)."""
    scene = load_scene(overrides=["rotation.rpm=1000"])
    m = modes_of(build("lebb", scene, None), 4)
    lam = m.eigenvalues
    assert m.damping_ratios == pytest.approx(-lam.real / np.abs(lam), rel=1e-14)
    sigma = scene.damping.c / (2 * scene.material.rho)
    assert m.damping_ratios == pytest.approx(sigma / np.abs(lam), rel=0.05)
    d = m.to_dict()
    assert len(d["damping_ratios"]) == len(d["frequencies_hz"]) == 4
