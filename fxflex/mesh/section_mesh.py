"""Hexahedral solid mesh of a blade whose section is not the paper's rectangle (SPEC section 9).

The root section (:meth:`fxflex.section.blade.Blade.outline` at x = 0, about its centroid from
:func:`fxflex.section.outline.moments`) is meshed by gmsh in quadrilaterals, which are repeated
at the nx + 1 (order 2: 2 nx + 1) levels x = k L / (order nx) into nx layers of hexahedra built
here (deterministic, and fast: gmsh's own extrusion of the 256-pole spline surfaces of an
airfoil took 5 s), and every node is mapped onto the body: the section point (y~, z~) of the
root is scaled by the sizes at x, (b(x) / b0, h(x) / h0) (a naca4 section scales with its chord
along both), and rotated by the twist theta(x) about +X
(:meth:`fxflex.mesh.geometry.BeamShape.point`). Each section is the root section stretched, so
the centroid stays on the X axis.

Element size: the quads are made in coordinates stretched by (ny / e_y, nz / e_z), e_y, e_z the
outline's extents, with a unit target size, so about ny elements lie across the extent along y~
and nz along z~ (a hollow section: smaller, two elements across the thinnest wall). The outline
(a polygon of up to 512 vertices) enters gmsh as splines through its vertices, broken at its
corners (a turn of more than :data:`CORNER_DEG`: an airfoil's trailing
edge, a polygon's vertices); the mesh's boundary nodes lie on those splines, whose distance from
the polygon is far below the mesh's own polygonal error (the chords between boundary nodes).
``order=2``: gmsh ``setOrder(2)`` puts the quads' edge midpoints on the splines as well (9-node
quads, curved boundary), the 27-node hexahedra take them at three levels per layer, and every
node is mapped in the same way.

A wall that does not scale with the section (constant thickness on a tapered blade, or a
stations table's wall column) is refused: the stretched root would not be the section of the
scene there.
"""

from __future__ import annotations

import numpy as np

from fxflex.errors import SceneError
from fxflex.mesh.geometry import BeamShape
from fxflex.section.outline import Outline, moments

__all__ = ["generate_section_mesh", "root_outline", "stretch", "CORNER_DEG"]

#: a turn of the outline sharper than this (degrees) is kept as a corner of the gmsh geometry
CORNER_DEG = 25.0


def root_outline(shape: BeamShape) -> tuple[Outline, float]:
    """The root section about its centroid and its area (of the polygon)."""
    out = shape.blade.outline(0.0)
    M = moments(out, 1)
    c = np.array([M[1, 0], M[0, 1]]) / M[0, 0]
    inner = None if out.inner is None else out.inner - c
    return Outline(out.outer - c, inner), float(M[0, 0])


def stretch(shape: BeamShape, x) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(s_y, s_z, theta) at x: the section's scale factors from the root and its twist."""
    x = np.asarray(x, float)
    blade, g = shape.blade, shape.g
    if blade.table is not None:
        t = blade.table
        by, bz, tw = (np.interp(x, t[:, 0], t[:, k]) for k in (1, 2, 3))
        by0, bz0 = t[0, 1], t[0, 2]
        theta = np.radians(tw)
    else:
        s = x / g.length
        by, bz = g.size_y(s), g.size_z(s)
        by0, bz0 = g.root_y, g.root_z
        theta = shape.twist_rad * s
    sy = by / by0
    sz = sy if g.section == "naca4" else bz / bz0
    return sy, sz, theta


def _check_stretch(shape: BeamShape, area0: float) -> None:
    """Refuse a scene whose sections are not the stretched root (a wall that keeps its
    thickness on a tapered blade)."""
    blade = shape.blade
    for x in blade.stations():
        sy, sz, _ = stretch(shape, x)
        a = float(moments(blade.outline(float(x)), 0)[0, 0])
        if abs(a - area0 * sy * sz) > 1e-6 * a:
            key = "geometry.stations" if blade.table is not None else "geometry.wall"
            raise SceneError(key, f"at x = {x:g} m the section is not the root section "
                                  f"stretched (area {a:.6g} vs {area0 * sy * sz:.6g} m^2): the "
                                  f"solid methods mesh stretched sections only; allowed: a wall "
                                  f"on an untapered blade, or no wall")


