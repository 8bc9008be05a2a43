"""NEBB: Euler-Bernoulli beam with von Karman strain in the floating frame (Sect. 3.2, Eq. 45-48).

Kinematics, inertia and damping are LEBB's (:mod:`fxflex.beam.frame`), except that NEBB's
spin-softening matrix N and phi'' stiffness carry the second-order rotation of its sections and
tip body (the propeller moment, docs/beams.md); the axial strain gains the
von Karman term, eps_X = W_X' - Z0 W_Z'' - Y0 W_Y'' + (W_Y'^2 + W_Z'^2) / 2 (Eq. 45). Over a
section the strain energy becomes

    V = 1/2 W^T K_L W + 1/2 int N_L(X) w(X) dX + 1/8 int E A w(X)^2 dX,
    w = W_Y'^2 + W_Z'^2,   N_L = e1(X) . W = E A W_X' - E S_Y W_Z'' - E S_Z W_Y''

(e1 is the first column of the paper's E_1 applied to L_2 N_E). W_Y' and W_Z' use the same four
Hermite derivatives d(X), so with the slot matrix B (rows: the 4 Hermite functions, columns: the
Y and Z coefficients) w = d^T B B^T d and the invariant tensors of Eq. 48 are

    T1[k, p, q] = int e1_k d_p d_q dX      (K_N1e = T1 / 2, K_N2e = T1^T)
    T4[p, q, r, s] = int E A d_p d_q d_r d_s dX      (K_N3e = T4 / 2).

``force_eval = "invariant"`` evaluates them as system invariant matrices
(:class:`~fxflex.beam.invariants.GramChain`); ``"element"`` integrates the element matrix of Eq. 66
at the Gauss points every step, K_Ne = l_e int [B_N^T E_1^T L_2 N_E + 1/2 N_E^T L_2^T E_1 B_N +
1/2 B_N^T E_3 B_N] dxi with B_N from Eq. 45, and assembles K_Ne W_e.

``mesh.beam_variant = "locking-free"`` (docs/beams.md, "Locking-free variants"): the membrane
strain of Eq. 45 takes the element mean of the von Karman term, eps_X = W_X' + mean_e(w) / 2 -
Z0 W_Z'' - Y0 W_Y'' (the L2 projection of w / 2 onto the constants, the space of the P1 axial
strain W_X'), which removes membrane locking. In the tensors d_p d_q becomes its element mean
D_pq = mean_e(d_p d_q): T1[k, p, q] = (int e1_k dX) D_pq, T4 = (int E A dX) D_pq D_rs; in Eq. 66
B_N becomes its element mean. Same coordinates, same cost per step.
"""

from __future__ import annotations

import time

import numpy as np

from fxflex.beam.frame import FloatingFrameBeam
from fxflex.beam.invariants import GramChain
from fxflex.formulation import FORCE_EVAL, BuildOptions
from fxflex.scene import Scene

__all__ = ["build", "dof_count", "NEBB", "SLOT_MAP", "SLOT_SIGN"]

#: element slot s (Hermite function [value_i, slope_i, value_j, slope_j]) x component (Y, Z) ->
#: element coordinate: W_Y = N2 W_Y + N3 theta_Z, W_Z = N2 W_Z - N3 theta_Y (Eq. 37)
SLOT_MAP = np.array([[1, 2], [5, 4], [7, 8], [11, 10]])
SLOT_SIGN = np.array([[1.0, 1.0], [1.0, -1.0], [1.0, 1.0], [1.0, -1.0]])


