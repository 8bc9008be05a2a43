"""The memory a build needs, estimated before building, and the memory this machine has (issue 11).

:func:`estimate` predicts the peak resident memory of ``fxflex steady`` (build, steady state and
stability verdict; ``fxflex run`` needs about the same or less, except ANCF's, whose invariant
route builds its system matrices for the time loop only: the estimate covers the run, 409 MB
against 294 MB for ``steady`` at 40 elements) from the scene alone, without
meshing, as a sum of parts whose coefficients are fitted to the measured peak resident set size
of real builds (docs/robustness.md, "Memory and size", has the measurements and the laws):

- beams (LEBB, NEBB, ANCF) on n unknowns: dense linear algebra, so ``dense matrices`` = c n^2
  bytes (the model's matrices, their M^-1 products, the Newton tangent, the 2n x 2n companion
  matrix of the stability verdict and its eigen-decomposition), and ``element tables`` per
  unknown;
- solids (FFRF, GCMS, TLF) on n = 3 nx (ny + 1) (nz + 1) unknowns (Q1; 3 2nx (2ny + 1) (2nz + 1)
  for Q2, whose parts carry ``Q2_FACTOR``): ``mesh and matrices`` per
  unknown (gmsh model, dolfinx mesh and dof maps, sparse K, M or Jacobian, work vectors),
  ``factorisation`` (MUMPS; the fill of a 3-D factor grows as n^(4/3), nested dissection's law
  for meshes refined in all three directions, which the factors of these meshes follow: 9.4 to
  12.8 n^(4/3) entries from 5e3 to 2e5 unknowns), ``modes`` (FFRF, GCMS: per unknown and clamped
  mode) and TLF's ``invariants`` (``--force-eval invariant``) and ``mass factorisation``
  (``--mass consistent``);
- ``base``: the interpreter and the libraries once imported, per rank.

Under MPI the solid parts are shared out over the ranks and the beams are replicated on every
rank; :func:`check` adds up the ranks that share one machine and compares that with the machine's
:func:`available` memory, refusing the build with one line (:class:`~fxflex.errors.FxflexError`)
that names the estimate, what is available and the largest size that fits.
``FXFLEX_MEMORY_CHECK=0`` skips the check; ``FXFLEX_MEMORY_LIMIT=8G`` caps what it counts on.

The solids' linear systems go one of two routes (``[solver] linear``, docs/solvers.md): direct
(MUMPS, the ``factorisation`` part above) or iterative (GAMG-preconditioned Krylov, whose
``preconditioner`` part -- the coarse operators, prolongators and smoother and Krylov vectors --
grows as n, not n^(4/3); TLF adds its ``stability eigensolve``, the verdict's PEP with its own
hierarchy, also as n). With "auto" :func:`check` takes the direct route whenever it fits,
which is what every build did before the key existed, and else the iterative one; it refuses
only when neither fits.
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from fxflex.errors import FxflexError
from fxflex.methods import dof_count
from fxflex.scene import METHODS, Scene

if TYPE_CHECKING:
    from fxflex.formulation import BuildOptions

__all__ = ["Estimate", "estimate", "available", "check", "route", "parse_size", "format_size",
           "BEAMS", "SOLIDS"]

BEAMS = ("lebb", "nebb", "ancf")
SOLIDS = ("ffrf", "gcms", "tlf")

#: Fitted coefficients (bytes) of the parts, per method: least squares on the measured peaks,
#: raised by about 12 % so that the estimate lies above every measurement (docs/robustness.md).
#: Beams: the interpreter with numpy and scipy, per unknown (quadrature and element tables, the
#: invariant engines of ANCF) and per unknown squared (dense matrices: 18 doubles for LEBB and
#: NEBB, 44 for ANCF, whose tangent and companion matrices carry all 21 slot coordinates).
BEAM = {"lebb": (65e6, 50e3, 145.0), "nebb": (65e6, 50e3, 145.0), "ancf": (85e6, 195e3, 350.0)}
#: Solids: the interpreter with dolfinx, PETSc and SLEPc (per rank); per unknown (mesh, dof maps,
#: sparse K, M or Jacobian, work vectors); per unknown and clamped mode (FFRF, GCMS: the
#: eigenvectors, SLEPc's basis of about twice as many, the gathered copy); per unknown^(4/3)
#: (MUMPS: 9.4 to 12.8 n^(4/3) entries of about 9 bytes per factor; TLF's steady Newton and its
#: stability verdict hold about two); TLF with ``--force-eval invariant``: per unknown (the
#: invariant matrices K_L, K_N2, K_N3 and the pair map); ``--mass consistent``: one more factor
SOLID_BASE = 180e6
SOLID = {"ffrf": (2.6e3, 130.0), "gcms": (2.6e3, 130.0), "tlf": (2.85e3, 245.0)}
PER_MODE = 46.0
INVARIANTS = 12e3
#: Q2 solids (``mesh.solid_degree = 2``), on their own unknown count: the mesh, sparse matrices
#: (about 190 nonzeros per row against 81 for Q1, but fewer cells per unknown) and factors take
#: this factor more than the Q1 law per unknown. Measured peaks of TLF steady, serial: 607 MB at
#: 35100 unknowns (50 x 6 x 4), 956 MB at 58752 (64 x 8 x 4), 1.15 and 1.07 times the Q1 law;
#: FFRF 792 MB at 58752 -- raised by 12 % as the Q1 coefficients were
Q2_FACTOR = 1.3
#: iterative route (per unknown): GAMG's hierarchy (coarse operators of six rigid-body modes per
#: aggregate, prolongators), the Chebyshev smoothers' and Krylov vectors. Measured peaks of TLF
#: steady, serial (docs/solvers.md): 323 MB at 58752 unknowns (128 x 16 x 8), 707 MB at 187200
#: (192 x 24 x 12), 3.31 GB at 1033200 (400 x 40 x 20), i.e. 3.0 to 3.1 kB per unknown in all;
#: raised by 12 % like the others, less the mesh and matrices part. FFRF and GCMS (one
#: hierarchy inside SLEPc's shift-and-invert) are given TLF's figure, not measured
ITERATIVE = {"ffrf": 600.0, "gcms": 600.0, "tlf": 600.0}
#: TLF's stability verdict on the iterative route (per unknown), beyond the steady state's peak:
#: the PEP's K (assembled whole, then its free block), C and M, GAMG's hierarchy of K and SLEPc's
#: TOAR basis (about 54 vectors). Measured peaks of the serial steady state and verdict
#: (docs/solvers.md): 423 MB at 58752 unknowns, 1020 MB at 187200, 1.69 and 1.64 kB per unknown
#: above the steady state alone (323 and 713 MB in the same runs); the estimate lies 13 and 10 %
#: above them. The direct route's factorisation part already counts the verdict's factor
PEP_ITERATIVE = 1.6e3
#: the solid parts grow by this fraction per rank beyond the first (TLF 128 x 16 x 8 on 2 ranks:
#: 2 x 558 MB at most against 808 MB on one)
MPI_OVERHEAD = 0.1
#: the iterative route's solid parts grow by this fraction per rank beyond the first: GAMG's
#: distributed Galerkin products (MatPtAPSymbolic 49 MB serial, 240 MB on 2 ranks at 58752
#: unknowns) and the halo copies of the hierarchy. TLF steady on 2 ranks (docs/solvers.md), sum
#: of the ranks' peaks: 703 MB at 58752 unknowns, 1.64 GB at 187200, 7.93 GB at 1033200, 2.2 to
#: 2.4 times the serial peak; fitted at 2 ranks with the serial law's margin (measured 0.81-0.86
#: of the estimate), more ranks extrapolated linearly
MPI_OVERHEAD_ITERATIVE = 1.5


@dataclass(frozen=True)
class Estimate:
    """Peak memory of a build in bytes, by part, for ``ranks`` ranks on one machine."""

    method: str
    parts: dict[str, float]
    ranks: int = 1
    route: str | None = None        # solids: "direct" or "iterative" (docs/solvers.md)

    @property
    def total(self) -> float:
        return sum(self.parts.values())

    def describe(self) -> str:
        """'about 31 GB (dense matrices 20 GB, ...)': the total and its largest parts."""
        parts = sorted(((v, k) for k, v in self.parts.items() if k != "base"), reverse=True)
        inner = ", ".join(f"{k} {format_size(v)}" for v, k in parts if v >= 0.05 * self.total)
        return f"about {format_size(self.total)}" + (f" ({inner})" if inner else "")


def estimate(method: str, scene: Scene, ranks: int = 1, options: BuildOptions | None = None,
             route: str | None = None) -> Estimate:
    """The peak memory of building ``method`` for ``scene`` with ``options`` and solving its
    steady state (or running it) on ``ranks`` ranks of one machine (module docstring), its
    linear systems by ``route`` (solids; default: the options' or the scene's
    ``[solver] linear``, "auto" counted as direct)."""
    if method not in METHODS:
        raise FxflexError(f"--method: {method!r} is not a method; allowed: {' '.join(METHODS)}")
    ranks = max(1, int(ranks))
    if method in BEAMS:
        n = float(dof_count(method, scene))
        base, per_unknown, dense = BEAM[method]
        per_rank = {"base": base, "dense matrices": dense * n * n,
                    "element tables": per_unknown * n}
        return Estimate(method, {k: ranks * v for k, v in per_rank.items()}, ranks)
    degree = scene.mesh.solid_degree
    n = _unknowns(scene.mesh.solid, degree)
    per_unknown, factor = SOLID[method]
    scale = 1.0 if degree == 1 else Q2_FACTOR
    route = route or _requested(scene, options)
    route = "direct" if route == "auto" else route
    parts = {"base": ranks * SOLID_BASE, "mesh and matrices": scale * per_unknown * n}
    if route == "direct":
        parts["factorisation"] = scale * factor * n ** (4.0 / 3.0)
    else:
        parts["preconditioner"] = scale * ITERATIVE[method] * n
    if method == "ffrf":
        parts["modes"] = PER_MODE * n * scene.reduction.ffrf_modes
    elif method == "gcms":
        parts["modes"] = PER_MODE * n * (scene.reduction.gcms_modes // 3)
    else:
        if getattr(options, "force_eval", None) == "invariant" and degree == 1:
            parts["invariants"] = INVARIANTS * n     # Q2 refuses the route (tlf_invariants)
        if getattr(options, "mass", None) == "consistent":
            parts["mass factorisation"] = scale * SOLID["ffrf"][1] * n ** (4.0 / 3.0)
        if route == "iterative":
            parts["stability eigensolve"] = scale * PEP_ITERATIVE * n
    # a distributed factor and mesh carry ghosts and halo copies: measured +10 % at 2 ranks
    # (direct), +150 % (iterative: GAMG's distributed products)
    overhead = MPI_OVERHEAD if route == "direct" else MPI_OVERHEAD_ITERATIVE
    spread = 1.0 + overhead * (ranks - 1)
    return Estimate(method, {k: v if k == "base" else spread * v for k, v in parts.items()}, ranks,
                    route)


def _requested(scene: Scene, options: BuildOptions | None) -> str:
    """The route asked for: the options' resolved one, else the scene's ``[solver] linear``."""
    return getattr(options, "linear", None) or scene.solver.linear


def route(scene: Scene, estimate: Estimate | None, options: BuildOptions | None = None) -> str:
    """The linear solver route of a solid build: the one :func:`check` chose, else (check
    skipped) the one asked for, "auto" meaning direct as before the key existed."""
    if estimate is not None and estimate.route is not None:
        return estimate.route
    wanted = _requested(scene, options)
    return "direct" if wanted == "auto" else wanted


def _unknowns(divisions, degree: int = 1) -> float:
    """Nodal unknowns of a solid mesh of element degree p after the root clamp,
    3 p nx (p ny + 1) (p nz + 1) (as ``fxflex.solid.model.solid_dof_count``, which imports
    dolfinx)."""
    nx, ny, nz = (float(v) for v in divisions)
    return 3.0 * degree * nx * (degree * ny + 1) * (degree * nz + 1)


# -- what the machine has ----------------------------------------------------------------------

def _read_int(path: Path) -> int | None:
    try:
        text = path.read_text().split()[0]
    except (OSError, IndexError):
        return None
    return int(text) if text.isdigit() else None


def _meminfo(path: Path) -> int | None:
    try:
        for line in path.read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def _cgroup_free(proc: Path, cgroup: Path) -> int | None:
    """Room left under the memory limits of this process's cgroups (v2: memory.max of its group
    and every parent; v1: memory.limit_in_bytes), reclaimable page cache counted as free."""
    try:
        lines = (proc / "self" / "cgroup").read_text().splitlines()
    except OSError:
        return None
    best = None
    for line in lines:
        _, controllers, rel = line.split(":", 2)
        if controllers == "":
            base, files = cgroup, ("memory.max", "memory.current", "inactive_file")
        elif "memory" in controllers.split(","):
            base = cgroup / "memory"
            files = ("memory.limit_in_bytes", "memory.usage_in_bytes", "total_inactive_file")
        else:
            continue
        leaf = base / rel.strip("/")
        for folder in (leaf, *leaf.parents):
            if folder != base and base not in folder.parents:
                break
            limit, used = _read_int(folder / files[0]), _read_int(folder / files[1])
            if limit is None or used is None or limit >= 1 << 60:      # "max": no limit
                continue
            free = limit - used + _stat(folder / "memory.stat", files[2])
            best = free if best is None else min(best, free)
    return best


def _stat(path: Path, name: str) -> int:
    try:
        for line in path.read_text().splitlines():
            key, _, value = line.partition(" ")
            if key == name:
                return int(value)
    except (OSError, ValueError):
        pass
    return 0


def available(proc: Path = Path("/proc"), cgroup: Path = Path("/sys/fs/cgroup")) -> int | None:
    """Bytes a new build may use on this machine: MemAvailable of ``/proc/meminfo`` or the room
    under this process's cgroup memory limit, whichever is smaller, and at most
    ``FXFLEX_MEMORY_LIMIT`` if set; None when nothing is known."""
    values = [v for v in (_meminfo(proc / "meminfo"), _cgroup_free(proc, cgroup)) if v is not None]
    limit = os.environ.get("FXFLEX_MEMORY_LIMIT", "").strip()
    if limit:
        values.append(parse_size(limit, "FXFLEX_MEMORY_LIMIT"))
    return max(0, min(values)) if values else None


_UNITS = {"": 1, "K": 1 << 10, "M": 1 << 20, "G": 1 << 30, "T": 1 << 40}


def parse_size(text: str, key: str) -> int:
    """'8G', '512M', '1.5e9' -> bytes (binary K, M, G, T)."""
    match = re.fullmatch(r"\s*([0-9.eE+]+)\s*([KMGT]?)i?B?\s*", text, flags=re.IGNORECASE)
    try:
        value = float(match.group(1)) * _UNITS[match.group(2).upper()] if match else math.nan
    except ValueError:
        value = math.nan
    if not math.isfinite(value) or value < 0:
        raise FxflexError(f"{key}: {text!r} is not a size; allowed: a number of bytes, optionally "
                          f"with K, M, G or T (e.g. 8G)")
    return int(value)


def format_size(n: float) -> str:
    for unit, scale in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6)):
        if n >= scale or unit == "MB":
            return f"{n / scale:.3g} {unit}"
    return f"{n:.0f} B"


# -- the check before a build ------------------------------------------------------------------

def _largest(method: str, scene: Scene, ranks: int, room: float,
             options: BuildOptions | None, way: str | None = None) -> str:
    """What fits in ``room`` bytes: the largest beam element count, or the largest solid mesh of
    the scene's proportions on the linear solver route ``way`` (bisection on the estimate,
    which grows with the size)."""
    def fits(s: float) -> bool:
        return estimate(method, _scaled(method, scene, s), ranks, options, way).total <= room

    if not fits(1e-9):
        return "nothing: the libraries alone need more"
    lo, hi = 1e-9, 1.0
    for _ in range(80):
        mid = math.sqrt(lo * hi)
        lo, hi = (mid, hi) if fits(mid) else (lo, mid)
    best = _scaled(method, scene, lo)
    if method in BEAMS:
        return f"up to about {best.mesh.beam_elements} elements on this machine"
    return (f"meshes up to about {_unknowns(best.mesh.solid, best.mesh.solid_degree):.2g} "
            f"unknowns on this machine, "
            f"e.g. mesh.solid = {list(best.mesh.solid)}")


def _scaled(method: str, scene: Scene, s: float) -> Scene:
    """The scene with its mesh scaled by s (beams: the element count; solids: each division by
    s^(1/3), Y and Z kept even)."""
    if method in BEAMS:
        return scene.replace(**{"mesh.beam_elements": max(1, int(scene.mesh.beam_elements * s))})
    nx, ny, nz = scene.mesh.solid
    f = s ** (1.0 / 3.0)
    even = lambda v: max(2, 2 * int(v * f / 2))
    return scene.replace(**{"mesh.solid": (max(1, int(nx * f)), even(ny), even(nz))})


#: estimated bytes beyond the running interpreter's (the estimate's ``base``, already held)
#: below which :func:`check` on one rank does not read the available memory, unless
#: ``FXFLEX_MEMORY_LIMIT`` caps it (no machine that runs Python and PETSc lacks 64 MB more)
SMALL_BUILD = 64 * 2**20


def check(method: str, scene: Scene, comm, options: BuildOptions | None = None
          ) -> Estimate | None:
    """Refuse (FxflexError, on every rank) a build whose estimate exceeds the available memory of
    a machine it runs on; the ranks of one machine (MPI shared-memory node) are added up. A
    solid with ``[solver] linear = "auto"`` takes the direct route when it fits and the
    iterative one otherwise. Returns the estimate (its ``route`` the one chosen), or None when
    ``FXFLEX_MEMORY_CHECK=0``. Collective."""
    if os.environ.get("FXFLEX_MEMORY_CHECK", "").strip() == "0":
        return None
    from mpi4py import MPI

    comm = comm if comm is not None else MPI.COMM_SELF     # the beams' replicated builds
    wanted = _requested(scene, options)
    routes = [None] if method in BEAMS else (
        ["direct", "iterative"] if wanted == "auto" else [wanted])
    if comm.size == 1 and not os.environ.get("FXFLEX_MEMORY_LIMIT", "").strip():
        # a build that adds little to the running process skips reading /proc and the cgroup
        # (0.5 ms, a sixth of a small beam build, paid per --tol level)
        first = estimate(method, scene, 1, options, route=routes[0])
        if first.total - first.parts.get("base", 0.0) <= SMALL_BUILD:
            return first
    node = comm.Split_type(MPI.COMM_TYPE_SHARED) if comm.size > 1 else None
    local_ranks = node.size if node is not None else 1
    if node is not None:
        node.Free()
    room = available()
    for way in routes:
        mine = estimate(method, scene, comm.size, options, route=way)
        need = mine.total * local_ranks / comm.size
        worst = comm.allreduce((room / need if room is not None else math.inf, comm.rank),
                               op=MPI.MIN)
        if worst[0] >= 1.0:
            return mine
    # the message names the tightest rank's figures
    room, local_ranks = comm.bcast((room, local_ranks), root=worst[1])
    key = "mesh.beam_elements" if method in BEAMS else "mesh.solid"
    value = scene.mesh.beam_elements if method in BEAMS else list(scene.mesh.solid)
    share = f" ({local_ranks} ranks on one machine)" if comm.size > 1 else ""
    node_est = Estimate(method, {k: v * local_ranks / comm.size for k, v in mine.parts.items()})
    way = f" (linear solver {mine.route})" if mine.route else ""
    largest = _largest(method, scene, comm.size, room * comm.size / local_ranks, options,
                       mine.route)
    raise FxflexError(
        f"{key} = {value}: the {method} build{way} needs {node_est.describe()}{share}; "
        f"{format_size(room)} available; allowed: {largest} "
        f"(FXFLEX_MEMORY_CHECK=0 builds anyway)")
