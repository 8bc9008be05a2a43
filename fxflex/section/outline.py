"""Cross-section outlines (issue 14, SPEC section 9): closed polygons in the section's own y, z.

An :class:`Outline` is the outer contour, counter-clockwise, and optionally one inner contour (a
hole), clockwise, both as (n, 2) arrays of (y, z) vertices, the closing edge implicit. y runs
along the chord (or the root_y side), z across it, before the twist. Coordinates are the shape's
own: the rectangle and ellipse are centred on the origin, the NACA airfoil starts at its leading
edge, a polygon keeps the file's coordinates. :mod:`fxflex.section.properties` finds the centroid.

Curved shapes are polygons fine enough for their discretisation error to be negligible beside the
section mesh's: :data:`CURVE_POINTS` vertices on an ellipse lose 2 pi^2 / (3 n^2) = 2.5e-5 of the
area at n = 512.

Pure functions: no gmsh, no dolfinx (polygon tests and offsets by shapely).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Outline", "CURVE_POINTS", "rectangle", "ellipse", "naca4", "naca_digits", "polygon",
           "hollow", "signed_area", "self_intersects", "moments"]

#: vertices on a curved outline (ellipse, airfoil: half on each surface)
CURVE_POINTS = 512
#: the 4-digit thickness polynomial with a closed trailing edge (SPEC section 9)
NACA_THICKNESS = (0.2969, -0.1260, -0.3516, 0.2843, -0.1036)


@dataclass(frozen=True)
class Outline:
    """Outer contour (ccw) and an optional inner one (cw), (n, 2) arrays of (y, z) in m."""

    outer: np.ndarray
    inner: np.ndarray | None = None

    def contours(self) -> list[np.ndarray]:
        return [self.outer] + ([self.inner] if self.inner is not None else [])

    @property
    def extent(self) -> tuple[float, float]:
        """(size along y, size along z) of the outer contour's bounding box."""
        span = self.outer.max(axis=0) - self.outer.min(axis=0)
        return float(span[0]), float(span[1])


