"""Shared low-level numerics of every formulation, integrator and analysis: dense LU and Newton
with continuation (:mod:`.dense`), the quadratic eigenproblem of the linearised rotating system
and its stability verdict (:mod:`.qep` dense, :mod:`.petsc` SLEPc), growth-rate fits and AB2's
root (:mod:`.growth`), the factor of an iteration matrix held in the hub frame (:mod:`.hub`) and
the sparse product of the beam time loop (:mod:`.sparse`).

This layer imports nothing from the formulations (solid, beam), the integrators (time), the
analyses or the benchmarks; they all import from it (tests/test_layers.py).
"""

__all__ = ["dense", "growth", "hub", "petsc", "qep", "sparse"]
