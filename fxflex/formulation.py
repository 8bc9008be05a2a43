"""The one interface all six formulations offer, and the registry that builds them.

A formulation is built once from a scene (mesh, matrices, modes, invariant matrices: everything
that does not change in time) and then answers a handful of questions. Integrators and analyses
talk only to this interface, so every integrator works with every method.

State convention: ``q`` and ``v`` are 1-D float64 numpy arrays holding the unknowns this rank
owns (the whole vector for small replicated models). ``comm`` is the communicator over which
they are distributed -- ``MPI.COMM_SELF`` when every rank holds a full copy -- and is what
global reductions (norms) must use. Constrained coordinates (TLF and ANCF root nodes, which
follow the drive) may be part of ``q``; ``constrain`` writes their exact values.

Modes and stability about the rotating steady state (SPEC section 6, docs/stability.md): every
method also offers ``linearise()`` -> (M, C, K) (dense, or PETSc matrices for TLF),
``rotating_modes(pairs)`` -> the lowest roots and mode vectors, ``mode_tip(X)`` -> the tip
section's translation and rotation in them, ``growth_rate()`` and ``stable()``.

Robustness (docs/robustness.md), optional: ``deflection_range`` -- the deflection, in lengths,
beyond which a run stops (default 0.25; TLF and ANCF, geometrically exact, 2); ``omega_max()`` --
the highest circular frequency, for step limits; ``rotating_state(t, q, v)`` -> (z, z') in the
coordinates of a dense ``linearise()`` (the energy of long runs); ``state_points()`` -> the
undeformed coordinates of the owned nodes of a distributed state (TLF), by which checkpoints
order it independently of the partition.

Implicit integration (:class:`Implicit`, used by ``generalized-alpha``): the same equations written
on the free coordinates as M q'' = F(t, q, q'), with the tangents K_t = -dF/dq and C_t = -dF/dq'
folded into one factorised iteration matrix S = m M + c C_t + k K_t.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

from fxflex.errors import FxflexError
from fxflex.methods import MODULES as _MODULES
from fxflex.methods import dof_count
from fxflex.scene import METHODS, Scene

__all__ = ["Formulation", "Implicit", "TangentFactor", "SteadyState", "BuildOptions", "build", "check_options", "dof_count",
           "default_integration", "method_info", "METHODS", "FORCE_EVAL", "PAPER_INTEGRATION",
           "IMPLICIT_STEP", "IMPLICIT_MIN_STEP", "implicit_step"]

#: --force-eval choices per method (SPEC section 8); the first is the default
FORCE_EVAL = {"tlf": ("ufl", "invariant"), "nebb": ("invariant", "element"),
              "ancf": ("invariant", "element")}
MASS = ("lumped", "consistent")


@dataclass(frozen=True)
class BuildOptions:
    """Choices that change what is built, but not the physics of the scene."""

    force_eval: str | None = None   # None: the method's default (FORCE_EVAL[method][0])
    mass: str | None = None         # TLF: "consistent" (Eq. 29) or "lumped" (row sum); None: default
    need_steady: bool = True        # False: skip work only the steady state needs


@dataclass
class SteadyState:
    """Rotating-frame equilibrium at constant speed (SPEC section 6)."""

    tip: np.ndarray                     # free-end deflection in O-XYZ (m): long., orth., load
    q: np.ndarray | None = None         # the method's own coordinates at phi = 0 (local part)
    iterations: int = 0
    residuals: list[float] = field(default_factory=list)
    converged: bool = True
    timings: dict[str, float] = field(default_factory=dict)
    extra: dict = field(default_factory=dict)


@runtime_checkable
class Formulation(Protocol):
    method: str
    scene: Scene
    comm: object                        # mpi4py communicator of the state arrays
    dof: int                            # global number of unknowns after constraints
    timings: dict[str, float]           # preprocessing breakdown (s)

    def initial_state(self) -> tuple[np.ndarray, np.ndarray]:
        """(q0, v0): undeformed body in rigid rotation at phi(0), phi'(0) (NOTES.md)."""

    def acceleration(self, t: float, q: np.ndarray, v: np.ndarray, out: np.ndarray) -> None:
        """out = M^-1 F(t, q, v): all forces except inertia M q''. On constrained coordinates,
        out is their exact prescribed acceleration."""

    def constrain(self, t: float, q: np.ndarray, v: np.ndarray) -> None:
        """Overwrite constrained coordinates of q, v with their exact values at t (no-op when the
        clamp is built into the unknowns)."""

    def tip(self, t: float, q: np.ndarray) -> np.ndarray:
        """Free-end deflection (m) in O-XYZ at time t: rigid rotation removed (SPEC section 2).
        Same value on every rank."""

    def steady_state(self) -> SteadyState:
        """Rotating-frame equilibrium at the scene's constant speed."""


