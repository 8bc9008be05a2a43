"""Small dense linear algebra of the beam formulations: moved to :mod:`fxflex.numerics.dense`."""

# old import path kept: the implementation lives in fxflex.numerics.dense
from fxflex.numerics.dense import DenseLU, newton, omega_max

__all__ = ["newton", "omega_max", "DenseLU"]
