"""The public Python API: what ``import fxflex`` offers a user in a script or a notebook.

The same functions the command line calls, with Python arguments in place of flags (SPEC section
8; ``docs/api.md`` walks through them)::

    import fxflex

    scene = fxflex.load_scene(overrides=["rotation.rpm=5000"])     # or fxflex.Scene(), a TOML file
    form = fxflex.build("lebb", scene)                             # a Formulation
    st = fxflex.steady(form)                                       # st.tip: deflection (m)
    result = fxflex.run(form, t_end=2e-3, out="lebb.csv")          # RunResult; CSV as --out
    modes = fxflex.modes(form, 6)                                  # Modes about the steady state

Units are SI (m, s, N; speeds in rpm as in the scene); the CLI's reports print millimetres.
Bad input raises :class:`~fxflex.errors.FxflexError` (a bad scene value its subclass
:class:`~fxflex.errors.SceneError`) with the one-line message the CLI prints.

Communicator. Every function that builds takes ``comm``; None means ``MPI.COMM_WORLD``, as for
the CLI: a script started by ``mpirun -n 4`` distributes TLF (and the solid preprocessing) over
the four ranks and gives the numbers ``fxflex`` gives there, and in a notebook (one process)
COMM_WORLD is COMM_SELF. Pass ``MPI.COMM_SELF`` for a copy of its own on each rank (independent
studies per rank). Beam methods are replicated whatever ``comm`` is (``form.comm`` is
COMM_SELF). Under MPI every rank calls every function, in the same order (they are collective),
and only rank 0 writes files.

Importing this module stays light: numpy, the scene and the formulation registry. MPI, SciPy's
eigensolvers, dolfinx and matplotlib are imported by the functions that need them, and dolfinx
only for the solid methods: beam-only use never imports it.
"""

from __future__ import annotations

import warnings as _warnings
from collections.abc import Callable, Iterable, Sequence
from typing import TYPE_CHECKING

from fxflex.errors import FxflexError, OutputError, SceneError
from fxflex.formulation import (BuildOptions, Formulation, Linearisation, SteadyState,
                                default_integration, method_info)
from fxflex.formulation import build as _build
from fxflex.methods import dof_count
from fxflex.scene import METHODS, PAPER_DAMPING, PAPER_RPM, Scene, load_scene, scene_from_dict

if TYPE_CHECKING:
    from fxflex.analysis.modes import CampbellData, Modes
    from fxflex.time import RunResult

__all__ = ["Scene", "load_scene", "scene_from_dict", "SceneError", "FxflexError", "OutputError",
           "METHODS", "PAPER_RPM", "PAPER_DAMPING", "Formulation", "Linearisation",
           "BuildOptions", "SteadyState", "build", "info", "steady", "stability", "run",
           "default_integration", "modes", "campbell", "compare"]

#: the series columns every run writes first (SPEC section 8); ``form.extra_columns`` follow
SERIES_COLUMNS = ("t_s", "longitudinal_m", "orthogonal_m", "load_m")
#: how :func:`run` names its options in messages (fxflex.time.driver.plan_integration)
API_NAMES = {"dt": "dt", "t_end": "t_end", "rho_inf": "rho_inf",
             "implicit": "the generalized-alpha integrator"}


def _comm(comm):
    """``comm``, or MPI.COMM_WORLD (module docstring)."""
    if comm is not None:
        return comm
    from mpi4py import MPI
    return MPI.COMM_WORLD


def _options(options: dict) -> BuildOptions:
    """``BuildOptions`` from keyword arguments; an unknown one is a one-line FxflexError."""
    allowed = BuildOptions.__dataclass_fields__
    bad = [k for k in options if k not in allowed]
    if bad:
        raise FxflexError(f"build: unknown option(s) {', '.join(bad)}; allowed: "
                          f"{', '.join(allowed)}")
    return BuildOptions(**options)


