"""LEBB: linear Euler-Bernoulli beam in the floating frame (paper Sect. 3.1, Eq. 36-44).

Cubic Hermite deflections and linear axial/torsion fields (Eq. 37), linear strains (Eq. 40),
section stiffness (Eq. 41), mass from the inertia shape integrals of :mod:`fxflex.beam.frame`,
relative damping (Eq. 42). The steady state is Eq. 59 with the time derivatives set to zero.
"""

from __future__ import annotations

from fxflex.beam.frame import FloatingFrameBeam
from fxflex.formulation import BuildOptions
from fxflex.scene import Scene

__all__ = ["build", "dof_count", "LEBB"]


class LEBB(FloatingFrameBeam):
    """Linear Euler-Bernoulli beam: Q_k = K_L W (Eq. 44)."""

    def __init__(self, scene: Scene):
        super().__init__(scene, "lebb")


def build(scene: Scene, comm, options: BuildOptions | None = None) -> LEBB:
    """Replicated on every rank (a few dozen unknowns): ``form.comm`` is COMM_SELF."""
    return LEBB(scene)


def dof_count(scene: Scene) -> int:
    """Six coordinates per node, root node clamped."""
    return 6 * scene.mesh.beam_elements
