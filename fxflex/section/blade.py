"""The blade's sections along the span (SPEC section 9): shape, sizes, twist and wall at any x.

:class:`Blade` reads the scene's geometry: the section shape (``geometry.section``), its sizes and
twist either linear between root and tip (SPEC section 1) or from ``geometry.stations`` (a CSV
table ``x,size_y,size_z,twist_deg[,wall]``, linear between rows), and the wall
(``geometry.wall`` or the table's column). :meth:`Blade.outline` gives the section's
:class:`~fxflex.section.outline.Outline` at x, before the twist, in the shape's own coordinates:

- rectangle, ellipse: size_y x size_z, centred;
- naca4: the chord is size_y, the thickness follows from the digits (size_z must be unset or
  agree with it: t x chord);
- polygon: ``geometry.contour``, a CSV of y,z rows (a blank line, then an inner contour), is the
  root section, scaled by size_y / size_y(0) along y and size_z / size_z(0) along z.

:func:`check_geometry` is what :mod:`fxflex.scene.checks` calls: files read and checked, one-line
:class:`~fxflex.errors.SceneError` naming the key otherwise. :func:`section_table` analyses the
sections at stations (:mod:`fxflex.section.properties`) for ``fxflex section``.
"""

from __future__ import annotations

import csv
import io
import math
from typing import TYPE_CHECKING

import numpy as np

from fxflex.errors import SceneError
from fxflex.section.outline import Outline, ellipse, hollow, naca4, naca_digits, polygon, rectangle

if TYPE_CHECKING:
    from fxflex.scene.schema import Geometry

__all__ = ["Blade", "check_geometry", "read_contour", "read_stations", "section_table",
           "DEFAULT_STATIONS"]

#: stations `fxflex section` analyses without a table or --stations
DEFAULT_STATIONS = 11
#: the paper's Z sizes: taken as "not given" for a naca4 section, whose thickness is its own
_PAPER_Z = {"root_z": 0.06, "tip_z": 0.04}
STATION_COLUMNS = ("x", "size_y", "size_z", "twist_deg")


def _read_text(key: str, path: str) -> str:
    name = path if path.isprintable() else repr(path)
    try:
        with open(path, encoding="utf-8-sig") as f:
            return f.read()
    except FileNotFoundError:
        raise SceneError(key, f"file not found: {name}") from None
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        reason = getattr(exc, "strerror", None) or exc
        raise SceneError(key, f"cannot read {name}: {reason}") from None


