"""Twisted tapered hexahedral mesh from gmsh, built on rank 0 and distributed with gmshio.

``meshes/beam.geo`` makes a structured nx x ny x nz block of the unit beam; every node is then
mapped onto the body by :meth:`BeamShape.point_from_unit` (trilinear hexahedra between exact node
positions: untwisted, the map is trilinear and the volume exact; twisted, the faces are bilinear
and the volume error falls at second order). The result is cached as ``.msh`` in the cache folder
keyed by the geometry, the divisions and the ``.geo`` text, and regenerated when any changes
(never read or written with ``FXFLEX_NO_CACHE=1``, see :mod:`fxflex.cache`).
Facet tags: ``ROOT`` (x = 0, clamped) and ``TIP`` (x = L). A section other than the paper's
rectangle is meshed by :mod:`fxflex.mesh.section_mesh` (the root section's quadrilaterals
repeated in nx layers of hexahedra); its key adds the contour and stations files' text.

``order=2`` makes 27-node hexahedra (gmsh ``setOrder(2)``) whose edge, face and cell midpoints are
mapped onto the body as well: the geometry is then the quadratic interpolant of the exact twisted
shape (isoparametric for Q2 displacements, :mod:`fxflex.analysis.reference`), its volume error
falling at fourth order instead of second.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from fxflex import cache
from fxflex.mesh.geometry import BeamShape
from fxflex.scene import Geometry

__all__ = ["SolidMesh", "build_solid_mesh", "GEO_FILE", "ROOT", "TIP", "mesh_key"]

GEO_FILE = Path(__file__).resolve().parents[2] / "meshes" / "beam.geo"
ROOT, TIP = 1, 2


@dataclass
class SolidMesh:
    mesh: object            # dolfinx.mesh.Mesh
    cell_tags: object
    facet_tags: object
    shape: BeamShape
    divisions: tuple[int, int, int]
    order: int              # geometry degree: 1 (8-node hexahedra) or 2 (27-node)
    path: Path | None       # the cached .msh file (or the user's, mesh.solid_file)
    generated: bool         # False when read from the cache
    kind: str = "hexahedra"     # or "tetrahedra" (mesh.solid_file only)
    key: str | None = None      # what the cache keys of results on this mesh use


def mesh_key(geometry: Geometry, divisions, order: int = 1) -> str:
    """Hash of what the mesh depends on: geometry, divisions, geometry order, the ``.geo`` text
    and the source of this module and of the shape map (snapping every node onto the grid makes
    the node positions independent of the gmsh version)."""
    what = {"geometry": asdict(geometry), "divisions": list(divisions),
            "geo": GEO_FILE.read_text(),
            "code": cache.code_version(__name__, "fxflex.mesh.geometry")}
    if order != 1:
        what["order"] = order
    if not geometry.paper_shape:
        # the contour and stations are file paths: their text is what the mesh depends on
        what["files"] = {k: Path(getattr(geometry, k)).read_text()
                         for k in ("contour", "stations") if getattr(geometry, k)}
        what["section_code"] = cache.code_version("fxflex.mesh.section_mesh",
                                                  "fxflex.section.blade", "fxflex.section.outline")
    text = json.dumps(what, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _generate(gmsh, shape: BeamShape, divisions, order: int = 1) -> None:
    """Mesh the unit block from the .geo file and move every node onto the body; any other
    section than the paper's rectangle: :mod:`fxflex.mesh.section_mesh`."""
    if not shape.g.paper_shape:
        from fxflex.mesh.section_mesh import generate_section_mesh
        generate_section_mesh(gmsh, shape, divisions, order)
        return
    for name, value in zip(("nx", "ny", "nz"), divisions):
        gmsh.onelab.setNumber(name, [float(value)])
    gmsh.open(str(GEO_FILE))
    gmsh.model.mesh.generate(3)
    if order != 1:
        gmsh.option.setNumber("Mesh.SecondOrderIncomplete", 0)      # 27 nodes, not 20
        gmsh.model.mesh.setOrder(order)
    # the nodes of an order-k mesh of the unit block lie on a grid k times finer
    nx, ny, nz = (order * n for n in divisions)
    tags, coords, _ = gmsh.model.mesh.getNodes()
    ref = coords.reshape(-1, 3)
    # snap to the exact structured grid: the centerline (eta = zeta = 0) lands exactly on the axis
    x = np.round(ref[:, 0] * nx) / nx
    eta = np.round((ref[:, 1] + 0.5) * ny) / ny - 0.5
    zeta = np.round((ref[:, 2] + 0.5) * nz) / nz - 0.5
    X, Y, Z = shape.point_from_unit(shape.L * x, eta, zeta)
    for tag, x, y, z in zip(tags, X, Y, Z):
        gmsh.model.mesh.setNode(int(tag), [x, y, z], [])


def build_solid_mesh(geometry: Geometry, divisions, comm, *, use_cache: bool = True,
                     order: int = 1) -> SolidMesh:
    """The distributed dolfinx mesh of the beam for ``divisions = (nx, ny, nz)``, with
    ``order`` 1 (trilinear) or 2 (triquadratic, 27-node) cell geometry."""
    if order not in (1, 2):
        raise ValueError(f"mesh order must be 1 or 2, not {order}")
    import gmsh
    from dolfinx.io import gmshio

    divisions = tuple(int(n) for n in divisions)
    shape = BeamShape(geometry)
    use_cache = use_cache and cache.enabled("meshes")
    path = cache.cache_root() / "meshes" / f"beam-{mesh_key(geometry, divisions, order)}.msh"
    generated = False
    gmsh.initialize(readConfigFiles=False)
    gmsh.option.setNumber("General.Terminal", 0)
    try:
        if comm.rank == 0:
            gmsh.clear()
            if use_cache and path.exists():
                gmsh.open(str(path))
            else:
                _generate(gmsh, shape, divisions, order)
                generated = True
                # distribute what a later run reads from the file (the node and cell order of a
                # freshly generated model differ from the file's, and with them the MPI
                # partition and every round-off): cold, warm and uncached runs agree exactly
                folder = None
                if use_cache:
                    try:
                        folder = cache.cache_dir("meshes")
                    except OSError:             # not writable: mesh without caching
                        use_cache = False
                tmp = str(cache.temporary(folder or Path(tempfile.gettempdir()), path.stem,
                                          suffix=".msh"))
                try:
                    gmsh.write(tmp)
                    gmsh.clear()
                    gmsh.open(tmp)
                    if use_cache:
                        cache.publish(tmp, path)
                    else:
                        os.unlink(tmp)
                except BaseException:
                    if os.path.exists(tmp):
                        os.unlink(tmp)
                    raise
        mesh, cell_tags, facet_tags = gmshio.model_to_mesh(gmsh.model, comm, 0, gdim=3)
    finally:
        gmsh.finalize()
    generated, use_cache = comm.bcast((generated, use_cache), root=0)
    return SolidMesh(mesh=mesh, cell_tags=cell_tags, facet_tags=facet_tags, shape=shape,
                     divisions=divisions, order=order, path=path if use_cache else None,
                     generated=generated, key=mesh_key(geometry, divisions, order))
