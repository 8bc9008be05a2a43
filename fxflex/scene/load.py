"""Build and validate a :class:`Scene` from TOML files and ``--set KEY=VALUE`` overrides.

All validation happens here, in one place; every failure raises :class:`SceneError` whose
message names the dotted key and what is allowed (SPEC section 8).
"""

from __future__ import annotations

import dataclasses
import math
import os
import tomllib
import typing
from collections.abc import Iterable, Mapping

import numpy as np

from fxflex.errors import SceneError
from fxflex.scene.model import Scene

__all__ = ["load_scene", "parse_override", "scene_from_dict", "validate", "validate_for",
           "MAX_TWIST_PER_ELEMENT_DEG", "MIN_SECTION_RATIO"]

#: largest twist between the two ends of one element (deg): a hexahedron (and an ANCF element's
#: interpolated cross-section gradients) shrinks mid-element to cos^2(dtheta / 2) of its
#: cross-section and degenerates at 180 deg; beyond 90 deg (half the section) it is rejected
MAX_TWIST_PER_ELEMENT_DEG = 90.0
#: smallest section size relative to the length: below it the section is degenerate (the mesh
#: and the centreline probe work to 1e-9 of the length)
MIN_SECTION_RATIO = 1e-6
#: speed of light (m/s): no elastic wave is faster, sqrt(E / rho) included
_LIGHT = 299792458.0

_CHOICES = {
    "section.torsion": ("polar", "saint-venant"),
    "rotation.profile": ("constant", "spin-up"),
    "damping.model": ("relative", "absolute"),
    "mesh.ancf_root": ("free-axial", "full"),
}
_POSITIVE = {
    "geometry.length", "geometry.root_y", "geometry.root_z", "geometry.tip_y", "geometry.tip_z",
    "material.E", "material.rho", "mesh.beam_elements", "reduction.ffrf_modes",
    "reduction.gcms_modes", "reduction.gcms_gram_tol",
}
_NON_NEGATIVE = {
    "geometry.hub_radius", "load.ramp_time", "rotation.rpm", "rotation.spinup_time", "damping.c",
}


def _sections() -> dict[str, type]:
    return {f.name: f.type for f in dataclasses.fields(Scene)}


def _section_class(name: str):
    return typing.get_type_hints(Scene)[name]


def _coerce(key: str, value, annotation):
    """Check the TOML value against the dataclass annotation; ints are accepted for floats."""
    origin = typing.get_origin(annotation)
    if annotation is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise SceneError(key, f"expected a number, got {value!r}")
        value = float(value)
        if not math.isfinite(value):
            raise SceneError(key, f"expected a finite number, got {value!r}")
        return value
    if annotation is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise SceneError(key, f"expected an integer, got {value!r}")
        return value
    if annotation is str:
        if not isinstance(value, str):
            raise SceneError(key, f"expected a string, got {value!r}")
        return value
    if origin is tuple:
        args = typing.get_args(annotation)
        if not isinstance(value, (list, tuple)) or len(value) != len(args):
            raise SceneError(key, f"expected a list of {len(args)} values, got {value!r}")
        return tuple(_coerce(key, v, a) for v, a in zip(value, args))
    raise TypeError(f"unsupported annotation {annotation!r} for {key}")  # pragma: no cover


def scene_from_dict(data: Mapping, base: Scene | None = None) -> Scene:
    """Merge a nested mapping (TOML layout) onto ``base`` (default scene), checking keys and types."""
    scene = base or Scene()
    if not isinstance(data, Mapping):
        raise SceneError("scene", "expected a table of sections")
    sections = _sections()
    for sec, table in data.items():
        if sec not in sections:
            raise SceneError(sec, f"unknown section; allowed: {', '.join(sections)}")
        if not isinstance(table, Mapping):
            raise SceneError(sec, "expected a table of keys")
        cls = _section_class(sec)
        hints = typing.get_type_hints(cls)
        changes = {}
        for name, value in table.items():
            key = f"{sec}.{name}"
            if name not in hints:
                raise SceneError(key, f"unknown key; allowed in [{sec}]: {', '.join(hints)}")
            changes[name] = _coerce(key, value, hints[name])
        scene = dataclasses.replace(
            scene, **{sec: dataclasses.replace(getattr(scene, sec), **changes)})
    return scene


