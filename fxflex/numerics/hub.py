"""The factor of an iteration matrix held in the hub frame (TLF, ANCF).

When the forces are objective and the mass commutes with the hub rotation A = A(phi(t)) applied
per 3-vector slot (A_d), the iteration matrix of implicit integration is S(t) = A_d S_hub A_d^T,
so one factor of S_hub stays the tangent while the body turns: S^-1 r = A_d S_hub^-1 A_d^T r.
"""

from __future__ import annotations

import numpy as np

from fxflex.scene.kinematics import rotation_z

__all__ = ["HubFrameFactor"]


class HubFrameFactor:
    """``solve(t, r, out)``: out = A_d S_hub^-1 A_d^T r, allocating nothing. ``drive`` gives
    phi(t); ``rhs`` and ``sol`` are flat arrays (3 entries per slot, they may be one array);
    subclasses implement ``solve_hub()``: sol = S_hub^-1 rhs."""

    def __init__(self, drive, rhs: np.ndarray, sol: np.ndarray):
        self.drive, self.rhs, self.sol = drive, rhs, sol
        self._rotation = np.eye(3)

    def solve_hub(self) -> None:
        raise NotImplementedError

    def solve(self, t: float, r: np.ndarray, out: np.ndarray) -> None:
        A = rotation_z(self.drive.angle(t), self._rotation)
        np.matmul(r.reshape(-1, 3), A, out=self.rhs.reshape(-1, 3))          # A^T r per slot
        self.solve_hub()
        np.matmul(self.sol.reshape(-1, 3), A.T, out=out.reshape(-1, 3))      # A x per slot
