"""TLF at speed after speed (a Campbell diagram, ``fxflex modes --campbell``): what one speed can
give the next without changing its numbers.

A cold TLF build at each speed makes the mesh, the function space and the forms again, finds the
steady state by continuation in Omega^2 from the undeformed body (up to 4 stages at 12000 rpm, 5
Newton steps each on the default mesh) and starts SLEPc's Krylov search from a random vector. A
sweep instead

- builds the :class:`~fxflex.solid.model.SolidModel` once: nothing in it depends on the speed
  but the scene it carries, so each speed gets a shallow copy with its own scene (mesh, space,
  clamp, loads, probes and their caches shared);
- starts each steady Newton solve from the equilibria already found (:func:`predict`: the
  linear interpolation or extrapolation in Omega^2 of the two nearest, which is what the
  continuation in Omega^2 of :mod:`fxflex.solid.tlf_steady` would step along), converged to the
  same absolute residual as a cold solve; a start that fails falls back to the cold solve;
- factorises the PEP's shift-inverted operator P(0) = K as LDL^T when K is symmetric (relative
  damping: no circulatory term), and starts the Krylov search from the real parts of the nearest
  speed's mode vectors (SLEPc's initial space).

Every speed's roots are the cold build's to the eigensolver's tolerance and its equilibrium to
the Newton tolerance (tests/analysis/test_campbell_speed.py); docs/stability.md gives the times.
"""

from __future__ import annotations

import copy

import numpy as np

from fxflex.formulation import BuildOptions, SteadyState, build, rescene
from fxflex.scene import Scene
from fxflex.solid.tlf import TLF
from fxflex.solid.tlf_steady import STAGE_OMEGA, tlf_steady

__all__ = ["SpeedSweep", "predict", "KEEP_MODES"]

#: mode sets kept for the initial space (the latest: a refined speed lies between the last two)
KEEP_MODES = 3


def predict(known: list[tuple[float, np.ndarray]], omega: float
            ) -> tuple[float, np.ndarray] | None:
    """``start`` for :func:`~fxflex.solid.tlf_steady.tlf_steady` at omega from the equilibria
    ``known`` [(omega_i, U_i)]: the nearest in Omega^2, or, when a second one is known and the
    nearest lies within one continuation stage, the line through the two nearest evaluated at
    Omega^2 (then a prediction at omega itself). None when nothing is known."""
    if not known:
        return None
    w2 = omega**2
    near = sorted(known, key=lambda e: abs(e[0] ** 2 - w2))
    wa, Ua = near[0]
    if len(near) < 2 or abs(wa**2 - w2) > STAGE_OMEGA**2:
        return wa, Ua
    wb, Ub = near[1]
    return omega, Ua + ((w2 - wa**2) / (wb**2 - wa**2)) * (Ub - Ua)


class SpeedSweep:
    """TLF formulations of ``scene`` at other speeds (:meth:`at`) that share one SolidModel and
    continue each other's steady states and eigensolves (module docstring)."""

    def __init__(self, scene: Scene, comm, options: BuildOptions | None = None):
        self.scene, self.comm = scene, comm
        self.options = options or BuildOptions()
        self.model = None
        self.equilibria: list[tuple[float, np.ndarray]] = []
        self.modes: list[tuple[float, np.ndarray]] = []
        self.cold_fallbacks = 0         # warm starts that did not converge (solved cold)

    def at(self, rpm: float) -> TLF:
        """The member at ``rpm``; the first is built (and checked) as any build is."""
        scene = rescene(self.scene, rpm=rpm)
        if self.model is None:
            self.model = build("tlf", scene, self.comm, self.options).model
        model = copy.copy(self.model)               # shares everything but the scene
        model.scene = scene
        form = TLF(scene, self.comm, self.options, model=model, sweep=self)
        form.options = self.options
        return form

    def steady(self, form: TLF, linear: str = "direct") -> SteadyState:
        """The steady state of a member, from the known equilibria (cold when none converges),
        its Newton steps solved by the ``linear`` route."""
        omega = form.scene.rotation.omega
        start = predict(self.equilibria, omega)
        st = tlf_steady(form.model, omega, start=start, linear=linear)
        if start is not None and not st.converged:
            self.cold_fallbacks += 1
            st = tlf_steady(form.model, omega, linear=linear)
        if st.converged:
            self.equilibria.append((omega, st.q.copy()))
        return st

    def eigen_start(self, form: TLF, absolute: bool) -> dict:
        """The PEP's ``symmetric`` and ``initial`` for a member (module docstring)."""
        from fxflex.solid.rotating import k_symmetric

        omega = form.scene.rotation.omega
        symmetric = k_symmetric(form.scene)
        initial = None
        if self.modes:
            _, X = min(self.modes, key=lambda e: abs(e[0] ** 2 - omega**2))
            initial = np.ascontiguousarray(X.real)
        return {"symmetric": symmetric, "initial": initial}

    def record_modes(self, form: TLF, X: np.ndarray) -> None:
        """Keep a member's mode vectors (the widest set at its speed) for the next speeds."""
        omega = form.scene.rotation.omega
        same = [i for i, (w, _) in enumerate(self.modes) if w == omega]
        if same and self.modes[same[0]][1].shape[1] >= X.shape[1]:
            return
        self.modes = [e for e in self.modes if e[0] != omega][-(KEEP_MODES - 1):]
        self.modes.append((omega, X))
