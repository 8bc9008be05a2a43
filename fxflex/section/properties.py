"""Cross-section properties by a 2-D finite-element analysis in dolfinx (issue 14 item 3).

Given an :class:`~fxflex.section.outline.Outline`, gmsh meshes the section (triangles, size
``h`` = the larger extent / ``resolution``, at most half a hollow section's wall) and dolfinx computes, with P2 Lagrange elements:

- area A = int dA, centroid (y_c, z_c) = int (y, z) dA / A (in the outline's coordinates);
- about the centroid, in the section's own axes: Iy = int z^2 dA, Iz = int y^2 dA,
  Iyz = int y z dA, and the principal angle theta = 1/2 atan2(2 Iyz, Iz - Iy) (the axis of the
  largest second moment, the chord of an airfoil, is at theta from y);
- the Saint-Venant warping function omega about the centroid: the Neumann problem
  Laplace(omega) = 0, d omega / dn = z n_y - y n_z on every boundary, whose weak form
  int grad omega . grad v dA = int (z dv/dy - y dv/dz) dA has no boundary integral (holes need no
  special case); omega is fixed by int omega dA = 0 (a Lagrange multiplier);
- the torsion constant J = int ((omega_y - z)^2 + (omega_z + y)^2) dA = Ip - int |grad omega|^2 dA
  (Ip = Iy + Iz; the second form follows from the weak form with v = omega);
- the shear centre (Trefftz): the warping function about a point P = (y_p, z_p),
  omega_P = omega + y_p z - z_p y + c, has vanishing sectorial products int omega_P y dA =
  int omega_P z dA = 0 at P = the shear centre: Iyz y_p - Iz z_p = -int omega y dA and
  Iy y_p - Iyz z_p = -int omega z dA.

The mesh is serial (COMM_SELF on every rank: a section is small). The discretisation error of J
falls as h^4 on smooth outlines (P2 energy error squared), the integrals of the polygon exactly.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from fxflex.section.outline import Outline

__all__ = ["SectionResult", "RESOLUTION", "analyse", "analyse_many", "triangles"]

#: default section mesh: element size = largest extent / RESOLUTION
RESOLUTION = 40


@dataclass(frozen=True)
class SectionResult:
    """Properties of one section (SI units); SPEC section 9 names."""

    A: float
    centroid: tuple[float, float]
    Iy: float
    Iz: float
    Iyz: float
    principal_deg: float
    J: float
    shear_centre: tuple[float, float]
    cells: int

    def as_dict(self) -> dict:
        d = asdict(self)
        d["centroid"], d["shear_centre"] = list(self.centroid), list(self.shear_centre)
        return d


def element_size(outline: Outline, resolution: int) -> float:
    """The larger extent / resolution, and at most half the thinnest wall of a hollow section
    (two P2 elements across it)."""
    h = max(outline.extent) / resolution
    if outline.inner is not None:
        from shapely.geometry import LinearRing

        h = min(h, 0.5 * LinearRing(outline.outer).distance(LinearRing(outline.inner)))
    return h


def _mesh(gmsh, outline: Outline, h: float):
    """Triangles of the outline in gmsh's current model (geo kernel, straight edges)."""
    gmsh.clear()
    gmsh.model.add("section")
    loops = []
    for contour in outline.contours():
        pts = [gmsh.model.geo.addPoint(float(y), float(z), 0.0, h) for y, z in contour]
        lines = [gmsh.model.geo.addLine(pts[i], pts[(i + 1) % len(pts)]) for i in range(len(pts))]
        loops.append(gmsh.model.geo.addCurveLoop(lines))
    surface = gmsh.model.geo.addPlaneSurface(loops)
    gmsh.model.geo.synchronize()
    gmsh.model.addPhysicalGroup(2, [surface], 1)
    gmsh.option.setNumber("Mesh.CharacteristicLengthMin", h)
    gmsh.option.setNumber("Mesh.CharacteristicLengthMax", h)
    gmsh.option.setNumber("Mesh.CharacteristicLengthFromPoints", 0)
    gmsh.option.setNumber("Mesh.CharacteristicLengthExtendFromBoundary", 0)
    gmsh.model.mesh.generate(2)