def _pieces(points: np.ndarray) -> list[np.ndarray]:
    """The closed contour split at its corners: a list of vertex runs, each from a corner to the
    next (both ends included); a smooth contour in four runs (gmsh's built-in kernel does not
    extrude a closed curve)."""
    d_in = points - np.roll(points, 1, axis=0)
    d_out = np.roll(points, -1, axis=0) - points
    cross = d_in[:, 0] * d_out[:, 1] - d_in[:, 1] * d_out[:, 0]
    turn = np.degrees(np.abs(np.arctan2(cross, np.einsum("ij,ij->i", d_in, d_out))))
    corners = np.flatnonzero(turn > CORNER_DEG)
    n = len(points)
    if corners.size == 0:
        corners = np.arange(4) * n // 4
    runs = []
    for a, b in zip(corners, np.roll(corners, -1)):
        idx = np.arange(a, b + (n if b <= a else 0) + 1) % n
        runs.append(points[idx])
    return runs


def _curve_loop(geo, points: np.ndarray, size: float) -> tuple[int, list[tuple[int, int]]]:
    """A gmsh curve loop through a closed contour (in unit-element coordinates): lines between
    adjacent corners, splines through the vertices elsewhere, each divided into about its length
    in intervals, their total even (a full-quad recombination needs it)."""
    tags: dict[tuple, int] = {}

    def point(p) -> int:
        key = (float(p[0]), float(p[1]))
        if key not in tags:
            tags[key] = geo.addPoint(0.0, key[0], key[1])
        return tags[key]

    curves, counts = [], []
    for run in _pieces(points):
        ids = [point(p) for p in run]
        curves.append(geo.addLine(*ids) if len(ids) == 2 else geo.addSpline(ids))
        length = np.linalg.norm(np.diff(run, axis=0), axis=1).sum()
        counts.append(2 * max(1, int(round(length / (2 * size)))))
    return geo.addCurveLoop(curves), list(zip(curves, counts))


def _section_quads(gmsh, out: Outline, scale: np.ndarray, order: int):
    """gmsh quadrilaterals of the section in unit-element coordinates: (nodes (m, 2) in the
    section's own y~, z~, quads (k, 4 or 9) of node indices, counter-clockwise, gmsh order)."""
    size = 1.0
    if out.inner is not None:
        # a thin wall: two quads across it at least (the full-quad recombination meshes at
        # twice the size first, and leaves triangles where one element would span the wall)
        from shapely.geometry import LinearRing

        wall = LinearRing(out.outer * scale).distance(LinearRing(out.inner * scale))
        size = min(size, wall / 2)
    geo = gmsh.model.occ
    loops, counts = [], []
    for c in out.contours():
        loop, m = _curve_loop(geo, c * scale, size)
        loops.append(loop)
        counts += m
    surface = geo.addPlaneSurface(loops)
    geo.synchronize()
    # the splines' interior vertices stay free points of the model: drop them (no mesh nodes)
    used = {t for _, t in gmsh.model.getBoundary(gmsh.model.getEntities(1), False, False)}
    geo.remove([(0, t) for _, t in gmsh.model.getEntities(0) if t not in used])
    geo.synchronize()
    for tag, m in counts:
        gmsh.model.mesh.setTransfiniteCurve(tag, m + 1)
    gmsh.model.mesh.setRecombine(2, surface)
    opt = gmsh.option.setNumber
    opt("Mesh.MeshSizeMin", size)
    opt("Mesh.MeshSizeMax", size)
    opt("Mesh.MeshSizeFromPoints", 0)
    opt("Mesh.MeshSizeFromCurvature", 0)
    opt("Mesh.MeshSizeExtendFromBoundary", 0)
    opt("Mesh.Algorithm", 6)                 # frontal-Delaunay (8 crashes on splines, gmsh 4.8)
    opt("Mesh.RecombinationAlgorithm", 3)    # blossom full-quad: no triangle left
    gmsh.model.mesh.generate(2)
    if order != 1:
        opt("Mesh.SecondOrderIncomplete", 0)                  # 9-node quads, not 8
        gmsh.model.mesh.setOrder(order)          # edge midpoints on the splines
    quad = {1: 3, 2: 10}[order]
    types = list(gmsh.model.mesh.getElementTypes(2, surface))
    if types != [quad]:
        raise RuntimeError(f"section mesh: element types {types}, expected [{quad}] "
                           f"(quadrilaterals only)")
    tags, coords, _ = gmsh.model.mesh.getNodes(2, surface, includeBoundary=True)
    index = {int(t): k for k, t in enumerate(tags)}
    yz = coords.reshape(-1, 3)[:, 1:] / scale
    _, conn = gmsh.model.mesh.getElementsByType(quad, surface)
    quads = np.array([index[int(t)] for t in conn]).reshape(-1, 4 if order == 1 else 9)
    p = yz[quads[:, :3]]
    turn = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 1])
    flip = turn < 0                                  # make every quad counter-clockwise
    if order == 1:
        quads[flip] = quads[flip][:, [0, 3, 2, 1]]
    else:
        quads[flip] = quads[flip][:, [0, 3, 2, 1, 7, 6, 5, 4, 8]]
    return yz, quads


