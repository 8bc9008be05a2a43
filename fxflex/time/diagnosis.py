"""Why did a run stop? Physical instability, a step too large, or a response out of range
(SPEC section 4).

1. *physical* instability: the linearised rotating system about a converged steady state has an
   eigenvalue with positive real part (SPEC section 6) beyond the eigensolver's round-off: the
   formulation's own ``stable()`` is False; ``growth_rate()`` gives (Re lambda_max, |Im lambda|
   of that root).
2. *numerical*: the scheme amplifies the highest mode (w_max, damping c/rho; see
   :func:`fxflex.time.step_stability.top_mode`) at this step - central difference beyond its limit,
   AB2 by more than exp(``AB2_LOG_GROWTH``) by the time of the stop (its exact root) - or
   generalised-alpha's Newton iteration failed for good (it has no step limit on linear
   systems). When an unstable eigenvalue is there too, the faster growth is named.
3. otherwise the response itself left the model's range (a large but bounded physical
   response: the deflection limit of :func:`fxflex.time.driver.divergence_limit`), reported as
   *physical* with that explanation; a NaN without either cause is reported as numerical.

Every diagnosis also carries the growth rate measured from the deflections before the stop,
when they grew exponentially, to compare with the eigenvalue or the scheme's root.
"""

from __future__ import annotations

import math

import numpy as np

from fxflex.numerics.growth import growth_fit
from fxflex.time import step_stability as stability
from fxflex.formulation import SMALL_DEFORMATION_RANGE

__all__ = ["diagnose", "ab2_growth_exponent", "measured_growth_rate", "deviation_growth",
           "ab2_warning", "AB2_LOG_GROWTH"]

#: AB2 counts as the cause when it amplifies the highest mode by more than exp(10) = 2.2e4 by the
#: time of the stop: a mode excited at 1e-4 of the deflection limit or less reaches it
AB2_LOG_GROWTH = 10.0


def ab2_growth_exponent(omega: float, h: float, t: float) -> float:
    """ln of the AB2 amplification of an undamped mode omega after time t: w^4 h^3 t / 4."""
    return omega**4 * h**3 * t / 4.0


def measured_growth_rate(growth: np.ndarray | None, decades: float = 4.0) -> float | None:
    """Exponential growth rate (1/s) of the deflection magnitudes (t, |U|) before a stop: the
    least-squares slope of ln |U| over the last ``decades`` decades of growth, or None when those
    points are too few or do not lie on an exponential (R^2 < 0.9, or the slopes of the two
    halves differ by more than 30 %, as they do for a power law such as a load's t^2 start)."""
    if growth is None or len(growth) < 8:
        return None
    t, amp = growth[:, 0], growth[:, 1]
    ok = amp > 0
    if ok.sum() < 8:
        return None
    t, amp = t[ok], amp[ok]
    # the last stretch that stays within `decades` of the final value
    low = amp[-1] * 10.0**-decades
    start = len(amp) - 1
    while start > 0 and amp[start - 1] >= low:
        start -= 1
    t, y = t[start:], np.log(amp[start:])
    if len(t) < 8 or t[-1] - t[0] <= 0:
        return None
    slope, icpt = np.polyfit(t, y, 1)
    resid = y - (slope * t + icpt)
    spread = np.sum((y - y.mean()) ** 2)
    if spread <= 0 or 1.0 - np.sum(resid**2) / spread < 0.9 or slope <= 0:
        return None
    half = len(t) // 2
    first, second = np.polyfit(t[:half], y[:half], 1)[0], np.polyfit(t[half:], y[half:], 1)[0]
    if abs(first - second) > 0.3 * slope:
        return None
    return float(slope)


def deviation_growth(history, steady_tip, threshold: float = 100.0) -> tuple[float | None, int]:
    """(rate, samples): how fast a run leaves an unstable equilibrium -- the slope (1/s) of
    log |tip - steady| against t over the samples of ``history`` (rows t, tip...) where the
    deviation exceeds ``threshold`` |steady|, by then a pure exponential of the growing root;
    None below 3 such samples. Compare with ``growth_rate()``."""
    h = np.asarray(history, float)
    dev = np.linalg.norm(h[:, 1:4] - steady_tip, axis=1)
    late = dev > threshold * np.linalg.norm(steady_tip)
    if late.sum() < 3:
        return None, int(late.sum())
    return growth_fit(h[late, 0], dev[late]), int(late.sum())


def ab2_warning(form, dt: float, t: float) -> str | None:
    """For an AB2 run that reached t without stopping: a warning when AB2 amplified the highest
    mode by more than exp(AB2_LOG_GROWTH) (exact root, w_max from ``omega_max()``): its output
    may then carry a spurious high-frequency part too small to stop the run (docs/reduced.md:
    GCMS at 0.5 us is 20x off after 10 ms without diverging). None otherwise."""
    w = float(form.omega_max())
    d = form.scene.damping.c / form.scene.material.rho
    rate = stability.growth_rate("ab2", dt, w, d)
    if rate * t <= AB2_LOG_GROWTH:
        return None
    limit = stability.critical_step("ab2", w, d, window=t, log_growth=1.0)
    return (f"AB2 amplified the highest mode (w_max = {w:.4g} rad/s) by exp({rate * t:.3g}) over "
            f"this run: the output may carry a spurious high-frequency part; dt < {limit:.3g} s "
            f"keeps the growth below e over {t:.3g} s")


