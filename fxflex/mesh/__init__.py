"""Geometry of the twisted tapered beam, its section properties, and the gmsh solid mesh."""

from fxflex.mesh.geometry import BeamShape, SectionProperties, saint_venant_rectangle

__all__ = ["BeamShape", "SectionProperties", "saint_venant_rectangle"]
