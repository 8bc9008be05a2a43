"""Generalised-alpha (Chung & Hulbert 1993) over the :class:`~fxflex.formulation.Implicit` interface.

Parameters from the spectral radius at infinity rho_inf in [0, 1] (Chung & Hulbert, Eq. 25-27):

    alpha_m = (2 rho_inf - 1) / (rho_inf + 1),   alpha_f = rho_inf / (rho_inf + 1),
    gamma = 1/2 - alpha_m + alpha_f,             beta = (1 - alpha_m + alpha_f)^2 / 4.

Second order for every rho_inf, unconditionally stable on linear systems, and the amplification
matrix tends to spectral radius rho_inf as omega h -> infinity: rho_inf = 1 is the trapezoidal rule
(no numerical damping), smaller values damp the unresolved high frequencies more while the
resolved ones keep their amplitude to O((omega h)^3).

Form. The equation of motion on the free coordinates, M q'' = F(t, q, q'), is enforced at t_{n+1}
(the form of Arnold & Brüls 2007), with the Newmark update driven by an acceleration-like variable a:

    M qdd_{n+1} = F(t_{n+1}, q_{n+1}, v_{n+1}),
    q_{n+1} = q_n + h v_n + h^2 (1/2 - beta) a_n + h^2 beta a_{n+1},
    v_{n+1} = v_n + h (1 - gamma) a_n + h gamma a_{n+1},
    (1 - alpha_m) a_{n+1} + alpha_m a_n = (1 - alpha_f) qdd_{n+1} + alpha_f qdd_n,

with a_0 = qdd_0 = M^-1 F(0). On a linear system this is Chung and Hulbert's method (the same
amplification matrix, and the load enters as the same alpha_f average). On a nonlinear one it never
evaluates forces at interpolated states: in absolute coordinates (TLF, ANCF) averaging two rotated
configurations would shrink the body and create a spurious strain of order (Omega h)^2.
Prescribed coordinates (root nodes following the drive) take their exact values at t_{n+1} from
``constrain``; their rows are zero in the Newton system.

Newton on x = qdd_{n+1}: q_{n+1} = q^ + c_q x, v_{n+1} = v^ + c_v x with c_q = h^2 beta kappa,
c_v = h gamma kappa, kappa = (1 - alpha_f) / (1 - alpha_m), so the residual r = M x - F has the
Jacobian S = M + c_v C_t + c_q K_t (K_t = -dF/dq, C_t = -dF/dv). The predictor is x = qdd_n.

Modified Newton. S is factorised once and reused across steps while the iteration converges. The
test is RADAU5's (Hairer & Wanner, IV.8): with the contraction theta_k = |dq_k| / |dq_{k-1}| of the
position corrections dq = c_q dx, the remaining error is about eta_k |dq_k|, eta = theta /
(1 - theta), and the step is accepted when eta_k |dq_k| <= tol |q_{n+1} - q_n|, tol = 1e-5 (on
the 10 ms transients this moves the tip by at most 4e-6 of its peak against tol = 1e-9). At k = 1
eta is the last measured one to the power 0.8, for at most 8 steps in a row, so that a factor
that ages while the tangent changes is caught by the next measurement. A factor is renewed when
the extra iterations it has cost since it was made (beyond those of its first step) add up to the
measured cost of a factorisation, or when theta > 1/2. Corrections below 1e-13 |q| are round-off
and count as converged whatever the contraction says. ``atol`` (set per step by the adaptive
driver, :mod:`fxflex.time.adaptive`) bounds eta_k |dq_k| in metres as well: the test is then
eta_k |dq_k| <= max(min(tol |q_{n+1} - q_n|, atol), 1e-13 |q|).

Fallback. A step whose Newton iteration does not converge (theta >= 1, a non-finite residual, or
``max_iter`` iterations) with a factor made at an earlier step is retried with a fresh one; if it
fails with a fresh factor, or the iteration matrix is singular, the step is cut in two halves (recursively, ``max_halvings`` times) and
then the run stops with :class:`NewtonFailure`, whose message says where and how it failed.
"""

from __future__ import annotations

import math
import time

import numpy as np

from fxflex.formulation import Implicit

__all__ = ["GeneralizedAlpha", "NewtonFailure", "parameters", "DEFAULT_RHO_INF"]

DEFAULT_RHO_INF = 0.9
#: steps accepted after one iteration on the strength of an earlier contraction before the next
#: step must measure it again (k = 2)
_ETA_AGE = 8
#: corrections below this times |q| are round-off (converged whatever the contraction says)
_ROUNDOFF = 1e-13


