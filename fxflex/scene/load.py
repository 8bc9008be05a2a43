"""Build a :class:`Scene` from TOML files and ``--set KEY=VALUE`` overrides.

Parsing lives here; what a value may be is checked in one place, :mod:`fxflex.scene.checks`,
when the frozen dataclasses are built - from a file, from ``--set`` or from Python alike. Every
failure raises :class:`SceneError` whose one-line message names the dotted key (or ``--scene``
and the file) and what is allowed (SPEC section 8).
"""

from __future__ import annotations

import math
import os
import stat
import tomllib
from collections.abc import Iterable, Mapping
from pathlib import Path

from fxflex.errors import SceneError
from fxflex.scene.checks import MIN_SECTION_RATIO, check_keys, printable, shown
from fxflex.scene.schema import Scene

__all__ = ["load_scene", "parse_override", "scene_from_dict", "validate", "validate_for",
           "MAX_TWIST_PER_ELEMENT_DEG", "MIN_SECTION_RATIO"]

#: largest twist between the two ends of one element (deg): a hexahedron (and an ANCF element's
#: interpolated cross-section gradients) shrinks mid-element to cos^2(dtheta / 2) of its
#: cross-section and degenerates at 180 deg; beyond 90 deg (half the section) it is rejected
MAX_TWIST_PER_ELEMENT_DEG = 90.0
#: methods that carry a [tip_mass] (SPEC section 10); the others refuse one
TIP_MASS_METHODS = ("lebb", "nebb", "ancf", "ffrf", "gcms", "tlf")
#: a tip body's Pi_XX up to this share of tr(Pi) counts as zero (:func:`tip_body_is_flat`)
FLAT_TIP_BODY = 1e-9


def tip_body_is_flat(inertia) -> bool:
    """Whether a tip body of moments of inertia [J_X, J_Y, J_Z] has no extent along X: its second
    moment Pi_XX = (J_Y + J_Z - J_X) / 2 within FLAT_TIP_BODY of tr(Pi) = (J_X + J_Y + J_Z) / 2
    (J_X = J_Y + J_Z typed in decimals is flat): the solids then need no director
    (:mod:`fxflex.solid.tip_mass`)."""
    jx, jy, jz = (float(j) for j in inertia)
    return (jy + jz - jx) <= FLAT_TIP_BODY * (jx + jy + jz)


def scene_from_dict(data: Mapping, base: Scene | None = None) -> Scene:
    """Merge a nested mapping (TOML layout) onto ``base`` (default scene); the result is checked
    as a whole (:mod:`fxflex.scene.checks`)."""
    scene = base or Scene()
    check_keys(Scene, data)
    return scene.replace(**{f"{sec}.{name}": value
                            for sec, table in data.items() for name, value in table.items()})


def parse_override(text: str) -> dict:
    """``geometry.twist_deg=0`` -> ``{"geometry": {"twist_deg": 0}}``; the value is one TOML
    value, anything else (bare words included: ``--set damping.model=absolute``) a string."""
    if "=" not in text:
        raise SceneError("--set", f"expected KEY=VALUE with a dotted key, got {shown(text)}")
    key, raw = (s.strip() for s in text.split("=", 1))
    parts = key.split(".")
    if len(parts) != 2 or not all(parts):
        raise SceneError(printable(key) if key else "--set",
                         "expected a dotted key SECTION.NAME, e.g. geometry.twist_deg")
    try:
        parsed = tomllib.loads(f"v = {raw}")
    except tomllib.TOMLDecodeError:
        parsed = {}
    value = parsed["v"] if parsed.keys() == {"v"} else raw
    return {parts[0]: {parts[1]: value}}


def validate(scene: Scene) -> Scene:
    """``scene``, checked again from its values (construction checks them already; this catches
    a scene changed behind the frozen dataclasses' back)."""
    scene_from_dict(scene.to_dict())
    return scene


def _twist_per_element(scene: Scene, key: str, count: int, what: str) -> None:
    """Reject a twist of more than MAX_TWIST_PER_ELEMENT_DEG between an element's two ends."""
    twist = scene.geometry.twist_deg
    need = math.ceil(abs(twist) / MAX_TWIST_PER_ELEMENT_DEG)
    if count < need:                # an int comparison: a count beyond float range is fine
        per = abs(twist) / count
        raise SceneError(key, f"{count} {what} twist by {per:g} deg each (geometry.twist_deg = "
                              f"{twist!r}), which nearly or fully degenerates their cross-"
                              f"section; allowed: at least {need} {what}")


