"""Shape of the twisted tapered beam and its cross-section properties in closed form.

A point of the body is given by its distance x from the root along the undeformed centerline and
its section coordinates (y~, z~) in the section's own axes (y~ along the side that is root_y long
at the root). The section is a rectangle b(x) x h(x) with sizes linear in x, rotated about +X by
theta(x) = twist * x / L (SPEC section 1). In O-XYZ (paper notation X0, Y0, Z0):

    X = R + x,   Y = cos(theta) y~ - sin(theta) z~,   Z = sin(theta) y~ + cos(theta) z~

with R the hub radius. The section properties of the paper's Eq. 41 follow by rotating the
principal ones of the rectangle (I~_y = int z~^2 dA = b h^3 / 12, I~_z = int y~^2 dA = h b^3 / 12):

    A = b h,  S_Y = int Z dA = 0,  S_Z = int Y dA = 0  (the centroid is on the axis),
    I_Y = int Z^2 dA = sin^2 I~_z + cos^2 I~_y,   I_Z = int Y^2 dA = cos^2 I~_z + sin^2 I~_y,
    I_YZ = int Y Z dA = sin cos (I~_z - I~_y),    J_X = I_Y + I_Z (polar, the paper's choice),

and the Saint-Venant torsion constant of the rectangle (long side a, short side c) by its series
J = a c^3 / 3 [1 - 192 c / (pi^5 a) sum_{n odd} tanh(n pi a / (2 c)) / n^5].

Axial stress over a section from its stress resultants (:meth:`BeamShape.axial_stress`): beam
theory's linear distribution sigma_X = a + b Y + c Z (the strain of Eq. 40 times E) is fixed by
N = int sigma_X dA, int Y sigma_X dA and int Z sigma_X dA through the section properties above.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fxflex.scene import Geometry

__all__ = ["BeamShape", "SectionProperties", "saint_venant_rectangle"]


def saint_venant_rectangle(b, h, terms: int = 50):
    """Saint-Venant torsion constant of a b x h rectangle (exact series, relative error < 1e-12)."""
    b, h = np.broadcast_arrays(np.asarray(b, float), np.asarray(h, float))
    a, c = np.maximum(b, h), np.minimum(b, h)
    n = np.arange(1, 2 * terms, 2, dtype=float)
    ratio = (a / c)[..., None]
    series = np.sum(np.tanh(n * np.pi * ratio / 2) / n**5, axis=-1)
    return a * c**3 / 3 * (1 - 192 / np.pi**5 * (c / a) * series)


@dataclass(frozen=True)
class SectionProperties:
    """Section properties at stations x (arrays of the shape of x); SI units."""

    x: np.ndarray
    A: np.ndarray
    S_Y: np.ndarray
    S_Z: np.ndarray
    I_Y: np.ndarray
    I_Z: np.ndarray
    I_YZ: np.ndarray
    J_polar: np.ndarray
    J_saint_venant: np.ndarray

    def J_X(self, torsion: str = "polar") -> np.ndarray:
        """Torsion constant: ``polar`` (J_X = I_Y + I_Z, the paper) or ``saint-venant``."""
        return self.J_polar if torsion == "polar" else self.J_saint_venant


class BeamShape:
    """The undeformed body: map from (x, y~, z~) to O-XYZ and the section properties."""

    def __init__(self, geometry: Geometry):
        self.g = geometry
        self.L = geometry.length
        self.twist_rad = np.radians(geometry.twist_deg)
        self._span = None       # the 2-D section analysis, for a section not the paper's
        self._blade = None

    @property
    def blade(self):
        """:class:`fxflex.section.blade.Blade`: the scene's sections and sizes along the span."""
        if self._blade is None:
            from fxflex.section.blade import Blade
            self._blade = Blade(self.g)
        return self._blade

    @property
    def span(self):
        """:class:`fxflex.section.span.SpanSections` of a section other than the paper's
        rectangle (analysed on first use), or None."""
        if self._span is None and not self.g.paper_shape:
            from fxflex.section.span import span_sections
            self._span = span_sections(self.g)
        return self._span

    def sizes(self, x):
        """(b, h, theta) at distance x from the root: sizes along y~, z~ and the twist angle
        (linear; for another section than the paper's, :meth:`Blade.sizes`: the stations
        table, a naca4 thickness from its digits)."""
        if not self.g.paper_shape:
            xs = np.asarray(x, float)
            rows = np.array([self.blade.sizes(float(v))[:3] for v in xs.ravel()])
            return tuple(rows[:, k].reshape(xs.shape) for k in range(3))
        s = np.asarray(x, float) / self.L
        g = self.g
        return (g.root_y + (g.tip_y - g.root_y) * s, g.root_z + (g.tip_z - g.root_z) * s,
                self.twist_rad * s)

    def point(self, x, yt, zt):
        """O-XYZ coordinates of the point at x with section coordinates (y~, z~) in metres."""
        _, _, th = self.sizes(x)
        c, s = np.cos(th), np.sin(th)
        return (self.g.hub_radius + np.asarray(x, float), c * yt - s * zt, s * yt + c * zt)

    def point_from_unit(self, x, eta, zeta):
        """As :meth:`point`, with eta, zeta in [-1/2, 1/2] fractions of the local sizes."""
        b, h, _ = self.sizes(x)
        return self.point(x, b * np.asarray(eta, float), h * np.asarray(zeta, float))

    def unit_from_point(self, X: np.ndarray) -> np.ndarray:
        """The inverse of :meth:`point_from_unit` for points X (n, 3) in O-XYZ: (x, eta, zeta)
        per row, x from the root, eta and zeta fractions of the local sizes."""
        X = np.asarray(X, float)
        x = X[:, 0] - self.g.hub_radius
        b, h, th = self.sizes(x)
        c, s = np.cos(th), np.sin(th)
        return np.column_stack([x, (c * X[:, 1] + s * X[:, 2]) / b,
                                (-s * X[:, 1] + c * X[:, 2]) / h])

    def section(self, x) -> SectionProperties:
        """Properties at stations x: closed forms for the paper's rectangle, the interpolated
        2-D analysis (:mod:`fxflex.section.span`) for any other section, whose torsion constant
        is the Saint-Venant J whatever ``section.torsion`` says."""
        x = np.asarray(x, float)
        if self.span is not None:
            A, I_Y, I_Z, I_YZ, J = self.span.hub(x)
            zero = np.zeros_like(x)
            return SectionProperties(x=x, A=A, S_Y=zero, S_Z=zero, I_Y=I_Y, I_Z=I_Z, I_YZ=I_YZ,
                                     J_polar=J, J_saint_venant=J)
        b, h, th = self.sizes(x)
        c2, s2, sc = np.cos(th) ** 2, np.sin(th) ** 2, np.sin(th) * np.cos(th)
        Iy_loc = b * h**3 / 12.0   # int z~^2 dA
        Iz_loc = h * b**3 / 12.0   # int y~^2 dA
        zero = np.zeros_like(x)
        return SectionProperties(
            x=x, A=b * h, S_Y=zero, S_Z=zero,
            I_Y=s2 * Iz_loc + c2 * Iy_loc, I_Z=c2 * Iz_loc + s2 * Iy_loc,
            I_YZ=sc * (Iz_loc - Iy_loc), J_polar=Iy_loc + Iz_loc,
            J_saint_venant=saint_venant_rectangle(b, h))

    def corners(self, x: float) -> np.ndarray:
        """(4, 2): (Y, Z) of the four corners of the section at distance x from the root; for
        a section other than the paper's, the (n, 2) points of its outer contour."""
        if self.span is not None:
            return self.span.outline_points(x)
        b, h, _ = self.sizes(x)
        yt = 0.5 * b * np.array([1.0, -1.0, -1.0, 1.0])
        zt = 0.5 * h * np.array([1.0, 1.0, -1.0, -1.0])
        _, Y, Z = self.point(x, yt, zt)
        return np.column_stack([Y, Z])

    def axial_stress(self, x: float, resultants) -> np.ndarray:
        """sigma_X (Pa) at the four :meth:`corners` of the section at x from the resultants
        (N, int Y sigma_X dA, int Z sigma_X dA): solve [[A, S_Z, S_Y], [S_Z, I_Z, I_YZ],
        [S_Y, I_YZ, I_Y]] (a, b, c) = resultants for sigma_X = a + b Y + c Z."""
        p = self.section(np.asarray(float(x)))
        G = np.array([[p.A, p.S_Z, p.S_Y], [p.S_Z, p.I_Z, p.I_YZ], [p.S_Y, p.I_YZ, p.I_Y]],
                     dtype=float)
        a, b, c = np.linalg.solve(G, np.asarray(resultants, dtype=float))
        yz = self.corners(x)
        return a + b * yz[:, 0] + c * yz[:, 1]

    def volume(self) -> float:
        """Exact volume: int_0^L b(x) h(x) dx (the twist does not change it)."""
        g, L = self.g, self.L
        db, dh = g.tip_y - g.root_y, g.tip_z - g.root_z
        return L * (g.root_y * g.root_z + (g.root_y * dh + g.root_z * db) / 2 + db * dh / 3)