class NewtonFailure(RuntimeError):
    """Newton's method did not converge with a fresh tangent and the step cut ``max_halvings``
    times."""

    def __init__(self, message: str, time_s: float, reached_s: float):
        super().__init__(message)
        self.time_s = time_s          # end of the (sub)step that failed
        self.reached_s = reached_s    # time of the last converged state, which (q, v) hold


def parameters(rho_inf: float) -> tuple[float, float, float, float]:
    """(alpha_m, alpha_f, beta, gamma) of Chung & Hulbert for spectral radius rho_inf."""
    if not 0.0 <= rho_inf <= 1.0:
        raise ValueError(f"rho_inf must lie in [0, 1], got {rho_inf!r}")
    am = (2.0 * rho_inf - 1.0) / (rho_inf + 1.0)
    af = rho_inf / (rho_inf + 1.0)
    gamma = 0.5 - am + af
    beta = 0.25 * (1.0 - am + af) ** 2
    return am, af, beta, gamma


class GeneralizedAlpha:
    """Generalised-alpha with modified Newton (module docstring). Works in place on (q, v); the
    work arrays are allocated in ``start`` and ``step`` allocates none.

    ``stats`` counts steps, halvings, Newton iterations (= residual evaluations), factorisations
    and retries with a renewed factor.
    """

    name = "generalized-alpha"
    order = 2

    def __init__(self, rho_inf: float = DEFAULT_RHO_INF, *, tol: float = 1e-5, max_iter: int = 10,
                 max_halvings: int = 4, reuse_ratio: float = 1.0):
        self.rho_inf = rho_inf
        self.am, self.af, self.beta, self.gamma = parameters(rho_inf)
        self.tol, self.max_iter, self.max_halvings = tol, max_iter, max_halvings
        #: a factor made for step h_f serves steps h with h / h_f in [1/ratio, ratio] (1: only
        #: h_f itself). With a variable step (fxflex.time.adaptive) the stiff part of S scales
        #: as h^2, so the modified Newton contracts by about |1 - (h / h_f)^2| on the stiff modes:
        #: the contraction test and the renewal rule above decide whether the factor still pays.
        self.reuse_ratio = reuse_ratio
        #: an absolute bound (m, Euclidean norm of the whole state) on the remaining Newton error
        #: of a step, besides ``tol`` times its increment: the adaptive driver sets it per step
        #: below the local error it allows (:mod:`fxflex.time.adaptive`, "Newton's share")
        self.atol = math.inf
        self.stats = {"steps": 0, "iterations": 0, "factorizations": 0, "retries": 0,
                      "halvings": 0}

    # -- set-up ---------------------------------------------------------------------------------
    def start(self, form, t: float, h: float, q: np.ndarray, v: np.ndarray) -> None:
        """:meth:`begin`, then the first step."""
        self.begin(form, t, q, v)
        self.step(form, t, h, q, v)

    def begin(self, form, t: float, q: np.ndarray, v: np.ndarray) -> None:
        """qdd_0 = a_0 = M^-1 F(t0, q0, v0) (the formulation's explicit acceleration) and the work
        arrays; no step (the adaptive driver, :mod:`fxflex.time.adaptive`, chooses it)."""
        self._setup(form, q.size)
        form.constrain(t, q, v)
        form.acceleration(t, q, v, self.qdd)
        self.a[:] = self.qdd

    def resume(self, form, t: float, h: float, q: np.ndarray, v: np.ndarray,
               arrays: dict[str, np.ndarray]) -> None:
        """Continue from (q, v) at t with the history of :meth:`state_arrays` (checkpoints). The
        modified Newton's factor is not part of it: the next step makes a fresh one, so a resumed
        run agrees with an uninterrupted one to the Newton tolerance, not bit for bit (whose
        factor renewals follow measured timings: two uninterrupted runs can differ as much)."""
        n = q.size
        self._setup(form, n)
        for name in ("qdd", "a"):
            a = np.asarray(arrays[name], dtype=np.float64)
            if a.shape != (n,):
                raise ValueError(f"scheme history {name!r}: expected shape ({n},), got {a.shape}")
            getattr(self, name)[:] = a

    def _setup(self, form, n: int) -> None:
        """Work arrays and a fresh modified-Newton state."""
        if not isinstance(form, Implicit) or not callable(form.factorize):
            raise TypeError(f"generalized-alpha: {form.method} does not offer force(), "
                            "mass_apply() and factorize() (the Implicit interface of "
                            "fxflex.formulation)")
        self.qdd, self.a = np.empty(n), np.empty(n)
        (self.abar, self.qb, self.vb, self.x, self.qn, self.vn, self.r, self.f, self.dx,
         self.w) = (np.empty(n) for _ in range(10))
        self.comm = form.comm
        self._parallel = self.comm.size > 1
        self._red, self._red_sum = np.zeros(3), np.zeros(3)
        self.factor = None
        self._h_factor = None
        self._h_last = None
        self._renew = True
        self._eta, self._eta_age = 1.0, 0
        self._budget = math.inf        # iterations a factorisation is worth (measured)
        self._excess = 0.0
        self._fresh_iters = None       # iterations of the first step with the current factor
        self._t_factor = 0.0
        self.last_theta = 0.0

    # -- one step -------------------------------------------------------------------------------
    def step(self, form, t: float, h: float, q: np.ndarray, v: np.ndarray) -> None:
        """Advance (q, v) from t to t + h, halving the step if Newton fails (module docstring)."""
        self._advance(form, t, h, q, v, 0)
        self.stats["steps"] += 1

    def _advance(self, form, t: float, h: float, q, v, depth: int) -> None:
        if self._attempt(form, t, h, q, v):
            return
        if depth == self.max_halvings:
            raise NewtonFailure(
                f"generalized-alpha: Newton did not converge at t = {t + h:.6g} s with a fresh "
                f"tangent, even with the step cut to {h:.3g} s ({2**depth}x smaller); last "
                f"contraction {self.last_theta:.3g}, {self._why}", t + h, t)
        self.stats["halvings"] += 1
        self._advance(form, t, 0.5 * h, q, v, depth + 1)
        self._advance(form, t + 0.5 * h, 0.5 * h, q, v, depth + 1)

    def _attempt(self, form, t: float, h: float, q, v) -> bool:
        """One step of size h; commits (q, v, qdd, a) only on convergence."""
        am, af, beta, gamma = self.am, self.af, self.beta, self.gamma
        kappa = (1.0 - af) / (1.0 - am)
        cq, cv = h * h * beta * kappa, h * gamma * kappa
        # a_{n+1} = kappa x + abar; q_{n+1} = qb + cq x; v_{n+1} = vb + cv x
        abar, qb, vb, w = self.abar, self.qb, self.vb, self.w
        np.multiply(self.qdd, af / (1.0 - am), out=abar)
        np.multiply(self.a, -am / (1.0 - am), out=w)
        abar += w
        np.multiply(v, h, out=qb)
        qb += q
        np.multiply(self.a, h * h * (0.5 - beta), out=w)
        qb += w
        np.multiply(abar, h * h * beta, out=w)
        qb += w
        np.multiply(self.a, h * (1.0 - gamma), out=vb)
        vb += v
        np.multiply(abar, h * gamma, out=w)
        vb += w
        t1 = t + h
        renew = self.factor is None or self._renew or not self._serves(h)
        if not renew and h != self._h_factor and self._h_last != h:
            self._eta_age = _ETA_AGE       # a factor of another step: measure its contraction
        self._h_last = h
        for _ in range(2):
            if renew:
                try:
                    self._factorize(form, t1, cq, cv, h)
                except (np.linalg.LinAlgError, RuntimeError) as exc:   # PETSc.Error included
                    self.factor = None
                    self._why = f"the iteration matrix could not be factorised ({exc})"
                    return False
            ok, iters = self._newton(form, t1, q, cq, cv)
            if ok:
                self._book(iters)
                self._commit(form, t1, q, v, kappa, cq, cv)
                return True
            if renew:
                return False
            renew = True
            self.stats["retries"] += 1
        return False

    def _serves(self, h: float) -> bool:
        """Whether the factor made for ``_h_factor`` may be used for a step h (reuse_ratio)."""
        hf = self._h_factor
        if hf == h:
            return True
        return hf is not None and 1.0 / self.reuse_ratio <= h / hf <= self.reuse_ratio

    def _factorize(self, form, t1: float, cq: float, cv: float, h: float) -> None:
        """S = M + cv C_t + cq K_t at the predictor state (x = qdd_n)."""
        qn, vn = self.qn, self.vn
        np.multiply(self.qdd, cq, out=qn)
        qn += self.qb
        np.multiply(self.qdd, cv, out=vn)
        vn += self.vb
        form.constrain(t1, qn, vn)
        t0 = time.perf_counter()
        self.factor = form.factorize(t1, qn, vn, 1.0, cv, cq)
        self._t_factor = time.perf_counter() - t0
        self._h_factor = h
        self._renew = False
        self._excess = 0.0
        self._fresh_iters = None
        self._eta_age = _ETA_AGE          # measure the new factor's contraction at once
        self.stats["factorizations"] += 1

    def _newton(self, form, t1: float, q: np.ndarray, cq: float, cv: float) -> tuple[bool, int]:
        x, qn, vn, r, f, dx, w = self.x, self.qn, self.vn, self.r, self.f, self.dx, self.w
        x[:] = self.qdd
        prev = 0.0
        t0 = time.perf_counter()
        for k in range(1, self.max_iter + 1):
            np.multiply(x, cq, out=qn)
            qn += self.qb
            np.multiply(x, cv, out=vn)
            vn += self.vb
            form.constrain(t1, qn, vn)
            form.force(t1, qn, vn, f)           # first: M may depend on that q (TLF's tip body)
            form.mass_apply(x, r)
            r -= f
            self.factor.solve(t1, r, dx)
            x -= dx
            self.stats["iterations"] += 1
            np.subtract(qn, q, out=w)
            step, corr, size = self._norms(w, dx, qn)
            corr *= cq
            if not (math.isfinite(corr) and math.isfinite(step)):
                self._why = "non-finite residual"
                return False, k
            # below the round-off of q the contraction means nothing: that is converged
            floor = _ROUNDOFF * size
            target = max(min(self.tol * step, self.atol), floor)
            if k == 1:
                # the contraction is only measured from k = 2: trust an old one a few steps
                eta = max(self._eta, 1e-16) ** 0.8 if self._eta_age < _ETA_AGE else math.inf
            elif corr <= floor:
                # converged to round-off: the true correction is below the floor, so floor / prev
                # bounds the contraction from above, and that bound is what k = 1 trusts next
                # (not 0, which would accept any first correction)
                theta = min(floor / prev, 0.5) if prev > 0.0 else 0.5
                eta = 0.0
                self._eta, self._eta_age = theta / (1.0 - theta), 0
            else:
                theta = corr / prev
                self.last_theta = theta
                if theta >= 1.0:
                    self._why = "the iteration diverges"
                    return False, k
                eta = theta / (1.0 - theta)
                self._eta, self._eta_age = eta, 0
                if theta > 0.5:
                    self._renew = True
            if eta * corr <= target or corr <= floor:
                self._t_iter = (time.perf_counter() - t0) / k
                if k == 1:
                    self._eta_age += 1
                return True, k
            prev = corr
        self._why = f"no convergence in {self.max_iter} iterations"
        return False, self.max_iter

    def _norms(self, *arrays: np.ndarray) -> tuple[float, ...]:
        """Euclidean norms over the formulation's communicator (one reduction)."""
        red = self._red
        for i, a in enumerate(arrays):
            red[i] = np.dot(a, a)
        if self._parallel:
            self.comm.Allreduce(red, self._red_sum)
            red = self._red_sum
        return tuple(math.sqrt(red[i]) for i in range(len(arrays)))

    def _book(self, iters: int) -> None:
        """Renew the factor once the iterations it costs beyond a fresh one's add up to a
        factorisation (both measured; the budget is agreed on by every rank)."""
        if self._fresh_iters is None:
            self._fresh_iters = iters
            budget = self._t_factor / max(self._t_iter, 1e-9)
            if self._parallel:
                from mpi4py import MPI
                budget = self.comm.allreduce(budget, op=MPI.MAX)
            self._budget = max(budget, 1.0)
            return
        self._excess += max(iters - self._fresh_iters, 0)
        if self._excess >= self._budget:
            self._renew = True

    def _commit(self, form, t1: float, q: np.ndarray, v: np.ndarray, kappa: float, cq: float,
                cv: float) -> None:
        """(q, v) from the converged x (the last correction included), then a and qdd."""
        np.multiply(self.x, cq, out=q)
        q += self.qb
        np.multiply(self.x, cv, out=v)
        v += self.vb
        form.constrain(t1, q, v)
        np.multiply(self.x, kappa, out=self.a)
        self.a += self.abar
        self.qdd[:] = self.x

    def state_arrays(self) -> dict[str, np.ndarray]:
        """History needed to resume exactly (checkpoints): qdd_n and a_n."""
        return {"qdd": self.qdd, "a": self.a}
