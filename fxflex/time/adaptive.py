"""Adaptive generalised-alpha: a local error estimate per step and step-size control, so that the
time-integration error of the tip history stays below EPS of its peak (``fxflex run --tol``,
issue 15, SPEC section 9).

Local error (Zienkiewicz & Xie 1991). The Newmark displacement update of
:mod:`~fxflex.time.generalized_alpha`, q_{n+1} = q_n + h v_n + h^2 (1/2 - beta) a_n
+ h^2 beta a_{n+1}, differs from the Taylor series of the exact motion, q_n + h v_n + h^2 q''/2
+ h^3 q'''/6 + O(h^4), by h^2 beta (a_{n+1} - a_n) - h^3 q'''/6, and h q''' = a_{n+1} - a_n
+ O(h^2), so the displacement error of one step is

    e_{n+1} = h^2 (beta - 1/6) (a_{n+1} - a_n)

to O(h^4). On an oscillation of frequency w and amplitude A this is A (beta - 1/6) (w h)^3: the
phase error of one step (the trapezoidal rule's period error (w h)^2 / 12 per radian). It is
measured where the result is read: on the tip deflection, |tip(q + e) - tip(q)| (the rigid
rotation removed; prescribed root coordinates reset by ``constrain``, so e = 0 there).

Error per unit step. Phase errors add up over the steps rather than being damped (the physical
damping of these blades is c/rho = 0.13 1/s), so a run of N steps each held to EPS would end
N EPS off. Each step's error is measured against its share of the span,

    r_n = |e_tip,n| / s_n * (T / h_n),   T = t_end - t0,

and the run against its budget: the steps accepted up to t hold

    sum_n |e_tip,n| / s_n = sum_n r_n h_n / T <= EPS (t - t0) / T,

so that the whole run's sum stays below EPS s. The scale s_n is the largest |tip| so far, not
below ``scale`` (the caller passes the equilibrium's |tip| at the final speed): the peak of the
history is not known in advance, and the first steps, where the tip is still near zero, would
otherwise have no scale at all. The estimate reported at the end (``error_estimate``) is
sum_n |e_tip,n| per component over the peak |tip| of the history.

Step control. r is of order h^2 (e ~ h^3, divided by h), so the step that would give r = EPS is
h (EPS / r)^(1/2). A step is accepted when the budget above allows it and r <= R_CAP EPS;
otherwise the state and the scheme's history are restored and the step is redone with h f,
f = SAFETY (EPS / r)^(1/2) clamped to [0.2, 0.9], and the step after a rejection does not grow.
After an accepted step the next one is h f with f = SAFETY (EPS / r~)^(1/2) clamped to [0.2, 2],
where r~ is r smoothed over the past steps (r~ = SMOOTHING r~ (h / h~)^2 + (1 - SMOOTHING) r, the
old value carried to the new step size; a rejected step's r replaces it). Why a budget and not
r <= EPS at every step: on a vibrating blade e follows a_{n+1} - a_n, which swings with the
phase of the vibration, so r at a fixed step swings by 5-10x from one step to the next. Holding
every step to EPS then rejected a third of the steps (ANCF 10 elements, 1000 rpm, 10 ms, EPS
1e-3: 849 of 3178), and setting each step from the last r alone changed the step by more than
REUSE_RATIO at almost every other step, each change a new factorisation of S (1287). The budget
lets a step whose r swings above EPS pass on what the steps before it left unspent (R_CAP bounds
one step's excess: a step at most twice the one that would give r = EPS), and the smoothing
sets the step from the average r over about ten steps, the average the budget is spent at: 2
rejected steps, 269 factorisations, 2.5 s instead of 6.2 s, true error 4.3e-4 (estimate 6.0e-4,
was 4.7e-4 and 7.4e-4); TLF Q2 16x2x2 the same run: 1 rejected, 92 factorisations (1751), 8.5 s
instead of 50 s, true error 2.3e-4 (estimate 5.8e-4). S, the modified Newton matrix, depends on
h: a factor serves steps within REUSE_RATIO of its own, and the renewal rule of
:mod:`~fxflex.time.generalized_alpha` (iterations against a factorisation, both measured)
decides when a new one pays. A step of another size also costs a second Newton iteration (the
contraction of the factor on it is measured, not trusted), so a step factor f within HOLD =
[0.7, 1.4] keeps the step: a factor made for it serves, and the iteration converges in one
(the budget takes the r that a held step leaves up to 2x away from the target). TLF Q2
16x2x2, 1000 rpm, 10 ms, 1e-3: 2.7 -> 1.1 iterations a step, 92 -> 15 factorisations, 8.8 s ->
2.7 s (a fixed 1 us run that meets EPS: 9.4 s), true error 3.9e-4 (estimate 6.6e-4); LEBB,
FFRF, GCMS, ANCF likewise (docs/tolerance.md). A step whose Newton iteration fails (the scheme
runs without halvings here) counts as a rejection with f = 1/4. The step never exceeds
``h_max`` (default T / 50: the estimate assumes the step resolves the response), except the
last, which takes up to 1.1 h_max to land on t_end, and a step below ``H_FLOOR`` T stops the
run as a Newton failure.

The scale and the peak. The budget holds sum |e_tip| / s_n with s_n = max(peak so far, scale),
so the reported estimate (over the history's peak) is within EPS whenever the peak reaches
``scale``; a run that ends before it does (a short run, a slow spin-up) can report more than
EPS, and ``fxflex run`` then says so in a warning.

Newton's share. The step's modified Newton iteration stops with a remaining error dq in q (its
own test: eta |dq| <= tol |q_{n+1} - q_n|, tol = 1e-5), and a_{n+1} carries dq / (h^2 beta), so
e carries (beta - 1/6) / beta KAPPA dq = 0.8 dq at rho_inf = 0.9: Newton's error enters the
estimate one to one. Relative to the step's increment that is harmless in a floating frame, but
in absolute coordinates (TLF, ANCF) the increment is the rigid rotation's, Omega R h for every
node (100 m/s at the default blade's tip at 1000 rpm), so 1e-5 of it is tens of times the local
error EPS s h / T that the controller allows, and the controller shrank the step to chase
Newton's error: TLF Q2 16x2x2 at 1000 rpm, 2 ms at EPS 1e-3 took 2423 steps with tol = 1e-5
and 247 with tol = 1e-9. So the driver also bounds Newton's remaining error (the Euclidean norm
over the whole state, which bounds the tip's in nodal coordinates; for the mass-normalised modal
amplitudes of FFRF / GCMS it bounds it for a blade above a few kilograms, and there the
increment is small anyway) by NEWTON_SHARE of the error it allows the step,
``GeneralizedAlpha.atol`` = NEWTON_SHARE EPS s h / T: the same run then takes 272 steps, 2.4
iterations a step instead of 2.0. Newton's test never asks for less than q's round-off,
1e-13 |q| (|q| is tens of metres in absolute coordinates once the blade has turned), so there a
floor of about 0.8e-13 |q| / s T / h remains in r, which grows as the step shrinks: a small
enough EPS would drive the step to H_FLOOR (the run then stops as a Newton failure). Not reached
in the runs measured: TLF Q2 16x2x2, 10 ms at 1000 rpm, completes at EPS 1e-4 and 1e-5 (8637 and
27449 steps, the ratio sqrt(10) of an h^2 error; 2.0 iterations a step).

Sampling. Rows are written at t0 + k sample_dt and at t_end whatever the steps: inside a step,
q and v come from the cubic Hermite interpolant of (q_n, v_n, q_{n+1}, v_{n+1}) (error O(h^4),
below the scheme's O(h^3) local error), with the prescribed coordinates set by ``constrain``.
The last step lands on t_end.

Calibration. The sum of the local estimates undershoots the true error of the tip history:
with KAPPA = 1 the true error (against a fixed-step run of 0.5-1 us) was 1.4-2.2 times the sum
for LEBB, NEBB and ANCF at 0, 1000 and 5000 rpm over 10 ms, and ended at 1.0-1.4 EPS; the ratio
grows slowly with the length of the run (1.2 at 0.5 ms, 2.0 at 10 ms on LEBB: the local phase
errors' cross terms). KAPPA = 2 scales the estimate by that measured factor; the true error
then ended at 0.6-0.8 EPS (docs/tolerance.md); over 50 ms (six cases, Richardson references)
the true error was 0.5-0.8 of the estimate, within EPS, the steps growing as T^(3/2).

Checkpoints and resume. The controller's state (:class:`Clock`: time, next step, peak, counters,
accumulated estimate, budget spent, smoothed r) goes into the checkpoint with the state and the
scheme's history, so a resumed run tries the same next step as the uninterrupted one. Both
agree to the Newton tolerance, not bit for bit (the resumed run starts with a fresh factor, as
for fixed steps); the scheme's counters are carried over (:attr:`Clock.counts`).
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field

import numpy as np

from fxflex.time.driver import GROWTH_POINTS, RunResult, divergence_limit
from fxflex.time.generalized_alpha import GeneralizedAlpha, NewtonFailure

__all__ = ["Clock", "simulate_adaptive", "explicit_step", "SAFETY", "KAPPA", "GROW_MAX",
           "SHRINK_MIN", "R_CAP", "SMOOTHING", "HOLD", "NEWTON_SHARE", "H_FLOOR",
           "EXPLICIT_MARGIN", "MAX_EXPLICIT_STEPS", "local_error_factor"]

SAFETY = 0.9
#: the sum of the local displacement errors against the error of the history it leaves
#: (module docstring, "Calibration")
KAPPA = 2.0
GROW_MAX, SHRINK_MIN = 2.0, 0.2
#: the step cut after a Newton failure
NEWTON_CUT = 0.25
#: a Newton factor serves steps within this ratio of its own (generalized_alpha.reuse_ratio)
REUSE_RATIO = 1.25
#: a step is accepted when r <= R_CAP EPS and the budget allows it (module docstring)
R_CAP = 4.0
#: weight of the past in the smoothed r that sets the next step (module docstring)
SMOOTHING = 0.9
#: a step factor within these bounds keeps the step (module docstring)
HOLD = (0.7, 1.4)
#: Newton's remaining error in a step, at most this share of the local error allowed to it
NEWTON_SHARE = 0.1
#: a step below this times the span stops the run
H_FLOOR = 1e-9
#: default largest step, as a fraction of the span
H_MAX_SHARE = 1.0 / 50.0


@dataclass
class Clock:
    """The controller's state after an accepted step (all a resume needs besides q, v and the
    scheme's history)."""

    t: float                  # time reached (s)
    h: float                  # the next step to try (s)
    peak: float               # largest |tip| so far (m)
    accepted: int = 0
    rejected: int = 0
    samples: int = 0          # rows written (the next is row ``samples``)
    error_m: list = field(default_factory=lambda: [0.0, 0.0, 0.0])  # sum |e_tip| per component
    h_min: float = math.inf
    h_max: float = 0.0
    factor_changes: int = 0   # steps whose size differed from the previous one
    newton_failures: int = 0  # of the rejected steps, those whose Newton iteration failed
    used: float | None = 0.0  # sum over the accepted steps of |e_tip| / s (the error budget spent)
    r_smooth: float = 0.0     # the smoothed r (0: none yet) ...
    h_smooth: float = 1.0     # ... at this step size (s)
    #: the scheme's counters (Newton iterations, factorisations, ...) up to this step: a
    #: resumed run's include the runs before it, as its steps do
    counts: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        out = asdict(self)
        out["h_min"] = None if math.isinf(self.h_min) else self.h_min
        return out

    @classmethod
    def from_dict(cls, d: dict) -> "Clock":
        """A clock from :meth:`to_dict`; ``used`` is None when the checkpoint predates the
        budget (:func:`simulate_adaptive` then counts the budget as spent up to its time)."""
        d = dict(d)
        d["h_min"] = math.inf if d.get("h_min") is None else d["h_min"]
        d.setdefault("used", None)
        return cls(**d)