def parse_override(text: str) -> dict:
    """``geometry.twist_deg=0`` -> ``{"geometry": {"twist_deg": 0}}``; values are TOML, bare
    words are strings (``--set damping.model=absolute``)."""
    if "=" not in text:
        raise SceneError("--set", f"expected KEY=VALUE with a dotted key, got {text!r}")
    key, raw = (s.strip() for s in text.split("=", 1))
    parts = key.split(".")
    if len(parts) != 2 or not all(parts):
        raise SceneError(key or "--set", "expected a dotted key SECTION.NAME, e.g. "
                                         "geometry.twist_deg")
    try:
        value = tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw
    return {parts[0]: {parts[1]: value}}


def validate(scene: Scene) -> Scene:
    """Check value ranges and choices; raise :class:`SceneError` naming the first offending key."""
    for key, allowed in _CHOICES.items():
        sec, name = key.split(".")
        value = getattr(getattr(scene, sec), name)
        if value not in allowed:
            raise SceneError(key, f"{value!r} is not allowed; allowed: {', '.join(allowed)}")
    for key in sorted(_POSITIVE | _NON_NEGATIVE):
        sec, name = key.split(".")
        value = getattr(getattr(scene, sec), name)
        if key in _POSITIVE and not value > 0:
            raise SceneError(key, f"must be > 0, got {value!r}")
        if key in _NON_NEGATIVE and not value >= 0:
            raise SceneError(key, f"must be >= 0, got {value!r}")
    if not -1.0 < scene.material.nu < 0.5:
        raise SceneError("material.nu", f"must lie in (-1, 0.5), got {scene.material.nu!r}")
    nx, ny, nz = scene.mesh.solid
    if min(nx, ny, nz) <= 0:
        raise SceneError("mesh.solid", f"divisions must be > 0, got {list(scene.mesh.solid)}")
    if ny % 2 or nz % 2:
        raise SceneError("mesh.solid", "Y and Z divisions must be even (the centerline is a line "
                                       f"of nodes), got {list(scene.mesh.solid)}")
    if scene.reduction.gcms_gram_tol >= 1:
        raise SceneError("reduction.gcms_gram_tol",
                         f"must lie in (0, 1), got {scene.reduction.gcms_gram_tol!r}")
    _check_physics(scene)
    if scene.rotation.profile == "spin-up" and not scene.rotation.spinup_time > 0:
        raise SceneError("rotation.spinup_time",
                         "must be > 0 with rotation.profile = \"spin-up\", got "
                         f"{scene.rotation.spinup_time!r}")
    return scene