def validate_for(method: str, scene: Scene) -> None:
    """What only ``method`` needs of the scene: a mesh whose elements do not degenerate, a modal
    basis no larger than the mesh, and for ANCF and the solids a section that only stretches
    along the span (their reference configuration and meshes scale the root section; a hollow
    wall that keeps its thickness while the section tapers does not)."""
    g = scene.geometry
    if method in ("ancf", "ffrf", "gcms", "tlf") and g.wall_does_not_stretch():
        raise SceneError("geometry.wall", f"{method} takes a hollow section only untapered (its "
                                          f"reference stretches the root section along the "
                                          f"span; a wall does not stretch with it); allowed: "
                                          f"root and tip sizes equal and no wall in the "
                                          f"stations, or lebb, nebb")
    if scene.tip_mass.present and method not in TIP_MASS_METHODS:
        raise SceneError("tip_mass", f"{method} does not take a tip mass yet; allowed: mass and "
                                     f"inertia 0, or the methods {', '.join(TIP_MASS_METHODS)}")
    if scene.mesh.solid_file:
        if method not in ("ffrf", "gcms", "tlf"):
            raise SceneError("mesh.solid_file", f"{method} is a beam method and takes its body "
                                                f"from [geometry], not a solid mesh; allowed: "
                                                f"ffrf, gcms, tlf, or no mesh.solid_file")
        return                          # the file's own mesh (mesh.imported checks it)
    if method in ("ffrf", "gcms", "tlf"):
        nx, ny, nz = scene.mesh.solid
        _twist_per_element(scene, "mesh.solid", nx, "divisions along X")
        p = scene.mesh.solid_degree             # nodal unknowns after the clamp (solid_dof_count)
        dof = 3 * p * nx * (p * ny + 1) * (p * nz + 1)
        modes = {"ffrf": scene.reduction.ffrf_modes, "gcms": scene.reduction.gcms_modes // 3}
        # (the count holds for the paper's rectangle; another section's quad mesh has its own)
        if method in modes and modes[method] > dof and g.paper_shape:
            key = "reduction.ffrf_modes" if method == "ffrf" else "reduction.gcms_modes"
            raise SceneError(key, f"needs {modes[method]} clamped modes but mesh.solid "
                                  f"{list(scene.mesh.solid)} has {dof} unknowns; allowed: at "
                                  f"most {dof if method == 'ffrf' else 3 * dof}")
    if method == "ancf":
        _twist_per_element(scene, "mesh.beam_elements", scene.mesh.beam_elements,
                           "ANCF elements")


def _read_toml(path: str | os.PathLike) -> dict:
    """The TOML table of a scene file, or one line naming the file and why it cannot be one."""
    name = os.fspath(path)
    name = name if name.isprintable() else repr(name)
    try:
        if not stat.S_ISREG(os.stat(path).st_mode):
            kind = "a directory" if os.path.isdir(path) else "not a regular file"
            # a FIFO or a device would block or never end: only files are read
            raise SceneError("--scene", f"{name} is {kind}; allowed: a TOML file")
        raw = Path(path).read_bytes()
    except FileNotFoundError:
        raise SceneError("--scene", f"file not found: {name}") from None
    except (OSError, ValueError) as exc:    # ValueError: a NUL in the path
        reason = getattr(exc, "strerror", None) or exc
        raise SceneError("--scene", f"cannot read {name}: {reason}") from None
    if raw[:2] in (b"\xff\xfe", b"\xfe\xff"):
        raise SceneError("--scene", f"{name} is UTF-16 text (byte-order mark); allowed: UTF-8, "
                                    "as TOML requires")
    try:
        text = raw.decode("utf-8").removeprefix("\ufeff")
    except UnicodeDecodeError as exc:
        raise SceneError("--scene", f"{name} is not UTF-8 text (byte 0x{raw[exc.start]:02x} at "
                                    f"offset {exc.start}); allowed: UTF-8, as TOML requires") \
            from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        reason = " ".join(str(exc).split())
        raise SceneError("--scene", f"{name} is not valid TOML ({reason})") from None


def load_scene(path: str | os.PathLike | None = None, overrides: Iterable[str] = (),
               base: Scene | None = None) -> Scene:
    """The resolved scene: defaults (or ``base``), then the TOML file, then each ``--set`` in
    order (a later value of a key wins); checked once, as a whole."""
    tables = [] if path is None else [_read_toml(path)]
    tables += [parse_override(text) for text in overrides]
    merged: dict[str, dict] = {}
    for table in tables:
        check_keys(Scene, table)
        for sec, values in table.items():
            merged.setdefault(sec, {}).update(values)
    return scene_from_dict(merged, base)
