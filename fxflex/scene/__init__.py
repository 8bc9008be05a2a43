"""Scene description (SPEC sections 1 and 8): geometry, material, load, rotation, damping, mesh."""

from fxflex.scene.kinematics import Drive
from fxflex.scene.load import (load_scene, parse_override, scene_from_dict, validate,
                               validate_for)
from fxflex.scene.schema import (METHODS, PAPER_DAMPING, PAPER_RPM, Damping, Geometry, Load,
                                Material, MeshSpec, Reduction, Rotation, Scene, Section,
                                Solver, TipMass)

__all__ = [
    "Scene", "Geometry", "Material", "Section", "Load", "Rotation", "Damping", "MeshSpec",
    "Reduction", "TipMass", "Solver", "Drive", "load_scene", "parse_override", "scene_from_dict",
    "validate", "validate_for",
    "METHODS", "PAPER_RPM", "PAPER_DAMPING",
]
