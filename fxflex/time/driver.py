"""One time loop for every formulation and integrator.

The loop samples the free-end deflection (and any extra outputs the formulation offers, e.g. the
drive torque), hands each sample to a callback (the CSV writer), shows progress and stops early
when the response diverges: a non-finite value or a deflection beyond ``limit``, or an implicit
step whose Newton iteration fails for good (:class:`~fxflex.time.implicit.NewtonFailure`).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from fxflex.time.implicit import NewtonFailure
from fxflex.time.schemes import make_scheme

__all__ = ["RunResult", "simulate", "divergence_limit"]


@dataclass
class RunResult:
    t: float                         # time reached (s)
    steps: int                       # steps taken
    tip: np.ndarray                  # deflection at t (m, O-XYZ)
    diverged: dict | None            # None, or {"time_s", "reason"}; the cause is diagnosed later
    wall_s: float                    # wall time of the loop
    samples: int = 0
    history: list = field(default_factory=list)   # (t, tip...) rows when keep_history
    stats: dict = field(default_factory=dict)     # the scheme's counters (implicit: Newton)


def divergence_limit(form) -> float:
    """Deflection beyond which a run counts as divergent: a quarter of the beam length, far past
    the small-deformation range of every formulation here."""
    return 0.25 * form.scene.geometry.length


def simulate(form, integrator: str, dt: float, t_end: float, *, sample_every: int = 1,
             on_sample=None, progress=None, limit: float | None = None, keep_history=False,
             t0: float = 0.0, state: tuple[np.ndarray, np.ndarray] | None = None,
             extras: bool = True, rho_inf: float | None = None,
             scheme_options: dict | None = None) -> RunResult:
    """Integrate ``form`` from t0 to t_end with step dt.

    on_sample(t, tip, extras, q) is called at step 0, every ``sample_every`` steps and at the end
    (q is the live state array: copy it to keep it). The formulation's extra outputs (e.g. the
    drive torque, which costs an acceleration evaluation) are computed only when someone reads
    them: ``extras`` is true and there is an ``on_sample`` or a history; else the callback gets ().
    ``rho_inf`` and ``scheme_options`` (tol, max_iter, max_halvings) configure
    ``generalized-alpha``.
    """
    if dt <= 0 or not math.isfinite(dt):
        raise ValueError("dt must be positive")
    limit = divergence_limit(form) if limit is None else limit
    nsteps = max(int(round((t_end - t0) / dt)), 1)
    q, v = form.initial_state() if state is None else state
    wanted = extras and (on_sample is not None or keep_history)
    extras = getattr(form, "extras", None) if wanted else None
    history = []

    def sample(k: int, t: float | None = None) -> np.ndarray:
        t = t0 + k * dt if t is None else t
        tip = form.tip(t, q)
        ex = extras(t, q, v) if extras is not None else ()
        if keep_history:
            history.append((t, *tip, *ex))
        if on_sample is not None:
            on_sample(t, tip, ex, q)
        return tip

    check_every = max(1, min(sample_every, 100))
    options = dict(scheme_options or {})
    if rho_inf is not None:
        options["rho_inf"] = rho_inf
    scheme = make_scheme(integrator, **options)
    wall0 = time.perf_counter()
    diverged = None
    tip = sample(0)
    nsamples = 1
    k = 1
    try:
        scheme.start(form, t0, dt, q, v)
    except NewtonFailure as exc:
        return _failed(exc, form, sample, scheme, 0, wall0, nsamples, history)
    while True:
        last = k == nsteps
        sample_now = last or k % sample_every == 0
        if sample_now or k % check_every == 0:
            if sample_now:
                tip = sample(k)
                nsamples += 1
            else:
                tip = form.tip(t0 + k * dt, q)
            if not np.all(np.isfinite(tip)) or np.max(np.abs(tip)) > limit:
                if not sample_now:
                    tip = sample(k)
                    nsamples += 1
                reason = ("non-finite deflection" if not np.all(np.isfinite(tip)) else
                          f"deflection {np.max(np.abs(tip)):.3g} m beyond {limit:.3g} m")
                diverged = {"time_s": t0 + k * dt, "reason": reason}
                break
            if progress is not None:
                progress.update(k, f"t={t0 + k * dt:.4g} s")
        if last:
            break
        try:
            scheme.step(form, t0 + k * dt, dt, q, v)
        except NewtonFailure as exc:
            return _failed(exc, form, sample, scheme, k, wall0, nsamples, history)
        k += 1
    wall = time.perf_counter() - wall0
    return RunResult(t=t0 + k * dt, steps=k, tip=np.asarray(tip, dtype=float), diverged=diverged,
                     wall_s=wall, samples=nsamples, history=history,
                     stats=dict(getattr(scheme, "stats", {})))


def _failed(exc: NewtonFailure, form, sample, scheme, steps: int, wall0: float, nsamples: int,
            history: list) -> RunResult:
    """The run stops where an implicit step failed for good: the last converged state is sampled
    (its time may lie between output times when the step had been cut)."""
    tip = sample(steps, exc.reached_s)
    return RunResult(t=exc.reached_s, steps=steps, tip=np.asarray(tip, dtype=float),
                     diverged={"time_s": exc.time_s, "reason": str(exc)},
                     wall_s=time.perf_counter() - wall0, samples=nsamples + 1, history=history,
                     stats=dict(getattr(scheme, "stats", {})))
