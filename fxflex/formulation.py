"""The one interface all six formulations offer, and the registry that builds them.

A formulation is built once from a scene (mesh, matrices, modes, invariant matrices: everything
that does not change in time) and then answers a handful of questions. Integrators and analyses
talk only to this interface, so every integrator works with every method.

State convention: ``q`` and ``v`` are 1-D float64 numpy arrays holding the unknowns this rank
owns (the whole vector for small replicated models). ``comm`` is the communicator over which
they are distributed -- ``MPI.COMM_SELF`` when every rank holds a full copy -- and is what
global reductions (norms) must use. Constrained coordinates (TLF and ANCF root nodes, which
follow the drive) may be part of ``q``; ``constrain`` writes their exact values.

The contract is the whole of what callers use (no caller probes a formulation with getattr):
:class:`Dynamics` (what the explicit integrators need), :class:`Implicit` (generalized-alpha),
:class:`RotatingAnalysis` (modes and stability about the rotating steady state, SPEC section 6,
docs/stability.md) and :class:`Outputs` (optional outputs and probes, declared: an absent one is
None, never missing). :class:`Formulation` is all four, and every method's class derives from
:class:`FormulationBase`, which declares the defaults and computes the rotating analysis from the
one thing a method supplies, ``linearise(steady)`` -> a linearisation with one interface whether
dense (LAPACK, :class:`~fxflex.numerics.qep.DenseLinearisation`) or distributed (SLEPc PEP,
:class:`~fxflex.numerics.petsc.PetscLinearisation`). ``tests/test_contract.py`` checks all six.

Implicit integration (:class:`Implicit`, used by ``generalized-alpha``): the same equations written
on the free coordinates as M q'' = F(t, q, q'), with the tangents K_t = -dF/dq and C_t = -dF/dq'
folded into one factorised iteration matrix S = m M + c C_t + k K_t.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field, replace
from typing import Callable, Protocol, runtime_checkable

import numpy as np

from fxflex.errors import FxflexError
from fxflex.methods import MODULES as _MODULES
from fxflex.methods import dof_count
from fxflex.scene import METHODS, Scene

__all__ = ["Formulation", "Dynamics", "Implicit", "RotatingAnalysis", "Outputs", "Linearisation",
           "FormulationBase", "TangentFactor", "SteadyState", "BuildOptions", "build",
           "check_options", "dof_count", "default_integration", "method_info", "METHODS",
           "FORCE_EVAL", "PAPER_INTEGRATION", "IMPLICIT_STEP", "IMPLICIT_MIN_STEP",
           "implicit_step", "OUTPUTS", "SMALL_DEFORMATION_RANGE"]

#: --force-eval choices per method (SPEC section 8); the first is the default
FORCE_EVAL = {"tlf": ("ufl", "invariant"), "nebb": ("invariant", "element"),
              "ancf": ("invariant", "element")}
MASS = ("lumped", "consistent")
#: deflection, in beam lengths, beyond which a run stops (the ``deflection_range`` of models of
#: small deformation: floating-frame linear elasticity, von Karman)
SMALL_DEFORMATION_RANGE = 0.25


@dataclass(frozen=True)
class BuildOptions:
    """Choices that change what is built, but not the physics of the scene."""

    force_eval: str | None = None   # None: the method's default (FORCE_EVAL[method][0])
    mass: str | None = None         # TLF: "consistent" (Eq. 29) or "lumped" (row sum); None: default
    need_steady: bool = True        # False: skip work only the steady state needs
    linear: str | None = None       # solids: "direct" | "iterative"; None: [solver] linear, with
                                    # "auto" resolved by build() (fxflex.memory.check)


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
class Dynamics(Protocol):
    """What the explicit integrators and the steady-state solve need."""


    method: str
    scene: Scene
    comm: object                        # mpi4py communicator of the state arrays
    dof: int                            # global number of unknowns after constraints
    timings: dict[str, float]           # preprocessing breakdown (s)
    #: the state is a mesh field distributed over ``comm`` (TLF: tens of thousands of unknowns,
    #: PETSc operators), not a small dense model replicated on every rank: studies rebuild it
    #: rather than keep one per speed, time its steps on a short run and skip its eigen-analysis
    #: where no verdict is asked for
    distributed: bool
    #: the coordinates are at rest at the rotating steady state: (steady.q, q' = 0) is the
    #: equilibrium's state at phi = 0. False where they turn with the body there (absolute
    #: coordinates: GCMS's xi' = Omega J xi, TLF's and ANCF's nodal ones)
    steady_at_rest: bool
    #: the scene key that sets the mesh ("mesh.solid": hexahedra; "mesh.beam_elements")
    mesh_key: str

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
        constrained ones. Where M depends on q or t (a tip body of extent along X: TLF's on
        q, GCMS's on the hub angle), M at the (t, q) of the last ``force`` call, which
        integrators therefore make first."""

    def factorize(self, t: float, q: np.ndarray, v: np.ndarray, m: float, c: float, k: float
                  ) -> TangentFactor:
        """Assemble and factorise S = m M + c C_t + k K_t at (t, q, v) on the free coordinates
        (K_t = -dF/dq, C_t = -dF/dv, exact or, where a method says so, up to terms too small to
        slow Newton down); returns the handle, which stays valid until the next call."""