def _physical(form) -> tuple[float, float, bool] | None:
    """(Re lambda_max, |Im lambda| of that root, unstable) of the linearised system about a
    converged steady state (the verdict is the formulation's own ``stable()``, with its
    eigensolver's round-off tolerance), or None without a converged steady state."""
    try:
        if not form.steady_state().converged:
            return None
        rate, freq = form.growth_rate()
        grows = form.stable() is False
    except (ValueError, np.linalg.LinAlgError, RuntimeError):
        return None
    return (rate, freq, bool(grows and rate > 0.0)) if math.isfinite(rate) else None


def diagnose(form, integrator: str, dt: float, result) -> dict:
    """{"time_s", "cause", "detail", ...} for a run that stopped early (``result.diverged``).

    When both an unstable eigenvalue and the step could explain the stop, the faster growth
    wins: a physical root growing at 56 1/s cannot blow a run up within 0.1 ms, AB2 at 1e5 1/s
    can."""
    stop = result.diverged
    out = {"time_s": stop["time_s"], "cause": None, "detail": stop["reason"],
           "stop": stop.get("kind")}       # non-finite | range | newton
    measured = measured_growth_rate(result.growth)
    if measured is not None:
        out["measured_growth_rate"] = measured
    seen = f" (measured growth of the deflection: {measured:.4g} 1/s)" if measured else ""
    w, d = stability.top_mode(form)
    phys = _physical(form)
    rate = -math.inf
    if w is not None:
        out["omega_max"] = w
        rate = stability.growth_rate(integrator, dt, w, d)
        out["scheme_growth_rate"] = rate
    modes = (f"w_max = {w:.4g} rad/s" if w is not None else "w_max unknown") + \
        f", c/rho = {d:.4g} 1/s"
    elapsed = stop["time_s"]
    numerical = None
    if stop.get("kind") == "newton":
        numerical = ("; generalized-alpha is unconditionally stable on linear systems, so the "
                     "step only limits Newton's convergence: reduce dt")
    elif w is None:
        pass
    elif integrator == "cd":
        limit = stability.critical_step("cd", w, d)
        out["dt_limit_s"] = limit
        if dt > limit:
            numerical = (f"; central difference needs dt < {limit:.4g} s on the highest mode "
                         f"({modes}; 2/w_max = {2 / w:.4g} s), dt = {dt:.4g} s: its root grows "
                         f"at {rate:.4g} 1/s")
    elif integrator == "ab2":
        if rate * elapsed > AB2_LOG_GROWTH:
            window = max(elapsed, dt)
            limit = stability.critical_step("ab2", w, d, window=window)
            out["dt_limit_s"] = limit
            numerical = (f"; AB2 amplifies the highest mode ({modes}) at {rate:.4g} 1/s (exact "
                         f"root; law w^4 h^3/4 - c/(2 rho) = "
                         f"{stability.ab2_law_rate(w, dt, d):.4g} 1/s), by exp("
                         f"{rate * elapsed:.3g}) by this time; growth below e over {window:.3g} s "
                         f"needs dt < {limit:.3g} s")
    if phys is not None:
        out["growth_rate"] = phys[0]
    if phys is not None and phys[2] and (numerical is None or phys[0] >= 0.1 * rate):
        out["cause"] = "physical"
        out["detail"] += (f"; the linearised rotating system has an eigenvalue with real part "
                          f"{phys[0]:.4g} 1/s (frequency {phys[1] / (2 * math.pi):.4g} Hz)"
                          + seen)
        return out
    if numerical is not None:
        out["cause"] = "numerical"
        also = (f"; the rotating state is also unstable, but its root ({phys[0]:.4g} 1/s) grows "
                f"far slower" if phys is not None and phys[2] else "")
        out["detail"] += numerical + also + seen
        return out
    if stop.get("kind") == "non-finite":
        out["cause"] = "numerical"
        out["detail"] += ("; non-finite values although the step is within the integrator's "
                          f"limit on the highest mode ({modes}) and no eigenvalue of the "
                          "linearised system is unstable" + seen)
        return out
    out["cause"] = "physical"
    eig = ("no eigenvalue of the linearised rotating system has a positive real part "
           f"(largest {phys[0]:.3g} 1/s)" if phys is not None else
           f"{form.method} has no eigenvalue analysis of this state (no converged steady state)")
    span = form.deflection_range
    model = ("the small-deformation range of the model (the geometrically exact tlf and ancf "
             "follow large deflections)" if span <= SMALL_DEFORMATION_RANGE else
             "the range of the model")
    out["detail"] += (f"; not an instability of the step ({integrator} at dt = {dt:.4g} s is "
                      f"within its limit on the highest mode, {modes}) and {eig}: the response "
                      f"itself left {model}" + seen)
    return out
