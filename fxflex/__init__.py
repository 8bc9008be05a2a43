"""fxflex: dynamics of flexible bodies under large rotation, built on FEniCSx.

Six finite-element formulations of a rotating twisted tapered beam (FFRF, GCMS, TLF, LEBB, NEBB,
ANCF) behind one interface (:class:`fxflex.formulation.Formulation`), one set of integrators and one
output format.
"""

__version__ = "0.1.0"

__all__ = ["__version__"]
