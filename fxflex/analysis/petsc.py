"""The SLEPc quadratic eigenproblem: moved to :mod:`fxflex.numerics.petsc`."""

import sys

from fxflex.numerics import petsc as _petsc

# old import path kept as the same module object, so that setting TOL or MAX_IT here still
# reaches pep_eigen (a re-export would copy the values)
sys.modules[__name__] = _petsc