def build(method: str, scene: Scene | None = None, comm=None, **options) -> Formulation:
    """Build ``method`` (one of :data:`METHODS`) for ``scene`` (default: the paper's scene,
    SPEC section 1) on ``comm`` (None: MPI.COMM_WORLD, module docstring).

    ``options`` are those of :class:`~fxflex.formulation.BuildOptions`: ``force_eval`` (TLF
    ``"ufl"`` | ``"invariant"``, NEBB and ANCF ``"invariant"`` | ``"element"``; the CLI's
    ``--force-eval``), ``mass`` (TLF ``"lumped"`` | ``"consistent"``, ``--mass``) and
    ``need_steady`` (False skips what only the steady state needs, as ``fxflex run`` does).
    An option that does not apply to the method raises FxflexError naming what is allowed.

    The result is a :class:`~fxflex.formulation.Formulation`: ``form.steady_state()``,
    ``form.tip(t, q)``, ``form.dof``, ``form.stable()``, ``form.at(rpm=...)`` and the rest of
    the contract (``fxflex/formulation.py``). Meshes, clamped modes and invariant matrices
    are read from and written to the disk cache (:mod:`fxflex.cache`)."""
    return _build(method, scene if scene is not None else Scene(), _comm(comm),
                  _options(options))


def info(scene: Scene | None = None, methods: Iterable[str] | None = None) -> dict[str, dict]:
    """``{method: {"description", "dof"}}`` for ``methods`` (default: all) without building them
    (``dof`` None where it is known only after preprocessing): ``fxflex info``."""
    scene = scene if scene is not None else Scene()
    names = list(METHODS) if methods is None else list(methods)
    bad = [m for m in names if m not in METHODS]
    if bad:
        raise FxflexError(f"methods: {', '.join(map(repr, bad))} not a method; allowed: "
                          f"{' '.join(METHODS)}")
    return {m: {"description": method_info()[m], "dof": dof_count(m, scene)} for m in names}


def steady(form: Formulation) -> SteadyState:
    """The rotating-frame equilibrium at the scene's constant speed (SPEC section 6), as
    ``fxflex steady`` computes it: linear methods solve (K_L - Omega^2 M_rr6) W = Q_e +
    Omega^2 M_rr2 (paper Eq. 59 with the time derivatives zero), nonlinear ones Newton with
    continuation. ``st.tip`` is the free-end deflection (m; longitudinal, orthogonal, load, SPEC
    section 2), ``st.converged`` whether it converged. Its stability: :func:`stability`."""
    return form.steady_state()


def stability(form: Formulation, steady: SteadyState | None = None
              ) -> tuple[bool | None, str | None]:
    """(stable, note) of the equilibrium ``steady`` (default: the scene's), as ``fxflex steady``
    reports it: no root of (lambda^2 M + lambda (D + G) + K_eff) x = 0 with positive real part
    (SPEC section 6, Eq. 59-64). ``stable`` is None when the eigenvalues cannot decide; ``note``
    then says why."""
    from fxflex.numerics.qep import verdict
    return verdict(form, steady)


