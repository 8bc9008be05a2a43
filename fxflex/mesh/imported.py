"""The user's own solid mesh, ``mesh.solid_file`` (SPEC section 9): a gmsh ``.msh`` file.

What the file must hold, each refused with one line otherwise: hexahedra or tetrahedra of order 1
or 2 (8- or 27-node hexahedra, 4- or 10-node tetrahedra; one kind per file), the order equal to
``mesh.solid_degree`` (the displacement is isoparametric), physical surfaces named ``root`` (the
clamped face, in the plane X = 0) and ``tip``, and a body that spans X from 0 to
``geometry.length``. The body's volume elements need no physical group (all of them are taken).

The mesh is read on rank 0, its physical groups renamed to the built-in mesh's facet tags
(:data:`~fxflex.mesh.solid.ROOT`, :data:`~fxflex.mesh.solid.TIP`, one volume group) and
distributed with gmshio like the generated meshes; the nodes are then moved by the hub radius
along X (the file's root lies at X = 0, the body's at X = R, SPEC section 1). The scene's
geometry still describes the blade for what the mesh does not say: the section area's variation
along the span that scales the line load q / A(X) (:meth:`fxflex.solid.model.SolidModel`), and
the tip centroid's position. :func:`file_key` is the hash of the file's bytes (the cache keys of
the clamped modes use it).
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from fxflex.errors import FxflexError
from fxflex.mesh.geometry import BeamShape
from fxflex.scene import Scene

__all__ = ["read_solid_file", "file_key", "ELEMENTS"]

#: gmsh element type -> (kind, order) accepted
ELEMENTS = {5: ("hexahedra", 1), 12: ("hexahedra", 2), 4: ("tetrahedra", 1),
            11: ("tetrahedra", 2)}


def file_key(path: str) -> str:
    """16 hex digits of the SHA-256 of the file's bytes."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()[:16]


def _fail(path: str, why: str) -> FxflexError:
    return FxflexError(f"mesh.solid_file {path}: {why}")


def _prepare(gmsh, path: str, scene: Scene) -> tuple[str, int]:
    """Check the model just opened (module docstring) and renumber its physical groups; returns
    (kind, order). Rank 0 only."""
    from fxflex.mesh.solid import ROOT, TIP

    types = set()
    for dim, tag in gmsh.model.getEntities(3):
        types.update(int(t) for t in gmsh.model.mesh.getElementTypes(dim, tag))
    if not types:
        raise _fail(path, "has no volume elements; allowed: hexahedra or tetrahedra")
    unknown = sorted(types - set(ELEMENTS))
    if unknown:
        names = [gmsh.model.mesh.getElementProperties(t)[0] for t in unknown]
        raise _fail(path, f"has {', '.join(names)} elements; allowed: 8- or 27-node hexahedra, "
                          f"4- or 10-node tetrahedra")
    if len(types) > 1:
        raise _fail(path, "mixes element kinds or orders; allowed: one of 8- or 27-node "
                          "hexahedra, 4- or 10-node tetrahedra")
    kind, order = ELEMENTS[types.pop()]
    if order != scene.mesh.solid_degree:
        raise _fail(path, f"holds {kind} of order {order} but mesh.solid_degree = "
                          f"{scene.mesh.solid_degree}; allowed: mesh.solid_degree = {order}")
    groups = {}
    for dim, tag in gmsh.model.getPhysicalGroups(2):
        groups[gmsh.model.getPhysicalName(dim, tag).strip().lower()] = \
            [int(e) for e in gmsh.model.getEntitiesForPhysicalGroup(dim, tag)]
    missing = [name for name in ("root", "tip") if name not in groups]
    if missing:
        have = ", ".join(repr(n) for n in groups) or "none"
        raise _fail(path, f"has no physical surface {' or '.join(map(repr, missing))} (it has "
                          f"{have}); allowed: physical surfaces named 'root' and 'tip'")
    L = scene.geometry.length
    _, xyz, _ = gmsh.model.mesh.getNodes(includeBoundary=True, returnParametricCoord=False)
    x = xyz.reshape(-1, 3)[:, 0]
    tol = 1e-6 * L
    if abs(float(x.min())) > tol or abs(float(x.max()) - L) > tol:
        raise _fail(path, f"spans X from {x.min():.6g} to {x.max():.6g} m; allowed: 0 to "
                          f"geometry.length = {L:g} m")
    for entity in groups["root"]:
        _, node_xyz, _ = gmsh.model.mesh.getNodes(2, entity, includeBoundary=True)
        if node_xyz.size and np.max(np.abs(node_xyz.reshape(-1, 3)[:, 0])) > tol:
            raise _fail(path, "its 'root' surface is off the plane X = 0; allowed: the clamped "
                              "root in X = 0")
    volumes = [tag for _, tag in gmsh.model.getEntities(3)]
    gmsh.model.removePhysicalGroups()
    gmsh.model.addPhysicalGroup(3, volumes, 1)
    gmsh.model.addPhysicalGroup(2, groups["root"], ROOT)
    gmsh.model.addPhysicalGroup(2, groups["tip"], TIP)
    return kind, order


def read_solid_file(scene: Scene, comm):
    """The :class:`~fxflex.mesh.solid.SolidMesh` of ``scene.mesh.solid_file`` on ``comm``
    (module docstring). Collective; a bad file raises FxflexError on every rank."""
    import gmsh
    from dolfinx.io import gmshio

    from fxflex.mesh.solid import SolidMesh

    path = scene.mesh.solid_file
    error, kind, order = None, None, None
    gmsh.initialize(readConfigFiles=False)
    gmsh.option.setNumber("General.Terminal", 0)
    try:
        if comm.rank == 0:
            try:
                gmsh.clear()
                gmsh.open(str(path))
                kind, order = _prepare(gmsh, path, scene)
            except FxflexError as exc:
                error = str(exc)
            except Exception as exc:        # gmsh's own reading errors
                error = f"mesh.solid_file {path}: gmsh cannot read it ({exc})"
        error, kind, order = comm.bcast((error, kind, order), root=0)
        if error is not None:
            raise FxflexError(error)
        mesh, cell_tags, facet_tags = gmshio.model_to_mesh(gmsh.model, comm, 0, gdim=3)
    finally:
        gmsh.finalize()
    mesh.geometry.x[:, 0] += scene.geometry.hub_radius
    return SolidMesh(mesh=mesh, cell_tags=cell_tags, facet_tags=facet_tags,
                     shape=BeamShape(scene.geometry), divisions=tuple(scene.mesh.solid),
                     order=order, path=Path(path), generated=False, kind=kind,
                     key=comm.bcast(file_key(path) if comm.rank == 0 else None, root=0))
