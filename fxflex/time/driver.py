"""One time loop for every formulation and integrator.

The loop samples the free-end deflection (and any extra outputs the formulation offers, e.g. the
drive torque), hands each sample to a callback (the CSV writer), shows progress, writes
checkpoints, and stops early when the run diverges. Divergence is checked every
``min(sample_every, 100)`` steps and at every sample:

- a NaN or inf anywhere in the state (q and v, through their global sum of squares, which is also
  where an overflow shows first), in the deflection or in an extra output;
- a deflection beyond the method's range, ``divergence_limit``: a quarter of the length for the
  small-deformation models, twice the length for the geometrically exact ones;
- an implicit step whose Newton iteration fails for good
  (:class:`~fxflex.time.generalized_alpha.NewtonFailure`): the run ends at the last converged state.

A sample is written only once it has passed these checks, so no output ever holds a NaN; the
result then carries the last finite deflection. The deflection magnitude at the last
``GROWTH_POINTS`` checks is kept (in a preallocated ring) so that the diagnosis can measure the
growth rate of a divergence.

A checkpoint is written only after its step passed these checks, so no checkpoint holds a NaN.
An interrupt (Ctrl-C, SIGINT) in a run on one process ends the loop like a divergence: the result
carries the last checked deflection and ``interrupted``; on several ranks it propagates (each
rank may be at a different step, so none can report a common state).

The step must divide the time span (``t_end - t0``) so that the run ends at t_end:
:func:`step_to_end` gives the largest such step not above the one asked for.

Resuming: ``resume`` restarts the loop at step ``Resume.step`` from the state and the scheme's
history that ``on_checkpoint`` was given at that step. Times are ``t0 + k dt`` with the global
step index k in both runs, so a resumed run takes bit for bit the steps of an uninterrupted one.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from fxflex.errors import FxflexError
from fxflex.formulation import SMALL_DEFORMATION_RANGE, default_integration
from fxflex.time.generalized_alpha import DEFAULT_RHO_INF, NewtonFailure
from fxflex.time.schemes import make_scheme

__all__ = ["RunResult", "Resume", "simulate", "divergence_limit", "step_to_end", "GROWTH_POINTS",
           "Integration", "plan_integration", "sample_steps", "CLI_NAMES",
           "SMALL_DEFORMATION_RANGE"]

#: deflections checked for the measured growth rate of a divergence
GROWTH_POINTS = 512


@dataclass
class RunResult:
    t: float                         # time of ``tip`` (s): the last finite check
    steps: int                       # steps taken (global index of the last step)
    tip: np.ndarray                  # deflection at t (m, O-XYZ), always finite
    diverged: dict | None            # None, or {"time_s", "reason", "kind"}; cause diagnosed later
    wall_s: float                    # wall time of the loop
    samples: int = 0                 # samples handed to on_sample, counting those before a resume
    history: list = field(default_factory=list)   # (t, tip..., extras...) rows when keep_history
    growth: np.ndarray | None = None  # (m, 2) rows (t, max |tip|) of the last checks, oldest first
    stats: dict = field(default_factory=dict)     # the scheme's counters (implicit: Newton)
    interrupted: bool = False        # stopped by SIGINT at step ``steps`` (one process only)
    adaptive: dict | None = None     # step control (fxflex.time.adaptive): clock and estimate


@dataclass
class Resume:
    """Where a checkpointed run continues: the global step and the scheme's history arrays at
    it (``state_arrays()``), and how many samples were written up to it."""

    step: int
    arrays: dict
    samples: int


def divergence_limit(form) -> float:
    """Deflection beyond which a run stops (m): ``form.deflection_range`` (default 0.25) times the
    beam length. A quarter of the length is far past the range of the linear and von Karman
    models; the geometrically exact ones (TLF, ANCF) set 2: the tip of an inextensible beam stays
    within 2 L of its rigidly rotated position, so beyond it only a run out of control goes."""
    return form.deflection_range * form.scene.geometry.length


def step_to_end(span: float, dt: float, rtol: float = 1e-9) -> tuple[float, int]:
    """(step, count): ``dt`` itself when a whole number of steps spans ``span`` (to ``rtol``:
    0.01 / 1e-5 is 999.9999999999999 in floating point), else the largest step below it that
    does, span / ceil(span / dt), so that the run ends exactly at its end time."""
    ratio = span / dt
    count = max(round(ratio), 1)
    if abs(count - ratio) <= rtol * max(ratio, 1.0):
        return dt, count
    count = math.ceil(ratio)
    return span / count, count


#: how a run's options are named in messages: the CLI's flags (the API passes its argument names)
CLI_NAMES = {"dt": "--dt", "t_end": "--t-end", "rho_inf": "--rho-inf",
             "implicit": "--integrator generalized-alpha"}


@dataclass(frozen=True)
class Integration:
    """A run's integration, resolved and checked (:func:`plan_integration`)."""

    integrator: str
    dt: float                   # the step, shortened to end exactly at t_end
    steps: int
    rho_inf: float | None       # generalized-alpha only
    note: str | None            # said when the given step was shortened