def local_error_factor(rho_inf: float) -> float:
    """beta - 1/6 of generalised-alpha at rho_inf (module docstring)."""
    return GeneralizedAlpha(rho_inf).beta - 1.0 / 6.0


def sample_times(t0: float, t_end: float, sample_dt: float) -> int:
    """Rows of a run: t0 + k sample_dt below t_end (to 1e-9 of the step), then t_end."""
    return int(math.ceil((t_end - t0) / sample_dt - 1e-9)) + 1


def simulate_adaptive(form, eps: float, t_end: float, *, h0: float, scale: float,
                      rho_inf: float, sample_dt: float, on_sample=None, progress=None,
                      limit: float | None = None, keep_history: bool = False,
                      extras: bool = True, t0: float = 0.0,
                      state: tuple[np.ndarray, np.ndarray] | None = None,
                      clock: Clock | None = None, arrays: dict | None = None,
                      h_max: float | None = None, checkpoint_every: int = 0,
                      checkpoint_dt: float | None = None, on_checkpoint=None,
                      scheme_options: dict | None = None) -> RunResult:
    """Integrate ``form`` from t0 to t_end with generalised-alpha under step control to ``eps``
    (module docstring). ``on_sample(t, tip, extras, q)`` as for :func:`~fxflex.time.simulate`,
    at the sample times. ``clock`` and ``arrays`` (the scheme's history) with ``state`` resume a
    checkpointed run. ``on_checkpoint(step, q, v, arrays, samples, clock=dict)`` is called after
    every ``checkpoint_every`` accepted steps, or, without it, at the first accepted step past
    each multiple of ``checkpoint_dt``, never at the last. ``RunResult.adaptive`` holds the
    final :class:`Clock` as a dict with the per-component estimate ``error_estimate``."""
    span = t_end - t0
    if not (span > 0 and h0 > 0 and math.isfinite(h0) and eps > 0 and sample_dt > 0):
        raise ValueError("simulate_adaptive: needs t_end > t0, h0 > 0, eps > 0, sample_dt > 0")
    h_max = span * H_MAX_SHARE if h_max is None else h_max
    if limit is None:
        limit = divergence_limit(form)
    q, v = form.initial_state() if state is None else state
    n = q.size
    comm = form.comm
    distributed = comm.size > 1
    options = {"max_halvings": 0, "reuse_ratio": REUSE_RATIO, **(scheme_options or {})}
    scheme = GeneralizedAlpha(rho_inf, **options)
    c_err = KAPPA * (scheme.beta - 1.0 / 6.0)
    wanted = extras and (on_sample is not None or keep_history)
    extras_fn = form.extras if wanted else None
    rows = sample_times(t0, t_end, sample_dt)
    # work arrays: the state before the step (restored on rejection), the error probe, the
    # interpolant
    q_old, v_old, qdd_old, a_old = (np.empty(n) for _ in range(4))
    w_q, w_v, tmp = np.empty(n), np.empty(n), np.empty(n)
    history: list = []
    ring = np.zeros((GROWTH_POINTS, 2))
    checks = [0]
    diverged = None
    interrupted = False
    resumed = clock is not None
    if clock is None:
        clock = Clock(t=t0, h=min(h0, h_max), peak=0.0)
    scale = max(float(scale), 1e-9 * form.scene.geometry.length)

    def sample_time(k: int) -> float:
        return t_end if k == rows - 1 else t0 + k * sample_dt

    def emit(t: float, qs: np.ndarray, vs: np.ndarray, tip: np.ndarray) -> dict | None:
        ex = extras_fn(t, qs, vs) if extras_fn is not None else ()
        if not all(math.isfinite(x) for x in ex):
            return {"time_s": t, "kind": "non-finite", "reason": "non-finite extra output"}
        if keep_history:
            history.append((t, *tip, *ex))
        if on_sample is not None:
            on_sample(t, tip, ex, qs)
        clock.samples += 1
        return None

    def samples_in_step(t_a: float, h: float, tip_b: np.ndarray) -> dict | None:
        """Rows in (t_a, t_a + h]: Hermite interpolation of q and v between the two states."""
        t_b = t_a + h
        while clock.samples < rows:
            ts = sample_time(clock.samples)
            if ts > t_b + 1e-9 * h:
                break
            s = (ts - t_a) / h
            if s >= 1.0 - 1e-9:
                out = emit(ts, q, v, tip_b)
            else:
                s2, s3 = s * s, s * s * s
                h00, h10, h01, h11 = 2 * s3 - 3 * s2 + 1, s3 - 2 * s2 + s, -2 * s3 + 3 * s2, s3 - s2
                d00, d10, d01, d11 = (6 * s2 - 6 * s) / h, 3 * s2 - 4 * s + 1, \
                    (-6 * s2 + 6 * s) / h, 3 * s2 - 2 * s
                _combine(w_q, tmp, (q_old, h00), (v_old, h * h10), (q, h01), (v, h * h11))
                _combine(w_v, tmp, (q_old, d00), (v_old, d10), (q, d01), (v, d11))
                form.constrain(ts, w_q, w_v)
                out = emit(ts, w_q, w_v, form.tip(ts, w_q))
            if out is not None:
                return out
        return None

    def state_check(t: float, tip: np.ndarray) -> dict | None:
        norm2 = float(np.dot(q, q) + np.dot(v, v))
        if distributed:
            norm2 = comm.allreduce(norm2)
        if not math.isfinite(norm2):
            return {"time_s": t, "kind": "non-finite",
                    "reason": "NaN or inf in the state (or a state beyond 1e154)"}
        if not np.all(np.isfinite(tip)):
            return {"time_s": t, "kind": "non-finite", "reason": "non-finite deflection"}
        amp = float(np.max(np.abs(tip)))
        ring[checks[0] % GROWTH_POINTS] = t, amp
        checks[0] += 1
        if amp > limit:
            return {"time_s": t, "kind": "range",
                    "reason": f"deflection {amp:.4g} m beyond the limit {limit:.4g} m"}
        return None

    last_tip = form.tip(clock.t, q)
    # checkpoints by time: at the first step past each multiple of checkpoint_dt after t0
    next_ckpt = [t0 + (math.floor((clock.t - t0) / checkpoint_dt + 1e-9) + 1) * checkpoint_dt
                 if checkpoint_dt else math.inf]
    counted = dict(clock.counts)                            # by the runs before this one

    def carry() -> None:
        clock.counts = {k: counted.get(k, 0) + v for k, v in scheme.stats.items()}

    wall0 = time.perf_counter()
    h_prev = None
    just_rejected = False
    with np.errstate(over="ignore", invalid="ignore"):
        if not resumed:
            clock.peak = float(np.linalg.norm(last_tip))
            diverged = state_check(t0, last_tip) or emit(t0, q, v, last_tip)
            scheme.begin(form, t0, q, v)
        else:
            if not (np.all(np.isfinite(q)) and np.all(np.isfinite(v))):
                raise ValueError("simulate_adaptive: the state to resume from holds NaN or inf")
            scheme.resume(form, clock.t, clock.h, q, v, arrays)
            if clock.used is None:          # a checkpoint of the rule before the budget, which
                clock.used = eps * (clock.t - t0) / span    # held r <= EPS: at most this
        try:
            while diverged is None and clock.t < t_end:
                t = clock.t
                remaining = t_end - t
                h = min(clock.h, h_max)
                final = remaining <= 1.1 * h
                if final:
                    h = remaining
                np.copyto(q_old, q)
                np.copyto(v_old, v)
                np.copyto(qdd_old, scheme.qdd)
                np.copyto(a_old, scheme.a)
                # Newton's own error enters e one to one (module docstring, "Newton's share")
                scheme.atol = NEWTON_SHARE * eps * max(clock.peak, scale) * h / span
                try:
                    scheme.step(form, t, h, q, v)
                except NewtonFailure as exc:
                    _restore(scheme, q, v, q_old, v_old, qdd_old, a_old)
                    clock.rejected += 1
                    clock.newton_failures += 1
                    just_rejected = True
                    clock.h = h * NEWTON_CUT
                    if clock.h < H_FLOOR * span:
                        diverged = {"time_s": t + h, "kind": "newton",
                                    "reason": f"{exc}; the adaptive step fell below "
                                              f"{H_FLOOR:g} of the span"}
                    continue
                t1 = t_end if final else t + h
                # the local error, on the tip (module docstring)
                np.subtract(scheme.a, a_old, out=w_q)
                w_q *= c_err * h * h
                w_q += q
                np.copyto(w_v, v)
                form.constrain(t1, w_q, w_v)
                tip = form.tip(t1, q)
                e_tip = np.abs(form.tip(t1, w_q) - tip)
                if not np.all(np.isfinite(e_tip)):
                    e_tip[:] = math.inf
                peak = max(clock.peak, float(np.linalg.norm(tip))) if np.all(
                    np.isfinite(tip)) else clock.peak
                s = max(peak, scale)
                r = float(np.linalg.norm(e_tip)) / s * (span / h)
                share = r * h / span           # this step's error over the scale
                if r > R_CAP * eps or clock.used + share > eps * (t1 - t0) / span * (1 + 1e-12):
                    _restore(scheme, q, v, q_old, v_old, qdd_old, a_old)
                    clock.rejected += 1
                    just_rejected = True
                    clock.h = h * min(_growth(eps, r), SAFETY)
                    if math.isfinite(r):       # the next steps are set from this r on
                        clock.r_smooth, clock.h_smooth = r, h
                    if clock.h < H_FLOOR * span:
                        diverged = {"time_s": t1, "kind": "newton",
                                    "reason": f"the adaptive step fell below {H_FLOOR:g} of the "
                                              f"span (local error {r:.3g} of EPS {eps:g})"}
                    continue
                # accepted
                diverged = state_check(t1, tip)
                if diverged is not None:
                    break
                clock.accepted += 1
                if h_prev is not None and h != h_prev:
                    clock.factor_changes += 1
                h_prev = h
                clock.peak = peak
                clock.used += share
                for i in range(3):
                    clock.error_m[i] += float(e_tip[i])
                clock.h_min, clock.h_max = min(clock.h_min, h), max(clock.h_max, h)
                # the next step from the smoothed r, carried to this step's size (r ~ h^2)
                r_s = r if clock.r_smooth == 0.0 else (
                    SMOOTHING * clock.r_smooth * (h / clock.h_smooth) ** 2 + (1 - SMOOTHING) * r)
                clock.r_smooth, clock.h_smooth = r_s, h
                if not final:
                    f = _growth(eps, r_s)
                    if HOLD[0] <= f <= HOLD[1]:   # not worth a factorisation (docstring)
                        f = 1.0
                    clock.h = min(h * (min(f, 1.0) if just_rejected else f), h_max)
                just_rejected = False
                diverged = samples_in_step(t, h, tip)
                clock.t = t1
                last_tip = tip
                if diverged is not None:
                    break
                if progress is not None:
                    progress.update(int(1000 * (t1 - t0) / span), f"t={t1:.4g} s")
                save = on_checkpoint is not None and not final and (
                    (checkpoint_every and clock.accepted % checkpoint_every == 0)
                    or (not checkpoint_every and t1 >= next_ckpt[0]))
                if save:
                    while next_ckpt[0] <= t1:
                        next_ckpt[0] += checkpoint_dt or math.inf
                    carry()
                    on_checkpoint(clock.accepted, q, v, scheme.state_arrays(), clock.samples,
                                  clock=clock.to_dict())
        except KeyboardInterrupt:
            if distributed:
                raise
            interrupted = True
    wall = time.perf_counter() - wall0
    m = min(checks[0], GROWTH_POINTS)
    order = np.arange(checks[0] - m, checks[0]) % GROWTH_POINTS
    carry()
    info = clock.to_dict()
    peak = max(clock.peak, 1e-300)
    info["error_estimate"] = [x / peak for x in clock.error_m]
    info["eps"] = eps
    info["scale_m"] = scale
    stats = dict(clock.counts)
    stats["rejected"] = clock.rejected
    return RunResult(t=clock.t, steps=clock.accepted, tip=np.array(last_tip, dtype=float),
                     diverged=diverged, wall_s=wall, samples=clock.samples, history=history,
                     growth=ring[order].copy(), stats=stats, interrupted=interrupted,
                     adaptive=info)


