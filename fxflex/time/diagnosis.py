"""Why did a run diverge? Physical instability or a step too large (SPEC section 4).

A divergence is *physical* when the linearised rotating system has an eigenvalue with positive
real part (SPEC section 6); otherwise it is *numerical*: for CD the step exceeds 2 / w_max, for
AB2 the undamped modes grow like exp(w^4 h^3 t / 4) (NOTES.md); generalised-alpha has no step
limit on linear systems and fails only through Newton's method (``NewtonFailure``). Formulations
that can answer offer ``growth_rate()`` -> (Re lambda_max, |Im lambda| of that root) and
``omega_max()`` -> the highest circular frequency of the discrete system.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["diagnose", "ab2_growth_exponent", "deviation_growth"]


def ab2_growth_exponent(omega: float, h: float, t: float) -> float:
    """ln of the AB2 amplification of an undamped mode omega after time t: w^4 h^3 t / 4."""
    return omega**4 * h**3 * t / 4.0


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
    return float(np.polyfit(h[late, 0], np.log(dev[late]), 1)[0]), int(late.sum())


def diagnose(form, integrator: str, dt: float, result) -> dict:
    """{"time_s", "cause", "detail"} for a run that stopped on divergence."""
    out = {"time_s": result.diverged["time_s"], "cause": None,
           "detail": result.diverged["reason"]}
    growth = getattr(form, "growth_rate", None)
    if callable(growth):
        rate, freq = growth()
        if rate > 0:
            out["cause"] = "physical"
            out["detail"] += (f"; the linearised rotating system has an eigenvalue with real part "
                              f"{rate:.4g} 1/s (frequency {freq / (2 * math.pi):.4g} Hz)")
            out["growth_rate"] = rate
            return out
    wmax_fn = getattr(form, "omega_max", None)
    wmax = wmax_fn() if callable(wmax_fn) else None
    out["cause"] = "numerical"
    if wmax is not None and integrator == "cd":
        out["detail"] += (f"; central difference needs dt < 2/w_max = {2 / wmax:.4g} s "
                          f"(w_max = {wmax:.4g} rad/s), dt = {dt:.4g} s")
    elif wmax is not None and integrator == "ab2":
        expo = ab2_growth_exponent(wmax, dt, out["time_s"])
        out["detail"] += (f"; AB2 amplifies the highest mode (w_max = {wmax:.4g} rad/s) by "
                          f"exp(w^4 h^3 t / 4) = exp({expo:.3g}) by this time; reduce dt")
    elif integrator == "generalized-alpha":
        out["detail"] += ("; generalized-alpha is unconditionally stable on linear systems, so "
                          "the step only limits Newton's convergence: reduce dt")
    elif growth is None:
        out["cause"] = "numerical"
        out["detail"] += "; no unstable eigenvalue check available for this method"
    else:
        out["detail"] += "; no eigenvalue of the linearised system has positive real part"
    return out
