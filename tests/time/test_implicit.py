"""Generalised-alpha on systems with known answers: parameters, spectral radius, second order with
a prescribed coordinate and mass coupling, factor reuse, and every fallback of Newton's method."""

import math

import numpy as np
import pytest
from mpi4py import MPI
from scipy.integrate import solve_ivp

from fxflex.formulation import FormulationBase, SteadyState
from fxflex.numerics.qep import DenseLinearisation
from fxflex.scene import Scene
from fxflex.time import GeneralizedAlpha, diagnose, simulate
from fxflex.time.generalized_alpha import parameters


class _Factor:
    def __init__(self, form):
        self.form = form

    def solve(self, t, r, out):
        f = self.form.free
        out[:] = 0.0
        out[f] = np.linalg.solve(self.S, r[f])


class Chain(FormulationBase):
    """M q'' + C q' + K q = f(t) on three coordinates; q_0 = b sin(w t) is prescribed, and the mass
    couples it to the free ones (M_fc != 0), so F carries -M_fc q_0'' as the Implicit interface
    says. Rayleigh damping C = 0.02 K + 0.01 M."""

    method = "chain"

    def __init__(self, b=0.3, w=2.5):
        self.scene, self.dof, self.comm = Scene(), 2, MPI.COMM_SELF
        self.b, self.w = b, w
        self.M = np.array([[2.0, 0.5, 0.0], [0.5, 2.0, 0.3], [0.0, 0.3, 1.0]])
        self.K = np.array([[30.0, -20.0, 0.0], [-20.0, 35.0, -15.0], [0.0, -15.0, 15.0]])
        self.C = 0.02 * self.K + 0.01 * self.M
        self.free, self.con = np.array([1, 2]), 0
        self.factorizations = 0

    def drive(self, t):
        b, w = self.b, self.w
        return b * math.sin(w * t), b * w * math.cos(w * t), -b * w * w * math.sin(w * t)

    def load(self, t):
        return np.array([0.0, math.sin(3.0 * t), 0.5 * math.cos(2.0 * t)])

    def initial_state(self):
        q0, v0, _ = self.drive(0.0)
        return np.array([q0, 0.1, -0.05]), np.array([v0, 0.0, 0.0])

    def constrain(self, t, q, v):
        q[0], v[0], _ = self.drive(t)

    def force(self, t, q, v, out):
        f = self.free
        a0 = self.drive(t)[2]
        out[:] = self.load(t) - self.C @ v - self.K @ q - self.M[:, 0] * a0
        out[0] = 0.0
        return f

    def acceleration(self, t, q, v, out):
        f = self.free
        self.force(t, q, v, out)
        out[f] = np.linalg.solve(self.M[np.ix_(f, f)], out[f])
        out[0] = self.drive(t)[2]

    def mass_apply(self, x, out):
        f = self.free
        out[:] = 0.0
        out[f] = self.M[np.ix_(f, f)] @ x[f]

    def factorize(self, t, q, v, m, c, k):
        f = np.ix_(self.free, self.free)
        factor = _Factor(self)
        factor.S = m * self.M[f] + c * self.C[f] + k * self.K[f]
        self.factorizations += 1
        return factor

    def tip(self, t, q):
        return np.array([q[1], q[2], 0.0])

    def exact(self, times):
        """The free coordinates from a tight Runge-Kutta solution of the same equations."""
        def rhs(t, y):
            q, v = np.r_[0.0, y[:2]], np.r_[0.0, y[2:]]
            self.constrain(t, q, v)
            a = np.empty(3)
            self.acceleration(t, q, v, a)
            return np.r_[y[2:], a[1:]]
        q0, v0 = self.initial_state()
        # the reference solution, far more accurate than the errors (>= 1e-6) measured against it
        sol = solve_ivp(rhs, (0.0, times[-1]), np.r_[q0[1:], v0[1:]], method="DOP853",
                        t_eval=times, rtol=1e-12, atol=1e-14)
        return sol.y[:2].T


class Duffing(FormulationBase):
    """q'' = -q - k3 q^3 from q = 1 at rest: a tangent that changes by a factor 3 k3 over the
    swing, so a stale factor fails, and at large steps even a fresh one."""

    method = "duffing"

    def __init__(self, k3=1e4, nan_after=math.inf):
        self.scene, self.dof, self.comm = Scene(), 1, MPI.COMM_SELF
        self.k3, self.nan_after = k3, nan_after
        self._factor = _Factor(self)
        self.free = np.array([0])

    def initial_state(self):
        return np.array([1.0]), np.array([0.0])

    def constrain(self, t, q, v):
        pass

    def acceleration(self, t, q, v, out):
        out[:] = -q - self.k3 * q**3
        if t > self.nan_after:
            out[:] = math.nan

    force = acceleration

    def mass_apply(self, x, out):
        out[:] = x

    def factorize(self, t, q, v, m, c, k):
        self._factor.S = np.array([[m + k * (1.0 + 3.0 * self.k3 * q[0] ** 2)]])
        return self._factor

    def tip(self, t, q):
        return np.array([q[0], 0.0, 0.0])

    def steady_state(self):
        return SteadyState(tip=np.zeros(3), q=np.zeros(1))

    def linearise(self, steady=None):
        """About q = 0: x'' + x = 0 (the cubic term has no slope there)."""
        return DenseLinearisation(np.eye(1), np.zeros((1, 1)), np.eye(1))

    def omega_max(self):
        return 1.0