class TangentFactor(Protocol):
    """A factorised iteration matrix S (see :meth:`Implicit.factorize`)."""

    def solve(self, t: float, r: np.ndarray, out: np.ndarray) -> None:
        """out = S^-1 r for a state array r that is zero on constrained coordinates; out is zero
        there too. ``t`` is the time of the state being solved for: formulations whose tangent
        turns with the hub (TLF, ANCF) keep the factor in the hub frame and rotate r and out with
        A(phi(t)), so one factor serves while the body rotates."""


@runtime_checkable
class Implicit(Protocol):
    """What implicit integrators need besides :class:`Formulation` (all six methods offer it).

    The equations of motion on the free coordinates, M q_f'' = F(t, q, q'): F holds every force
    but the inertia of the free coordinates -- elastic, damping, external, the rotating-frame
    (inertia-coupling) terms, and the inertia of the prescribed motion M_fc q_c''(t) moved to the
    right-hand side. ``acceleration`` is M^-1 F on the free rows. Arrays are state arrays as in
    :class:`Formulation`; on constrained coordinates F, M x and S^-1 r are zero, so those rows
    drop out of Newton's method and ``constrain`` supplies their exact values. Nothing here
    allocates arrays except ``factorize``.
    """

    def force(self, t: float, q: np.ndarray, v: np.ndarray, out: np.ndarray) -> None:
        """out = F(t, q, v) on the free coordinates, 0 on constrained ones. q, v constrained."""

    def mass_apply(self, x: np.ndarray, out: np.ndarray) -> None:
        """out = M_ff x_f on the free coordinates (constrained entries of x ignored), 0 on
        constrained ones."""

    def factorize(self, t: float, q: np.ndarray, v: np.ndarray, m: float, c: float, k: float
                  ) -> TangentFactor:
        """Assemble and factorise S = m M + c C_t + k K_t at (t, q, v) on the free coordinates
        (K_t = -dF/dq, C_t = -dF/dv, exact or, where a method says so, up to terms too small to
        slow Newton down); returns the handle, which stays valid until the next call."""


def method_info() -> dict[str, str]:
    return {"ffrf": "solid, floating frame, relative coordinates, CMS (Sect. 2.1)",
            "gcms": "solid, floating frame, absolute coordinates, CMS (Sect. 2.2)",
            "tlf": "solid, total Lagrangian, Green-Lagrange strain (Sect. 2.3)",
            "lebb": "beam, floating frame, linear Euler-Bernoulli (Sect. 3.1)",
            "nebb": "beam, floating frame, von Karman strain (Sect. 3.2)",
            "ancf": "beam, absolute nodal coordinates, 2nd order (Sect. 3.3)"}




#: PETSc's error code for a failed allocation (petscerror.h)
PETSC_ERR_MEM = 55


def check_options(method: str, options: BuildOptions) -> None:
    """Reject options that do not apply to ``method`` with one line naming what is allowed."""
    if method not in METHODS:
        raise FxflexError(f"--method: {method!r} is not a method; allowed: {' '.join(METHODS)}")
    if options.force_eval is not None:
        allowed = FORCE_EVAL.get(method)
        if allowed is None:
            raise FxflexError(f"--force-eval: not an option of {method}; it applies to "
                              f"{', '.join(FORCE_EVAL)}")
        if options.force_eval not in allowed:
            raise FxflexError(f"--force-eval: {options.force_eval!r} is not valid for {method}; "
                              f"allowed: {' '.join(allowed)}")
    if options.mass is not None:
        if options.mass not in MASS:
            raise FxflexError(f"--mass: {options.mass!r} is not allowed; allowed: {' '.join(MASS)}")
        if method != "tlf":
            raise FxflexError(f"--mass: not an option of {method}; it applies to tlf")


