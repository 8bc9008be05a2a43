"""Step limits on one mode from the schemes' own code, against closed forms."""

import math

import numpy as np
import pytest

from fxflex.time.diagnosis import measured_growth_rate
from fxflex.time.step_stability import (ab2_law_rate, ab2_law_step, amplification, critical_step,
                                   growth_rate, step_map)


def ab2_principal_root(hl: complex) -> float:
    """Larger |root| of z^2 - (1 + 3/2 h lambda) z + 1/2 h lambda = 0."""
    return max(abs(z) for z in np.roots([1.0, -(1 + 1.5 * hl), 0.5 * hl]))


@pytest.mark.parametrize("hw", [0.03, 0.24, 0.48, 1.0])
@pytest.mark.parametrize("d", [0.0, 500.0])
def test_ab2_map_has_the_characteristic_roots(hw, d):
    w = 1e5
    h = hw / w
    lam = -d / 2 + 1j * math.sqrt(w * w - d * d / 4)
    # the map's spectral radius (dense eig of a 3 x 3 map) against the closed-form root: round-off
    assert amplification("ab2", h, w, d) == pytest.approx(ab2_principal_root(h * lam), rel=1e-12)


def test_ab2_law_is_the_small_step_limit():
    w = 1e5
    # h w = 0.03: law and root agree to 0.2 %; at 0.24 and 0.48 the law is 11 % and 38 % low
    for hw, low in ((0.03, 0.002), (0.24, 0.11), (0.48, 0.38)):
        exact, law = growth_rate("ab2", hw / w, w), ab2_law_rate(w, hw / w)
        assert (exact - law) / exact == pytest.approx(low, abs=0.005)
    h = ab2_law_step(w, window=0.01, log_growth=1.0)
    assert ab2_law_rate(w, h) * 0.01 == pytest.approx(1.0)
    # the exact root reaches e over the window at a slightly smaller step than the law says
    assert 0.95 * h < critical_step("ab2", w, window=0.01) < h


def test_central_difference_limit():
    w = 2e5
    assert critical_step("cd", w) * w == pytest.approx(2.0, rel=1e-5)
    assert amplification("cd", 1.99 / w, w) == pytest.approx(1.0, abs=1e-12)
    assert amplification("cd", 2.01 / w, w) > 1.1
    # damping lowers it: the damping force sees v_n ~ v_{n-1/2} + h/2 a_{n-1}, whose recurrence
    # under pure damping is AB2's: limit h d = 1 (not leapfrog's ideal 2)
    assert critical_step("cd", w, 0.1 * w) * w < 1.9
    # the map's characteristic polynomial 2 z^3 + (2 h^2 w^2 + 3 d h - 4) z^2 + (2 - 4 d h) z
    # + d h has its root z = -1 where h^2 w^2 + 4 d h = 4: h = 2 (sqrt(w^2 + d^2) - d) / w^2
    for d in (1e-3 * w, 0.5 * w, 3 * w, 50 * w):
        assert critical_step("cd", w, d, rtol=1e-10) == pytest.approx(
            2 * (math.sqrt(w * w + d * d) - d) / w**2, rel=1e-8)
    assert critical_step("cd", 1.0, 1e6) * 1e6 == pytest.approx(1.0, rel=1e-4)
    assert critical_step("ab2", 1.0, 1e6, window=1.0, log_growth=1e-9) * 1e6 == \
        pytest.approx(1.0, rel=1e-3)


@pytest.mark.parametrize("scheme", ["ab2", "cd"])
def test_step_map_is_the_code_that_runs(scheme):
    """Twenty steps of the map equal twenty steps of the scheme on the oscillator."""
    from fxflex.time import make_scheme

    w, zeta, h = 3.0, 0.1, 0.05

    class Oscillator:
        def constrain(self, t, q, v):
            pass

        def acceleration(self, t, q, v, out):
            out[0] = -w * w * q[0] - 2 * zeta * w * v[0]

    osc = Oscillator()
    q, v = np.array([0.2]), np.array([0.0])
    s = make_scheme(scheme)
    s.start(osc, 0.0, h, q, v)

    def vector():
        return np.array([q[0], v[0], *(a[0] for a in s.state_arrays().values())])

    y0 = vector()
    for k in range(1, 21):
        s.step(osc, k * h, h, q, v)
    T = step_map(scheme, h, w, 2 * zeta * w)
    # 20 steps of the map and of the scheme: the same arithmetic, round-off ~ 20 x few eps
    np.testing.assert_allclose(np.linalg.matrix_power(T, 20) @ y0, vector(), rtol=1e-12,
                               atol=1e-15)


def test_measured_growth_rate_tells_exponentials_from_power_laws():
    t = np.linspace(0.0, 0.01, 200)
    assert measured_growth_rate(np.column_stack([t, 1e-6 * np.exp(800.0 * t)])) == \
        pytest.approx(800.0, rel=1e-6)
    assert measured_growth_rate(np.column_stack([t[1:], t[1:] ** 2])) is None
    assert measured_growth_rate(np.column_stack([t, np.full_like(t, 1e-3)])) is None


@pytest.mark.parametrize("rho_inf", [0.5, 0.9, 1.0])
def test_generalized_alpha_has_no_step_limit(rho_inf):
    """The implicit scheme's one-mode map (its own Newton on a one-dof Implicit formulation):
    spectral radius <= 1 at every h w, tending to rho_inf."""
    radii = [amplification("generalized-alpha", hw, 1.0, 0.0, rho_inf=rho_inf)
             for hw in np.logspace(-2, 5, 29)]
    # unconditionally stable: spectral radius at most 1 up to round-off of a 3 x 3 eig
    assert max(radii) <= 1.0 + 1e-12
    assert radii[-1] == pytest.approx(rho_inf, abs=2e-3)
    assert critical_step("cd", 1.0) == pytest.approx(2.0, rel=1e-5)     # for contrast
