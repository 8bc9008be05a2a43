"""The beam line: equal elements along X from the root, Gauss points, section properties there.

Element e joins nodes e and e + 1 at distances x_e = e l_e and x_e + l_e from the root (the root
is node 0, the free end node n_el). The section properties (area, moments, torsion constants of the
twisted tapered rectangle, paper Eq. 41) come in closed form from
:class:`fxflex.mesh.geometry.BeamShape` at every Gauss point.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fxflex.beam.elements import gauss
from fxflex.errors import SceneError
from fxflex.mesh.geometry import BeamShape, SectionProperties
from fxflex.scene import Scene
from fxflex.scene.load import MAX_TWIST_PER_ELEMENT_DEG

__all__ = ["BeamLine", "beam_line", "twist_check", "twist_error", "TWIST_ERROR", "WARN_ERROR"]

#: relative error of the tip deflection caused by the twist dtheta (rad) between an element's
#: ends, e ~ a dtheta^p, (a, p) measured (docs/robustness.md): LEBB and NEBB at twist_deg 180 to
#: 1440 against 320 elements converge at 4th order (the Hermite bending field follows the turning
#: principal axes); ANCF at 180 deg against the Richardson extrapolation of 48, 96 and 192
#: elements, less the untwisted beam's own error, at order 1.8 (its section gradients
#: interpolate the turn by its chord, cos^2(dtheta / 2) of the section mid-element). Upper bounds
#: from 45 deg per element down; 1.6 (LEBB) and 1.4 (ANCF) times the measured error at 90 deg.
TWIST_ERROR = {"lebb": (0.0122, 4.0), "nebb": (0.0122, 4.0), "ancf": (0.27, 1.8)}
#: estimated error above which the build warns (and says how many elements bring it to 1e-3):
#: LEBB and NEBB beyond 54 deg per element, ANCF beyond 9.2 deg (the paper's scene: 4.5 deg)
WARN_ERROR = 1e-2


@dataclass(frozen=True)
class BeamLine:
    n_el: int
    le: float
    length: float
    hub_radius: float
    x_nodes: np.ndarray          # (n_el + 1,) distance of each node from the root
    xi: np.ndarray               # (nq,) Gauss points on [0, 1]
    w: np.ndarray                # (nq,) weights on [0, 1]
    xq: np.ndarray               # (n_el, nq) distance of each Gauss point from the root
    dx: np.ndarray               # (n_el, nq) weight x element length
    sec: SectionProperties       # arrays (n_el, nq)
    shape: BeamShape

    @property
    def n_nodes(self) -> int:
        return self.n_el + 1


def beam_line(scene: Scene, nq: int) -> BeamLine:
    """Discretise the scene's beam into ``mesh.beam_elements`` equal elements, nq Gauss points
    each."""
    g = scene.geometry
    n_el = scene.mesh.beam_elements
    le = g.length / n_el
    xi, w = gauss(nq)
    x_nodes = le * np.arange(n_el + 1)
    xq = x_nodes[:-1, None] + le * xi[None, :]
    shape = BeamShape(g)
    return BeamLine(n_el=n_el, le=le, length=g.length, hub_radius=g.hub_radius, x_nodes=x_nodes,
                    xi=xi, w=w, xq=xq, dx=np.broadcast_to(le * w, xq.shape).copy(),
                    sec=shape.section(xq), shape=shape)


def twist_error(method: str, per_element_deg: float) -> float:
    """Estimated relative error of the tip deflection from the twist per element (TWIST_ERROR)."""
    a, p = TWIST_ERROR[method]
    return a * math.radians(per_element_deg) ** p


def twist_check(scene: Scene, method: str) -> list[str]:
    """The solid's limit for the beams: refuse more than MAX_TWIST_PER_ELEMENT_DEG (90 deg) of
    twist between an element's ends, where LEBB's and NEBB's tip deflection is off by 4 % or more
    (30 % at 180 deg: 720 deg on 4 elements) and ANCF's by 48 %; above an estimated error of
    WARN_ERROR, one warning with it and the element count that brings it to 1e-3."""
    twist = abs(scene.geometry.twist_deg)
    n_el = scene.mesh.beam_elements
    per = twist / n_el
    what = f"{n_el} {method.upper()} elements twist by {per:g} deg each (geometry.twist_deg = " \
           f"{scene.geometry.twist_deg!r})"
    if per > MAX_TWIST_PER_ELEMENT_DEG:
        need = math.ceil(twist / MAX_TWIST_PER_ELEMENT_DEG)
        raise SceneError("mesh.beam_elements", f"{what}: beyond {MAX_TWIST_PER_ELEMENT_DEG:g} deg "
                                               f"per element the tip deflection is off by more "
                                               f"than 4 % (30 % at 180 deg); allowed: at least "
                                               f"{need:.6g} elements")
    error = twist_error(method, per)
    if not error > WARN_ERROR:
        return []
    a, p = TWIST_ERROR[method]
    good = math.ceil(twist / math.degrees((1e-3 / a) ** (1.0 / p)))
    return [f"{what}: the twist alone puts the tip deflection off by up to {100 * error:.2g} % "
            f"(estimated {a:g} x (twist per element in rad)^{p:g}, measured); "
            f"mesh.beam_elements >= {good} brings it to 0.1 %"]
