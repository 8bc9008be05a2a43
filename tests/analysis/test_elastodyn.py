"""ElastoDyn mode-shape polynomials (SPEC section 10) against the closed-form cantilever modes."""

import numpy as np
import pytest
from scipy.optimize import brentq

from fxflex.analysis.elastodyn import (POWERS, SHAPES, choose_modes, elastodyn_section,
                                       fit_mode_shape, polynomial, write_elastodyn)


def cantilever_mode(n: int, xi: np.ndarray) -> np.ndarray:
    """The n-th Euler-Bernoulli clamped-free bending mode at xi = x / L (unit length)."""
    guess = (2 * n - 1) * np.pi / 2
    bl = brentq(lambda b: 1 + np.cos(b) * np.cosh(b), guess - 0.6, guess + 0.6)
    s = (np.cosh(bl) + np.cos(bl)) / (np.sinh(bl) + np.sin(bl))
    b = bl * xi
    return np.cosh(b) - np.cos(b) - s * (np.sinh(b) - np.sin(b))


@pytest.mark.parametrize("n", [1, 2])
def test_fit_of_the_cantilever_modes(n):
    x = np.linspace(0.0, 2.5, 41)                 # a 2.5 m blade, 40 beam elements
    fit = fit_mode_shape(x, -3.0 * cantilever_mode(n, x / 2.5), name="shape")
    assert np.sum(fit.coefficients) == pytest.approx(1.0, abs=1e-12)
    exact = cantilever_mode(n, x / 2.5) / cantilever_mode(n, np.array([1.0]))[0]
    misfit = polynomial(fit.coefficients, x / 2.5) - exact
    rms = np.sqrt(np.trapz(misfit**2, x / 2.5))
    assert fit.residual == pytest.approx(rms, rel=1e-6)
    # the polynomial's own error (no round-off involved): 1.5e-6 for mode 1, 3.0e-4 for mode 2
    # (the series of the modes go on with xi^7 (beta L)^7 / 2520, beta L = 1.875, 4.694), 2.2e-2
    # for mode 3, which the six terms cannot follow
    assert fit.residual < {1: 1e-5, 2: 2e-3}[n]
    assert abs(polynomial(fit.coefficients, 0.5) - exact[20]) < 5 * fit.residual


def test_polynomial_data_is_fitted_exactly():
    c = np.array([0.3, 1.2, -0.9, 0.5, -0.1])
    x = np.sort(np.random.default_rng(1).uniform(0.0, 1.0, 30))
    x[-1] = 1.0
    fit = fit_mode_shape(x, 7.0 * polynomial(c, x))
    assert np.allclose(fit.coefficients, c, atol=1e-9)
    assert fit.residual < 1e-10


def test_bad_shapes_are_refused():
    x = np.linspace(0.0, 1.0, 4)
    with pytest.raises(ValueError, match="at least 5"):
        fit_mode_shape(x, x**2)
    x = np.linspace(0.0, 1.0, 10)
    with pytest.raises(ValueError, match="tip deflection"):
        fit_mode_shape(x, np.sin(np.pi * x))


def test_modes_chosen_by_family_and_frequency():
    part = [{"axial": 0, "in-plane": 0.1, "out-of-plane": 0.9, "torsion": 0},
            {"axial": 0, "in-plane": 0.8, "out-of-plane": 0.2, "torsion": 0},
            {"axial": 0, "in-plane": 0.0, "out-of-plane": 0.1, "torsion": 0.9},
            {"axial": 0, "in-plane": 0.0, "out-of-plane": 1.0, "torsion": 0}]
    chosen = choose_modes(part, [10.0, 20.0, 25.0, 30.0])
    assert chosen == {"BldFl1Sh": 0, "BldFl2Sh": 3, "BldEdgSh": 1}
    assert "BldFl2Sh" not in choose_modes(part[:3], [10.0, 20.0, 25.0])


def test_section_layout(tmp_path):
    x = np.linspace(0.0, 1.0, 21)
    fits = [fit_mode_shape(x, cantilever_mode(1 + (stem == "BldFl2Sh"), x), name=stem)
            for stem, *_ in SHAPES]
    text = elastodyn_section(fits, "fitted by fxflex")
    lines = text.splitlines()
    assert lines[0].startswith("---") and "BLADE MODE SHAPES" in lines[0]
    values = [ln for ln in lines if "coeff of x^" in ln]
    assert len(values) == 15
    assert values[0].split()[1] == "BldFl1Sh(2)" and values[-1].split()[1] == "BldEdgSh(6)"
    for stem, *_ in SHAPES:
        got = [float(ln.split()[0]) for ln in values if ln.split()[1].startswith(stem)]
        assert len(got) == len(POWERS) and sum(got) == pytest.approx(1.0, abs=1e-6)
    path = tmp_path / "blade.dat"
    write_elastodyn(str(path), fits)
    assert path.read_text() == elastodyn_section(fits)
    assert [p.name for p in tmp_path.iterdir()] == ["blade.dat"]