def plan_integration(method: str, integrator: str | None, dt: float | None, t_end: float,
                     rho_inf: float | None, rpm: float, names: dict = CLI_NAMES) -> Integration:
    """The paper's integration unless given (:func:`fxflex.formulation.default_integration`), the
    step shortened to end exactly at ``t_end`` (:func:`step_to_end`; ``note`` says so), rho_inf
    for generalized-alpha only (default DEFAULT_RHO_INF, in [0, 1]); what ``fxflex run`` and
    ``fxflex.run`` both do, each naming the options its own way (``names``)."""
    integrator, asked = default_integration(method, integrator, dt, rpm)
    step, steps = step_to_end(t_end, asked)
    note = None
    if dt is not None and step != asked:
        note = (f"{names['dt']} {asked:g} s does not divide {names['t_end']} {t_end:g} s: the step "
                f"was shortened to {step:.9g} s ({steps} steps) to end at t_end")
    if integrator == "generalized-alpha":
        rho_inf = DEFAULT_RHO_INF if rho_inf is None else rho_inf
        if not 0.0 <= rho_inf <= 1.0:
            raise FxflexError(f"{names['rho_inf']}: must lie in [0, 1] (spectral radius at "
                              f"infinity), got {rho_inf:g}")
    elif rho_inf is not None:
        raise FxflexError(f"{names['rho_inf']}: only applies to {names['implicit']} (the "
                          f"integrator is {integrator})")
    return Integration(integrator, step, steps, rho_inf, note)


def sample_steps(dt: float, t_end: float, sample_dt: float | None) -> int:
    """Steps between samples: ``sample_dt`` (default: the step, or t_end / 20000 when larger,
    so that a series holds at most about 20000 rows), rounded to whole steps."""
    return max(1, int(round((sample_dt or max(dt, t_end / 20000)) / dt)))