def run(form: Formulation, t_end: float = 0.01, *, integrator: str | None = None,
        dt: float | None = None, rho_inf: float | None = None, out: str | None = None,
        sample_dt: float | None = None, history: bool = False,
        on_sample: Callable | None = None, progress: bool = False, diagnose: bool = True
        ) -> RunResult:
    """Integrate ``form`` from rest (undeformed, in rigid rotation) to ``t_end`` (s), as
    ``fxflex run`` does, and return the :class:`~fxflex.time.RunResult` of
    :func:`fxflex.time.simulate`: ``result.tip`` (m) at ``result.t`` (the last finite check),
    ``result.steps``, ``result.wall_s`` and ``result.diverged``: None, or where and why the run
    stopped (``time_s``, ``kind``, ``reason``), with ``diagnose`` (default) also the cause as
    ``fxflex run`` reports it (:func:`fxflex.time.diagnose`): ``cause`` ``"physical"`` (a root
    of the linearised rotating system with positive real part) or ``"numerical"`` (the step too
    large for the integrator, SPEC section 4) and ``detail``.

    ``integrator`` (``"ab2"``, ``"cd"``, ``"generalized-alpha"``) and ``dt`` default to the
    paper's for the method (SPEC section 4, :func:`default_integration`); a ``dt`` that does not
    divide ``t_end`` is shortened so that the run ends at ``t_end`` (with a warning).
    ``rho_inf`` (generalized-alpha only, in [0, 1], default 0.9) is the spectral radius at
    infinity.

    Sampling, as the CLI's: every ``sample_dt`` (default max(dt, t_end / 20000)) when something
    reads the samples -- ``out`` (a CSV file written as the run goes, the same file as
    ``fxflex run --out``: a commented JSON header, then ``t_s, longitudinal_m, orthogonal_m,
    load_m`` and the method's ``extra_columns``), ``history`` (rows (t, tip..., extras...) kept
    in ``result.history``) or ``on_sample(t, tip, extras, q)`` (q is the live state: copy it to
    keep it); without any of them only the final deflection is computed. ``progress`` shows a
    progress line on stderr (rank 0).

    Like the CLI, an AB2 run that ends without stopping warns when AB2 amplified the highest
    mode enough to spoil the output (:func:`fxflex.time.diagnosis.ab2_warning`)."""
    from fxflex.io import Progress, SeriesWriter, envelope
    from fxflex.io.paths import Output, check_paths
    from fxflex.time import simulate
    from fxflex.time.diagnosis import ab2_warning
    from fxflex.time.driver import plan_integration, sample_steps

    if not t_end > 0:
        raise FxflexError(f"t_end: must be > 0, got {t_end!r}")
    scene, comm = form.scene, form.comm
    plan = plan_integration(form.method, integrator, dt, t_end, rho_inf, scene.rotation.rpm,
                            names=API_NAMES)
    integrator, step, nsteps, rho_inf = plan.integrator, plan.dt, plan.steps, plan.rho_inf
    if plan.note:
        _warnings.warn(plan.note, stacklevel=2)
    if sample_dt is not None and not sample_dt > 0:
        raise FxflexError(f"sample_dt: must be > 0, got {sample_dt!r}")
    sampled = out is not None or history or on_sample is not None
    sample_every = sample_steps(step, t_end, sample_dt)
    if not sampled:
        sample_every = nsteps       # nothing reads the samples: only the final deflection
    writer = None
    if out is not None:
        check_paths(comm, [Output("out", str(out))])
        implicit = {"rho_inf": rho_inf} if rho_inf is not None else {}
        meta = envelope(scene, method=form.method, integrator=integrator, dt_s=step, **implicit,
                        t_end_s=t_end, dof=form.dof, force_eval=form.force_eval,
                        mass=form.mass_kind)
        writer = SeriesWriter(str(out), meta, [*SERIES_COLUMNS, *form.extra_columns],
                              enabled=comm.rank == 0, flag="out")

    def sample(t, tip, extras, q=None):
        if writer is not None:
            writer.write((t, *tip, *extras))
        if on_sample is not None:
            on_sample(t, tip, extras, q)

    bar = (Progress(nsteps, f"{form.method} {integrator} dt={step:.3g}",
                    enabled=comm.rank == 0) if progress else None)
    try:
        res = simulate(form, integrator, step, t_end, sample_every=sample_every,
                       on_sample=sample if sampled else None, progress=bar,
                       keep_history=history, extras=writer is not None or history,
                       rho_inf=rho_inf)
    except BaseException as exc:
        if writer is not None:
            writer.close_after(exc)
        raise
    if writer is not None:
        writer.close()
    if bar is not None:
        bar.close(f"{res.steps} steps")
    if res.diverged is not None and diagnose:
        from fxflex.time import diagnose as cause_of
        res.diverged = {**res.diverged, **cause_of(form, integrator, step, res)}
    if integrator == "ab2" and res.diverged is None and not res.interrupted:
        note = ab2_warning(form, step, res.t)
        if note:
            _warnings.warn(note, stacklevel=2)
    return res


def modes(form: Formulation, n: int = 10) -> Modes:
    """The ``n`` lowest modes of the motion about the rotating steady state (SPEC section 6),
    one per conjugate pair, lowest frequency first, as ``fxflex modes`` reports them
    (:func:`fxflex.analysis.modes.modes_of`): ``m.frequencies_hz``, ``m.growth_rates`` (1/s),
    ``m.labels`` (axial, in-plane, out-of-plane, torsion), ``m.stable``, ``m.warnings``,
    ``m.to_dict()`` (the JSON fields)."""
    from fxflex.analysis.modes import modes_of

    if n < 1:
        raise FxflexError(f"n: must be >= 1, got {n}")
    return modes_of(form, n)


