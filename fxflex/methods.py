"""Where each method lives, and its unknown count without building it: below both
:mod:`fxflex.formulation` (which builds) and :mod:`fxflex.memory` (which estimates before the
build), so that neither imports the other."""

from __future__ import annotations

import importlib

from fxflex.scene import Scene

__all__ = ["MODULES", "CLASSES", "dof_count", "formulation_class"]

#: where each method's ``build(scene, comm, options)`` lives; imported lazily so that beam runs
#: never import dolfinx
MODULES = {"ffrf": "fxflex.solid.ffrf", "gcms": "fxflex.solid.gcms", "tlf": "fxflex.solid.tlf",
           "lebb": "fxflex.beam.lebb", "nebb": "fxflex.beam.nebb", "ancf": "fxflex.beam.ancf"}
#: the formulation class in each module: its declared traits (``distributed``, ``mesh_key``, ...)
#: answer what studies must know before building
CLASSES = {"ffrf": "FFRF", "gcms": "GCMS", "tlf": "TLF", "lebb": "LEBB", "nebb": "NEBB",
           "ancf": "ANCF"}


def formulation_class(method: str) -> type:
    """The class of ``method``'s formulation, imported (the solids import dolfinx), not built."""
    return getattr(importlib.import_module(MODULES[method]), CLASSES[method])


def dof_count(method: str, scene: Scene) -> int | None:
    """Unknowns after constraints, without building the method (None if not yet known)."""
    try:
        module = importlib.import_module(MODULES[method])
    except ModuleNotFoundError as exc:
        if exc.name == MODULES[method]:
            return None
        raise
    count = getattr(module, "dof_count", None)
    if method in ("ffrf", "gcms", "tlf") and (not scene.geometry.paper_shape
                                              or scene.mesh.solid_file):
        return None                 # another section's quad mesh: known once it is meshed
    return count(scene) if count is not None else None