def simulate(form, integrator: str, dt: float, t_end: float, *, sample_every: int = 1,
             on_sample=None, progress=None, limit: float | None = None, keep_history=False,
             t0: float = 0.0, state: tuple[np.ndarray, np.ndarray] | None = None,
             extras: bool = True, rho_inf: float | None = None,
             scheme_options: dict | None = None, checkpoint_every: int = 0, on_checkpoint=None,
             resume: Resume | None = None) -> RunResult:
    """Integrate ``form`` from t0 to t_end with step dt.

    on_sample(t, tip, extras, q) is called at step 0, every ``sample_every`` steps and at the end
    (q is the live state array: copy it to keep it). The formulation's extra outputs (e.g. the
    drive torque, which costs an acceleration evaluation) are computed only when someone reads
    them: ``extras`` is true and there is an ``on_sample`` or a history; else the callback gets ().
    ``rho_inf`` and ``scheme_options`` (tol, max_iter, max_halvings) configure
    ``generalized-alpha``. on_checkpoint(step, q, v, arrays, samples) is called every
    ``checkpoint_every`` steps (not at the last), after that step's sample and checks. With
    ``resume`` the loop continues after step ``resume.step`` from ``state``, which must be
    finite. ``t_end - t0`` should be a whole number of steps (:func:`step_to_end`); otherwise the
    run ends at the nearest multiple.
    """
    if dt <= 0 or not math.isfinite(dt):
        raise ValueError("dt must be positive")
    where = ""
    if limit is None:
        limit = divergence_limit(form)
        where = f" ({limit / form.scene.geometry.length:g} of the length)"
    nsteps = max(int(round((t_end - t0) / dt)), 1)
    q, v = form.initial_state() if state is None else state
    wanted = extras and (on_sample is not None or keep_history)
    extras = form.extras if wanted else None
    comm = form.comm
    distributed = comm.size > 1
    history = []
    ring = np.zeros((GROWTH_POINTS, 2))
    last_tip = np.zeros(3)
    counters = {"checks": 0, "samples": 0 if resume is None else resume.samples}
    last = {"t": t0}
    diverged = None
    interrupted = False

    def check(k: int, sample_now: bool, t: float | None = None) -> dict | None:
        """Check the state at step k (or time t) and write its sample; the reason if it
        diverged."""
        t = t0 + k * dt if t is None else t
        norm2 = float(np.dot(q, q) + np.dot(v, v))
        if distributed:
            norm2 = comm.allreduce(norm2)
        if not math.isfinite(norm2):
            return {"time_s": t, "kind": "non-finite",
                    "reason": "NaN or inf in the state (or a state beyond 1e154)"}
        tip = form.tip(t, q)
        if not np.all(np.isfinite(tip)):
            return {"time_s": t, "kind": "non-finite", "reason": "non-finite deflection"}
        amp = float(np.max(np.abs(tip)))
        ring[counters["checks"] % GROWTH_POINTS] = t, amp
        counters["checks"] += 1
        out = None
        if amp > limit:
            out = {"time_s": t, "kind": "range",
                   "reason": f"deflection {amp:.4g} m beyond the limit {limit:.4g} m{where}"}
            sample_now = True
        if sample_now:
            ex = extras(t, q, v) if extras is not None else ()
            if not all(math.isfinite(x) for x in ex):
                return {"time_s": t, "kind": "non-finite", "reason": "non-finite extra output"}
            if keep_history:
                history.append((t, *tip, *ex))
            if on_sample is not None:
                on_sample(t, tip, ex, q)
            counters["samples"] += 1
        last_tip[:] = tip
        last["t"] = t
        return out

    options = dict(scheme_options or {})
    if rho_inf is not None:
        options["rho_inf"] = rho_inf
    scheme = make_scheme(integrator, **options)
    wall0 = time.perf_counter()
    # a run that blows up overflows between two checks; the check reports it, numpy need not
    with np.errstate(over="ignore", invalid="ignore"):
        if resume is None:
            k = 0
            diverged = check(0, True)
            if diverged is None:
                try:
                    scheme.start(form, t0, dt, q, v)
                except NewtonFailure as exc:
                    diverged = _newton_stop(exc, check, last, k)
                k = 1
            fresh = True
        else:
            k = resume.step
            last["t"] = t0 + k * dt
            last_tip[:] = form.tip(last["t"], q)
            if not (np.all(np.isfinite(q)) and np.all(np.isfinite(v))
                    and np.all(np.isfinite(last_tip))):
                raise ValueError("simulate: the state to resume from holds NaN or inf")
            scheme.resume(form, t0 + k * dt, dt, q, v, resume.arrays)
            fresh = False                 # step k was checked and sampled before the checkpoint
        check_every = max(1, min(sample_every, 100))
        try:
            while diverged is None:
                final = k >= nsteps
                if fresh:
                    sample_now = final or k % sample_every == 0
                    save = (checkpoint_every and on_checkpoint is not None and not final
                            and k % checkpoint_every == 0)
                    if sample_now or save or k % check_every == 0:
                        diverged = check(k, sample_now)
                        if diverged is not None:
                            break
                        if progress is not None:
                            progress.update(k, f"t={t0 + k * dt:.4g} s")
                    if save:
                        on_checkpoint(k, q, v, scheme.state_arrays(), counters["samples"])
                fresh = True
                if final:
                    break
                try:
                    scheme.step(form, t0 + k * dt, dt, q, v)
                except NewtonFailure as exc:
                    diverged = _newton_stop(exc, check, last, k)
                    break
                k += 1
        except KeyboardInterrupt:
            if distributed:
                raise
            interrupted = True
    wall = time.perf_counter() - wall0
    n = min(counters["checks"], GROWTH_POINTS)
    order = (np.arange(counters["checks"] - n, counters["checks"]) % GROWTH_POINTS)
    return RunResult(t=last["t"], steps=k, tip=last_tip.copy(), diverged=diverged, wall_s=wall,
                     samples=counters["samples"], history=history, growth=ring[order].copy(),
                     stats=dict(getattr(scheme, "stats", {})), interrupted=interrupted)


def _newton_stop(exc: NewtonFailure, check, last: dict, k: int) -> dict:
    """An implicit step failed for good: (q, v) hold the last converged state, at
    ``exc.reached_s`` (between output times when the step had been cut); it is checked and
    written unless it is the state already checked last."""
    stop = {"time_s": exc.time_s, "kind": "newton", "reason": str(exc)}
    if exc.reached_s > last["t"]:
        return check(k, True, t=exc.reached_s) or stop
    return stop