class Linearisation(Protocol):
    """The motion linearised about the rotating steady state, M x'' + C x' + K x = 0 (SPEC
    section 6, paper Eq. 59-64), and its roots x = e^(lambda t) x: dense arrays solved by LAPACK
    (all roots) or distributed PETSc matrices solved by SLEPc (the lowest), behind one interface.
    """

    kind: str                   # "dense" or "petsc"
    dof: int
    M: object
    C: object
    K: object
    note: str | None            # why :meth:`stable` returned None, when it did

    def modes(self, pairs: int) -> tuple[np.ndarray, np.ndarray]:
        """The ``pairs`` lowest roots, one per conjugate pair, lowest frequency first, and their
        mode vectors (this rank's entries)."""

    def eigenvalues(self) -> np.ndarray:
        """The roots the verdict is decided on (all, or the lowest)."""

    def growth_rate(self) -> tuple[float, float]:
        """(Re lambda, |Im lambda|) of the rightmost of them (1/s, rad/s)."""

    def stable(self) -> bool | None:
        """No root grows; None when round-off or the eigensolver cannot decide (``note``)."""

    def top_frequency(self) -> float | None:
        """sqrt of the largest eigenvalue of (K, M) (rad/s), or None when not computed."""

    def destroy(self) -> None:
        """Free the matrices (PETSc)."""