def moments(outline: Outline, degree: int = 4, origin=(0.0, 0.0)) -> np.ndarray:
    """M[i, j] = int (y - y0)^i (z - z0)^j dA over the section for i + j <= degree, exact for
    the polygon: by Green's theorem int y^i z^j dA = 1 / (i + 1) oint y^(i+1) z^j dz along every
    contour (the outer one counter-clockwise, a hole clockwise), each straight edge integrated by
    Gauss-Legendre with enough points for the degree i + j + 1 of the integrand along it."""
    o = np.asarray(origin, float)
    t, w = np.polynomial.legendre.leggauss(degree // 2 + 2)
    t, w = 0.5 * (t + 1.0), 0.5 * w                                 # on [0, 1]
    M = np.zeros((degree + 1, degree + 1))
    for pts in outline.contours():
        p = pts - o
        d = np.roll(p, -1, axis=0) - p                               # edge vectors
        y = p[None, :, 0] + t[:, None] * d[None, :, 0]               # (points, edges)
        z = p[None, :, 1] + t[:, None] * d[None, :, 1]
        dz = w[:, None] * d[None, :, 1]
        for i in range(degree + 1):
            for j in range(degree + 1 - i):
                M[i, j] += float(np.sum(y ** (i + 1) * z**j * dz)) / (i + 1)
    return M


def signed_area(points: np.ndarray) -> float:
    """Shoelace area of the closed polygon: positive when counter-clockwise."""
    y, z = points[:, 0], points[:, 1]
    return 0.5 * float(np.dot(y, np.roll(z, -1)) - np.dot(np.roll(y, -1), z))


def self_intersects(points: np.ndarray) -> bool:
    """Whether the closed polygon's boundary crosses or touches itself."""
    from shapely.geometry import LinearRing

    return not LinearRing(np.asarray(points, float)).is_simple


def _ccw(points: np.ndarray, ccw: bool = True) -> np.ndarray:
    points = np.asarray(points, float)
    return points if (signed_area(points) > 0) == ccw else points[::-1].copy()


def rectangle(b: float, h: float) -> Outline:
    """b along y by h along z, centred on the origin (the paper's section)."""
    return Outline(np.array([[-b / 2, -h / 2], [b / 2, -h / 2], [b / 2, h / 2], [-b / 2, h / 2]]))


def ellipse(b: float, h: float, n: int = CURVE_POINTS) -> Outline:
    """Axes b along y and h along z (full lengths), centred on the origin."""
    t = 2 * np.pi * np.arange(n) / n
    return Outline(np.column_stack([b / 2 * np.cos(t), h / 2 * np.sin(t)]))


def naca_digits(code: str) -> tuple[float, float, float]:
    """(max camber m, its chordwise position p, thickness t), fractions of the chord, of a 4-digit
    designation such as "2412"; ValueError naming what is allowed otherwise."""
    if not (isinstance(code, str) and len(code) == 4 and code.isdigit()):
        raise ValueError(f"got {code!r}: a NACA 4-digit designation is 4 digits, e.g. \"0012\"")
    m, p, t = int(code[0]) / 100, int(code[1]) / 10, int(code[2:]) / 100
    if t <= 0:
        raise ValueError(f"got {code!r}: the thickness (last two digits) must be above 0")
    if (m > 0) != (p > 0):
        raise ValueError(f"got {code!r}: camber and its position must be both zero or both set")
    return m, p, t


def naca_thickness(x: np.ndarray, t: float) -> np.ndarray:
    """Half-thickness y_t(x) / chord of the 4-digit section, closed trailing edge."""
    a0, a1, a2, a3, a4 = NACA_THICKNESS
    return 5 * t * (a0 * np.sqrt(x) + a1 * x + a2 * x**2 + a3 * x**3 + a4 * x**4)


def naca_camber(x: np.ndarray, m: float, p: float) -> tuple[np.ndarray, np.ndarray]:
    """Mean line y_c(x) / chord and its slope dy_c/dx of the 4-digit section."""
    if m == 0:
        return np.zeros_like(x), np.zeros_like(x)
    fore = x < p
    yc = np.where(fore, m / p**2 * (2 * p * x - x**2), m / (1 - p)**2 * (1 - 2 * p + 2 * p * x - x**2))
    dyc = np.where(fore, 2 * m / p**2 * (p - x), 2 * m / (1 - p)**2 * (p - x))
    return yc, dyc


def naca4(code: str, chord: float, n: int = CURVE_POINTS) -> Outline:
    """The 4-digit airfoil with chord along y from the leading edge (y = 0) to the trailing edge
    (y = chord), thickness along z: the thickness laid perpendicular to the mean line (Abbott and
    von Doenhoff), cosine spacing, n vertices in all."""
    m, p, t = naca_digits(code)
    k = n // 2
    x = 0.5 * (1 - np.cos(np.pi * np.arange(k + 1) / k))          # 0 .. 1
    yt = naca_thickness(x, t)
    yc, dyc = naca_camber(x, m, p)
    th = np.arctan(dyc)
    upper = np.column_stack([x - yt * np.sin(th), yc + yt * np.cos(th)])
    lower = np.column_stack([x + yt * np.sin(th), yc - yt * np.cos(th)])
    # ccw: from the trailing edge along the upper surface to the leading edge, back along the lower
    pts = np.vstack([upper[::-1][:-1], lower[:-1]]) * chord
    return Outline(_ccw(pts))


def polygon(outer, inner=None) -> Outline:
    """A user's contour(s), oriented; ValueError if a contour has fewer than 3 points, no area or
    crosses itself, or the inner one is not strictly inside the outer one."""
    from shapely.geometry import Polygon

    contours = []
    for name, pts in (("outer", outer), ("inner", inner)):
        if pts is None:
            contours.append(None)
            continue
        pts = np.asarray(pts, float)
        if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 3:
            raise ValueError(f"the {name} contour needs at least 3 points of (y, z)")
        if np.allclose(pts[0], pts[-1]):
            pts = pts[:-1]
        if len(pts) < 3 or abs(signed_area(pts)) <= 1e-12 * np.ptp(pts, axis=0).max() ** 2 and (
                np.linalg.matrix_rank(pts[1:] - pts[0], tol=1e-12 * np.ptp(pts)) < 2):
            raise ValueError(f"the {name} contour encloses no area")
        if self_intersects(pts):
            raise ValueError(f"the {name} contour crosses itself")
        contours.append(pts)
    outer_pts = _ccw(contours[0])
    inner_pts = None if contours[1] is None else _ccw(contours[1], ccw=False)
    if inner_pts is not None and not (Polygon(outer_pts).contains(Polygon(inner_pts))
                                      and not Polygon(outer_pts).exterior.intersects(
                                          Polygon(inner_pts).exterior)):
        raise ValueError("the inner contour must lie strictly inside the outer one")
    return Outline(outer_pts, inner_pts)


def hollow(outline: Outline, wall: float) -> Outline:
    """The outer contour with a wall of thickness ``wall`` inside it: the inner contour is the set
    of points at least ``wall`` from the outer one (shapely's inward buffer with mitred corners, so
    a polygon's corners stay corners). Where the body is thinner than two walls (an airfoil's
    trailing edge) the section is solid. ValueError if the wall leaves no hollow, splits it in
    two, or the outline already has a hole."""
    from shapely.geometry import Polygon

    if outline.inner is not None:
        raise ValueError("a contour with a hole cannot be made hollow again")
    if not wall > 0:
        raise ValueError(f"the wall thickness must be above 0, got {wall}")
    inner = Polygon(outline.outer).buffer(-wall, join_style=2, mitre_limit=10.0)
    if inner.is_empty or inner.area <= 0:
        raise ValueError(f"a wall of {wall} m leaves no hollow inside the contour")
    if inner.geom_type != "Polygon":
        raise ValueError(f"a wall of {wall} m splits the hollow in {len(inner.geoms)} parts; "
                         f"allowed: a wall that leaves one")
    pts = np.asarray(inner.exterior.coords, float)[:-1]
    return Outline(outline.outer, _ccw(pts, ccw=False))
