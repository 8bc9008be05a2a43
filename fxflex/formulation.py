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
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

from fxflex.errors import FxflexError
from fxflex.scene import METHODS, Scene

__all__ = ["Formulation", "SteadyState", "BuildOptions", "build", "check_options", "dof_count",
           "default_integration", "method_info", "METHODS", "FORCE_EVAL", "PAPER_INTEGRATION"]

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


def method_info() -> dict[str, str]:
    return {"ffrf": "solid, floating frame, relative coordinates, CMS (Sect. 2.1)",
            "gcms": "solid, floating frame, absolute coordinates, CMS (Sect. 2.2)",
            "tlf": "solid, total Lagrangian, Green-Lagrange strain (Sect. 2.3)",
            "lebb": "beam, floating frame, linear Euler-Bernoulli (Sect. 3.1)",
            "nebb": "beam, floating frame, von Karman strain (Sect. 3.2)",
            "ancf": "beam, absolute nodal coordinates, 2nd order (Sect. 3.3)"}


#: where each method's ``build(scene, comm, options)`` lives; imported lazily so that beam runs
#: never import dolfinx
_MODULES = {"ffrf": "fxflex.solid.ffrf", "gcms": "fxflex.solid.gcms", "tlf": "fxflex.solid.tlf",
            "lebb": "fxflex.beam.lebb", "nebb": "fxflex.beam.nebb", "ancf": "fxflex.beam.ancf"}


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
    """Build ``method`` for ``scene`` on communicator ``comm``."""
    options = options or BuildOptions()
    check_options(method, options)
    try:
        module = importlib.import_module(_MODULES[method])
    except ModuleNotFoundError as exc:
        if exc.name == _MODULES[method]:
            raise FxflexError(f"--method: {method} is not implemented yet") from None
        raise
    return module.build(scene, comm, options)


#: the paper's integrator and step per method (Sect. 4, SPEC section 4)
PAPER_INTEGRATION = {"ffrf": ("ab2", 0.5e-6), "gcms": ("ab2", 0.3e-6), "tlf": ("cd", 0.5e-6),
                     "lebb": ("ab2", 0.4e-6), "nebb": ("ab2", 0.4e-6), "ancf": ("cd", 1.7e-6)}
#: the paper's efficiency study (Sect. 4.2) runs AB for every method at this step
PAPER_AB_STEP = 0.02e-6


def default_integration(method: str, integrator: str | None, dt: float | None
                        ) -> tuple[str, float]:
    """(integrator, dt) with the paper's defaults filled in (SPEC section 4)."""
    paper_integrator, paper_dt = PAPER_INTEGRATION[method]
    integrator = integrator or paper_integrator
    if dt is None:
        if integrator == paper_integrator:
            dt = paper_dt
        elif integrator == "ab2":
            dt = PAPER_AB_STEP
        else:
            raise FxflexError(f"--dt: required with --integrator {integrator} for {method} (the "
                              f"paper's step is for {paper_integrator}: {paper_dt:g} s)")
    if integrator not in ("ab2", "cd"):
        raise FxflexError(f"--integrator: {integrator} is not implemented yet; allowed: ab2 cd")
    return integrator, dt


def dof_count(method: str, scene: Scene) -> int | None:
    """Unknowns after constraints, without building the method (None if not yet known)."""
    try:
        module = importlib.import_module(_MODULES[method])
    except ModuleNotFoundError as exc:
        if exc.name == _MODULES[method]:
            return None
        raise
    count = getattr(module, "dof_count", None)
    return count(scene) if count is not None else None
