"""The convergence cases of issue 13 and the fitted order of an error sequence.

Three cases, each a :class:`~fxflex.scene.Scene` built from the default one:

- (i) the default blade's equilibrium (SPEC section 1) at 1000 and 10000 rpm, measured against
  the stored converged reference (:mod:`fxflex.analysis.reference`): :func:`default_blade`;
- (ii) the slender spin-up (L = 10 m, EA = 2.8e7 N, EI = 1.4e4 N m^2, rhoA = 1.2 kg/m, spin-up
  to 6 rad/s over 15 s, no load), transient: :func:`slender_spinup`;
- (iii) the thin, strongly twisted cantilever (L = 12, 1.1 x 0.32, twist 90 deg, E = 29e6,
  nu = 0.22, unit tip force along Y or Z, at rest), static: :func:`thin_twisted`.

:func:`fitted_order` is the least-squares slope of log(error) against log(h) (h = 1 / n for n
elements), the observed order a convergence test checks.
"""

from __future__ import annotations

from typing import Mapping

import numpy as np

from fxflex.scene import Scene, scene_from_dict

__all__ = ["SLENDER_SPINUP", "THIN_TWISTED", "SPINUP_TIMES", "default_blade", "slender_spinup",
           "thin_twisted", "fitted_order"]

#: case (ii): the slender spin-up scene of issue 13
SLENDER_SPINUP = {
    "geometry": {"length": 10.0, "root_y": 0.0774597, "root_z": 0.0051640, "tip_y": 0.0774597,
                 "tip_z": 0.0051640, "twist_deg": 0.0},
    "material": {"E": 7.0e10, "nu": 0.3, "rho": 3000.0},
    "load": {"line_load": 0.0},
    "rotation": {"rpm": 57.29578, "profile": "spin-up", "spinup_time": 15.0},
}
#: the times (s) at which case (ii) is compared
SPINUP_TIMES = (2.5, 5.0, 7.5)

#: case (iii): the thin twisted cantilever of issue 13 (the tip force is set by thin_twisted)
THIN_TWISTED = {
    "geometry": {"length": 12.0, "root_y": 1.1, "root_z": 0.32, "tip_y": 1.1, "tip_z": 0.32,
                 "twist_deg": 90.0},
    "material": {"E": 29.0e6, "nu": 0.22},
    "load": {"line_load": 0.0},
    "rotation": {"rpm": 0.0},
}


def _merge(base: Mapping, extra: Mapping) -> dict:
    out = {k: dict(v) for k, v in base.items()}
    for k, v in extra.items():
        out.setdefault(k, {}).update(v)
    return out


def default_blade(rpm: float = 1000.0, mesh: Mapping | None = None) -> Scene:
    """Case (i): the default scene at ``rpm`` with the ``mesh`` keys given."""
    return scene_from_dict(_merge({"rotation": {"rpm": rpm}}, {"mesh": dict(mesh or {})}))


def slender_spinup(mesh: Mapping | None = None) -> Scene:
    """Case (ii) with the ``mesh`` keys given (beam_elements, beam_variant, ...)."""
    return scene_from_dict(_merge(SLENDER_SPINUP, {"mesh": dict(mesh or {})}))


def thin_twisted(direction: str, mesh: Mapping | None = None) -> Scene:
    """Case (iii) with a unit tip force along ``direction`` ("Y" or "Z")."""
    axes = {"Y": (0.0, 1.0, 0.0), "Z": (0.0, 0.0, 1.0)}
    if direction not in axes:
        raise ValueError(f"thin_twisted: direction {direction!r}; allowed: Y, Z")
    extra = {"load": {"tip_force": axes[direction]}, "mesh": dict(mesh or {})}
    return scene_from_dict(_merge(THIN_TWISTED, extra))


def fitted_order(n, err) -> float:
    """Least-squares slope p of log|err| = log C - p log h over the levels, h = 1 / n."""
    h = 1.0 / np.asarray(n, float)
    e = np.abs(np.asarray(err, float))
    if len(h) < 2 or np.any(e == 0.0):
        raise ValueError("fitted_order: needs two or more levels with non-zero errors")
    return float(np.polyfit(np.log(h), np.log(e), 1)[0])