#: 27-node hexahedron (gmsh order) from a 9-node quad (gmsh order) at the levels 0, 1, 2 of a
#: layer: (quad node, level) per hexahedron node -- corners, the 12 edges, the 6 faces, the centre
_HEX27 = ([(q, 0) for q in range(4)] + [(q, 2) for q in range(4)]
          + [(4, 0), (7, 0), (0, 1), (5, 0), (1, 1), (6, 0), (2, 1), (3, 1),
             (4, 2), (7, 2), (5, 2), (6, 2)]
          + [(8, 0), (4, 1), (7, 1), (5, 1), (6, 1), (8, 2), (8, 1)])


def generate_section_mesh(gmsh, shape: BeamShape, divisions, order: int = 1) -> None:
    """Build the hexahedral mesh of the body as a new gmsh model (discrete entities), with the
    physical surfaces "root" (1) and "tip" (2) and the volume "beam" (1) of
    :mod:`fxflex.mesh.solid`: the section's quads repeated at order nx + 1 levels along X (the
    layers are exact: x = k L / (order nx)), each node mapped onto the body."""
    nx, ny, nz = (int(n) for n in divisions)
    out, area0 = root_outline(shape)
    _check_stretch(shape, area0)
    ey, ez = out.extent
    yz, quads = _section_quads(gmsh, out, np.array([ny / ey, nz / ez]), order)
    m, levels = len(yz), order * nx + 1
    x = np.repeat(np.linspace(0.0, shape.L, levels), m)
    yt, zt = np.tile(yz[:, 0], levels), np.tile(yz[:, 1], levels)
    sy, sz, _ = stretch(shape, x)
    X, Y, Z = _place(shape, x, sy * yt, sz * zt)
    node = lambda q, level: q + level * m + 1                   # noqa: E731 (gmsh node tag)
    if order == 1:
        pattern = [(q, 0) for q in range(4)] + [(q, 1) for q in range(4)]
    else:
        pattern = _HEX27
    qi = np.array([q for q, _ in pattern])
    li = np.array([lv for _, lv in pattern])
    hexes = np.vstack([node(quads[:, qi], order * k + li) for k in range(nx)])
    gmsh.model.add("solid")
    gmsh.model.addDiscreteEntity(3, 1)
    gmsh.model.addDiscreteEntity(2, 1)
    gmsh.model.addDiscreteEntity(2, 2)
    gmsh.model.mesh.addNodes(3, 1, np.arange(1, levels * m + 1),
                             np.column_stack([X, Y, Z]).ravel())
    hexa, quad = {1: (5, 3), 2: (12, 10)}[order]
    gmsh.model.mesh.addElementsByType(1, hexa, [], hexes.ravel())
    tip = node(quads, levels - 1)
    gmsh.model.mesh.addElementsByType(1, quad, [], node(quads, 0).ravel())
    gmsh.model.mesh.addElementsByType(2, quad, [], tip.ravel())
    for dim, tag, name in ((2, 1, "root"), (2, 2, "tip"), (3, 1, "beam")):
        gmsh.model.addPhysicalGroup(dim, [tag], tag)
        gmsh.model.setPhysicalName(dim, tag, name)


def _place(shape: BeamShape, x, yt, zt):
    """O-XYZ of section points (y~, z~) at x, twisted (BeamShape.point with the table's twist
    interpolated at once)."""
    _, _, th = stretch(shape, x)
    c, s = np.cos(th), np.sin(th)
    return shape.g.hub_radius + x, c * yt - s * zt, s * yt + c * zt