def _growth(eps: float, r: float) -> float:
    """The step factor that brings r to SAFETY^2 EPS (r ~ h^2), within [SHRINK_MIN, GROW_MAX]."""
    if r == 0.0:
        return GROW_MAX
    if not math.isfinite(r):
        return SHRINK_MIN
    return min(GROW_MAX, max(SHRINK_MIN, SAFETY * math.sqrt(eps / r)))


def _combine(out: np.ndarray, tmp: np.ndarray, *terms) -> None:
    """out = sum of coefficient * array over ``terms``, without temporaries."""
    (a, c), *rest = terms
    np.multiply(a, c, out=out)
    for a, c in rest:
        np.multiply(a, c, out=tmp)
        out += tmp


def _restore(scheme, q, v, q_old, v_old, qdd_old, a_old) -> None:
    """Undo a step: the state and the scheme's history as they were before it."""
    np.copyto(q, q_old)
    np.copyto(v, v_old)
    np.copyto(scheme.qdd, qdd_old)
    np.copyto(scheme.a, a_old)


#: explicit schemes under --tol: the step is this share of the critical step
EXPLICIT_MARGIN = 0.9
#: explicit schemes under --tol: no run of more steps than this is started
MAX_EXPLICIT_STEPS = 2_000_000


def explicit_step(integrator: str, w_max: float | None, d: float, span: float,
                  eps: float) -> tuple[float, str]:
    """(step, rule) of an explicit scheme under ``--tol EPS``; FxflexError when EPS cannot be
    met at a bounded cost.

    An explicit step is bounded by stability, not by the accuracy of the response: central
    difference is stable up to h_c = 2 (sqrt(w^2 + d^2) - d) / w^2 on the top mode, and has no
    spurious growth below it; AB2 has no stability interval on an undamped mode and amplifies
    it like exp(w^4 h^3 t / 4), so its critical step is the one whose growth of the top mode over
    the run stays below 1 + EPS (:func:`~fxflex.time.step_stability.critical_step` with the span
    as the window and log(1 + EPS) as the threshold). The step is EXPLICIT_MARGIN of it (the top
    frequency is computed on the clamped body or about the equilibrium, and moves with the
    deformation by about sigma / E). Refused (one line) when that step needs more than
    MAX_EXPLICIT_STEPS steps: AB2's step shrinks as EPS^(1/3), so a small EPS makes it cost
    more than any implicit run. The error of the resolved response is not estimated: at the
    stable step it is a phase error of (w h)^2 / 24 (CD) per radian, small on the modes far
    below w_max that carry the tip history (docs/tolerance.md)."""
    from fxflex.errors import FxflexError
    from fxflex.time.step_stability import critical_step

    if w_max is None:
        raise FxflexError(f"--tol: {integrator} needs the top frequency of the model, which this "
                          "formulation does not give; use --integrator generalized-alpha")
    if integrator == "cd":
        crit = critical_step("cd", w_max, d)
        rule = f"{EXPLICIT_MARGIN:g} x the central-difference limit 2 (sqrt(w^2 + d^2) - d) / w^2"
    else:
        crit = critical_step("ab2", w_max, d, window=span, log_growth=math.log1p(eps))
        rule = (f"{EXPLICIT_MARGIN:g} x the AB2 step whose growth of the top mode over the run "
                f"stays below 1 + EPS")
    h = EXPLICIT_MARGIN * crit
    steps = span / h
    if steps > MAX_EXPLICIT_STEPS:
        raise FxflexError(f"--tol {eps:g}: {integrator} would need {steps:.3g} steps of "
                          f"{h:.3g} s ({rule}; w_max = {w_max:.4g} rad/s), more than the cap of "
                          f"{MAX_EXPLICIT_STEPS:g}; use --integrator generalized-alpha")
    return h, rule
