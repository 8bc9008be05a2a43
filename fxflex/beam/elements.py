"""Beam shape functions, tabulated once with basix.

Two one-dimensional elements on the reference interval xi in [0, 1] (xi = X~ / l_e):

- cubic Hermite (basix ``Hermite``, degree 3), C1: for the bending deflections W_Y, W_Z of
  LEBB/NEBB (paper Eq. 37: N_2E, N_3E and their derivatives N_4E = N_2E', N_5E = N_3E') and for the
  ANCF centerline (Eq. 52: N_1, N_2);
- linear Lagrange (basix ``P``, degree 1): for W_X and theta_X (Eq. 37: N_1E) and for the ANCF
  cross-section gradients (Eq. 52: N_3).

basix orders the Hermite basis as (value at 0, derivative at 0, value at 1, derivative at 1) and
maps with the identity, so the physical slope functions are l_e times the reference ones and every
derivative along X carries 1 / l_e. The closed forms of the paper are checked against these
tables in ``tests/beam/test_elements.py``.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import basix
import numpy as np

__all__ = ["gauss", "hermite", "linear", "LebbTables", "lebb_tables", "AncfTables", "ancf_tables",
           "ANCF_SLOTS", "pascal2"]

#: the seven nodal "slots" of the second-order ANCF node (Eq. 50-51): position, d/dX~, then the
#: Pascal-triangle gradients 1, Y~, Z~, Y~^2, Y~Z~, Z~^2 (the first is the position itself)
ANCF_SLOTS = ("r", "r_X", "r_Y", "r_Z", "r_YY", "r_YZ", "r_ZZ")


def gauss(n: int) -> tuple[np.ndarray, np.ndarray]:
    """n-point Gauss rule on [0, 1] (exact to degree 2n - 1): points, weights."""
    pts, wts = basix.make_quadrature(basix.CellType.interval, 2 * n - 1)
    pts = np.asarray(pts, float)[:, 0]
    if pts.size != n:   # pragma: no cover - basix picks Gauss-Jacobi with exactly n points
        raise RuntimeError(f"basix returned {pts.size} points for a {n}-point rule")
    return pts, np.asarray(wts, float)


def _tabulate(family, degree: int, nderiv: int, xi: np.ndarray) -> np.ndarray:
    """Reference-interval tabulation (nderiv + 1, npoints, ndofs), read-only: every level of a
    ``--tol`` ladder tabulates at the same points, so it is kept (callers copy before scaling)."""
    xi = np.asarray(xi, float)
    return _tabulate_cached(family, degree, nderiv, xi.tobytes())


@functools.lru_cache(maxsize=64)
def _tabulate_cached(family, degree: int, nderiv: int, xi: bytes) -> np.ndarray:
    element = basix.create_element(family, basix.CellType.interval, degree)
    tab = np.array(element.tabulate(nderiv, np.frombuffer(xi).reshape(-1, 1))[..., 0])
    tab.flags.writeable = False
    return tab


def hermite(xi: np.ndarray, le: float, nderiv: int = 2) -> np.ndarray:
    """Physical cubic Hermite functions [value_i, slope_i, value_j, slope_j] and their X-derivatives
    at xi: array (nderiv + 1, npoints, 4). Paper Eq. 37: N_2Ei, N_3Ei, N_2Ej, N_3Ej (and Eq. 52:
    N_1i, N_2i, N_1j, N_2j), slopes scaled by l_e; derivative k carries l_e^-k."""
    tab = _tabulate(basix.ElementFamily.Hermite, 3, nderiv, xi).copy()
    tab[:, :, [1, 3]] *= le
    for k in range(1, nderiv + 1):
        tab[k] /= le**k
    return tab


def linear(xi: np.ndarray, le: float, nderiv: int = 1) -> np.ndarray:
    """Physical linear functions [1 - xi, xi] and X-derivatives: (nderiv + 1, npoints, 2).
    Paper Eq. 37 N_1Ei, N_1Ej and Eq. 52 N_3i, N_3j."""
    tab = _tabulate(basix.ElementFamily.P, 1, nderiv, xi).copy()
    for k in range(1, nderiv + 1):
        tab[k] /= le**k
    return tab


@dataclass(frozen=True)
class LebbTables:
    """LEBB/NEBB element arrays at the quadrature points of one element (all elements have the
    same length): N_E (Eq. 37), the generalized strains of Eq. 40 and the slopes of Eq. 45."""

    N: np.ndarray        # (nq, 6, 12): W_f = N_E W_fe, rows W_X W_Y W_Z th_X th_Y th_Z
    B: np.ndarray        # (nq, 4, 12): L_2 N_E, rows W_X', W_Z'', W_Y'', th_X'
    dY: np.ndarray       # (nq, 12): W_Y' = dY . W_fe
    dZ: np.ndarray       # (nq, 12): W_Z' = dZ . W_fe
    d: np.ndarray        # (nq, 4): the four Hermite derivatives [N2i', N3i', N2j', N3j']


def lebb_tables(xi: np.ndarray, le: float) -> LebbTables:
    """Tabulate the LEBB shape matrix N_E(xi) of Eq. 37 (6 x 12, nodes i and j, six coordinates
    W_X, W_Y, W_Z, theta_X, theta_Y, theta_Z each) and the strain operators of Eq. 40/45."""
    H = hermite(xi, le, 2)
    P = linear(xi, le, 1)
    nq = len(xi)
    N = np.zeros((nq, 6, 12))
    B = np.zeros((nq, 4, 12))
    dY = np.zeros((nq, 12))
    dZ = np.zeros((nq, 12))
    for node in (0, 1):
        o = 6 * node
        n1, n2, n3 = P[0][:, node], H[0][:, 2 * node], H[0][:, 2 * node + 1]
        n4, n5 = H[1][:, 2 * node], H[1][:, 2 * node + 1]     # N_4E = N_2E', N_5E = N_3E'
        N[:, 0, o + 0] = n1
        N[:, 1, o + 1], N[:, 1, o + 5] = n2, n3
        N[:, 2, o + 2], N[:, 2, o + 4] = n2, -n3
        N[:, 3, o + 3] = n1
        N[:, 4, o + 2], N[:, 4, o + 4] = -n4, n5
        N[:, 5, o + 1], N[:, 5, o + 5] = n4, n5
        B[:, 0, o + 0] = P[1][:, node]
        B[:, 1, o + 2], B[:, 1, o + 4] = H[2][:, 2 * node], -H[2][:, 2 * node + 1]
        B[:, 2, o + 1], B[:, 2, o + 5] = H[2][:, 2 * node], H[2][:, 2 * node + 1]
        B[:, 3, o + 3] = P[1][:, node]
        dY[:, o + 1], dY[:, o + 5] = n4, n5
        dZ[:, o + 2], dZ[:, o + 4] = n4, -n5
    return LebbTables(N=N, B=B, dY=dY, dZ=dZ, d=H[1].copy())


def pascal2(y: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Pascal-triangle polynomials of order 2 (Eq. 51): g = [1, Y~, Z~, Y~^2, Y~ Z~, Z~^2] and
    their derivatives: array (3, npoints, 6) = (g, dg/dY~, dg/dZ~)."""
    y, z = np.broadcast_arrays(np.asarray(y, float), np.asarray(z, float))
    one, zero = np.ones_like(y), np.zeros_like(y)
    g = np.stack([one, y, z, y * y, y * z, z * z], -1)
    gy = np.stack([zero, one, zero, 2 * y, z, zero], -1)
    gz = np.stack([zero, zero, one, zero, y, 2 * z], -1)
    return np.stack([g, gy, gz])


