"""The stability verdict under heavy damping (issue 11, section 7: ``--damping 1e30`` reported
``stable: true`` next to growth rates of +2.2e10 1/s): accurate roots from the tropically scaled
quadratic eigenproblem, and a verdict that agrees with them."""

import json
import math

import numpy as np
import pytest
import scipy.linalg as la

from fxflex.numerics.qep import companion, conjugate_pairs, quadratic_eigen
from fxflex.cli import main


def cli(capsys, *args):
    code = main(list(args))
    out, err = capsys.readouterr()
    return code, out, err


def test_heavily_damped_roots_are_accurate():
    """Three overdamped oscillators x'' + d x' + w^2 x = 0 coupled by a rotation of the
    coordinates (K = Q diag(w^2) Q^T): roots -d/2 +- sqrt(d^2/4 - w^2), about -d and -w^2/d. At
    d = 1e26 the companion form loses the small ones (eps ||M^-1 C|| = 2e10 1/s, the issue's
    +2.2e10); the tropical scaling gets both to 1e-12 relative."""
    w2 = np.array([1.0e4, 3.0e6, 1.2e11])
    d = 1.0e26
    Q = la.qr(np.random.default_rng(7).standard_normal((3, 3)))[0]
    M, C, K = np.eye(3), d * np.eye(3), Q @ np.diag(w2) @ Q.T
    small = -2.0 * w2 / (d + np.sqrt(d * d - 4.0 * w2))      # stable form of the small root
    big = -d - small
    plain = np.sort(la.eigvals(companion(M, C, K)).real)       # what went wrong before
    assert not np.allclose(plain[3:], np.sort(small), rtol=1e-3, atol=0.0)
    lam, X = quadratic_eigen(M, C, K)
    got = np.sort(lam.real)
    np.testing.assert_allclose(got, np.sort(np.concatenate([big, small])), rtol=1e-12)
    assert np.abs(lam.imag).max() == 0.0
    for k in range(lam.size):          # each vector solves P(lambda) x = 0 to round-off
        r = (lam[k] ** 2 * M + lam[k] * C + K) @ X[:, k]
        scale = abs(lam[k]) ** 2 + abs(lam[k]) * d + w2.max()
        assert np.linalg.norm(r) < 1e-14 * scale * np.linalg.norm(X[:, k])
    assert conjugate_pairs(lam).size == 6


@pytest.mark.serial    # checks the CLI's output, which only rank 0 prints
@pytest.mark.parametrize("c", ["1e30", "1e12"])
def test_heavy_damping_verdict_matches_the_growth_rates(capsys, c):
    """Rotating frame, relative damping c/rho M: M > 0, K > 0 at 1000 rpm and a positive
    definite damping make the equilibrium asymptotically stable (Thomson-Tait-Chetaev); the
    creeping roots are about -w^2 rho / c and every growth rate is negative."""
    code, out, err = cli(capsys, "modes", "--method", "lebb", "--damping", c, "--n", "6",
                         "--json")
    assert code == 0, err
    d = json.loads(out)
    g = np.array(d["growth_rates"])
    assert d["stable"] is True and (g < 0).all()
    w = 2 * math.pi * 59.37                      # the lowest bending mode at 1000 rpm
    assert g.max() == pytest.approx(-w * w * 7850.0 / float(c), rel=0.05)
    code, out, err = cli(capsys, "steady", "--method", "lebb", "--damping", c, "--json")
    assert code == 0 and json.loads(out)["stable"] is True


@pytest.mark.serial    # checks the CLI's output, which only rank 0 prints
def test_absolute_damping_that_buries_the_stiffness_is_undecided(capsys):
    """Absolute damping c = 1e30 adds the circulatory (c/rho) Omega M_S, norm 6e28, to a
    stiffness of norm 6e11: K_T is below eps times it and the creeping roots (1e-11 1/s, both
    signs) are round-off. No verdict then, with the reason; the undamped model's roots on the
    imaginary axis (real parts 1e-11 too, but resolved) stay a stable verdict."""
    code, out, err = cli(capsys, "modes", "--method", "lebb", "--damping", "1e30",
                         "--damping-model", "absolute", "--n", "4", "--json")
    assert code == 0, err
    d = json.loads(out)
    assert d["stable"] is None and max(d["growth_rates"]) > 0
    assert d["warnings"][0].startswith("stability not decided: ") and "round-off" in err
    code, out, err = cli(capsys, "modes", "--method", "lebb", "--damping", "0", "--n", "4",
                         "--json")
    d = json.loads(out)
    assert d["stable"] is True and d["warnings"] == [] and max(map(abs, d["growth_rates"])) < 1e-9
