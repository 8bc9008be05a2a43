"""The dense quadratic eigenproblem of the linearised rotating system: moved to
:mod:`fxflex.numerics.qep`, which the formulations use."""

# old import path kept: the implementation lives in fxflex.numerics.qep
from fxflex.numerics.qep import (STABILITY_RTOL, TROPICAL_TAU, DenseLinearisation, EigenNotConverged,
                                 companion, companion_eigenvalues, conjugate_pairs, growth_rate,
                                 quadratic_eigen, rightmost, root_errors, unstable, verdict)

__all__ = ["companion", "companion_eigenvalues", "quadratic_eigen", "conjugate_pairs",
           "rightmost", "growth_rate", "unstable", "root_errors", "STABILITY_RTOL",
           "TROPICAL_TAU", "DenseLinearisation", "EigenNotConverged", "verdict"]
