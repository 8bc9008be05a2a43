"""Integrators (explicit AB2 and central difference, implicit generalised-alpha), the one time
loop that drives them, their step limits and the diagnosis of a run that stopped early."""

from fxflex.time.diagnosis import (ab2_growth_exponent, deviation_growth, diagnose,
                                   measured_growth_rate)
from fxflex.time.driver import Resume, RunResult, divergence_limit, simulate
from fxflex.time.explicit import AB2, SCHEMES, CentralDifference
from fxflex.time.generalized_alpha import GeneralizedAlpha, NewtonFailure
from fxflex.time.schemes import INTEGRATORS, make_scheme

__all__ = ["AB2", "CentralDifference", "GeneralizedAlpha", "NewtonFailure", "SCHEMES",
           "INTEGRATORS", "make_scheme", "simulate", "RunResult", "Resume", "divergence_limit",
           "diagnose", "ab2_growth_exponent", "measured_growth_rate", "deviation_growth"]
