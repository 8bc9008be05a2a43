"""Integrators (explicit AB2 and central difference) and the one time loop that drives them."""

from fxflex.time.diagnosis import ab2_growth_exponent, deviation_growth, diagnose
from fxflex.time.driver import RunResult, divergence_limit, simulate
from fxflex.time.explicit import AB2, SCHEMES, CentralDifference, make_scheme

__all__ = ["AB2", "CentralDifference", "SCHEMES", "make_scheme", "simulate", "RunResult",
           "divergence_limit", "diagnose", "ab2_growth_exponent", "deviation_growth"]