@runtime_checkable
class RotatingAnalysis(Protocol):
    """Modes and stability about the rotating steady state (SPEC section 6, docs/stability.md)."""

    stability_note: str | None          # why ``stable()`` is None, when it is
    #: ``eigenvalues()`` are every root of the linearised system (dense, LAPACK); False: only
    #: the lowest (TLF's SLEPc PEP), so the highest frequency is ``omega_max()``'s
    all_roots: bool

    def linearise(self, steady: SteadyState | None = None) -> Linearisation:
        """The motion linearised about ``steady`` (default: the scene's own steady state)."""

    def rotating_modes(self, pairs: int, steady: SteadyState | None = None
                       ) -> tuple[np.ndarray, np.ndarray]:
        """The lowest roots, one per conjugate pair, and their mode vectors."""

    def mode_tip(self, X: np.ndarray) -> np.ndarray:
        """(6, k) tip-section translation and rotation of mode vectors (O-XYZ)."""

    def mode_span(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(x, S) of mode vectors: x (s,) span stations in m from the root (the beam nodes, the
        solids' node layers) and S (4, s, k) the section centroid's translation X, Y, Z and the
        section rotation about X there (O-XYZ; SPEC section 10). Same on every rank
        (collective for TLF)."""

    def eigenvalues(self, steady: SteadyState | None = None) -> np.ndarray:
        """The roots the verdict is decided on."""

    def growth_rate(self) -> tuple[float, float]:
        """(Re lambda, |Im lambda|) of the rightmost root (1/s, rad/s)."""

    def stable(self, steady: SteadyState | None = None) -> bool | None:
        """No root grows (True / False); None when undecided, the reason in stability_note."""

    def omega_max(self) -> float:
        """The highest circular frequency of the clamped body at rest (rad/s): step limits."""

    def top_frequency(self) -> float | None:
        """The highest undamped circular frequency about the steady state where that is cheap
        (a dense linearisation), otherwise ``omega_max()`` (rad/s): what explicit steps face."""


#: the optional outputs of :class:`Outputs`: None where a method does not offer one
OUTPUTS = ("extras", "root_stress", "field_writer", "state_points", "rotating_state")


@runtime_checkable
class Outputs(Protocol):
    """Outputs and probes. The callables named in :data:`OUTPUTS` are None where a method does
    not offer them (``form.probes()`` tells which); the rest always have a value."""

    options: BuildOptions                # what the formulation was built with
    warnings: list[str] | tuple[str, ...]  # said once about the build (e.g. twist per element)
    force_eval: str | None               # the --force-eval route in use (None: not an option)
    mass_kind: str | None                # the --mass in use (None: not an option)
    deflection_range: float              # deflection, in lengths, beyond which a run stops
    extra_columns: tuple[str, ...]       # series columns ``extras`` fills
    #: (t, q, v) -> the values of extra_columns (drive torque)
    extras: Callable[[float, np.ndarray, np.ndarray], tuple] | None
    #: (t, q) -> axial stress sigma_X on the root section's points (Pa)
    root_stress: Callable[[float, np.ndarray], np.ndarray] | None
    #: (path) -> a writer of displacement fields with write(t, q) and close() (XDMF)
    field_writer: Callable[[str], object] | None
    #: () -> the undeformed coordinates of a distributed state's owned nodes (checkpoints)
    state_points: Callable[[], np.ndarray] | None
    #: (t, q, v) -> (z, z') in the coordinates of the dense linearisation (energy of long runs)
    rotating_state: Callable[[float, np.ndarray, np.ndarray], tuple] | None

    def probes(self) -> dict[str, bool]:
        """Which of :data:`OUTPUTS` this formulation offers."""


@runtime_checkable
class Formulation(Dynamics, Implicit, RotatingAnalysis, Outputs, Protocol):
    """Everything a built method offers: the whole contract."""

    def at(self, *, rpm: float | None = None, damping: float | None = None,
           model: str | None = None) -> "Formulation":
        """The same method and build options for the scene at another constant speed (rpm),
        damping coefficient c (kg/(m^3 s)) or damping model, sharing every operator that does
        not depend on them."""


class FormulationBase:
    """The declared defaults of :class:`Outputs` and the rotating analysis of
    :class:`RotatingAnalysis` computed from ``linearise()``, once per formulation; every method's
    class derives from it. A method overrides a default by defining the member."""

    options: BuildOptions = BuildOptions()
    warnings: tuple[str, ...] = ()
    distributed: bool = False
    steady_at_rest: bool = True
    all_roots: bool = True
    mesh_key: str = "mesh.beam_elements"
    stability_note: str | None = None
    force_eval: str | None = None
    mass_kind: str | None = None
    deflection_range: float = SMALL_DEFORMATION_RANGE
    extra_columns: tuple[str, ...] = ()
    extras = None
    root_stress = None
    field_writer = None
    state_points = None
    rotating_state = None
    #: Newton's relative residual for steady_state() (the methods that iterate: TLF, NEBB, ANCF),
    #: each against its own reference residual (TLF: the undeformed body's; NEBB: at W = 0; ANCF:
    #: at x = 0, a collapsed body's); the ``--tol`` ladder loosens it for TLF and NEBB to what EPS
    #: needs (fxflex.analysis.tolerance, NEWTON_EPS)
    steady_rtol: float = 1e-10
    _linear: Linearisation | None = None

    def probes(self) -> dict[str, bool]:
        """Which optional outputs (:data:`OUTPUTS`) this formulation offers."""
        return {name: getattr(self, name) is not None for name in OUTPUTS}

    def linearise(self, steady: SteadyState | None = None) -> Linearisation:
        raise NotImplementedError(f"{type(self).__name__} does not define linearise()")

    def linearisation(self, steady: SteadyState | None = None) -> Linearisation:
        """``linearise(steady)``, computed once and kept with its roots (a formulation is built
        for one scene, so for one steady state)."""
        if self._linear is None:
            self._linear = self.linearise(steady)
        return self._linear

    def rotating_modes(self, pairs: int, steady: SteadyState | None = None
                       ) -> tuple[np.ndarray, np.ndarray]:
        """The ``pairs`` lowest roots of the linearised rotating system, one per conjugate pair,
        lowest frequency first, and their mode vectors (Linearisation.modes). Collective for
        distributed models."""
        return self.linearisation(steady).modes(pairs)

    def eigenvalues(self, steady: SteadyState | None = None) -> np.ndarray:
        """The roots of the linearised rotating system the verdict is decided on: all of them
        for dense models, the lowest for TLF (SPEC section 6, Eq. 59-64)."""
        return self.linearisation(steady).eigenvalues()

    def growth_rate(self) -> tuple[float, float]:
        """(Re lambda, |Im lambda|) of the rightmost root (1/s, rad/s)."""
        return self.linearisation().growth_rate()

    def top_frequency(self) -> float | None:
        """sqrt of the largest eigenvalue of (K, M) of the linearisation about the steady state
        (spin softening included, damping and gyroscopic terms left out), or ``omega_max()`` (the
        body at rest) when there is no usable steady state or the linearisation does not say."""
        try:
            w = self.linearisation().top_frequency()
        except (ValueError, np.linalg.LinAlgError):
            w = None                # no usable steady state: the structure at rest
        return w if w is not None else float(self.omega_max())

    def stable(self, steady: SteadyState | None = None) -> bool | None:
        """No root of the linearised rotating system grows; None when undecided, the reason
        then in ``stability_note``."""
        lin = self.linearisation(steady)
        result = lin.stable()
        if lin.note is not None:
            self.stability_note = lin.note
        return result

    def at(self, *, rpm: float | None = None, damping: float | None = None,
           model: str | None = None) -> "Formulation":
        """The same method and build options for this scene at another constant speed, damping
        coefficient or damping model. This default builds afresh (meshes, modes and invariants
        come from the cache); methods that can share more override it (FFRF, GCMS). The beams
        keep it: a rebuild costs 20 to 60 ms (LEBB, NEBB, ANCF on the default scene), less than
        one steady state; so does TLF, whose SolidModel holds the scene's speed and damping."""
        return build(self.method, rescene(self.scene, rpm=rpm, damping=damping, model=model),
                     self.comm, self.options)


def rescene(scene: Scene, *, rpm: float | None = None, damping: float | None = None,
            model: str | None = None) -> Scene:
    """``scene`` with the rotation speed (rpm), damping coefficient c or damping model replaced
    (None: kept); checked like any scene."""
    changes = {key: value for key, value in (("rotation.rpm", rpm), ("damping.c", damping),
                                             ("damping.model", model)) if value is not None}
    changes = {key: float(v) if key != "damping.model" else v for key, v in changes.items()}
    return scene.replace(**changes) if changes else scene


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
    fits = memory.check(method, scene, comm, options)
    if method in memory.SOLIDS:     # the linear solver route, "auto" resolved (docs/solvers.md)
        options = replace(options, linear=memory.route(scene, fits, options))
    try:
        module = importlib.import_module(_MODULES[method])
    except ModuleNotFoundError as exc:
        if exc.name == _MODULES[method]:
            raise FxflexError(f"--method: {method} is not implemented yet") from None
        raise
    with cache.deferred():
        try:
            form = module.build(scene, comm, options)
            form.options = options
            return form
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