@dataclass(frozen=True)
class AncfTables:
    """Scalar ANCF shape functions of Eq. 52 at points (xi, Y~, Z~) of one element: 14 functions,
    7 per node in the order of ``ANCF_SLOTS``; each multiplies I_3 in N(X~)."""

    N: np.ndarray        # (npoints, 14)
    dN: np.ndarray       # (npoints, 14, 3): d/dX~, d/dY~, d/dZ~


def ancf_tables(xi: np.ndarray, y: np.ndarray, z: np.ndarray, le: float) -> AncfTables:
    """Eq. 52 with n = 2: node k contributes N_1k (position), N_2k (d/dX~) and g_{i,a} N_3k for the
    five cross-section gradients, g from Eq. 51. Cubic Hermite in X~ for the centerline, linear
    for the section gradients."""
    H = hermite(xi, le, 1)
    P = linear(xi, le, 1)
    G = pascal2(y, z)
    npts = len(xi)
    N = np.zeros((npts, 14))
    dN = np.zeros((npts, 14, 3))
    for node in (0, 1):
        o = 7 * node
        N[:, o], N[:, o + 1] = H[0][:, 2 * node], H[0][:, 2 * node + 1]
        dN[:, o, 0], dN[:, o + 1, 0] = H[1][:, 2 * node], H[1][:, 2 * node + 1]
        for k in range(1, 6):
            N[:, o + 1 + k] = G[0][:, k] * P[0][:, node]
            dN[:, o + 1 + k, 0] = G[0][:, k] * P[1][:, node]
            dN[:, o + 1 + k, 1] = G[1][:, k] * P[0][:, node]
            dN[:, o + 1 + k, 2] = G[2][:, k] * P[0][:, node]
    return AncfTables(N=N, dN=dN)
