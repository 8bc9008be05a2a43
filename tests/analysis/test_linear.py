"""The dense quadratic eigenproblem and the two-DOF system of Eq. 61-64."""

import math
import pathlib
import subprocess
import sys

import numpy as np
import pytest

from fxflex.numerics.qep import (companion_eigenvalues, conjugate_pairs, quadratic_eigen,
                                    unstable)
from fxflex.analysis.twodof import (CASES, behaviour, case_systems, eq63_roots, integrate,
                                    measured_growth)

ROOT = pathlib.Path(__file__).parents[2]


def test_damped_oscillators_closed_form():
    """Two uncoupled oscillators, lambda = -zeta w +- i w sqrt(1 - zeta^2), and one overdamped:
    one root per pair (real roots each), lowest frequency first."""
    M = np.diag([2.0, 1.0, 1.0])
    K = np.diag([2.0 * 9.0, 100.0, 1.0])
    C = np.diag([2.0 * 0.6, 2.0, 5.0])
    lam, X = quadratic_eigen(M, C, K)
    keep = conjugate_pairs(lam)
    expected = [(-2.5 + math.sqrt(5.25), 0.0), (-2.5 - math.sqrt(5.25), 0.0),
                (-0.3, 3 * math.sqrt(1 - 0.01)), (-1.0, 10 * math.sqrt(1 - 0.01))]
    # a 6 x 6 companion matrix with roots of size ~10: dense eig to ~ eps ||A|| cond, well below
    # 1e-12
    np.testing.assert_allclose(np.c_[lam[keep].real, lam[keep].imag], expected, atol=1e-12)
    # the displacement part of each eigenvector solves the quadratic problem
    for k in keep:
        r = (lam[k] ** 2 * M + lam[k] * C + K) @ X[:, k]
        # backward-stable eig: residual ~ eps ||companion|| ||x||, ||companion|| ~ ||K|| here
        assert np.linalg.norm(r) < 1e-12 * np.linalg.norm(K) * np.linalg.norm(X[:, k])
    assert not unstable(lam)
    assert unstable(companion_eigenvalues(M, C, -K))


def test_eq63_against_the_companion_form_and_the_paper_verdicts():
    """Eq. 63 gives the four roots of Eq. 62 in every case; the paper's verdicts without damping;
    NOTES.md's corrections: case 4 is negative semi-definite, and relative damping turns case 1
    unstable (Kelvin-Tait-Chetaev) while absolute damping does not."""
    for n, s in case_systems().items():
        lam = s.eigenvalues()
        roots = eq63_roots(s.k1, s.k2, s.omega)
        assert all(np.abs(roots - x).min() < 1e-7 for x in lam)
        assert s.stable() == (CASES[n][1] == "stable")
        assert s.eq64_stable() == (n == 3)
    assert case_systems()[4].stiffness_definiteness() == "negative semi-definite"
    assert case_systems()[5].stiffness_definiteness() == "positive semi-definite"
    damped = case_systems(c=0.1)
    assert [damped[n].stable() for n in (1, 2, 3, 4)] == [False, False, True, False]
    assert case_systems(c=0.1, damping="absolute")[1].stable()


def test_eq61_in_time_grows_as_the_eigenvalues_say():
    """Eq. 61 (inertial frame, rotating stiffness) through the generic driver: case 2 grows at its
    positive root, case 4 linearly (double zero root). The demo checks the other cases."""
    s = case_systems()
    g2 = measured_growth(integrate(s[2], t_end=60.0))
    assert behaviour(g2) == "exponential"
    assert g2["rate"] == pytest.approx(s[2].eigenvalues().real.max(), rel=1e-3)
    g4 = measured_growth(integrate(s[4]))
    assert behaviour(g4) == "polynomial" and g4["power"] == pytest.approx(1.0, abs=0.05)


@pytest.mark.serial       # a child of an mpirun'd process would inherit its MPI environment
def test_twodof_demo_runs():
    p = subprocess.run([sys.executable, str(ROOT / "demos" / "twodof_stability.py")],
                       capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    assert "damped case 1: eigenvalue growth" in p.stdout