def campbell(method: str, speeds: Sequence[float], scene: Scene | None = None, n: int = 10,
             comm=None, *, progress: Callable | None = None, track: bool = True,
             **options) -> CampbellData:
    """Modes at each of ``speeds`` (rpm, increasing), followed from speed to speed by MAC: the
    data of ``fxflex modes --campbell`` without its files
    (:func:`fxflex.analysis.modes.plot_campbell` draws them as the CLI's PNG).
    ``data.modes[i]`` are the :func:`modes` at ``speeds[i]``,
    ``data.table()`` the frequencies and growth rates as arrays, ``data.unstable_ranges()`` the
    speed ranges with an unstable equilibrium, ``data.tracking`` the tracked branches
    (:class:`fxflex.analysis.tracking.Tracking`: ``rpm`` with the speeds refined where a MAC fell
    below 0.9, ``branches`` with their labels, frequencies, growth rates, damping ratios and MAC,
    ``resonances``, ``to_dict()`` the CLI's JSON fields). ``track=False``: the modes only, sorted
    by frequency at each speed (any order of speeds, ``data.tracking`` None). FFRF and GCMS share
    one build's mesh and clamped modes across speeds. ``progress(i, modes)`` is called after
    each of ``speeds``; ``options`` as for :func:`build`."""
    import numpy as np

    from fxflex.analysis.modes import CampbellData, campbell_tracked, check_speeds, speed_builder
    from fxflex.analysis.modes import campbell as _campbell
    from fxflex.formulation import check_options

    scene = scene if scene is not None else Scene()
    opts = _options(options)
    check_options(method, opts)
    if n < 1:
        raise FxflexError(f"n: must be >= 1, got {n}")
    rpm = np.asarray(speeds, dtype=float)
    if rpm.ndim != 1 or rpm.size == 0:
        raise FxflexError(f"speeds: expected a non-empty list of speeds (rpm), got {speeds!r}")
    if track and np.any(np.diff(rpm) <= 0.0):
        raise FxflexError(f"speeds: the branches are followed in increasing speed, got "
                          f"{rpm.tolist()}; allowed: increasing speeds, or track=False")
    check_speeds(scene, rpm)
    build_at = speed_builder(method, scene, _comm(comm), opts)
    if not track:
        return CampbellData(method, rpm, _campbell(build_at, rpm, n, progress))
    done: list = []

    def step(sample):               # the requested speeds come in order, refined ones between
        if sample.requested:
            done.append(sample.modes)
            if progress is not None:
                progress(len(done) - 1, sample.modes)

    tracking = campbell_tracked(build_at, rpm, n, method, step)
    return CampbellData(method, rpm, done, tracking)


def compare(scene: Scene | None = None, methods: Iterable[str] | None = None,
            out_dir: str | None = None, comm=None, *, full: bool = False,
            progress: Callable[[str], None] | None = None, **windows) -> dict:
    """The paper's comparison (Sect. 4; ``fxflex compare``, :mod:`fxflex.analysis.compare`):
    every method of ``methods`` (default all) at the paper's speeds and damping, steady states,
    transients, the SPEC section 7 rows. Returns the dict ``results.json`` holds, plus
    ``"report"`` (the Markdown report); with ``out_dir`` the files are written there as each
    study finishes. ``full`` runs the paper's windows for TLF too (about 50 min);
    ``progress(line)`` receives progress lines; ``windows`` (``paper_window``, ``tlf_windows``)
    shorten the runs for a quick look."""
    from fxflex.analysis.compare import run_compare

    names = list(METHODS) if methods is None else list(methods)
    bad = [m for m in names if m not in METHODS]
    if bad or not names:
        raise FxflexError(f"methods: {', '.join(map(repr, bad)) or 'none given'} not a method; "
                          f"allowed: {' '.join(METHODS)}")
    return run_compare(scene if scene is not None else Scene(), names, out_dir, _comm(comm),
                       progress=progress, full=full, **windows)
