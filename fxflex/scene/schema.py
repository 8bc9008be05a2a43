"""The scene: frozen dataclasses mirroring the TOML schema of SPEC section 8.

Defaults are the paper's Sect. 4 example (SPEC section 1). Every class checks itself on
construction through :mod:`fxflex.scene.checks` (the one place of validation), so a scene built
from Python is held to what a TOML file or ``--set`` is: a bad value raises the one-line
:class:`~fxflex.errors.SceneError` naming the key. Beyond that the classes only hold values and
derived quantities.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
from dataclasses import dataclass, field

import numpy as np

from fxflex.scene.checks import check_keys, check_scene, check_section

__all__ = [
    "Geometry", "Material", "Section", "Load", "Rotation", "Damping", "MeshSpec", "Reduction",
    "TipMass", "Solver", "Scene", "PAPER_RPM", "PAPER_DAMPING", "METHODS",
]

METHODS = ("ffrf", "gcms", "tlf", "lebb", "nebb", "ancf")
PAPER_RPM = (1000.0, 5000.0, 10000.0)
#: keys beyond the paper's scene (SPEC sections 9-10): in the scene hash only when not at their
#: defaults (Scene.hash)
LATER_KEYS = ("mesh.solid_degree", "mesh.beam_variant", "geometry.section", "geometry.airfoil",
              "geometry.contour", "geometry.wall", "geometry.stations", "mesh.solid_file")
#: whole tables beyond the paper's scene (SPEC section 10): left out of the hash when every key
#: is at its default
LATER_TABLES = ("tip_mass", "solver")
#: keys that name a file: a hash of the scene covers the file's bytes, not only its path
FILE_KEYS = ("geometry.contour", "geometry.stations", "mesh.solid_file")
PAPER_DAMPING = (100.0, 500.0, 1000.0)


@dataclass(frozen=True)
class Geometry:
    length: float = 1.0
    root_y: float = 0.12
    root_z: float = 0.06
    tip_y: float = 0.08
    tip_z: float = 0.04
    twist_deg: float = -45.0
    hub_radius: float = 0.0
    #: SPEC section 9: the section's shape (fxflex.section), a hollow wall, a stations table
    section: str = "rectangle"
    airfoil: str = "0012"
    contour: str = ""
    wall: float = 0.0
    stations: str = ""

    def __post_init__(self) -> None:
        check_section(self, "geometry")

    def wall_does_not_stretch(self) -> bool:
        """A hollow wall that keeps its thickness while the section tapers (or a stations table
        with a wall anywhere): not a stretch of the root section, which ANCF's reference and the
        solid meshes need."""
        if self.stations:
            from fxflex.section.blade import read_stations

            t = read_stations(self.stations, self.length)
            walls = t[:, 4] if not all(w != w for w in t[:, 4]) else [self.wall] * len(t)
            sizes = {(float(a), float(b)) for a, b in t[:, 1:3]}
            return any(w > 0 for w in walls) and (len(sizes) > 1 or len(set(walls)) > 1)
        # naca4: the thickness follows the chord, the Z keys do not count
        root = (self.root_y,) if self.section == "naca4" else (self.root_y, self.root_z)
        tip = (self.tip_y,) if self.section == "naca4" else (self.tip_y, self.tip_z)
        return self.wall > 0 and root != tip

    @property
    def paper_shape(self) -> bool:
        """The paper's solid rectangle, tapered and twisted linearly (SPEC section 1)."""
        return self.section == "rectangle" and self.wall == 0.0 and not self.stations

    def size_y(self, s):
        """Section size along Y~ at normalised position s = X~/L in [0, 1] (linear taper)."""
        return self.root_y + (self.tip_y - self.root_y) * s

    def size_z(self, s):
        return self.root_z + (self.tip_z - self.root_z) * s

    def twist(self, s):
        """Section rotation about +X (rad) at s = X~/L, linear in X (right-hand rule)."""
        return math.radians(self.twist_deg) * s