class Explicit(Duffing):
    """Duffing without the tangent: a formulation that offers only the explicit interface."""

    factorize = None


def test_a_formulation_without_the_implicit_interface_is_refused():
    with pytest.raises(TypeError, match=r"duffing does not offer .*factorize\(\) \(the Implicit"):
        simulate(Explicit(), "generalized-alpha", 0.01, 0.1, limit=10.0)


@pytest.mark.parametrize("rho", [0.0, 0.5, 0.9, 1.0])
def test_chung_hulbert_parameters(rho):
    """Chung & Hulbert (1993), Eq. 25-27: second order (gamma = 1/2 - am + af) and the high-frequency
    dissipation maximised (beta = (1 - am + af)^2 / 4); rho = 1 is the trapezoidal rule."""
    am, af, beta, gamma = parameters(rho)
    assert am == pytest.approx((2 * rho - 1) / (rho + 1))
    assert af == pytest.approx(rho / (rho + 1))
    assert gamma == pytest.approx(0.5 - am + af) and beta == pytest.approx((1 - am + af) ** 2 / 4)
    if rho == 1.0:
        assert (am, af, beta, gamma) == pytest.approx((0.5, 0.5, 0.25, 0.5))
    with pytest.raises(ValueError):
        parameters(1.1)


def amplification(rho, wh):
    """The one-step map of (q, v, a) for q'' = -w^2 q (w = 1, h = wh), column by column (q'' = -q
    holds after every step, so (q, v, a) is the whole state)."""
    form = Chain()
    form.M, form.C, form.K = np.eye(3), np.zeros((3, 3)), np.eye(3)
    form.b = 0.0
    form.load = lambda t: np.zeros(3)
    G = np.empty((3, 3))
    for j, e in enumerate(np.eye(3)):
        s = GeneralizedAlpha(rho)
        q, v = np.array([0.0, 1.0, 0.0]), np.zeros(3)
        s.start(form, 0.0, wh, q, v)            # sets up; the state is overwritten below
        q[:] = [0.0, e[0], 0.0]
        v[:] = [0.0, e[1], 0.0]
        s.qdd[:] = -q
        s.a[:] = [0.0, e[2], 0.0]
        s.step(form, 0.0, wh, q, v)
        G[:, j] = q[1], v[1], s.a[1]
    return G


@pytest.mark.parametrize("rho", [0.0, 0.5, 0.9, 1.0])
def test_spectral_radius_is_rho_inf_at_high_frequency(rho):
    """rho_inf controls the high-frequency dissipation: the spectral radius of the amplification
    matrix tends to rho_inf as w h -> infinity (triple root -rho_inf, hence the loose
    tolerance of a defective eigenvalue), while a resolved mode (w h = 0.01) keeps its amplitude
    to O((w h)^3)."""
    high = max(abs(np.linalg.eigvals(amplification(rho, 1e5))))
    low = max(abs(np.linalg.eigvals(amplification(rho, 1e-2))))
    assert high == pytest.approx(rho, abs=2e-3)
    # above 1 only by the round-off of a 3 x 3 eig
    assert 1.0 - 1e-6 <= low <= 1.0 + 1e-12
    if rho < 1.0:
        mid = max(abs(np.linalg.eigvals(amplification(rho, 10.0))))
        assert rho < mid < 1.0


@pytest.mark.parametrize("rho", [0.0, 0.5, 0.9, 1.0])
def test_second_order_on_a_linear_system_with_a_prescribed_coordinate(rho):
    errors = []
    for h in (0.02, 0.01, 0.005):
        form = Chain()
        res = simulate(form, "generalized-alpha", h, 4.0, keep_history=True, rho_inf=rho, limit=10.0,
                       scheme_options={"tol": 1e-10})
        # times are t0 + k dt (the driver), one rounding, not a sum of steps
        assert res.diverged is None and abs(res.t - 4.0) < 1e-12
        hist = np.array(res.history)
        errors.append(np.max(np.abs(hist[:, 1:3] - form.exact(hist[:, 0]))))
    order = np.log2(np.array(errors[:-1]) / errors[1:])
    assert np.all(np.abs(order - 2) < 0.1), (order, errors)
    assert errors[-1] < 1e-3


def test_the_factor_is_reused_on_a_linear_system():
    """Constant coefficients: one factorisation for the whole run, and most steps accepted after
    one iteration (the contraction is re-measured every ninth step)."""
    form = Chain()
    res = simulate(form, "generalized-alpha", 0.01, 4.0, rho_inf=0.9, limit=10.0)
    st = res.stats
    assert res.diverged is None and st["steps"] == 400
    assert st["factorizations"] == form.factorizations == 1
    assert st["retries"] == 0 and st["halvings"] == 0
    assert st["steps"] < st["iterations"] < 1.25 * st["steps"]


