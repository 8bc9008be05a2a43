"""The paper's two-DOF rotating system (Sect. 4.1, Eq. 61-64): five stability cases, analytic and
integrated in time.

Eq. 61 is written in the inertial frame, u'' + A K_L A^T u = 0 with A = A(Omega t) the plane
rotation and K_L = diag(K_L1, K_L2), K_L1 > K_L2 > 0: the stiffness turns with the body, a
parametrically excited system. In the rotating frame, U = A^T u, it becomes the constant-coefficient
Eq. 62,

    U'' + 2 Omega J U' + (K_L - Omega^2 I) U = 0,    J = [[0, -1], [1, 0]] = -G_3,

whose roots iota (Eq. 63) are

    iota^2 = (-(K_L1 + K_L2 + 2 Omega^2) +- sqrt((K_L1 - K_L2)^2 + 8 (K_L1 + K_L2) Omega^2)) / 2.

The five cases of the paper, with NOTES.md's two corrections:

1. Omega^2 > K_L1: K_L - Omega^2 I negative definite, four imaginary roots: stable *without
   damping* (gyroscopic stabilisation). With damping the even number of negative stiffnesses can
   no longer be held by the gyroscopic term (Kelvin-Tait-Chetaev): unstable.
2. K_L2 < Omega^2 < K_L1: indefinite; a positive real root: unstable.
3. Omega^2 < K_L2: positive definite; stable (asymptotically with damping).
4. Omega^2 = K_L1: K_L - Omega^2 I = diag(0, K_L2 - K_L1) is negative *semi*-definite (the paper
   prints "positive"); a double zero root with one eigenvector: polynomial growth, unstable.
5. Omega^2 = K_L2: positive semi-definite, double zero root: unstable.

For comparison Eq. 64 drops the gyroscopic term: stable only when K_L - Omega^2 I is positive
definite.

Damping (SPEC section 5): ``relative`` damps the rotating-frame rate, c U' (in the inertial frame
c (u' - Omega J u)); ``absolute`` damps the inertial rate, c u' (in the rotating frame
c (U' + Omega J U), the circulatory term).

:class:`TwoDof` also behaves as a formulation (``initial_state``, ``acceleration``, ``constrain``,
``tip``), so the generic integrators of :mod:`fxflex.time` integrate Eq. 61 itself, in the
inertial frame with the rotating stiffness; ``tip`` reports U = A^T u.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from mpi4py import MPI

from fxflex.formulation import FormulationBase
from fxflex.numerics.growth import growth_fit
from fxflex.numerics.qep import companion_eigenvalues, unstable

__all__ = ["TwoDof", "Inertial", "CASES", "case_systems", "eq63_roots", "integrate", "measured_growth",
           "behaviour"]

J2 = np.array([[0.0, -1.0], [1.0, 0.0]])

#: case number -> (Omega^2 as a function of (K_L1, K_L2), the paper's verdict, its wording)
CASES = {
    1: (lambda k1, k2: 1.5625 * k1, "stable", "Omega^2 > K_L1: negative definite"),
    2: (lambda k1, k2: 0.5 * (k1 + k2), "unstable", "K_L2 < Omega^2 < K_L1: indefinite"),
    3: (lambda k1, k2: 0.25 * k2, "stable", "Omega^2 < K_L2: positive definite"),
    4: (lambda k1, k2: k1, "unstable", "Omega^2 = K_L1: paper 'positive semi-definite', in fact "
                                       "negative semi-definite"),
    5: (lambda k1, k2: k2, "unstable", "Omega^2 = K_L2: positive semi-definite"),
}


def eq63_roots(k1: float, k2: float, omega: float) -> np.ndarray:
    """The four roots iota of Eq. 63 (undamped), complex."""
    w2 = omega * omega
    disc = math.sqrt((k1 - k2) ** 2 + 8.0 * (k1 + k2) * w2)
    iota2 = np.array([(-(k1 + k2 + 2 * w2) + disc) / 2, (-(k1 + k2 + 2 * w2) - disc) / 2])
    r = np.sqrt(iota2.astype(complex))
    return np.concatenate([r, -r])


@dataclass(frozen=True)
class TwoDof:
    """Eq. 61/62 with stiffnesses k1 > k2 > 0 (1/s^2), speed omega (rad/s), damping c (1/s)."""

    k1: float
    k2: float
    omega: float
    c: float = 0.0
    damping: str = "relative"

    # -- rotating frame (Eq. 62) -------------------------------------------------------------------
    def stiffness(self) -> np.ndarray:
        """K_L - Omega^2 I (+ c Omega J, absolute damping)."""
        K = np.diag([self.k1, self.k2]) - self.omega**2 * np.eye(2)
        if self.damping == "absolute":
            K = K + self.c * self.omega * J2
        return K

    def linearise(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(M, C, K) of Eq. 62: M = I, C = 2 Omega J + c I."""
        return np.eye(2), 2.0 * self.omega * J2 + self.c * np.eye(2), self.stiffness()

    def eigenvalues(self) -> np.ndarray:
        return companion_eigenvalues(*self.linearise())

    def stable(self) -> bool:
        """No root with a positive real part and no repeated root on the imaginary axis (the
        paper's criterion; the double zero root of cases 4 and 5 has a single eigenvector)."""
        lam = self.eigenvalues()
        if unstable(lam, rtol=1e-9):
            return False
        scale = np.abs(lam).max()
        on_axis = lam[np.abs(lam.real) <= 1e-7 * scale]
        for i in range(on_axis.size):
            if np.sum(np.abs(on_axis - on_axis[i]) <= 1e-6 * scale) > 1:
                return False
        return True

    def stiffness_definiteness(self) -> str:
        """'positive definite', 'negative definite', 'indefinite', 'positive semi-definite' or
        'negative semi-definite' of the symmetric part of K_L - Omega^2 I."""
        ev = np.linalg.eigvalsh(np.diag([self.k1, self.k2]) - self.omega**2 * np.eye(2))
        tol = 1e-12 * max(self.k1, self.omega**2)
        pos, neg = np.sum(ev > tol), np.sum(ev < -tol)
        if pos == 2:
            return "positive definite"
        if neg == 2:
            return "negative definite"
        if pos and neg:
            return "indefinite"
        return "positive semi-definite" if pos else "negative semi-definite"

    def eq64_stable(self) -> bool:
        """Eq. 64 (no gyroscopic term): stable iff K_L - Omega^2 I is positive definite."""
        return self.stiffness_definiteness() == "positive definite"


