"""The solid formulations' physics as pure UFL forms (no assembly, no I/O).

Notation of NOTES.md: S = [[0,-1,0],[1,0,0],[0,0,0]] (S r = e_z x r), P = diag(1,1,0) = -S^2.
A material point at X0 with displacement U (measured in O-XYZ) accelerates as
a = U'' + 2 phi' S U' + phi'' S (X0 + U) - phi'^2 P (X0 + U); the inertia-coupling forms below are
the pieces of its virtual work. The strain energy is Hooke's (small strain, Eq. 12-14) or
St.Venant-Kirchhoff in the Green-Lagrange strain (TLF, Eq. 30-33).
"""

from __future__ import annotations

import ufl

from fxflex.scene import Material

__all__ = ["S_MAT", "P_MAT", "mass", "mass_P", "mass_S", "centrifugal", "euler", "epsilon",
           "hooke", "linear_elastic", "green_lagrange", "svk_stress", "svk_residual",
           "svk_energy", "traction"]

S_MAT = ufl.as_matrix([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
P_MAT = ufl.as_matrix([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.0]])


def mass(rho, u, v, dx):
    """M: int rho u . v (paper M_ff, Eq. 11, and the TLF mass, Eq. 29)."""
    return rho * ufl.inner(u, v) * dx


def mass_P(rho, u, v, dx):
    """M_P: int rho (P u) . v -- spin softening (FFRF invariant N, paper M_rr6)."""
    return rho * ufl.inner(ufl.dot(P_MAT, u), v) * dx


def mass_S(rho, u, v, dx):
    """M_S: int rho (S u) . v -- Coriolis (skew; FFRF invariant G, paper M_rf3)."""
    return rho * ufl.inner(ufl.dot(S_MAT, u), v) * dx


def centrifugal(rho, X0, v, dx):
    """f_c: int rho (P X0) . v -- centrifugal load per unit phi'^2 (FFRF invariant n)."""
    return rho * ufl.inner(ufl.dot(P_MAT, X0), v) * dx


def euler(rho, X0, v, dx):
    """f_S: int rho (S X0) . v -- tangential (Euler) load per unit phi'' (FFRF invariant g)."""
    return rho * ufl.inner(ufl.dot(S_MAT, X0), v) * dx


def epsilon(u):
    return ufl.sym(ufl.grad(u))


def hooke(material: Material, eps):
    """Isotropic linear elastic stress (Hooke), also the SVK law S = C : E."""
    lmbda, mu = material.lame
    return lmbda * ufl.tr(eps) * ufl.Identity(3) + 2.0 * mu * eps


def linear_elastic(material: Material, u, v, dx):
    """K_L: int eps(u) : C : eps(v) (paper Eq. 14)."""
    return ufl.inner(hooke(material, epsilon(u)), epsilon(v)) * dx


def green_lagrange(u):
    """E = (F^T F - I) / 2 with F = I + grad u (paper Eq. 30), evaluated as (H + H^T + H^T H) / 2
    with H = grad u: forming F^T F - I subtracts I from numbers near 1 and loses about
    -log10(strain) digits (six at the default scene's strains)."""
    H = ufl.grad(u)
    return 0.5 * (H + H.T + H.T * H)


def svk_stress(material: Material, u):
    """Second Piola-Kirchhoff stress of the St.Venant-Kirchhoff material."""
    return hooke(material, green_lagrange(u))


def svk_residual(material: Material, u, v, dx):
    """Internal virtual work int S(E) : dE = int (F S) : grad v (paper Eq. 33)."""
    F = ufl.Identity(3) + ufl.grad(u)
    return ufl.inner(F * svk_stress(material, u), ufl.grad(v)) * dx


def svk_energy(material: Material, u, dx):
    """Strain energy int E : C : E / 2."""
    E = green_lagrange(u)
    return 0.5 * ufl.inner(hooke(material, E), E) * dx


def traction(t_vec, v, ds):
    """int t . v over a boundary part (the tip force as a uniform traction)."""
    return ufl.inner(t_vec, v) * ds
