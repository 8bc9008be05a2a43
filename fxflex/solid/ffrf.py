"""FFRF: floating frame of reference, relative elastic coordinates, modal reduction (Sect. 2.1).

The elastic displacement, measured in the rotating frame O-XYZ, is U = Phi eta with the clamped
eigenmodes Phi (Phi^T M Phi = I, Phi^T K_L Phi = Lambda; :mod:`fxflex.solid.cms`). With the
rotation phi(t) prescribed, the kinetic energy of Eq. 11,

    T = 1/2 int rho |phi' S (X0 + U) + U'|^2 dV
      = 1/2 phi'^2 (J0 + 2 n.eta + eta^T N eta) + phi' (g + G eta).eta' + 1/2 eta'.eta',

gives through Lagrange's equations (Eq. 17: M q'' = Q_e + Q_v - Q_d - Q_k) the elastic rows

    eta'' + (2 phi' G + (c/rho) I) eta' + (Lambda + phi'' G - phi'^2 N) eta
        = r(t) Phi^T F - phi'' g + phi'^2 n                                       (NOTES.md)

with the four inertia invariants G, N, g, n (module :mod:`fxflex.solid.reduction`). The
quadratic velocity vector of Eq. 17 is Q_v = (-2 phi' G eta' + phi'^2 (n + N eta),
-2 phi' (n + N eta).eta') in (eta, phi) rows. Damping: the relative model F_d = -c U' (Eq. 15-16)
gives (c/rho) eta'; the absolute one (SPEC section 5) adds the circulatory (c/rho) phi' G eta.
As in the paper, D_rf2 (the deformation-dependent lever arm of the damping force in the reference
rows, Eq. 16) is neglected; it only enters the drive torque.

The drive torque is the phi row of Lagrange's equations -- what the hub must apply to hold phi(t):

    tau = d/dt (dT/dphi') - Q_phi
        = phi'' (J0 + 2 n.eta + eta^T N eta) + 2 phi' (n + N eta).eta' + (g + G eta).eta''
          - r(t) (s0 + b.eta) - Q_phi^d,

s0 + b.eta the torque of the external load about z, Q_phi^d = -(c/rho) (g.eta' [+ phi' n.eta]).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from fxflex.formulation import BuildOptions
from fxflex.scene import Scene
from fxflex.scene.kinematics import P3, S3
from fxflex.solid.reduction import (MeshData, ReducedFormulation, RotatingSystem,
                                  director_corrections, inner, mat_apply, nodal, reduced_key,
                                  tip_rows)

if TYPE_CHECKING:                   # a cache hit needs neither dolfinx nor SLEPc: imported on use
    from fxflex.solid.cms import ClampedModes
    from fxflex.solid.model import SolidModel

__all__ = ["FFRF", "FFRFInvariants", "ffrf_invariants", "build", "dof_count"]


def dof_count(scene: Scene) -> int:
    return scene.reduction.ffrf_modes


@dataclass
class FFRFInvariants:
    """Mesh integrals projected on the modes (docs/reduced.md), replicated on every rank."""

    Lambda: np.ndarray      # Phi^T K_L Phi (= diag omega^2)
    G: np.ndarray           # int rho Phi^T S Phi (skew): Coriolis, paper M_rf3 up to sign
    N: np.ndarray           # int rho Phi^T P Phi: spin softening, paper M_rr6
    g: np.ndarray           # int rho Phi^T S X0: tangential (Euler) load per unit phi''
    n: np.ndarray           # int rho Phi^T P X0: centrifugal load per unit phi'^2, M_rr2(,1)
    fe: np.ndarray          # Phi^T F: external load after the ramp
    b: np.ndarray           # Phi^T S^T F: torque of F about z per unit eta
    tip: np.ndarray         # (3, m) tip-centre displacement per unit eta
    section: np.ndarray     # (6, m) tip-centre translation and tip-section rotation per unit eta
    J0: float               # int rho X0^T P X0
    s0: float               # (S X0) . F: torque of F about z on the undeformed body


def ffrf_invariants(model: SolidModel, data: MeshData, Phi: np.ndarray) -> FFRFInvariants:
    """Project the mesh integrals on the modes Phi (n_owned, m); collective on model.comm.

    M commutes with the nodal 3x3 operators, so int rho Phi^T B Phi = (M Phi)^T (B_d Phi); a
    tip body's Pi_XX does not, and :func:`director_corrections` mends its share.
    """
    comm = model.comm
    MPhi = mat_apply(data.M, Phi)
    Lam = inner(comm, Phi, mat_apply(data.K, Phi))
    SPhi, PPhi = nodal(S3, Phi), nodal(P3, Phi)
    G = inner(comm, MPhi, SPhi)
    N = inner(comm, MPhi, PPhi)
    fix = director_corrections(data, Phi, [(S3, SPhi), (P3, PPhi)])  # a tip body's Pi_XX
    if fix:
        G, N = G + fix[0], N + fix[1]
    return FFRFInvariants(
        Lambda=0.5 * (Lam + Lam.T), G=0.5 * (G - G.T), N=0.5 * (N + N.T),
        g=inner(comm, Phi, data.f_S), n=inner(comm, Phi, data.f_c), fe=inner(comm, Phi, data.F),
        b=inner(comm, Phi, nodal(S3.T, data.F)), tip=tip_rows(model, Phi),
        section=model.tip_section(Phi), J0=data.J0,
        s0=data.load_torque)


class FFRF(ReducedFormulation):
    """FFRF with ``reduction.ffrf_modes`` clamped modes behind the Formulation interface.

    ``model``, ``data`` and ``modes`` may be passed to share them with other builds (studies
    over the number of modes, FFRF next to GCMS); the first ``ffrf_modes`` modes are used.
    """

    method = "ffrf"

    def __init__(self, scene: Scene, comm, options: BuildOptions | None = None, *,
                 modes: ClampedModes | None = None, model: SolidModel | None = None,
                 data: MeshData | None = None):
        super().__init__(scene, comm, options)
        t0 = time.perf_counter()
        count = scene.reduction.ffrf_modes
        cached = self._use(count, model, data, modes)
        key = reduced_key(scene, "ffrf", count) if cached else None
        self.inv = inv = self._projections(key, FFRFInvariants, ffrf_invariants)
        self.dof = inv.Lambda.shape[0]
        self.rot = RotatingSystem(K=inv.Lambda, G=inv.G, N=inv.N, f=inv.fe, n=inv.n, tip=inv.tip,
                                  section=inv.section)
        self._build_operators()
        self.timings["build"] = time.perf_counter() - t0

    def _build_operators(self) -> None:
        inv, cr, eye = self.inv, self.c_rho, np.eye(self.dof)
        ab = 1.0 if self.absolute else 0.0
        if self.constant_speed:
            # everything but the load ramp is constant: one matrix each for q and v
            w = self.omega_s
            K = inv.Lambda - w * w * inv.N + ab * cr * w * inv.G
            C = 2.0 * w * inv.G + cr * eye
            if self.drive.at_rest:               # no centrifugal load column
                self._setup_operators([-inv.Lambda], [-cr * eye], [inv.fe])
            else:
                self._setup_operators([-K], [-C], [inv.fe, w * w * inv.n])
                self.fw[1] = 1.0
        else:
            self._setup_operators([-inv.Lambda, -inv.G, inv.N], [-inv.G, -eye],
                                  [inv.fe, inv.g, inv.n])
            self._ab = ab

    def _weights(self, t: float) -> None:
        if self.constant_speed:
            self.fw[0] = self.ramp(t)
            return
        _, w, a = self.drive.state(t)
        kw, cw, fw = self.kstack.w, self.cstack.w, self.fw
        kw[1] = a + self._ab * self.c_rho * w
        kw[2] = w * w
        cw[0] = 2.0 * w
        cw[1] = self.c_rho
        fw[0] = self.ramp(t)
        fw[1] = -a
        fw[2] = w * w

    def tip(self, t: float, q: np.ndarray) -> np.ndarray:
        """U_tip = Phi_tip eta: the coordinates are already relative to the rotating frame."""
        return self.inv.tip @ q

    def nodal_basis(self) -> tuple[np.ndarray, bool]:
        return self.modes.vectors[:, : self.dof], False

    # -- reference-coordinate row and energies ---------------------------------------------------
    def drive_torque(self, t: float, q: np.ndarray, v: np.ndarray) -> float:
        """Torque (N m) about z that holds the prescribed rotation (module docstring)."""
        inv = self.inv
        _, w, a = self.drive.state(t)
        acc = self._acc
        self.acceleration(t, q, v, acc)
        Nq, Gq = inv.N @ q, inv.G @ q
        tau = (a * (inv.J0 + 2.0 * inv.n @ q + q @ Nq) + 2.0 * w * (inv.n + Nq) @ v
               + (inv.g + Gq) @ acc)
        tau -= self.ramp(t) * (inv.s0 + inv.b @ q)
        ab = 1.0 if self.absolute else 0.0
        tau += self.c_rho * (inv.g @ v + ab * w * (inv.n @ q))
        return float(tau)

    def kinetic_energy(self, t: float, q: np.ndarray, v: np.ndarray) -> float:
        """T of Eq. 11 in terms of the invariants (module docstring)."""
        inv = self.inv
        w = self.drive.rate(t)
        return float(0.5 * w * w * (inv.J0 + 2.0 * inv.n @ q + q @ inv.N @ q)
                     + w * (inv.g + inv.G @ q) @ v + 0.5 * v @ v)

    def strain_energy(self, t: float, q: np.ndarray) -> float:
        """V_e = eta^T Lambda eta / 2 (Eq. 14)."""
        return float(0.5 * q @ self.inv.Lambda @ q)


def build(scene: Scene, comm, options: BuildOptions) -> FFRF:
    return FFRF(scene, comm, options)