def step_by_step(form, h, steps):
    """Drive the scheme directly; after every step, the residual of the equation of motion at the
    new state, |qdd - F(q)|, relative to the largest force of the swing, 1 + k3 (q'' = F). Newton
    stops when its position error is below tol of the step's increment (< 2), and the tangent is
    below 3 (1 + k3), so the residual must stay below 6 tol (1 + k3)."""
    s = GeneralizedAlpha()
    q, v = form.initial_state()
    residuals, f = [], np.empty(1)
    for k in range(steps):
        (s.start if k == 0 else s.step)(form, k * h, h, q, v)
        form.force((k + 1) * h, q, v, f)
        residuals.append(abs(s.qdd[0] - f[0]) / (1.0 + form.k3))
    return s.stats, np.array(residuals) / (6.0 * s.tol)


def test_a_stale_factor_is_renewed_when_newton_fails():
    """Duffing at h = 0.01 (w h up to 2): the tangent of an earlier step fails as the spring
    stiffens; the step is retried with a fresh factor, never halved, and every accepted state
    satisfies the equation of motion."""
    st, res = step_by_step(Duffing(), 0.01, 50)
    assert st["retries"] > 0 and st["halvings"] == 0 and st["steps"] == 50
    assert 1 < st["factorizations"] < 50
    assert res.max() < 1.0, res.max()


def test_a_step_that_fails_with_a_fresh_factor_is_halved():
    """At h = 0.05 modified Newton fails even with the tangent of the step's predictor: the step
    is cut (recursively) and completed; the states at the full steps satisfy the equation."""
    st, res = step_by_step(Duffing(), 0.05, 10)
    assert st["halvings"] > 0 and st["steps"] == 10
    assert res.max() < 1.0, res.max()
    run = simulate(Duffing(), "generalized-alpha", 0.05, 0.5, limit=10.0)
    assert run.diverged is None and run.steps == 10 and run.stats == st


def test_newton_failure_stops_the_run_with_a_diagnosis():
    """A force that turns NaN after t = 0.2: every halving fails, the run stops there with the
    last converged (finite) state and a reason naming Newton; diagnose calls it numerical."""
    form = Duffing(k3=0.0, nan_after=0.2)
    samples = []
    res = simulate(form, "generalized-alpha", 0.01, 1.0, limit=10.0, on_sample=lambda t, tip, ex, q:
                   samples.append((t, tip[0])))
    assert res.diverged is not None and "Newton did not converge" in res.diverged["reason"]
    assert res.stats["halvings"] == GeneralizedAlpha().max_halvings
    assert 0.2 <= res.diverged["time_s"] <= 0.21 and 0.19 <= res.t < res.diverged["time_s"]
    assert np.isfinite(res.tip).all() and np.isfinite(samples).all() and samples[-1][0] == res.t
    assert abs(res.tip[0] - math.cos(res.t)) < 1e-3
    out = diagnose(form, "generalized-alpha", 0.01, res)
    assert out["cause"] == "numerical" and "Newton" in out["detail"]


def test_a_singular_iteration_matrix_cuts_the_step():
    """A factorisation that fails (as LAPACK or MUMPS do on a singular S) counts as a failed step:
    the step is halved and the run goes on with the factor of the half step."""
    form = Duffing(k3=1.0)
    calls = []
    original = form.factorize

    def factorize(t, q, v, m, c, k):
        calls.append(k)
        if len(calls) == 1:
            raise np.linalg.LinAlgError("singular")
        return original(t, q, v, m, c, k)

    form.factorize = factorize
    res = simulate(form, "generalized-alpha", 1e-3, 0.01, limit=10.0)
    assert res.diverged is None and res.stats["halvings"] == 1 and res.steps == 10
    assert calls[1] == pytest.approx(calls[0] / 4)       # k ~ h^2: the half step's factor


def test_round_off_convergence_is_not_trusted_as_a_zero_contraction():
    """After an iteration that converged to round-off (a linear system, an exact factor: the
    second correction is below 1e-13 |q|), the contraction trusted at k = 1 of the next steps is
    the bound that round-off gives, floor / previous correction, not 0: with 0 the next step's
    first correction was accepted whatever its size, so a tight ``atol`` (the adaptive driver's
    bound on Newton's error) was bypassed. Here the first step converges at k = 2 to round-off;
    with atol tiny the next step must iterate again, where a trusted 0 took one iteration."""
    form = Chain()
    scheme = GeneralizedAlpha(0.9)
    q, v = form.initial_state()
    scheme.begin(form, 0.0, q, v)
    scheme.step(form, 0.0, 0.01, q, v)
    assert scheme.stats["iterations"] == 2 and 0.0 < scheme._eta < 1e-6
    scheme.atol = 1e-300
    before = scheme.stats["iterations"]
    scheme.step(form, 0.01, 0.01, q, v)
    assert scheme.stats["iterations"] - before >= 2
    scheme.atol = math.inf                  # the default test: one iteration on the trusted bound
    before = scheme.stats["iterations"]
    scheme.step(form, 0.02, 0.01, q, v)
    assert scheme.stats["iterations"] - before == 1