class NEBB(FloatingFrameBeam):
    """Von Karman beam: Q_k = (K_L + K_N(W)) W (Eq. 48)."""

    nonlinear = True

    def __init__(self, scene: Scene, force_eval: str | None = None):
        super().__init__(scene, "nebb")
        t0 = time.perf_counter()
        self.force_eval = force_eval or FORCE_EVAL["nebb"][0]
        self.variant = scene.mesh.beam_variant
        line, tab = self.line, self.tab
        sec, dx = line.sec, line.dx
        E = scene.material.E
        EA = E * sec.A
        # e1 = E1[:, 0]^T L_2 N_E: the axial force of the linear strain per unit W_e
        self.e1 = (EA[..., None] * tab.B[None, :, 0, :] - (E * sec.S_Y)[..., None] * tab.B[:, 1]
                   - (E * sec.S_Z)[..., None] * tab.B[:, 2])                  # (n_el, nq, 12)
        d = tab.d
        if self.variant == "paper":
            T1 = np.einsum("eq,eqk,qp,qr->ekpr", dx, self.e1, d, d)
            T4 = np.einsum("eq,qp,qr,qs,qt->eprst", dx * EA, d, d, d, d)
        else:                       # element-mean membrane strain: D_pq = mean_e(d_p d_q)
            D = np.einsum("q,qp,qr->pr", line.w, d, d)
            T1 = np.einsum("eqk,pr->ekpr", dx[..., None] * self.e1, D)
            T4 = np.einsum("e,pr,st->eprst", np.sum(dx * EA, axis=1), D, D)
        # the system matrices serve the time loop's invariant route only: built on its first
        # force (a steady state or modes analysis never needs them: half of a small build)
        self.engine = GramChain(T1, T4, dpn=6, spn=2, emap=SLOT_MAP, esign=SLOT_SIGN,
                                system=False)
        # Eq. 66 work arrays
        n_el, nq = line.n_el, len(line.xi)
        self.EA = EA
        self.dx_e1 = dx[..., None] * self.e1
        self._wY, self._wZ = np.zeros((n_el, nq)), np.zeros((n_el, nq))
        self._bn, self._bt = np.zeros((n_el, nq, 12)), np.zeros((n_el, nq, 12))
        self._a2 = np.zeros((n_el, nq, 12))
        self._bmean = np.zeros((n_el, 12)) if self.variant != "paper" else None
        self._Ke, self._Kt = np.zeros((n_el, 12, 12)), np.zeros((n_el, 12, 12))
        self._fe = np.zeros((n_el, 12, 1))
        self.timings["invariants"] = time.perf_counter() - t0

    def add_nonlinear_force(self, Wfull: np.ndarray, out: np.ndarray) -> None:
        if self.force_eval == "invariant":
            self.engine.add_force_system(Wfull, out)
        else:
            self.add_force_eq66(Wfull, out)

    def initial_state(self) -> tuple[np.ndarray, np.ndarray]:
        """As the frame's; a time loop follows, so the invariant route's system matrices are
        built here, before its clock starts (a steady state or modes never needs them)."""
        if self.force_eval == "invariant":
            self.engine.prepare_system()
        return super().initial_state()

    def add_static_force(self, Wfull: np.ndarray, out: np.ndarray) -> None:
        """The element invariant route (the same force to round-off; no system matrices)."""
        self.engine.add_force_element(Wfull, out)

    def add_force_eq66(self, Wfull: np.ndarray, out: np.ndarray) -> None:
        """out += sum_e K_Ne(W_e) W_e with K_Ne integrated at the Gauss points (Eq. 66)."""
        tab, dx = self.tab, self.line.dx
        ue = self.engine.element_views(Wfull)
        np.matmul(ue, tab.dY.T, out=self._wY)                  # W_Y' at the Gauss points
        np.matmul(ue, tab.dZ.T, out=self._wZ)
        bn, bt = self._bn, self._bt                            # B_N = (L_3 N_E W)^T L_3 N_E
        np.multiply(self._wY[..., None], tab.dY, out=bn)
        np.multiply(self._wZ[..., None], tab.dZ, out=bt)
        bn += bt
        if self._bmean is not None:                          # locking-free: element mean of B_N
            np.matmul(self.line.w, bn, out=self._bmean)
            bn[...] = self._bmean[:, None, :]
        # K_Ne = sum_q dx [B_N^T e1 + 1/2 e1^T B_N + 1/2 EA B_N^T B_N]
        np.multiply(bn, dx[..., None], out=bt)
        np.multiply(bn, 0.5 * self.EA[..., None], out=self._a2)
        self._a2 += self.e1
        np.matmul(bt.transpose(0, 2, 1), self._a2, out=self._Ke)
        np.matmul(self.dx_e1.transpose(0, 2, 1), bn, out=self._Kt)
        self._Kt *= 0.5
        self._Ke += self._Kt
        np.matmul(self._Ke, ue[..., None], out=self._fe)
        nodes = out.reshape(-1, 6)
        nodes[:-1] += self._fe[:, :6, 0]
        nodes[1:] += self._fe[:, 6:, 0]

    def nonlinear_tangent(self, Wfull: np.ndarray) -> np.ndarray:
        return self.engine.tangent(Wfull)


def build(scene: Scene, comm, options: BuildOptions | None = None) -> NEBB:
    """Replicated on every rank: ``form.comm`` is COMM_SELF."""
    options = options or BuildOptions()
    return NEBB(scene, options.force_eval)


def dof_count(scene: Scene) -> int:
    """Six coordinates per node, root node clamped."""
    return 6 * scene.mesh.beam_elements