def _number(key: str, path: str, line: int, text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise SceneError(key, f"{path} line {line}: {text.strip()!r} is not a number") from None
    if not math.isfinite(value):
        raise SceneError(key, f"{path} line {line}: {text.strip()!r} is not a finite number")
    return value


def read_contour(path: str) -> tuple[np.ndarray, np.ndarray | None]:
    """(outer, inner or None) of a contour CSV: rows ``y,z`` (an optional header line ``y,z``),
    a blank line before the inner contour's rows."""
    key = "geometry.contour"
    blocks: list[list[tuple[float, float]]] = [[]]
    for n, line in enumerate(_read_text(key, path).splitlines(), 1):
        if not line.strip():
            if blocks[-1]:
                blocks.append([])
            continue
        cells = line.split(",")
        if n == 1 and [c.strip().lower() for c in cells] == ["y", "z"]:
            continue
        if len(cells) != 2:
            raise SceneError(key, f"{path} line {n}: expected 2 values y,z, got {len(cells)}")
        blocks[-1].append((_number(key, path, n, cells[0]), _number(key, path, n, cells[1])))
    blocks = [b for b in blocks if b]
    if not blocks or len(blocks) > 2:
        raise SceneError(key, f"{path}: {len(blocks)} contours; allowed: an outer one and "
                              f"optionally, after a blank line, an inner one")
    return np.array(blocks[0]), (np.array(blocks[1]) if len(blocks) == 2 else None)


def read_stations(path: str, length: float) -> np.ndarray:
    """The stations table (n, 5): x, size_y, size_z, twist_deg, wall (NaN where the optional wall
    column is absent); rows checked: x from 0 to the length, increasing, sizes above 0."""
    key = "geometry.stations"
    rows = list(csv.reader(io.StringIO(_read_text(key, path))))
    rows = [(n, r) for n, r in enumerate(rows, 1) if any(c.strip() for c in r)]
    if not rows:
        raise SceneError(key, f"{path} is empty; allowed: a header x,size_y,size_z,twist_deg"
                              f"[,wall] and two or more rows")
    header = [c.strip() for c in rows[0][1]]
    if header not in (list(STATION_COLUMNS), list(STATION_COLUMNS) + ["wall"]):
        raise SceneError(key, f"{path} line {rows[0][0]}: header {','.join(header)!r}; allowed: "
                              f"x,size_y,size_z,twist_deg or x,size_y,size_z,twist_deg,wall")
    table = []
    for n, r in rows[1:]:
        if len(r) != len(header):
            raise SceneError(key, f"{path} line {n}: {len(r)} values; expected {len(header)}")
        vals = [_number(key, path, n, c) for c in r] + ([math.nan] if len(header) == 4 else [])
        table.append(vals)
    t = np.array(table, float).reshape(-1, 5)
    if len(t) < 2:
        raise SceneError(key, f"{path}: {len(t)} row(s); allowed: two or more")
    if t[0, 0] != 0.0 or not math.isclose(t[-1, 0], length, rel_tol=1e-9):
        raise SceneError(key, f"{path}: x runs from {t[0, 0]:g} to {t[-1, 0]:g}; allowed: from "
                              f"0 to geometry.length = {length:g}")
    if np.any(np.diff(t[:, 0]) <= 0):
        raise SceneError(key, f"{path}: x is not increasing; allowed: increasing x")
    if np.any(t[:, 1:3] <= 0):
        raise SceneError(key, f"{path}: a size is not above 0; allowed: size_y, size_z > 0")
    if np.any(t[:, 4] < 0):
        raise SceneError(key, f"{path}: a wall is below 0; allowed: wall >= 0")
    t[-1, 0] = length
    return t


class Blade:
    """Sections of the scene's blade along the span; see the module docstring."""

    def __init__(self, geometry: "Geometry"):
        g = self.geometry = geometry
        self.table = read_stations(g.stations, g.length) if g.stations else None
        self.contour = read_contour(g.contour) if g.section == "polygon" else None
        if self.table is None:
            self.root_sizes = (g.root_y, g.root_z)
        else:
            self.root_sizes = (float(self.table[0, 1]), float(self.table[0, 2]))

    def sizes(self, x: float) -> tuple[float, float, float, float]:
        """(size_y, size_z, twist in rad, wall) at x; for naca4 size_z is the airfoil's
        thickness t x chord whatever the Z keys say (they may be left at the paper's values)."""
        g = self.geometry
        if self.table is None:
            s = x / g.length
            by, bz, tw, wall = g.size_y(s), g.size_z(s), g.twist(s), g.wall
        else:
            t = self.table
            by, bz, tw = (float(np.interp(x, t[:, 0], t[:, k])) for k in (1, 2, 3))
            tw = math.radians(tw)
            wall = g.wall if np.isnan(t[:, 4]).all() else float(np.interp(x, t[:, 0], t[:, 4]))
        if g.section == "naca4":
            bz = naca_digits(g.airfoil)[2] * by
        return by, bz, tw, wall

    def stations(self, n: int | None = None) -> np.ndarray:
        """The table's rows, or n (default DEFAULT_STATIONS) evenly spaced stations."""
        if n is None and self.table is not None:
            return self.table[:, 0].copy()
        return np.linspace(0.0, self.geometry.length, n or DEFAULT_STATIONS)

    def outline(self, x: float) -> Outline:
        """The section at x before the twist (module docstring)."""
        g = self.geometry
        by, bz, _, wall = self.sizes(x)
        if g.section == "rectangle":
            out = rectangle(by, bz)
        elif g.section == "ellipse":
            out = ellipse(by, bz)
        elif g.section == "naca4":
            out = naca4(g.airfoil, by)
        else:
            outer, inner = self.contour
            scale = np.array([by / self.root_sizes[0], bz / self.root_sizes[1]])
            out = polygon(outer * scale, None if inner is None else inner * scale)
        return hollow(out, wall) if wall > 0 else out


def check_geometry(g: "Geometry") -> None:
    """The section keys of SPEC section 9, with one-line errors naming the key (nothing to read
    for the paper's rectangle)."""
    if g.paper_shape and not g.contour and g.airfoil == "0012":
        return
    if g.contour and g.section != "polygon":
        raise SceneError("geometry.contour", f"given with geometry.section = {g.section!r}; "
                                             f"allowed: only with section = \"polygon\"")
    if g.section == "polygon" and not g.contour:
        raise SceneError("geometry.contour", "section = \"polygon\" needs a contour CSV file; "
                                             "allowed: a path to rows y,z")
    if g.section == "naca4":
        try:
            _, _, t = naca_digits(g.airfoil)
        except ValueError as exc:
            raise SceneError("geometry.airfoil", str(exc)) from None
    blade = Blade(g)
    if g.section == "naca4" and blade.table is None:
        for key, chord in (("root_z", g.root_y), ("tip_z", g.tip_y)):
            z = getattr(g, key)
            if z != _PAPER_Z[key] and not math.isclose(z, t * chord, rel_tol=1e-6):
                raise SceneError(f"geometry.{key}", f"got {z!r}: a naca4 section's thickness "
                                                    f"follows from geometry.airfoil; allowed: "
                                                    f"unset or {t * chord:.6g} (t x chord)")
    if g.section == "naca4" and blade.table is not None:
        bad = ~np.isclose(blade.table[:, 2], t * blade.table[:, 1], rtol=1e-6)
        if bad.any():
            row = int(np.argmax(bad))
            raise SceneError("geometry.stations", f"row {row + 1}: size_z "
                                                  f"{blade.table[row, 2]:g} disagrees with the "
                                                  f"airfoil's thickness; allowed: t x size_y = "
                                                  f"{t * blade.table[row, 1]:.6g}")
    key = "geometry.contour" if g.section == "polygon" else "geometry.section"
    wall_key = "geometry.stations" if (blade.table is not None
                                       and not np.isnan(blade.table[:, 4]).all()) \
        else "geometry.wall"
    for x in blade.stations():
        try:
            blade.outline(x)
        except ValueError as exc:
            wall = blade.sizes(x)[3]
            raise SceneError(wall_key if wall > 0 and "wall" in str(exc) else key,
                             f"at x = {x:g} m: {exc}") from None


def section_table(scene, n: int | None = None, resolution: int | None = None) -> list[dict]:
    """Properties of the scene's sections at the stations (SPEC section 9 names; mass per length
    rho A)."""
    from fxflex.section.properties import RESOLUTION, analyse_many

    blade = Blade(scene.geometry)
    xs = blade.stations(n)
    results = analyse_many([blade.outline(x) for x in xs], resolution or RESOLUTION)
    rows = []
    for x, r in zip(xs, results):
        by, bz, twist, wall = blade.sizes(x)
        d = {"x": float(x)}
        d.update(r.as_dict())
        d["mass_per_length"] = scene.material.rho * r.A
        d["twist_deg"] = math.degrees(twist)
        rows.append(d)
    return rows
