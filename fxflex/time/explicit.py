"""Explicit integrators over the :class:`~fxflex.formulation.Formulation` interface.

Each scheme advances (q, v) in place, allocates its work arrays once in ``start`` and nothing in
``step``. Before every force evaluation the state is passed through ``form.constrain`` so that
prescribed coordinates (root nodes following the drive) are exact. ``state_arrays()`` names the
history a scheme carries between steps besides (q, v); ``resume`` rebuilds a scheme from them, so
that a run continued from a checkpoint takes bit for bit the steps of an uninterrupted one.

- ``ab2``: two-step Adams-Bashforth on the first-order form y = (q, v), y' = (v, a) (the paper's
  AB [58]); the first step is Heun's (explicit trapezoid), second order like AB2 itself. AB2 has no
  stability interval on the imaginary axis: an undamped mode of circular frequency w grows like
  exp(w^4 h^3 t / 4) (NOTES.md).
- ``cd``: central difference in leapfrog form, q_{n+1} = q_n + h v_{n+1/2},
  v_{n+1/2} = v_{n-1/2} + h a_n, which is q_{n+1} - 2 q_n + q_{n-1} = h^2 a_n (the paper's CD
  [59]); velocity-dependent forces see v_n ~ v_{n-1/2} + h/2 a_{n-1}. Stable for w_max h < 2.
"""

from __future__ import annotations

import numpy as np

__all__ = ["AB2", "CentralDifference", "SCHEMES"]


class AB2:
    name = "ab2"
    order = 2

    def start(self, form, t: float, h: float, q: np.ndarray, v: np.ndarray) -> None:
        """Heun step from t to t + h; leaves f(y_0) as the AB2 history."""
        n = q.size
        self.a, self.v_prev, self.a_prev = np.empty(n), np.empty(n), np.empty(n)
        self.w1, self.w2 = np.empty(n), np.empty(n)
        form.constrain(t, q, v)
        form.acceleration(t, q, v, self.a_prev)
        self.v_prev[:] = v
        # predictor y* = y0 + h f(y0), in (w1, w2)
        _axpy(q, h, v, self.w1)
        _axpy(v, h, self.a_prev, self.w2)
        form.constrain(t + h, self.w1, self.w2)
        form.acceleration(t + h, self.w1, self.w2, self.a)
        # corrector y1 = y0 + h/2 (f(y0) + f(y*))
        self.w2 += self.v_prev
        _axpy(q, 0.5 * h, self.w2, q)
        self.a += self.a_prev
        _axpy(v, 0.5 * h, self.a, v)
        form.constrain(t + h, q, v)

    def step(self, form, t: float, h: float, q: np.ndarray, v: np.ndarray) -> None:
        """y_{n+1} = y_n + h (3/2 f_n - 1/2 f_{n-1}); t is t_n and (q, v) = y_n."""
        a, w1, w2 = self.a, self.w1, self.w2
        form.acceleration(t, q, v, a)
        np.multiply(v, 1.5 * h, out=w1)
        np.multiply(self.v_prev, -0.5 * h, out=w2)
        self.v_prev[:] = v
        q += w1
        q += w2
        np.multiply(a, 1.5 * h, out=w1)
        np.multiply(self.a_prev, -0.5 * h, out=w2)
        v += w1
        v += w2
        self.a_prev, self.a = a, self.a_prev
        form.constrain(t + h, q, v)

    def state_arrays(self) -> dict[str, np.ndarray]:
        """History needed to resume exactly (checkpoints)."""
        return {"v_prev": self.v_prev, "a_prev": self.a_prev}

    def resume(self, form, t: float, h: float, q: np.ndarray, v: np.ndarray,
               arrays: dict[str, np.ndarray]) -> None:
        """Continue from (q, v) at t with the history of :meth:`state_arrays`."""
        n = q.size
        self.a, self.w1, self.w2 = np.empty(n), np.empty(n), np.empty(n)
        self.v_prev, self.a_prev = _copy(arrays, "v_prev", n), _copy(arrays, "a_prev", n)


class CentralDifference:
    name = "cd"
    order = 2

    def start(self, form, t: float, h: float, q: np.ndarray, v: np.ndarray) -> None:
        """Half step v_{1/2} = v_0 + h/2 a_0, then the first full step."""
        n = q.size
        self.a, self.v_half, self.w = np.empty(n), np.empty(n), np.empty(n)
        form.constrain(t, q, v)
        form.acceleration(t, q, v, self.a)
        np.multiply(self.a, 0.5 * h, out=self.v_half)
        self.v_half += v
        self._advance(form, t, h, q, v)

    def _advance(self, form, t: float, h: float, q: np.ndarray, v: np.ndarray) -> None:
        # q_{n+1} = q_n + h v_{n+1/2}; estimate v_{n+1} = v_{n+1/2} + h/2 a_n for damping forces
        np.multiply(self.v_half, h, out=self.w)
        q += self.w
        np.multiply(self.a, 0.5 * h, out=v)
        v += self.v_half
        form.constrain(t + h, q, v)
        form.acceleration(t + h, q, v, self.a)
        # v_{n+3/2} = v_{n+1/2} + h a_{n+1}
        np.multiply(self.a, h, out=self.w)
        self.v_half += self.w

    def step(self, form, t: float, h: float, q: np.ndarray, v: np.ndarray) -> None:
        self._advance(form, t, h, q, v)

    def state_arrays(self) -> dict[str, np.ndarray]:
        """History needed to resume exactly: a_n and v_{n+1/2}."""
        return {"a": self.a, "v_half": self.v_half}

    def resume(self, form, t: float, h: float, q: np.ndarray, v: np.ndarray,
               arrays: dict[str, np.ndarray]) -> None:
        """Continue from (q, v) at t with the history of :meth:`state_arrays`."""
        n = q.size
        self.w = np.empty(n)
        self.a, self.v_half = _copy(arrays, "a", n), _copy(arrays, "v_half", n)


def _copy(arrays: dict[str, np.ndarray], name: str, n: int) -> np.ndarray:
    """A private float64 copy of a history array, checked against the state size."""
    a = np.array(arrays[name], dtype=np.float64)
    if a.shape != (n,):
        raise ValueError(f"scheme history {name!r}: expected shape ({n},), got {a.shape}")
    return a


def _axpy(y: np.ndarray, alpha: float, x: np.ndarray, out: np.ndarray) -> None:
    """out = y + alpha x (out may be y); used outside the time loop only."""
    out[:] = y + alpha * x


SCHEMES = {"ab2": AB2, "cd": CentralDifference}
