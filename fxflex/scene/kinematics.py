"""The prescribed hub rotation phi(t) about z and the rotation matrix A (paper Eq. 5).

NOTES.md notation: S = [[0,-1,0],[1,0,0],[0,0,0]] (S r = e_z x r), P = diag(1,1,0) = -S^2,
dA/dt = phi' S A. Profiles (SPEC section 8): ``constant`` (phi = Omega t) and ``spin-up``
(Omega(t) = Omega_s (t/T - sin(2 pi t/T) / (2 pi)) for t < T, Omega_s after; phi(0) = 0).
"""

from __future__ import annotations

import math

import numpy as np

from fxflex.scene.schema import Rotation

__all__ = ["Drive", "S3", "P3", "rotation_z", "rotation_cs"]

S3 = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
P3 = np.diag([1.0, 1.0, 0.0])


def rotation_z(phi: float, out: np.ndarray | None = None) -> np.ndarray:
    """A(phi): rotation by phi about z (paper Eq. 5); into ``out`` when given (see
    :func:`rotation_cs`)."""
    return rotation_cs(math.cos(phi), math.sin(phi), out)


def rotation_cs(c: float, s: float, out: np.ndarray | None = None) -> np.ndarray:
    """A from (cos phi, sin phi). With ``out``, a 3x3 array whose third row and column are the
    identity's (``np.eye(3)`` or a previous result), only the xy block is written: the time loops
    rotate preallocated arrays without allocating."""
    if out is None:
        return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    out[0, 0], out[0, 1], out[1, 0], out[1, 1] = c, -s, s, c
    return out


class Drive:
    """phi(t), phi'(t), phi''(t) of the prescribed rotation."""

    def __init__(self, rotation: Rotation):
        self.omega = rotation.omega
        self.spinup = rotation.profile == "spin-up"
        self.T = rotation.spinup_time

    @property
    def at_rest(self) -> bool:
        """True when phi, phi' and phi'' are identically zero (0 rpm, either profile): the
        formulations then drop their rotation terms instead of multiplying them by zero."""
        return self.omega == 0.0

    def angle(self, t: float) -> float:
        w, T = self.omega, self.T
        if not self.spinup:
            return w * t
        if t < T:
            return w * (t * t / (2 * T) + T * (math.cos(2 * math.pi * t / T) - 1) / (4 * math.pi**2))
        return w * (T / 2 + (t - T))

    def rate(self, t: float) -> float:
        w, T = self.omega, self.T
        if not self.spinup or t >= T:
            return w
        return w * (t / T - math.sin(2 * math.pi * t / T) / (2 * math.pi))

    def accel(self, t: float) -> float:
        w, T = self.omega, self.T
        if not self.spinup or t >= T:
            return 0.0
        return w / T * (1 - math.cos(2 * math.pi * t / T))

    def state(self, t: float) -> tuple[float, float, float]:
        """(phi, phi', phi'') at time t."""
        return self.angle(t), self.rate(t), self.accel(t)

    def A(self, t: float) -> np.ndarray:
        return rotation_z(self.angle(t))