class Inertial(FormulationBase):
    """Eq. 61 of a :class:`TwoDof` in the inertial frame, behind the formulation contract of
    :mod:`fxflex.formulation` so that fxflex.time integrates it (only the dynamics: no scene,
    steady state or rotating analysis of its own -- :class:`TwoDof` has those)."""

    method = "twodof"
    dof = 2
    comm = MPI.COMM_SELF

    def __init__(self, system: TwoDof):
        self.k1, self.k2, self.omega, self.c = system.k1, system.k2, system.omega, system.c
        self.damping = system.damping

    def initial_state(self) -> tuple[np.ndarray, np.ndarray]:
        return np.array([1e-3, 1e-3]), np.zeros(2)
    def constrain(self, t: float, q: np.ndarray, v: np.ndarray) -> None:
        """No constraints."""

    def acceleration(self, t: float, q: np.ndarray, v: np.ndarray, out: np.ndarray) -> None:
        """u'' = -A K_L A^T u - c (u' [- Omega J u, relative])."""
        c, s = math.cos(self.omega * t), math.sin(self.omega * t)
        a1, a2 = c * q[0] + s * q[1], -s * q[0] + c * q[1]          # A^T u
        f1, f2 = self.k1 * a1, self.k2 * a2
        out[0] = -(c * f1 - s * f2) - self.c * v[0]
        out[1] = -(s * f1 + c * f2) - self.c * v[1]
        if self.damping == "relative":
            out[0] += self.c * self.omega * -q[1]
            out[1] += self.c * self.omega * q[0]

    def tip(self, t: float, q: np.ndarray) -> np.ndarray:
        """U = A^T u in the rotating frame, padded to three components."""
        c, s = math.cos(self.omega * t), math.sin(self.omega * t)
        return np.array([c * q[0] + s * q[1], -s * q[0] + c * q[1], 0.0])


def case_systems(k1: float = 4.0, k2: float = 1.0, c: float = 0.0,
                 damping: str = "relative") -> dict[int, TwoDof]:
    """The five cases for the given stiffnesses (rad^2/s^2)."""
    return {n: TwoDof(k1, k2, math.sqrt(w2(k1, k2)), c, damping)
            for n, (w2, _, _) in CASES.items()}


def integrate(system: TwoDof, t_end: float = 200.0, dt: float = 2e-3, integrator: str = "cd"
              ) -> np.ndarray:
    """Eq. 61 integrated from u = (1e-3, 1e-3), u' = 0 with the generic driver: rows (t, U1, U2)
    in the rotating frame.

    Central difference by default: on the undamped Eq. 61 (no velocity term in the inertial
    frame) it is the symplectic Stoermer-Verlet scheme, which keeps the marginal cases 4 and 5
    marginal. AB2 splits their double zero root by its O(h^2) error: at dt = 0.01 case 4 ends
    4.8 times too large after 200 s."""
    from fxflex.time import simulate

    res = simulate(Inertial(system), integrator, dt, t_end, sample_every=max(1, int(round(0.05 / dt))),
                   keep_history=True, limit=1e12)
    h = np.array(res.history)
    return h[:, :3]


def measured_growth(history: np.ndarray) -> dict:
    """How |U(t)| evolves over the second half of the window: the exponential rate (slope of
    log |U| against t, 1/s), the power law exponent (slope of log |U| against log t) and the
    growth factor (peak of the second half over the peak of the first)."""
    t, amp = history[:, 0], np.linalg.norm(history[:, 1:3], axis=1)
    half = t > 0.5 * t[-1]
    # the envelope: running maxima over windows, so that oscillations do not bias the fit
    k = max(1, half.sum() // 40)
    tt = t[half][: (half.sum() // k) * k].reshape(-1, k).max(axis=1)
    aa = amp[half][: (half.sum() // k) * k].reshape(-1, k).max(axis=1)
    rate = growth_fit(tt, aa)
    power = float(np.polyfit(np.log(tt), np.log(aa), 1)[0])
    factor = float(amp[half].max() / amp[~half].max())
    return {"rate": rate, "power": power, "factor": factor}


def behaviour(growth: dict) -> str:
    """Words for :func:`measured_growth`: ``decaying``, ``bounded``, ``polynomial`` (|U| ~ t^p,
    p < 1.5 over the second half) or ``exponential``."""
    if growth["factor"] < 0.5:
        return "decaying"
    if growth["factor"] <= 1.1:
        return "bounded"
    return "polynomial" if growth["power"] < 1.5 else "exponential"
