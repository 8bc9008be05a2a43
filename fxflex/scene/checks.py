"""What a scene may hold: types, finite ranges, choices and the physics limits (SPEC section 8).

This is the one place the scene is validated. The frozen dataclasses of
:mod:`fxflex.scene.schema` call :func:`check_section` and :func:`check_scene` on construction, so
a scene built from Python (``Material(nu=0.5)``, ``Scene.replace``), from a TOML file or from
``--set`` passes the same checks and fails with the same one-line :class:`SceneError` naming the
dotted key and what is allowed.

The ranges are physical: lengths from a micrometre to 1000 km (beyond every rotor, and inside
them the powers the models form - L^4 in a second moment, Omega^2 (R + L)^2 in the centrifugal
load - stay well inside floating point), a wave speed below light's, and speeds, loads and
twists short of straining the beam by 100 % or winding its section into a helix.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import os
import numbers
import typing
from collections.abc import Mapping
from typing import NamedTuple

import numpy as np

from fxflex.errors import SceneError

__all__ = ["Interval", "RANGES", "CHOICES", "MIN_SECTION_RATIO", "shown", "printable",
           "check_keys", "check_section", "check_scene"]

#: smallest section size relative to the length: below it the section is degenerate (the mesh
#: and the centreline probe work to 1e-9 of the length)
MIN_SECTION_RATIO = 1e-6
#: speed of light (m/s): no elastic wave is faster, sqrt(E / rho) included
_LIGHT = 299792458.0
#: the shortest and the longest length (m): continuum elasticity below, no rotor above
_MIN_LENGTH, _MAX_LENGTH = 1e-6, 1e6


class Interval(NamedTuple):
    """An interval of allowed values, open or closed at each end."""

    low: float
    high: float = math.inf
    low_open: bool = True
    high_open: bool = True

    def __contains__(self, value) -> bool:
        above = value > self.low if self.low_open else value >= self.low
        below = value < self.high if self.high_open else value <= self.high
        return above and below

    def __str__(self) -> str:
        if self.high == math.inf:
            return f"{'>' if self.low_open else '>='} {self.low:g}"
        return (f"{'(' if self.low_open else '['}{self.low:g}, {self.high:g}"
                f"{')' if self.high_open else ']'}")


_LENGTH = Interval(0.0, _MAX_LENGTH, high_open=False)
_POSITIVE = Interval(0.0)
_NON_NEGATIVE = Interval(0.0, low_open=False)
#: allowed range of each number of the scene (beyond being finite); see the module docstring
RANGES: dict[str, Interval] = {
    "geometry.length": Interval(_MIN_LENGTH, _MAX_LENGTH, low_open=False, high_open=False),
    "geometry.root_y": _LENGTH, "geometry.root_z": _LENGTH,
    "geometry.tip_y": _LENGTH, "geometry.tip_z": _LENGTH,
    "geometry.hub_radius": Interval(0.0, _MAX_LENGTH, low_open=False, high_open=False),
    "geometry.wall": _NON_NEGATIVE,
    "material.E": _POSITIVE,
    "material.nu": Interval(-1.0, 0.5),
    "material.rho": _POSITIVE,
    "load.ramp_time": _NON_NEGATIVE,
    "rotation.rpm": _NON_NEGATIVE,
    "rotation.spinup_time": _NON_NEGATIVE,
    "damping.c": _NON_NEGATIVE,
    "mesh.solid": _POSITIVE,
    "mesh.beam_elements": _POSITIVE,
    "reduction.ffrf_modes": _POSITIVE,
    "reduction.gcms_modes": _POSITIVE,
    "reduction.gcms_gram_tol": Interval(0.0, 1.0),
    "tip_mass.mass": _NON_NEGATIVE,
    "tip_mass.inertia": _NON_NEGATIVE,
}
CHOICES: dict[str, tuple[str, ...]] = {
    "geometry.section": ("rectangle", "ellipse", "naca4", "polygon"),
    "section.torsion": ("polar", "saint-venant"),
    "rotation.profile": ("constant", "spin-up"),
    "damping.model": ("relative", "absolute"),
    "mesh.ancf_root": ("free-axial", "full"),
    "mesh.solid_degree": (1, 2),
    "mesh.beam_variant": ("paper", "locking-free"),
    "solver.linear": ("auto", "direct", "iterative"),
}


def shown(value, width: int = 60) -> str:
    """``repr`` of a user's value cut to ``width`` characters: one short, printable line."""
    text = repr(value)
    return text if len(text) <= width else f"{text[:width - 5]}...{text[-2:]}"