def build(method: str, scene: Scene, comm, options: BuildOptions | None = None) -> Formulation:
    """Build ``method`` for ``scene`` on communicator ``comm``.

    Refused up front (one line) when the estimated memory exceeds what the machine has
    (:func:`fxflex.memory.check`); the cache entries the build writes appear only if it succeeds
    (:func:`fxflex.cache.deferred`), so a build that fails leaves none behind. Running out of
    memory inside PETSc raises :class:`MemoryError`, as numpy does."""
    from fxflex import cache, memory
    from fxflex.scene.load import validate_for

    options = options or BuildOptions()
    check_options(method, options)
    validate_for(method, scene)
    memory.check(method, scene, comm, options)
    try:
        module = importlib.import_module(_MODULES[method])
    except ModuleNotFoundError as exc:
        if exc.name == _MODULES[method]:
            raise FxflexError(f"--method: {method} is not implemented yet") from None
        raise
    with cache.deferred():
        try:
            return module.build(scene, comm, options)
        except Exception as exc:
            # PETSc's (and so MUMPS's and SLEPc's) failed allocation is an error code, not
            # Python's MemoryError: made one, the CLI reports it as out of memory in one line
            if getattr(exc, "ierr", None) == PETSC_ERR_MEM:
                raise MemoryError(str(exc)) from exc
            raise


#: the paper's integrator and step per method (Sect. 4, SPEC section 4)
PAPER_INTEGRATION = {"ffrf": ("ab2", 0.5e-6), "gcms": ("ab2", 0.3e-6), "tlf": ("cd", 0.5e-6),
                     "lebb": ("ab2", 0.4e-6), "nebb": ("ab2", 0.4e-6), "ancf": ("cd", 1.7e-6)}
#: the paper's efficiency study (Sect. 4.2) runs AB for every method at this step
PAPER_AB_STEP = 0.02e-6
#: generalized-alpha's default step up to 1000 rpm: the largest round step at which the 10 ms
#: transient of the default scene stays within about half of 1 % of the peak deflection of the
#: paper's explicit run (docs/implicit.md)
IMPLICIT_STEP = {"ffrf": 20e-6, "gcms": 20e-6, "tlf": 10e-6, "lebb": 20e-6, "nebb": 20e-6,
                 "ancf": 20e-6}
#: ... and the smallest it becomes at high speed
IMPLICIT_MIN_STEP = 4e-6


def implicit_step(method: str, rpm: float | None = None) -> float:
    """Default generalized-alpha step: IMPLICIT_STEP below 1000 rpm, scaled by (1000 / rpm)^1.5
    above, not below IMPLICIT_MIN_STEP. The error is the phase of the axial ringing that the
    sudden centrifugal load starts, whose share of the peak grows with the speed; the law keeps
    the 10 ms transient within 0.6 % of the peak from 0 to 10000 rpm (docs/implicit.md)."""
    base = IMPLICIT_STEP[method]
    if not rpm or rpm <= 1000.0:
        return base
    return min(base, max(IMPLICIT_MIN_STEP, base * (1000.0 / rpm) ** 1.5))


def default_integration(method: str, integrator: str | None, dt: float | None,
                        rpm: float | None = None) -> tuple[str, float]:
    """(integrator, dt) with the paper's defaults filled in (SPEC section 4); generalized-alpha's
    step from :func:`implicit_step` at ``rpm``."""
    paper_integrator, paper_dt = PAPER_INTEGRATION[method]
    integrator = integrator or paper_integrator
    if integrator not in ("ab2", "cd", "generalized-alpha"):
        raise FxflexError(f"--integrator: {integrator!r} is not allowed; allowed: ab2 cd "
                          f"generalized-alpha")
    if dt is None:
        if integrator == paper_integrator:
            dt = paper_dt
        elif integrator == "ab2":
            dt = PAPER_AB_STEP
        elif integrator == "generalized-alpha":
            dt = implicit_step(method, rpm)
        else:
            raise FxflexError(f"--dt: required with --integrator {integrator} for {method} (the "
                              f"paper's step is for {paper_integrator}: {paper_dt:g} s)")
    return integrator, dt