@dataclass(frozen=True)
class Material:
    E: float = 210e9
    nu: float = 0.28
    rho: float = 7850.0

    def __post_init__(self) -> None:
        check_section(self, "material")

    @property
    def G(self) -> float:
        return self.E / (2.0 * (1.0 + self.nu))

    @property
    def lame(self) -> tuple[float, float]:
        """(lambda, mu) of the St.Venant-Kirchhoff / Hooke material."""
        mu = self.E / (2.0 * (1.0 + self.nu))
        lmbda = self.E * self.nu / ((1.0 + self.nu) * (1.0 - 2.0 * self.nu))
        return lmbda, mu


@dataclass(frozen=True)
class Section:
    torsion: str = "polar"

    def __post_init__(self) -> None:
        check_section(self, "section")


@dataclass(frozen=True)
class Load:
    line_load: float = -8000.0
    tip_force: tuple[float, float, float] = (0.0, 0.0, 0.0)
    ramp_time: float = 300e-6

    def __post_init__(self) -> None:
        check_section(self, "load")

    def factor(self, t: float) -> float:
        """Load ramp: linear from 0 at t = 0 to 1 at ramp_time, then constant."""
        if self.ramp_time <= 0.0 or t >= self.ramp_time:
            return 1.0
        return max(t, 0.0) / self.ramp_time


@dataclass(frozen=True)
class Rotation:
    rpm: float = 1000.0
    profile: str = "constant"
    spinup_time: float = 0.0

    def __post_init__(self) -> None:
        check_section(self, "rotation")

    @property
    def omega(self) -> float:
        """Steady angular speed Omega_s (rad/s)."""
        return self.rpm * 2.0 * math.pi / 60.0


@dataclass(frozen=True)
class Damping:
    c: float = 1000.0
    model: str = "relative"

    def __post_init__(self) -> None:
        check_section(self, "damping")


@dataclass(frozen=True)
class MeshSpec:
    solid: tuple[int, int, int] = (100, 12, 6)
    beam_elements: int = 10
    ancf_root: str = "free-axial"
    solid_degree: int = 1           # 1: trilinear hexahedra (the paper's); 2: 27-node (SPEC 9)
    beam_variant: str = "paper"     # "paper" (Eq. 45-57) or "locking-free" (NEBB, ANCF; SPEC 9)
    solid_file: str = ""            # the user's gmsh .msh for FFRF, GCMS, TLF (SPEC 9)

    def __post_init__(self) -> None:
        check_section(self, "mesh")


@dataclass(frozen=True)
class Reduction:
    ffrf_modes: int = 30
    gcms_modes: int = 90
    gcms_gram_tol: float = 1e-6

    def __post_init__(self) -> None:
        check_section(self, "reduction")


@dataclass(frozen=True)
class TipMass:
    """SPEC section 10: a rigid body attached at the tip section centroid, of mass ``mass`` (kg)
    and principal moments of inertia ``inertia`` (kg m^2) about axes through that point parallel
    to X, Y, Z in the undeformed beam. The defaults (0) leave every operator as it was."""

    mass: float = 0.0
    inertia: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        check_section(self, "tip_mass")

    @property
    def present(self) -> bool:
        return self.mass > 0.0 or any(j > 0.0 for j in self.inertia)

    def second_moments(self):
        """Pi = int r r^T dm (3 x 3, about the centroid) of the body whose moments of inertia
        are J = tr(Pi) I - Pi: Pi = tr(J) / 2 I - J (diagonal; non-negative for a rigid body,
        the triangle inequality that :mod:`fxflex.scene.checks` asks of the inertia)."""
        J = np.asarray(self.inertia, dtype=float)
        return np.diag(0.5 * J.sum() - J)