def _coerce(key: str, value, annotation):
    """The value as the annotation's type (ints and numpy numbers accepted for floats, lists for
    tuples), finite, or a SceneError."""
    if annotation is float:
        if isinstance(value, bool) or not isinstance(value, numbers.Real):
            raise SceneError(key, f"expected a number, got {shown(value)}")
        try:
            value = float(value)
        except OverflowError:
            value = math.inf
        if not math.isfinite(value):
            allowed = f"; allowed: {RANGES[key]}" if key in RANGES else ""
            raise SceneError(key, f"expected a finite number, got {shown(value)}{allowed}")
        return value
    if annotation is int:
        if isinstance(value, bool) or not isinstance(value, numbers.Integral):
            raise SceneError(key, f"expected an integer, got {shown(value)}")
        return int(value)
    if annotation is str:
        if key == "geometry.airfoil" and isinstance(value, numbers.Integral) \
                and not isinstance(value, bool) and 0 <= value <= 9999:
            return f"{int(value):04d}"          # --set geometry.airfoil=0012 reads as 12
        if not isinstance(value, str):
            raise SceneError(key, f"expected a string, got {shown(value)}")
        return value
    args = typing.get_args(annotation)
    if not isinstance(value, (list, tuple)) or len(value) != len(args):
        raise SceneError(key, f"expected a list of {len(args)} values, got {shown(value)}")
    return tuple(_coerce(key, v, a) for v, a in zip(value, args))


@functools.cache
def _hints(cls: type) -> dict[str, type]:
    return {f.name: typing.get_type_hints(cls)[f.name] for f in dataclasses.fields(cls)}


def check_section(section, name: str) -> None:
    """Coerce and check every field of one section (``name`` is its TOML table), then the
    relations between its own fields. Called by the section's ``__post_init__``."""
    for field, annotation in _hints(type(section)).items():
        key = f"{name}.{field}"
        value = _coerce(key, getattr(section, field), annotation)
        object.__setattr__(section, field, value)
        if key in CHOICES and value not in CHOICES[key]:
            raise SceneError(key, f"{shown(value)} is not allowed; allowed: "
                                  f"{', '.join(map(str, CHOICES[key]))}")
        allowed = RANGES.get(key)
        if allowed is not None and not all(
                v in allowed for v in (value if isinstance(value, tuple) else (value,))):
            raise SceneError(key, f"got {shown(value)}; allowed: {allowed}")
    relations = _RELATIONS.get(name)
    if relations is not None:
        relations(section)


def _geometry(g) -> None:
    """Sections not degenerate against the length; a twist that leaves a beam, not a helix: the
    corner fibre, at r_max from the axis, runs at atan(r_max |theta| / L) to it, and at 45 deg
    (r_max |theta| = L) the section winds round faster than the bar advances."""
    for key in ("root_y", "root_z", "tip_y", "tip_z"):
        size = getattr(g, key)
        if size < MIN_SECTION_RATIO * g.length:
            raise SceneError(f"geometry.{key}", f"{size!r} m is below {MIN_SECTION_RATIO:g} of the "
                                                f"length ({g.length!r} m): a degenerate section; "
                                                f"allowed: >= {MIN_SECTION_RATIO * g.length:g} m")
    r_max = max(math.hypot(g.root_y, g.root_z), math.hypot(g.tip_y, g.tip_z)) / 2.0
    limit = math.degrees(g.length / r_max)
    if abs(g.twist_deg) > limit:
        raise SceneError("geometry.twist_deg", f"got {g.twist_deg!r}: the section's corners would "
                                               "wind round the axis at more than 45 deg (a helix, "
                                               f"not a beam); allowed: |twist_deg| <= {limit:.4g} "
                                               "for this section and length")
    from fxflex.section.blade import check_geometry

    check_geometry(g)


