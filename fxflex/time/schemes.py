"""The integrators by name (SPEC section 4): ``ab2`` and ``cd`` (explicit, :mod:`.explicit`) and
``generalized-alpha`` (implicit, :mod:`.implicit`)."""

from __future__ import annotations

from fxflex.time.explicit import SCHEMES
from fxflex.time.generalized_alpha import GeneralizedAlpha

__all__ = ["INTEGRATORS", "make_scheme"]

INTEGRATORS = ("ab2", "cd", "generalized-alpha")


def make_scheme(name: str, **options):
    """A fresh scheme object; ``options`` go to the implicit scheme (rho_inf, tol, max_iter,
    max_halvings) and must be empty for the explicit ones."""
    if name == GeneralizedAlpha.name:
        return GeneralizedAlpha(**options)
    if name not in SCHEMES:
        raise ValueError(f"unknown integrator {name!r}; allowed: {' '.join(INTEGRATORS)}")
    if options:
        raise ValueError(f"{name} takes no options, got {sorted(options)}")
    return SCHEMES[name]()
