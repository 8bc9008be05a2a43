"""Step-size limits of the time integrators on one mode: exact roots and closed-form laws.

The test mode is q'' + d q' + w^2 q = 0: an undamped circular frequency w and the damping rate
d = c/rho, which every method's internal damping gives each mode (D = (c/rho) M, SPEC section 5).
Its one-step map under a scheme is built by running the scheme's own ``step`` on a one-dof
formulation from unit states and histories (``resume`` / ``state_arrays``), so the roots are those
of the code, including details such as central difference's lagged velocity in the damping
force. The spectral radius rho of that map is the amplification per step; ln(rho) / h the growth
rate (1/s) of the scheme's fastest solution.

- Central difference has a sharp limit: rho = 1 up to h w = 2 without damping. The damping force
  sees the lagged velocity v_{n-1/2} + h/2 a_{n-1}, and the map's characteristic polynomial
  2 z^3 + (2 h^2 w^2 + 3 d h - 4) z^2 + (2 - 4 d h) z + d h has its root z = -1 where
  h^2 w^2 + 4 d h = 4: the limit is h = 2 (sqrt(w^2 + d^2) - d) / w^2, 1/d for d >> w (AB2's
  limit under pure damping too).
- AB2 has none: on an undamped mode its principal root grows like exp(w^4 h^3 t / 4) for small
  h w (NOTES.md), and the law underestimates the exact root by 10 % at h w = 0.24 and 40 % at
  0.48 (docs/reduced.md). Its critical step is defined against a window T and a threshold G:
  the largest h whose growth over T stays below G (``critical_step`` with ``window``).
"""

from __future__ import annotations

import math

import numpy as np
from mpi4py import MPI

from fxflex.time.schemes import make_scheme

__all__ = ["step_map", "amplification", "growth_rate", "critical_step", "ab2_law_rate",
           "ab2_law_step", "top_mode"]


class _Mode:
    """q'' + d q' + w^2 q = 0 behind the Formulation and Implicit interfaces (one dof, M = 1)."""

    comm = MPI.COMM_SELF
    method = "one-mode"

    def __init__(self, w: float, d: float):
        self.w2, self.d = w * w, d

    def constrain(self, t, q, v):
        pass

    def acceleration(self, t, q, v, out):
        out[0] = -self.w2 * q[0] - self.d * v[0]

    force = acceleration

    def mass_apply(self, x, out):
        out[0] = x[0]

    def factorize(self, t, q, v, m, c, k):
        return _Scalar(m + c * self.d + k * self.w2)


class _Scalar:
    """The factor of the one-dof tangent S = m + c d + k w^2."""

    def __init__(self, s: float):
        self.s = s

    def solve(self, t, r, out):
        out[0] = r[0] / self.s


@np.errstate(invalid="ignore")      # generalized-alpha's convergence test sees inf * 0 here
def step_map(integrator: str, h: float, w: float, d: float = 0.0, **options) -> np.ndarray:
    """The matrix of one step of ``integrator`` on the test mode, acting on (q, v) followed by
    the scheme's history arrays (in ``state_arrays()`` order); ``options`` go to the scheme
    (generalized-alpha: rho_inf)."""
    mode = _Mode(w, d)
    scheme = make_scheme(integrator, **options)
    q, v = np.zeros(1), np.zeros(1)
    scheme.start(mode, 0.0, h, q, v)
    names = list(scheme.state_arrays())
    dim = 2 + len(names)
    T = np.zeros((dim, dim))
    for j in range(dim):
        e = np.zeros(dim)
        e[j] = 1.0
        q[0], v[0] = e[0], e[1]
        scheme.resume(mode, 0.0, h, q, v, {n: e[2 + i: 3 + i] for i, n in enumerate(names)})
        scheme.step(mode, 0.0, h, q, v)
        hist = scheme.state_arrays()
        T[:, j] = [q[0], v[0], *(hist[n][0] for n in names)]
    return T


def amplification(integrator: str, h: float, w: float, d: float = 0.0, **options) -> float:
    """Spectral radius of the one-step map: the largest |root| of the scheme on the mode."""
    return float(np.max(np.abs(np.linalg.eigvals(step_map(integrator, h, w, d, **options)))))


def growth_rate(integrator: str, h: float, w: float, d: float = 0.0, **options) -> float:
    """ln(amplification) / h (1/s): the growth rate of the scheme's fastest solution."""
    return math.log(amplification(integrator, h, w, d, **options)) / h


def critical_step(integrator: str, w: float, d: float = 0.0, *, window: float | None = None,
                  log_growth: float = 1.0, rtol: float = 1e-6) -> float:
    """Largest step h at which the scheme does not amplify the mode: without ``window``, the step
    where the spectral radius first exceeds 1 (central difference); with it, where the growth over
    ``window`` first exceeds exp(log_growth) (AB2). Bisection on h in (0, 10/w]."""
    def grows(h: float) -> bool:
        rate = growth_rate(integrator, h, w, d)
        if window is None:
            return rate * h > 1e-9
        return rate * window > log_growth
    lo, hi = 0.0, 10.0 / max(w, d, 1e-300)
    if not grows(hi):
        return hi
    while hi - lo > rtol * hi:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if not grows(mid) else (lo, mid)
    return lo


def ab2_law_rate(w: float, h: float, d: float = 0.0) -> float:
    """Growth rate of AB2 on the mode by the small-step law of NOTES.md: w^4 h^3 / 4 - d / 2."""
    return w**4 * h**3 / 4.0 - d / 2.0


def ab2_law_step(w: float, window: float, log_growth: float = 1.0, d: float = 0.0) -> float:
    """The step at which the law's growth over ``window`` reaches exp(log_growth):
    w^4 h^3 / 4 - d / 2 = log_growth / window."""
    return (4.0 * (log_growth / window + d / 2.0) / w**4) ** (1.0 / 3.0)


def top_mode(form) -> tuple[float | None, float]:
    """(w_max, d) of a formulation: its highest undamped circular frequency (rad/s, its
    ``top_frequency()``: about the steady state where the linearisation is dense, otherwise the
    clamped body at rest) and the damping rate c/rho (1/s)."""
    scene = form.scene
    return form.top_frequency(), scene.damping.c / scene.material.rho