def _material(mat) -> None:
    """A wave speed sqrt(E / rho) below light's: no elastic wave is faster."""
    wave = math.sqrt(mat.E / mat.rho)
    if not wave < _LIGHT:
        raise SceneError("material.E", f"with material.rho = {mat.rho!r} the wave speed "
                                       f"sqrt(E/rho) = {wave:.3g} m/s exceeds the speed of light; "
                                       f"allowed: below {mat.rho * _LIGHT**2:.4g} Pa")


def _rotation(rot) -> None:
    if rot.profile == "spin-up" and not rot.spinup_time > 0:
        raise SceneError("rotation.spinup_time", f"got {rot.spinup_time!r} with rotation.profile "
                                                 "= \"spin-up\"; allowed: > 0")


def _mesh(mesh) -> None:
    if mesh.solid[1] % 2 or mesh.solid[2] % 2:
        raise SceneError("mesh.solid", f"got {shown(list(mesh.solid))}: Y and Z divisions must be "
                                       "even (the centerline is a line of nodes); allowed: even "
                                       "Y and Z divisions")
    if mesh.solid_file and not os.path.isfile(mesh.solid_file):
        raise SceneError("mesh.solid_file", f"{shown(mesh.solid_file)} is not a file; allowed: a "
                                            "gmsh .msh file (hexahedra or tetrahedra)")


def _tip_mass(tip) -> None:
    """The moments of inertia of a rigid body about its principal axes: each at most the sum of
    the other two (J_X = int (y^2 + z^2) dm <= J_Y + J_Z = int (x^2 + y^2 + x^2 + z^2) dm), so
    that its second moments int x^2 dm, ... are not negative (SPEC section 10)."""
    J = tip.inertia
    for i, name in enumerate("XYZ"):
        others = J[(i + 1) % 3] + J[(i + 2) % 3]
        if J[i] > others * (1.0 + 1e-12):
            raise SceneError("tip_mass.inertia", f"got {shown(list(J))}: J_{name} exceeds the "
                                                 "sum of the other two, which no rigid body "
                                                 "does; allowed: each value at most the sum of "
                                                 "the other two (a thin disc in the Y-Z plane: "
                                                 "[2 J, J, J])")


_RELATIONS = {"geometry": _geometry, "material": _material, "rotation": _rotation,
              "mesh": _mesh, "tip_mass": _tip_mass}


def printable(name) -> str:
    """A user's key or section name as it can stand at the head of a one-line message: itself
    when printable, else its (cut) ``repr``."""
    return name if isinstance(name, str) and name.isprintable() and 0 < len(name) <= 60 \
        else shown(name)


def check_keys(scene_class: type, data) -> None:
    """Sections and keys of a nested mapping (TOML layout) that ``scene_class`` knows: an
    unknown one is named with what is allowed."""
    sections = _hints(scene_class)
    if not isinstance(data, Mapping):
        raise SceneError("scene", f"expected a table of sections, got {shown(data)}")
    for sec, table in data.items():
        if sec not in sections:
            raise SceneError(printable(sec), f"unknown section; allowed: {', '.join(sections)}")
        if not isinstance(table, Mapping):
            raise SceneError(sec, f"expected a table of keys, got {shown(table)}")
        names = _hints(sections[sec])
        for name in table:
            if name not in names:
                raise SceneError(f"{sec}.{printable(name)}",
                                 f"unknown key; allowed in [{sec}]: {', '.join(names)}")


