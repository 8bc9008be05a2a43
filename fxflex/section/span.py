"""Section properties anywhere along the span, for the beam methods (issue 14 items 3-4).

The 2-D analysis (:mod:`fxflex.section.properties`) runs at the stations: the rows of
``geometry.stations`` together with :data:`~fxflex.section.blade.DEFAULT_STATIONS` evenly spaced
ones. Between them the properties are interpolated in scaled form: with b(x), h(x) the section's
sizes along y~ and z~ (linear between stations, exact), each property is its station value over
the power of b and h it would have if the section only stretched,

    A = a b h,   Iz~ = int y~^2 dA = c_z b^3 h,   Iy~ = int z~^2 dA = c_y b h^3,
    Iy~z~ = c_yz b^2 h^2,   J = j (Iy~ + Iz~),

and the coefficients a, c_y, c_z, c_yz, j are interpolated linearly. For a section that keeps its
shape and only stretches (every shape with the linear root/tip keys and no wall) a, c_y, c_z and
c_yz are constant, so A and the second moments are exact at every x; j depends on the aspect
ratio b / h only and varies slowly (a hollow wall that does not scale with b and h makes the
coefficients vary; the stations keep that to the interpolation error between them).

Properties are about the centroid (the beam axis is the centroid line: sections are placed with
their centroid on the X axis, SPEC section 9), so the first moments S_Y = S_Z = 0, and rotated by
the twist theta(x) into the hub frame (Y = c y~ - s z~, Z = s y~ + c z~):

    I_Y = int Z^2 = s^2 Iz~ + c^2 Iy~ + 2 s c Iy~z~,   I_Z = c^2 Iz~ + s^2 Iy~ - 2 s c Iy~z~,
    I_YZ = s c (Iz~ - Iy~) + (c^2 - s^2) Iy~z~,

so a cambered airfoil's principal angle adds to the geometric twist through Iy~z~. The torsion
constant is the Saint-Venant J of the warping analysis whatever ``section.torsion`` says (that key
chooses between the polar moment and the series J for the paper's rectangle only). The shear
centre's offset from the centroid is computed (``fxflex section``) but the beams of Eq. 37-48 have
no bending-torsion coupling to put it in: they bend about the centroid and twist about it too.
"""

from __future__ import annotations

import numpy as np

from fxflex.section.blade import DEFAULT_STATIONS, Blade

__all__ = ["SpanSections", "span_sections"]

#: analyses kept in this process, by geometry and the state of its files (builds of one scene at
#: several speeds, a study over element counts: the section analysis runs once)
_KEPT: dict = {}


def span_sections(geometry) -> "SpanSections":
    """The :class:`SpanSections` of ``geometry``, analysed once per process (the contour and
    stations files' size and modification time are part of the key)."""
    import os

    files = tuple((p, os.stat(p).st_mtime_ns, os.stat(p).st_size)
                  for p in (geometry.contour, geometry.stations) if p)
    key = (geometry, files)
    if key not in _KEPT:
        if len(_KEPT) > 16:
            _KEPT.clear()
        _KEPT[key] = SpanSections(geometry)
    return _KEPT[key]


class SpanSections:
    """The scene's sections analysed at the stations, interpolated anywhere along the span."""

    def __init__(self, geometry, resolution: int | None = None):
        from fxflex.section.properties import RESOLUTION, analyse_many

        self.blade = Blade(geometry)
        xs = np.union1d(self.blade.stations(), self.blade.stations(DEFAULT_STATIONS))
        outlines = [self.blade.outline(x) for x in xs]
        results = analyse_many(outlines, resolution or RESOLUTION)
        b, h = self._bh(xs)
        A = np.array([r.A for r in results])
        Iy = np.array([r.Iy for r in results])
        Iz = np.array([r.Iz for r in results])
        Iyz = np.array([r.Iyz for r in results])
        J = np.array([r.J for r in results])
        self.x = xs
        self.coef = {"a": A / (b * h), "c_y": Iy / (b * h**3), "c_z": Iz / (b**3 * h),
                     "c_yz": Iyz / (b * h) ** 2, "j": J / (Iy + Iz)}
        self.results = results
        # the outer contour about the centroid, in the section's own axes, per station
        self._outer = [o.outer - np.asarray(r.centroid) for o, r in zip(outlines, results)]

    def _bh(self, x):
        x = np.atleast_1d(np.asarray(x, float))
        sizes = np.array([self.blade.sizes(float(v))[:3] for v in x.ravel()])
        return (sizes[:, 0].reshape(x.shape), sizes[:, 1].reshape(x.shape))

    def local(self, x):
        """(A, Iy~, Iz~, Iy~z~, J, theta) at stations x, in the section's own axes."""
        x = np.asarray(x, float)
        flat = np.atleast_1d(x).ravel()
        sizes = np.array([self.blade.sizes(float(v))[:3] for v in flat])
        b, h, th = sizes[:, 0], sizes[:, 1], sizes[:, 2]
        c = {k: np.interp(flat, self.x, v) for k, v in self.coef.items()}
        A = c["a"] * b * h
        Iy, Iz, Iyz = c["c_y"] * b * h**3, c["c_z"] * b**3 * h, c["c_yz"] * (b * h) ** 2
        J = c["j"] * (Iy + Iz)
        return tuple(v.reshape(x.shape) for v in (A, Iy, Iz, Iyz, J, th))

    def hub(self, x):
        """(A, I_Y, I_Z, I_YZ, J) in the hub frame at stations x (module docstring)."""
        A, Iy, Iz, Iyz, J, th = self.local(x)
        c, s = np.cos(th), np.sin(th)
        I_Y = s * s * Iz + c * c * Iy + 2 * s * c * Iyz
        I_Z = c * c * Iz + s * s * Iy - 2 * s * c * Iyz
        I_YZ = s * c * (Iz - Iy) + (c * c - s * s) * Iyz
        return A, I_Y, I_Z, I_YZ, J

    def outline_points(self, x: float) -> np.ndarray:
        """(n, 2): (Y, Z) of the outer contour of the section at x about the centroid, twisted,
        scaled from the nearest station's contour to the sizes at x."""
        k = int(np.argmin(np.abs(self.x - x)))
        b0, h0 = (float(v[0]) for v in self._bh(self.x[k]))
        b, h = (float(v[0]) for v in self._bh(x))
        pts = self._outer[k] * np.array([b / b0, h / h0])
        th = self.blade.sizes(float(x))[2]
        c, s = np.cos(th), np.sin(th)
        return np.column_stack([c * pts[:, 0] - s * pts[:, 1], s * pts[:, 0] + c * pts[:, 1]])