@dataclass(frozen=True)
class Solver:
    """How the linear systems of the solid methods are solved (issue 14, docs/solvers.md):
    ``linear`` = "direct" (MUMPS), "iterative" (GAMG-preconditioned Krylov; SLEPc with an
    iterative inner solve) or "auto", direct whenever the memory estimate says MUMPS fits
    (:func:`fxflex.memory.check`), else iterative. Not in the hash while at its default."""

    linear: str = "auto"

    def __post_init__(self) -> None:
        check_section(self, "solver")


@dataclass(frozen=True)
class Scene:
    geometry: Geometry = field(default_factory=Geometry)
    material: Material = field(default_factory=Material)
    section: Section = field(default_factory=Section)
    load: Load = field(default_factory=Load)
    rotation: Rotation = field(default_factory=Rotation)
    damping: Damping = field(default_factory=Damping)
    mesh: MeshSpec = field(default_factory=MeshSpec)
    reduction: Reduction = field(default_factory=Reduction)
    tip_mass: TipMass = field(default_factory=TipMass)
    solver: Solver = field(default_factory=Solver)

    def __post_init__(self) -> None:
        check_scene(self)

    def to_dict(self) -> dict:
        """The full resolved scene as plain JSON-able data (tuples become lists)."""
        return json.loads(json.dumps(dataclasses.asdict(self)))

    def stable_dict(self) -> dict:
        """:meth:`to_dict` without the keys of SPEC sections 9-10 (:data:`LATER_KEYS`) that are
        at their defaults, and without the tables of :data:`LATER_TABLES` whose keys all are:
        what a hash of a scene of sections 1-8 was computed from before those keys existed, so
        such hashes (checkpoints, the stored reference) keep their value."""
        data = self.to_dict()
        for sec in LATER_TABLES:
            if getattr(self, sec) == type(getattr(self, sec))():
                del data[sec]
        for key in LATER_KEYS:
            sec, name = key.split(".")
            defaults = {f.name: f.default for f in dataclasses.fields(getattr(self, sec))}
            if data[sec][name] == defaults[name]:
                del data[sec][name]
        return data

    def file_digests(self, section: str | None = None) -> dict:
        """{dotted key: 16 hex digits of the SHA-256 of the file's bytes} for the keys of
        :data:`FILE_KEYS` that are set (only those of ``section`` if given): what a result
        computed from the scene depends on beyond the path (an edited stations table is another
        blade). A file that cannot be read is named "unreadable"."""
        out = {}
        for key in FILE_KEYS:
            sec, name = key.split(".")
            path = getattr(getattr(self, sec), name)
            if path and section in (None, sec):
                try:
                    with open(path, "rb") as f:
                        out[key] = hashlib.sha256(f.read()).hexdigest()[:16]
                except OSError:
                    out[key] = "unreadable"
        return out

    @property
    def hash(self) -> str:
        """Stable 16-hex-digit hash of the resolved scene (keys sorted, floats as repr) over
        :meth:`stable_dict`, so a scene of sections 1-8 keeps the hash it had before sections
        9-10 existed (checkpoints resume), and over the bytes of the files it names
        (:meth:`file_digests`), so an edited file does not pass for the one a result was
        computed from."""
        data = self.stable_dict()
        digests = self.file_digests()
        if digests:
            data["files"] = digests
        text = json.dumps(data, sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    def replace(self, **sections) -> "Scene":
        """Copy with whole sections or dotted keys replaced: ``replace(**{"rotation.rpm": 5e3})``.

        The changes to one section are applied together and the scene is checked once at the
        end, so ``replace(**{"rotation.profile": "spin-up", "rotation.spinup_time": 0.05})``
        never passes through an invalid spin-up without its time."""
        whole = {key: value for key, value in sections.items() if "." not in key}
        changes: dict[str, dict] = {}
        for key, value in sections.items():
            if "." in key:
                sec, name = key.split(".", 1)
                changes.setdefault(sec, {})[name] = value
        check_keys(type(self), {**{sec: {} for sec in whole}, **changes})
        for sec, fields in changes.items():
            whole[sec] = dataclasses.replace(whole.get(sec, getattr(self, sec)), **fields)
        return dataclasses.replace(self, **whole)