class _Solver:
    """The compiled forms of the section analysis, reused for every section of a call."""

    def __init__(self):
        import gmsh

        self.gmsh = gmsh

    def analyse(self, outline: Outline, resolution: int) -> SectionResult:
        import ufl
        from dolfinx import fem
        from dolfinx.fem.petsc import assemble_matrix, assemble_vector
        from dolfinx.io import gmshio
        from mpi4py import MPI
        from scipy.sparse import bmat, csr_matrix
        from scipy.sparse.linalg import spsolve

        _mesh(self.gmsh, outline, element_size(outline, resolution))
        mesh, _, _ = gmshio.model_to_mesh(self.gmsh.model, MPI.COMM_SELF, 0, gdim=2)
        x = ufl.SpatialCoordinate(mesh)
        dx = ufl.dx(mesh, metadata={"quadrature_degree": 4})

        def integral(expr) -> float:
            return float(fem.assemble_scalar(fem.form(expr * dx)))

        one = fem.Constant(mesh, 1.0)
        A = integral(one)
        yc, zc = integral(x[0]) / A, integral(x[1]) / A
        # the centroid as a Constant: a float would be a literal of the form, one JIT per section
        c = fem.Constant(mesh, np.array([yc, zc]))
        y, z = x[0] - c[0], x[1] - c[1]
        Iy, Iz, Iyz = integral(z * z), integral(y * y), integral(y * z)
        V = fem.FunctionSpace(mesh, ("Lagrange", 2))
        w, v = ufl.TrialFunction(V), ufl.TestFunction(V)
        K = assemble_matrix(fem.form(ufl.inner(ufl.grad(w), ufl.grad(v)) * dx))
        K.assemble()
        b = assemble_vector(fem.form((z * v.dx(0) - y * v.dx(1)) * dx))
        m = assemble_vector(fem.form(v * dx))
        Kcsr = csr_matrix(K.getValuesCSR()[::-1], shape=K.getSize())
        mv, bv = m.array.copy(), b.array.copy()
        # bordered system [K m; m^T 0] [omega; mu] = [b; 0]: int omega dA = 0 fixes the constant
        S = bmat([[Kcsr, csr_matrix(mv[:, None])], [csr_matrix(mv[None, :]), None]], format="csc")
        sol = spsolve(S, np.concatenate([bv, [0.0]]))
        omega = fem.Function(V)
        omega.x.array[:] = sol[:-1]
        J = Iy + Iz - float(sol[:-1] @ (Kcsr @ sol[:-1]))
        Iwy, Iwz = integral(omega * y), integral(omega * z)
        yp, zp = np.linalg.solve([[Iyz, -Iz], [Iy, -Iyz]], [-Iwy, -Iwz])
        theta = 0.5 * math.degrees(math.atan2(2 * Iyz, Iz - Iy))
        cells = mesh.topology.index_map(2).size_local
        for obj in (K, b, m):
            obj.destroy()
        return SectionResult(A=A, centroid=(yc, zc), Iy=Iy, Iz=Iz, Iyz=Iyz, principal_deg=theta,
                             J=J, shear_centre=(float(yp), float(zp)), cells=cells)


def analyse_many(outlines, resolution: int = RESOLUTION) -> list[SectionResult]:
    """:func:`analyse` for each outline, with one gmsh session."""
    import gmsh

    if resolution < 4:
        raise ValueError(f"section resolution {resolution}: allowed 4 or more elements across")
    gmsh.initialize(readConfigFiles=False)
    gmsh.option.setNumber("General.Terminal", 0)
    try:
        solver = _Solver()
        return [solver.analyse(o, resolution) for o in outlines]
    finally:
        gmsh.finalize()


def triangles(outline: Outline, resolution: int = RESOLUTION) -> tuple[np.ndarray, np.ndarray]:
    """(points (n, 2), triangles (m, 3)) of the section mesh :func:`analyse` uses (for plots)."""
    import gmsh

    gmsh.initialize(readConfigFiles=False)
    gmsh.option.setNumber("General.Terminal", 0)
    try:
        _mesh(gmsh, outline, element_size(outline, resolution))
        tags, coords, _ = gmsh.model.mesh.getNodes()
        _, _, nodes = gmsh.model.mesh.getElements(2)
    finally:
        gmsh.finalize()
    index = np.empty(int(tags.max()) + 1, int)
    index[tags.astype(int)] = np.arange(len(tags))
    return coords.reshape(-1, 3)[:, :2].copy(), index[np.asarray(nodes[0], int)].reshape(-1, 3)


def analyse(outline: Outline, resolution: int = RESOLUTION) -> SectionResult:
    """The properties of one section (module docstring)."""
    return analyse_many([outline], resolution)[0]
