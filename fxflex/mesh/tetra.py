"""A tetrahedral gmsh ``.msh`` of the scene's blade, as a user would bring it (``mesh.solid_file``).

Tests and the measurements of docs/sections.md need tetrahedral meshes of the default blade; this
writes one. gmsh meshes the root-sized straight box [0, L] x [-b0/2, b0/2] x [-h0/2, h0/2] in
tetrahedra of size ``size`` (frontal-Delaunay), order 1 or 2 (10-node, mid-edge nodes on the
straight box edges), and every node is then moved onto the body by
:meth:`fxflex.mesh.geometry.BeamShape.point_from_unit` at (x, y / b0, z / h0), as the built-in
hexahedral mesh maps its unit block (:mod:`fxflex.mesh.solid`): the quadratic tetrahedra are the
quadratic interpolant of the exact twisted, tapered shape, isoparametric like Q2. The file's root
lies at X = 0 (the hub radius is the scene's business), physical surfaces ``root`` and ``tip``.
Paper's rectangle only (the box is its unit block); rank 0 or serial callers only.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fxflex.errors import FxflexError
from fxflex.mesh.geometry import BeamShape
from fxflex.scene import Geometry

__all__ = ["write_tet_blade"]


def write_tet_blade(geometry: Geometry, path, size: float, order: int = 1) -> Path:
    """Write the tetrahedral mesh of the module docstring to ``path`` and return it."""
    if not geometry.paper_shape:
        raise FxflexError("write_tet_blade: only the paper's rectangle section is meshed here")
    if order not in (1, 2):
        raise FxflexError(f"write_tet_blade: order {order}; allowed: 1 or 2")
    import gmsh

    shape = BeamShape(geometry)
    L, b0, h0 = geometry.length, geometry.root_y, geometry.root_z
    path = Path(path)
    gmsh.initialize(readConfigFiles=False)
    gmsh.option.setNumber("General.Terminal", 0)
    try:
        gmsh.model.add("tet-blade")
        box = gmsh.model.occ.addBox(0.0, -b0 / 2, -h0 / 2, L, b0, h0)
        gmsh.model.occ.synchronize()
        eps = 1e-3 * L               # OpenCASCADE pads the bounding boxes
        faces = {}
        for name, x in (("root", 0.0), ("tip", L)):
            found = gmsh.model.getEntitiesInBoundingBox(x - eps, -b0, -h0, x + eps, b0, h0, 2)
            faces[name] = [tag for _, tag in found]
        gmsh.model.addPhysicalGroup(3, [box], 1)
        for k, name in enumerate(("root", "tip")):
            gmsh.model.setPhysicalName(2, gmsh.model.addPhysicalGroup(2, faces[name], 10 + k),
                                       name)
        gmsh.option.setNumber("Mesh.MeshSizeMin", size)
        gmsh.option.setNumber("Mesh.MeshSizeMax", size)
        gmsh.model.mesh.generate(3)
        if order == 2:
            gmsh.model.mesh.setOrder(2)
        tags, coords, _ = gmsh.model.mesh.getNodes()
        ref = coords.reshape(-1, 3)
        x = np.clip(ref[:, 0], 0.0, L)
        X, Y, Z = shape.point_from_unit(x, ref[:, 1] / b0, ref[:, 2] / h0)
        X = X - geometry.hub_radius
        for tag, a, b, c in zip(tags, X, Y, Z):
            gmsh.model.mesh.setNode(int(tag), [a, b, c], [])
        path.parent.mkdir(parents=True, exist_ok=True)
        gmsh.write(str(path))
    finally:
        gmsh.finalize()
    return path
