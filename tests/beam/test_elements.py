"""Shape functions tabulated by basix against the paper's closed forms (Eq. 37 and Eq. 52)."""

import numpy as np
import pytest
import sympy as s

from fxflex.beam.elements import ancf_tables, hermite, lebb_tables, linear

XI = np.linspace(0.0, 1.0, 7)
LE = 0.137

xi, le, X, Y, Z = s.symbols("xi l_e X Y Z")
# paper Eq. 37
PAPER_LEBB = {"N1i": 1 - xi, "N1j": xi, "N2i": 1 - 3 * xi**2 + 2 * xi**3,
              "N2j": 3 * xi**2 - 2 * xi**3, "N3i": le * (xi - 2 * xi**2 + xi**3),
              "N3j": le * (xi**3 - xi**2), "N4i": (-6 * xi + 6 * xi**2) / le,
              "N4j": (6 * xi - 6 * xi**2) / le, "N5i": 1 - 4 * xi + 3 * xi**2,
              "N5j": 3 * xi**2 - 2 * xi}
# paper Eq. 52 (n = 2), with the Pascal triangle of Eq. 51
PAPER_ANCF_1D = {"N1i": 1 - 3 * xi**2 + 2 * xi**3, "N2i": le * (xi - 2 * xi**2 + xi**3),
                 "N3i": 1 - xi, "N1j": 3 * xi**2 - 2 * xi**3, "N2j": le * (-xi**2 + xi**3),
                 "N3j": xi}
PASCAL = [1, Y, Z, Y**2, Y * Z, Z**2]


def ev(expr, xs, **subs):
    """Evaluate a sympy expression of xi (and Y, Z) at points, d/dX = d/dxi / l_e applied by
    the caller."""
    f = s.lambdify((xi, le, Y, Z), expr, "numpy")
    return np.broadcast_to(np.asarray(f(xs, LE, subs.get("y", 0.0), subs.get("z", 0.0)), float),
                           np.shape(xs))


def d_dX(expr, k=1):
    return s.diff(expr, xi, k) / le**k


def test_hermite_and_linear_match_paper_with_derivatives():
    H, P = hermite(XI, LE, 2), linear(XI, LE, 1)
    names = ["N2i", "N3i", "N2j", "N3j"]
    for k in range(3):
        for col, name in enumerate(names):
            # shape functions against closed forms (sympy): round-off of polynomial evaluation
            np.testing.assert_allclose(H[k][:, col], ev(d_dX(PAPER_LEBB[name], k), XI),
                                       atol=1e-12 * LE**-k)
    for k in range(2):
        for col, name in enumerate(["N1i", "N1j"]):
            np.testing.assert_allclose(P[k][:, col], ev(d_dX(PAPER_LEBB[name], k), XI),
                                       atol=1e-13 * LE**-k)
    # N_4E and N_5E are the derivatives of N_2E and N_3E (Eq. 37)
    for name, base in (("N4i", "N2i"), ("N4j", "N2j"), ("N5i", "N3i"), ("N5j", "N3j")):
        assert s.simplify(PAPER_LEBB[name] - d_dX(PAPER_LEBB[base])) == 0


def test_lebb_shape_matrix_layout():
    """Rows of N_E (Eq. 37) reproduce the paper's 6 x 6 node blocks."""
    t = lebb_tables(XI, LE)
    for node, sfx in ((0, "i"), (1, "j")):
        o = 6 * node
        P = {k: ev(v, XI) for k, v in PAPER_LEBB.items() if k.endswith(sfx)}
        p = lambda n: P[n + sfx]
        expect = np.zeros((len(XI), 6, 6))
        expect[:, 0, 0] = p("N1")
        expect[:, 1, 1], expect[:, 1, 5] = p("N2"), p("N3")
        expect[:, 2, 2], expect[:, 2, 4] = p("N2"), -p("N3")
        expect[:, 3, 3] = p("N1")
        expect[:, 4, 2], expect[:, 4, 4] = -p("N4"), p("N5")
        expect[:, 5, 1], expect[:, 5, 5] = p("N4"), p("N5")
        np.testing.assert_allclose(t.N[:, :, o:o + 6], expect, atol=1e-11)


@pytest.mark.parametrize("y,z", [(0.0, 0.0), (0.03, -0.02), (-0.05, 0.01)])
def test_ancf_shape_functions_match_eq52(y, z):
    tab = ancf_tables(XI, np.full_like(XI, y), np.full_like(XI, z), LE)
    for node, sfx in ((0, "i"), (1, "j")):
        o = 7 * node
        funcs = [PAPER_ANCF_1D["N1" + sfx], PAPER_ANCF_1D["N2" + sfx]] + \
                [g * PAPER_ANCF_1D["N3" + sfx] for g in PASCAL[1:]]
        for a, f in enumerate(funcs):
            np.testing.assert_allclose(tab.N[:, o + a], ev(f, XI, y=y, z=z), atol=1e-12)
            for j, var in enumerate((None, Y, Z)):
                df = d_dX(f) if var is None else s.diff(f, var)
                np.testing.assert_allclose(tab.dN[:, o + a, j], ev(df, XI, y=y, z=z),
                                           atol=1e-11)