def _check_physics(scene: Scene) -> None:
    """Reject scenes no elastic body can be: degenerate sections, wave speeds above light's, and
    loads or speeds that strain the beam by 100 % or more (bounds below the true stress, so only
    what is meaningless for every model here is rejected)."""
    g, mat = scene.geometry, scene.material
    for key in ("root_y", "root_z", "tip_y", "tip_z"):
        size = getattr(g, key)
        if size < MIN_SECTION_RATIO * g.length:
            raise SceneError(f"geometry.{key}", f"{size!r} m is below {MIN_SECTION_RATIO:g} of the "
                                                f"length ({g.length!r} m): a degenerate section")
    wave = math.sqrt(mat.E / mat.rho)
    if not wave < _LIGHT:
        raise SceneError("material.E", f"with material.rho = {mat.rho!r} the wave speed "
                                       f"sqrt(E/rho) = {wave:.3g} m/s exceeds the speed of light")
    # centrifugal stress at the root of a uniform bar: rho Omega^2 ((R+L)^2 - R^2) / 2
    R, L = g.hub_radius, g.length
    arm2 = (R + L) ** 2 - R**2
    try:
        strain = mat.rho * scene.rotation.omega**2 * arm2 / (2.0 * mat.E)
    except OverflowError:
        strain = math.inf
    if not strain < 1.0:
        limit = math.sqrt(2.0 * mat.E / (mat.rho * arm2)) * 60 / (2 * math.pi)
        raise SceneError("rotation.rpm", f"{scene.rotation.rpm!r} rpm strains the beam by "
                                         f"{strain:.3g} (centrifugal stress / E >= 1 with "
                                         f"material.E = {mat.E!r}, rho = {mat.rho!r}): "
                                         f"meaningless for an elastic body; allowed: below "
                                         f"{limit:.4g} rpm for this scene")
    # bending at each station under the line load and the tip force, on the stiffer axis of the
    # section (a lower bound of the stress)
    x = np.linspace(0.0, L, 101)
    s = x / L
    b, h = g.root_y + (g.tip_y - g.root_y) * s, g.root_z + (g.tip_z - g.root_z) * s
    W = np.maximum(b * h * h, h * b * b) / 6.0
    Fx, Fy, Fz = scene.load.tip_force
    moment = abs(scene.load.line_load) * (L - x) ** 2 / 2.0 + math.hypot(Fy, Fz) * (L - x)
    strain = float(np.max((moment / W + abs(Fx) / (b * h)) / mat.E))
    if not strain < 1.0:
        key = "load.line_load" if scene.load.line_load else "load.tip_force"
        raise SceneError(key, f"strains the beam by {strain:.3g} in bending (stress / E >= 1 "
                              f"with material.E = {mat.E!r}): meaningless for an elastic body")


def _twist_per_element(scene: Scene, key: str, count: int, what: str) -> None:
    """Reject a twist of more than MAX_TWIST_PER_ELEMENT_DEG between an element's two ends."""
    twist = scene.geometry.twist_deg
    per = abs(twist) / count
    if per > MAX_TWIST_PER_ELEMENT_DEG:
        need = math.ceil(abs(twist) / MAX_TWIST_PER_ELEMENT_DEG)
        raise SceneError(key, f"{count} {what} twist by {per:g} deg each (geometry.twist_deg = "
                              f"{twist!r}), which nearly or fully degenerates their cross-"
                              f"section; allowed: at least {need} {what}")


def validate_for(method: str, scene: Scene) -> None:
    """What only ``method`` needs of the scene: a mesh whose elements do not degenerate and a
    modal basis no larger than the mesh."""
    if method in ("ffrf", "gcms", "tlf"):
        nx, ny, nz = scene.mesh.solid
        _twist_per_element(scene, "mesh.solid", nx, "divisions along X")
        dof = 3 * nx * (ny + 1) * (nz + 1)
        modes = {"ffrf": scene.reduction.ffrf_modes, "gcms": scene.reduction.gcms_modes // 3}
        if method in modes and modes[method] > dof:
            key = "reduction.ffrf_modes" if method == "ffrf" else "reduction.gcms_modes"
            raise SceneError(key, f"needs {modes[method]} clamped modes but mesh.solid "
                                  f"{list(scene.mesh.solid)} has {dof} unknowns; allowed: at "
                                  f"most {dof if method == 'ffrf' else 3 * dof}")
    if method == "ancf":
        _twist_per_element(scene, "mesh.beam_elements", scene.mesh.beam_elements,
                           "ANCF elements")


def load_scene(path: str | os.PathLike | None = None, overrides: Iterable[str] = (),
               base: Scene | None = None) -> Scene:
    """The resolved scene: defaults, then the TOML file, then each ``--set`` in order."""
    scene = base or Scene()
    if path is not None:
        try:
            with open(path, "rb") as fh:
                data = tomllib.load(fh)
        except FileNotFoundError:
            raise SceneError("--scene", f"file not found: {os.fspath(path)}") from None
        except IsADirectoryError:
            raise SceneError("--scene", f"is a directory, expected a TOML file: {path}") from None
        except tomllib.TOMLDecodeError as exc:
            raise SceneError("--scene", f"{os.fspath(path)} is not valid TOML ({exc})") from None
        scene = scene_from_dict(data, scene)
    for text in overrides:
        scene = scene_from_dict(parse_override(text), scene)
    return validate(scene)