def check_scene(scene) -> None:
    """Each section of the right class, then what no elastic body can be: speeds or loads that
    strain the beam by 100 % or more (bounds below the true stress, so only what is meaningless
    for every model here is rejected). Called by ``Scene.__post_init__``."""
    for name, cls in _hints(type(scene)).items():
        if not isinstance(getattr(scene, name), cls):
            raise SceneError(name, f"expected a {cls.__name__}, got "
                                   f"{shown(getattr(scene, name))}")
    _check_strains(scene.geometry, scene.material, scene.rotation, scene.load, scene.tip_mass)


@functools.lru_cache(maxsize=64)
def _check_strains(g, mat, rotation, load, tip_mass) -> None:
    """:func:`check_scene`'s strain bounds: a function of these frozen sections alone, kept for
    the ones already checked (a scene that changes only its mesh, as every ``--tol`` level does,
    is not checked again: two thirds of making such a scene; errors are not kept)."""
    # centrifugal stress at the root of a uniform bar: rho Omega^2 ((R+L)^2 - R^2) / 2, written
    # as L (2R + L) so that no square of a large radius is formed
    R, L = g.hub_radius, g.length
    arm2 = L * (2.0 * R + L)
    omega = rotation.omega
    strain = mat.rho * omega * omega * arm2 / (2.0 * mat.E)
    if not strain < 1.0:
        limit = math.sqrt(2.0 * mat.E / mat.rho) / math.sqrt(arm2) * 60 / (2 * math.pi)
        raise SceneError("rotation.rpm", f"{rotation.rpm!r} rpm strains the beam by "
                                         f"{strain:.3g} (centrifugal stress / E >= 1 with "
                                         f"material.E = {mat.E!r}, rho = {mat.rho!r}): "
                                         f"meaningless for an elastic body; allowed: below "
                                         f"{limit:.4g} rpm for this scene")
    # the tip mass's centrifugal force m Omega^2 (R + L) on the tip section (its area at most
    # tip_y tip_z: a lower bound of the stress)
    pull = tip_mass.mass * omega * omega * (R + L)
    strain = pull / (g.tip_y * g.tip_z * mat.E)
    if not strain < 1.0:
        raise SceneError("tip_mass.mass", f"{tip_mass.mass!r} kg at {rotation.rpm!r} "
                                          f"rpm pulls the tip section by {strain:.3g} times "
                                          f"material.E ({pull:.3g} N): meaningless for an "
                                          f"elastic body; allowed: below "
                                          f"{tip_mass.mass / strain:.4g} kg at this speed")
    # bending at each station under the line load and the tip force, on the stiffer axis of the
    # section (a lower bound of the stress)
    x = np.linspace(0.0, L, 101)
    s = x / L
    b, h = g.root_y + (g.tip_y - g.root_y) * s, g.root_z + (g.tip_z - g.root_z) * s
    W = np.maximum(b * h * h, h * b * b) / 6.0
    Fx, Fy, Fz = load.tip_force
    with np.errstate(over="ignore"):
        by_line = abs(load.line_load) * (L - x) ** 2 / 2.0 / W / mat.E
        by_tip = (math.hypot(Fy, Fz) * (L - x) / W + abs(Fx) / (b * h)) / mat.E
        strain = float(np.max(by_line + by_tip))
    if not strain < 1.0:
        # name the load that strains most; the strain is linear in each load
        line_part, tip_part = float(np.max(by_line)), float(np.max(by_tip))
        key = "load.line_load" if line_part >= tip_part else "load.tip_force"
        allowed = (f"{key} at most {1 / strain:.3g} times this one"
                   if math.isfinite(strain) and min(line_part, tip_part) == 0.0 else
                   "loads whose bending stress stays below material.E")
        raise SceneError(key, f"strains the beam by {strain:.3g} in bending (stress / E >= 1 "
                              f"with material.E = {mat.E!r}): meaningless for an elastic body; "
                              f"allowed: {allowed}")
